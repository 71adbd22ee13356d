"""One contract for every method (issue 14): the registry, Observer.run/step, named state."""

import subprocess
import sys
from inspect import signature

import casadi as ca
import numpy as np
import pytest

from fmscal import plant
from fmscal.analysis.cli import build_parser, main
from fmscal.observers import METHODS, Method, Observer, ObserverResult, RecursiveObserver, make_observer, method_names
from fmscal.observers.core import start_velocity
from fmscal.observers.core._state import INPUT, StateLayout
from fmscal.plant.numerics._errors import FmscalError


@pytest.fixture(scope="module")
def short_log():
    sc = plant.get_scenario("vision-50hz").with_(duration=1.5)      # multi-rate: empty pose cells too
    log, truth, _ = sc.generate(5)
    return sc, log, truth


@pytest.mark.parametrize("name", list(METHODS))
def test_every_method_is_an_observer_with_one_run(name, short_log):
    sc, log, truth = short_log
    method = METHODS[name]
    obs = method.build(sc.payload, truth.noise, {"offset": True})
    assert isinstance(obs, Observer) and obs.name == name and obs.online == method.online
    result = obs.run(log, truth.S0 if obs.online else None)
    assert isinstance(result, ObserverResult) and result.observer == name
    n = len(result.t)
    assert n == len(log) and result.S_hat_history.shape == (n, 3, 3) and result.x_hat_history.shape == (n, 6)
    np.testing.assert_array_equal(result.S_hat, result.S_hat_history[-1])
    assert result.b is not None and result.b.shape == (3,)            # offset=True honoured by every method
    assert result.wall_time > 0


@pytest.mark.parametrize("name", method_names(online=False))
def test_an_offline_method_refuses_S0_and_has_no_step(name, short_log):
    sc, log, truth = short_log
    obs = make_observer(name, sc.payload, truth.noise)
    with pytest.raises(FmscalError, match="takes no starting estimate"):
        obs.run(log, truth.S0)
    with pytest.raises(TypeError, match="offline method.*no step"):
        obs.step(0.001, [0, 0, 0], [1, 2, 3])
    with pytest.raises(TypeError, match="offline method.*no reset"):
        obs.reset()


@pytest.mark.slow
@pytest.mark.parametrize("name", method_names(online=True))
def test_step_after_reset_agrees_with_run(name, short_log):
    sc, log, truth = short_log
    obs = make_observer(name, sc.payload, truth.told_noise_spec())
    result = obs.run(log, truth.S0)
    # a method whose run starts its motion at the velocity the log's first poses show (the EKF, eq. D1) is given
    # that start for its steps: a live run has no poses ahead of it
    start = {"velocity": start_velocity(log, obs.model)} if "velocity" in signature(obs.reset).parameters else {}
    obs.reset(truth.S0, **start)
    x_steps, S_steps = [], []
    for k in range(len(log)):
        pose = log.pose[k] if log.has_pose[k] else None
        x, S = obs.step(log.dt, pose, log.w_hat[k])
        x_steps.append(x)
        S_steps.append(S)
    # over the first 0.1 s the EKF's compensation (kalman._eiv) solves with a still rank-deficient information,
    # which amplifies the rounding by which its compiled run and its filterpy steps differ (tests/test_eiv.py)
    early = int(round(0.1 / log.dt))
    np.testing.assert_allclose(np.array(S_steps)[early:], result.S_hat_history[early:], rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.array(S_steps), result.S_hat_history, rtol=0, atol=1e-6)
    np.testing.assert_allclose(np.array(x_steps), result.x_hat_history, rtol=0, atol=1e-9)


def test_run_leaves_the_observer_ready_to_step_on():
    sc = plant.get_scenario("paper").with_(duration=1.0)
    log, truth, _ = sc.generate(1)
    whole = make_observer("high-gain", sc.payload).run(log, truth.S0)
    first = plant.Log(log.t[:600], log.pose[:600], log.w_hat[:600])
    obs = make_observer("high-gain", sc.payload)
    obs.run(first, truth.S0)
    for k in range(600, len(log)):
        _, S = obs.step(log.dt, log.pose[k], log.w_hat[k])
    np.testing.assert_allclose(S, whole.S_hat, atol=1e-9)


def test_S0_is_honoured_by_every_online_method(short_log):
    sc, log, truth = short_log
    for name in method_names(online=True):
        a = make_observer(name, sc.payload, truth.noise).run(log, truth.S0)
        b = make_observer(name, sc.payload, truth.noise).run(log, 2 * truth.S0)
        np.testing.assert_allclose(a.S_hat_history[0], truth.S0, err_msg=name)
        np.testing.assert_allclose(b.S_hat_history[0], 2 * truth.S0, err_msg=name)


