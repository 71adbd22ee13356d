"""The compiled paths (C through buffers, or casadi's virtual machine) against the readable ones."""

import casadi as ca
import numpy as np
import pytest

from fmscal import plant
from fmscal.observers import AdaptiveObserver, HighGainObserver
from fmscal.plant.numerics import _compile as _compile
from fmscal.plant.numerics._compile import BufferedCall, compile_function
from fmscal.plant.physics._excitation import PaperWrench

LOGS = [("paper", 0), ("vision-50hz", 4), ("other-payload", 2)]


def _square():
    x = ca.SX.sym("x", 2)
    return ca.Function("square_plus", [x], [ca.vertcat(x[0] ** 2, x[1] + 1)])


def test_without_a_compiler_the_virtual_machine_runs(monkeypatch):
    monkeypatch.setenv("FMSCAL_COMPILER", "none")
    assert _compile.compiler() is None
    fun = _square()
    assert compile_function(fun) is fun


@pytest.mark.skipif(_compile.compiler() is None, reason="no C compiler on this machine")
def test_the_c_library_gives_the_same_numbers_and_is_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("FMSCAL_CACHE", str(tmp_path))
    fun = _square()
    compiled = compile_function(fun)
    assert compiled.class_name() == "External"
    assert len(list(tmp_path.glob("square_plus_*.so"))) == 1
    call = BufferedCall(compiled)
    call.inputs[0][:] = [3.0, 4.0]
    call()
    np.testing.assert_array_equal(call.outputs[0], [9.0, 5.0])