def test_the_registry_is_the_only_list_of_names_the_cli_accepts(monkeypatch, tmp_path, capsys):
    fake = Method("fake", "fake", METHODS["high-gain"].cls, {}, needs_noise_model=False, online=True,
                  role="design", calibrates=True, summary="a method only this test knows")
    payload = ["--mass", "2.5", "--inertia", "0.75", "--rho", "0.2", "0.25"]
    # a method added to the registry is offered by calibrate, compare and sweep ...
    monkeypatch.setitem(METHODS, "fake", fake)
    args = build_parser().parse_args(["calibrate", "x.csv", *payload, "--observer", "fake"])
    assert args.observer == "fake"
    assert "fake" in method_names(role="design")
    # ... and one removed from it is refused by all of them
    monkeypatch.delitem(METHODS, "fake")
    monkeypatch.delitem(METHODS, "high-gain")
    with pytest.raises(SystemExit):
        build_parser().parse_args(["calibrate", "x.csv", *payload, "--observer", "high-gain"])
    for argv in (["compare", "--observer", "high-gain", "--duration", "0.1"],
                 ["sweep", "--observer", "high-gain", "--duration", "0.1", "--seeds", "1", "--jobs", "1"]):
        assert main(argv) == 2
        assert "unknown observer 'high-gain'" in capsys.readouterr().err


def test_no_module_keeps_its_own_list_of_method_names():
    """Names appear as data only in observers/_registry.py (docstrings and help texts aside)."""
    import ast
    import pathlib
    root = pathlib.Path(__file__).resolve().parents[1]
    names = set(METHODS)
    offenders = []
    for path in sorted([*root.glob("analysis/*.py"), *root.glob("observers/*.py")]):
        if path.name == "registry.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.Tuple, ast.List, ast.Set, ast.Dict)):
                elements = node.keys if isinstance(node, ast.Dict) else node.elts
                found = [e.value for e in elements if isinstance(e, ast.Constant) and e.value in names]
                if len(found) >= 2:
                    offenders.append(f"{path.name}:{node.lineno} {found}")
    assert not offenders, offenders


@pytest.mark.slow
def test_importing_every_module_leaves_the_matplotlib_backend_alone():
    code = ("import importlib, pkgutil, matplotlib\n"
            "from fmscal import analysis, observers, plant\n"
            "for pkg in (plant, observers, analysis):\n"
            "    for m in pkgutil.iter_modules(pkg.__path__):\n"
            "        importlib.import_module(pkg.__name__ + '.' + m.name)\n"
            "print(matplotlib.get_backend())\n")
    env = {**__import__("os").environ, "MPLBACKEND": "svg"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    assert out.stdout.strip().lower() == "svg"


def test_a_genuine_bug_keeps_its_traceback(monkeypatch):
    """The CLI turns the toolkit's input errors into one line; anything else is a bug and is raised."""
    import fmscal.analysis.cli._main as cli

    def broken(args):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(cli, "cmd_check_gains", broken)
    with pytest.raises(ZeroDivisionError):
        main(["check-gains"])


# --- named state -------------------------------------------------------------------
def test_state_layout_packs_and_unpacks_numbers_and_symbols_alike():
    layout = StateLayout(("x", 6), ("S", 9), ("t", 1))
    z = layout.pack(None, x=np.arange(6.0), S=np.eye(3).ravel(), t=2.5)
    s = layout.unpack(z)
    assert layout.size == 16 and s.t == 2.5
    np.testing.assert_array_equal(s.S, np.eye(3).ravel())
    zs = ca.SX.sym("z", layout.size)
    parts = layout.unpack(zs)
    ops = __import__("fmscal.plant.numerics._backend", fromlist=["ops"]).ops
    packed = layout.pack(ops(zs), x=parts.x, S=parts.S, t=parts.t)
    f = ca.Function("f", [zs], [packed])
    np.testing.assert_array_equal(np.array(f(z)).ravel(), z)
    with pytest.raises(ValueError, match="missing"):
        layout.pack(None, x=np.zeros(6), S=np.zeros(9))
    with pytest.raises(ValueError, match="unique"):
        StateLayout(("x", 1), ("x", 2))


def test_input_layout_is_the_sample_every_transition_reads():
    assert INPUT.names == ("has_pose", "pose", "w_hat") and INPUT.size == 7


@pytest.mark.parametrize("name", [n for n, m in METHODS.items() if issubclass(m.cls, RecursiveObserver)])
def test_no_recursive_observer_keeps_a_sample_in_its_state(name):
    """The samples reach the transition as inputs (issue 14): no state part holds a pose or a reading."""
    obs = make_observer(name, plant.PAPER_PAYLOAD)
    assert {"x", "S"} <= set(obs.state.names)
    assert not {"pose", "has", "w", "w_hat", "has_pose", "pose_n", "w_n"} & set(obs.state.names)