@pytest.mark.skipif(_compile.compiler() is None, reason="no C compiler on this machine")
def test_workers_that_need_the_same_library_build_it_once(tmp_path, monkeypatch):
    """Two threads (as two test or sweep workers on a fresh machine) ask for one new library at once: the
    compiler runs once, the other waits for its library (a slow compiler that counts its runs)."""
    import threading
    runs = tmp_path / "runs"
    slow_cc = tmp_path / "slow-cc"
    slow_cc.write_text(f"#!/bin/sh\necho run >> {runs}\nsleep 1\nexec {_compile.compiler()} \"$@\"\n")
    slow_cc.chmod(0o755)
    monkeypatch.setenv("FMSCAL_COMPILER", str(slow_cc))
    monkeypatch.setenv("FMSCAL_CACHE", str(tmp_path))
    x = ca.SX.sym("x", 2)
    fun = ca.Function("built_once", [x], [x * 3.0])
    results = []
    threads = [threading.Thread(target=lambda: results.append(compile_function(fun))) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert runs.read_text().splitlines() == ["run"]
    assert [f.class_name() for f in results] == ["External", "External"]
    assert len(list(tmp_path.glob("built_once_*.so"))) == 1


@pytest.mark.skipif(_compile.compiler() is None, reason="no C compiler on this machine")
def test_a_lock_that_cannot_be_taken_builds_unlocked(tmp_path, monkeypatch):
    """A file system without locks (flock raises, as on NFS without lockd): the library is built and used, not
    left to casadi's virtual machine."""
    def no_locks(handle, operation):
        raise OSError(37, "No locks available")
    monkeypatch.setenv("FMSCAL_CACHE", str(tmp_path))
    monkeypatch.setattr(_compile.fcntl, "flock", no_locks)
    x = ca.SX.sym("x", 2)
    compiled = compile_function(ca.Function("built_unlocked", [x], [x * 5.0]))
    assert compiled.class_name() == "External"


def test_a_failing_compiler_falls_back_with_one_warning(tmp_path, monkeypatch):
    monkeypatch.setenv("FMSCAL_COMPILER", "false")          # exits 1: a broken toolchain
    monkeypatch.setenv("FMSCAL_CACHE", str(tmp_path))
    monkeypatch.setattr(_compile, "_warned", [])
    fun = _square()
    with pytest.warns(RuntimeWarning, match="virtual machine"):
        assert compile_function(fun) is fun


def test_buffers_refuse_sparse_outputs():
    x = ca.SX.sym("x", 2)
    fun = ca.Function("sparse", [x], [ca.jacobian(ca.vertcat(x[0], x[1]), x)])   # a sparse identity
    with pytest.raises(ValueError, match="must be dense"):
        BufferedCall(fun)


@pytest.mark.slow
@pytest.mark.parametrize("backend", ["c", "vm"])
@pytest.mark.parametrize("scenario, seed", LOGS)
def test_fast_and_readable_observers_agree(backend, scenario, seed, monkeypatch):
    if backend == "vm":
        monkeypatch.setenv("FMSCAL_COMPILER", "none")
    elif _compile.compiler() is None:
        pytest.skip("no C compiler on this machine")
    sc = plant.get_scenario(scenario).with_(duration=2.0)
    log, truth, _ = sc.generate(seed)
    for obs in (AdaptiveObserver(sc.payload), HighGainObserver(sc.payload)):
        fast, slow = obs.run(log, truth.S0), obs.run(log, truth.S0, compiled=False)
        np.testing.assert_allclose(fast.S_hat_history, slow.S_hat_history, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(fast.x_hat_history, slow.x_hat_history, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("backend", ["c", "vm"])
def test_fast_and_readable_simulators_agree(backend, monkeypatch):
    if backend == "vm":
        monkeypatch.setenv("FMSCAL_COMPILER", "none")
        plant.physics._simulate._compiled_steps.cache_clear()
    t = np.arange(0, 1.2, 1e-3)                       # not a whole number of chunks
    payload = plant.Payload(6.0, 0.3, (-0.15, 0.4))
    fast = plant.integrate(payload, PaperWrench(), t)
    slow = plant.integrate(payload, PaperWrench(), t, compiled=False)
    plant.physics._simulate._compiled_steps.cache_clear()
    np.testing.assert_allclose(fast, slow, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("backend", ["c", "vm"])
@pytest.mark.parametrize("chunk", [25, 40])
def test_chunks_that_keep_only_the_last_state_run_the_same_recursion(backend, chunk, monkeypatch):
    """``keep_states=False``: the same last state and outputs as the chunks that keep every state, over a run
    that is not a whole number of chunks, and where a health test stops it within a chunk (the kept steps
    replayed); it refuses to keep every state. A chunk of 25 steps is written out step after step, one of 40
    is four blocks of 10 (``_compile._UNROLLED``)."""
    if backend == "vm":
        monkeypatch.setenv("FMSCAL_COMPILER", "none")
    z, a, b = ca.SX.sym("z", 3), ca.SX.sym("a", 2), ca.SX.sym("b")
    z_next = ca.vertcat(ca.sin(z[0]) + a[0] * z[2], z[1] * b + a[1], z[2] * 0.9 + z[0] / (1 + z[1] ** 2))
    step = ca.Function(f"last_state_test_{backend}_{chunk}", [z, a, b], [z_next, ca.vertcat(z_next[0] + z_next[1], b)])
    every = _compile.ChunkedSteps(step, chunk)
    last = _compile.ChunkedSteps(step, chunk, keep_states=False)
    rng = np.random.default_rng(3)
    inputs = [rng.standard_normal((263, 2)), rng.uniform(0.5, 1.0, (263, 1))]
    z0 = np.array([0.1, 0.2, 0.3])
    Z, (Y,) = every.run(z0, inputs, outputs=True)
    z_end, (Y_last,) = last.run(z0, inputs, outputs=True, states=False)
    np.testing.assert_allclose(z_end, Z[-1], rtol=1e-14, atol=0.0)
    np.testing.assert_allclose(Y_last, Y, rtol=1e-14, atol=0.0)

    def healthy(rows, k0):                    # stops at step 137, within a chunk
        return min(len(rows), max(137 - k0, 0))

    z_stop, (Y_stop,) = last.run(z0, inputs, healthy=healthy, outputs=True, states=False)
    assert len(Y_stop) == 137
    np.testing.assert_allclose(z_stop, Z[136], rtol=1e-14, atol=0.0)
    np.testing.assert_allclose(Y_stop, Y[:137], rtol=1e-14, atol=0.0)
    with pytest.raises(ValueError, match="keep_states=False"):
        last.run(z0, inputs)
