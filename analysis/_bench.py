"""The benchmark behind ``fmscal bench``: speed, measured against plain numpy in the same run.

Every figure is a ratio of two timings taken in the same process, minutes
apart, so that a shared, noisy machine moves both alike; each timing is the
best of two or three repeats (noise only ever adds time):

- each observer's compiled path (:meth:`observers.Observer.run`, a casadi
  step generated as C and called through buffers) against its readable path
  (``run(compiled=False)``: the same transition evaluated in numpy, one step
  at a time), on the paper's scenario;
- the whole run of the EKF (compiled, as by default) and of the
  maximum-likelihood floor against the adaptive default's on the same log;
  the EKF's readable path (filterpy's ``ExtendedKalmanFilter``) against
  filterpy's bare ``predict`` + ``update`` with matrices of the same sizes, and
  the casadi call through ``Function.buffer()`` against the same function
  called the ordinary way;
- the simulator's compiled RK4 against its numpy loop;
- the wall time of ``fmscal reproduce`` and of a Monte Carlo sweep, beside
  the time the readable paths would take for the same steps, estimated from
  the per-step costs measured above (running them would take hours).
"""

import os
import platform
import tempfile
import time
from dataclasses import dataclass

import numpy as np

from fmscal.plant import PAPER_PAYLOAD, SPATIAL_SCENARIOS, SpatialModel, compiler, get_scenario, integrate
from fmscal.plant.physics import PaperWrench

from fmscal.observers import FLOOR_METHOD, METHODS, AugmentedEKF, RecursiveObserver, make_observer, method_names

from ._comparison import run_case
from ._reproduce import REPRODUCED_OBSERVERS, REPRODUCED_SCENARIOS, reproduce
from ._sweep import SWEEP_OBSERVERS, sweep

__all__ = ["BenchSettings", "run_bench", "bench_markdown", "machine_description", "TARGETS"]

#: The targets of issues 7 and 25, checked by :func:`bench_markdown`: run times as ratios to the
#: adaptive default's on the same log, wall times in s.
TARGETS = {"compiled_over_numpy": 10.0, "steps_per_s_stretch": 1e6, "ekf_over_adaptive": 4.0,
           "floor_over_adaptive": 3.0, "reproduce_s": 60.0, "sweep_s": 90.0, "spatial_fit_s": 10.0,
           "spatial_adaptive_step_us": 5.0}
#: The method every run-time ratio is taken against.
_REFERENCE = "adaptive"
#: Observers whose compiled path is benchmarked: every registered recursive observer.
_COMPILED = tuple(m.name for m in METHODS.values() if issubclass(m.cls, RecursiveObserver))


@dataclass(frozen=True)
class BenchSettings:
    """How long each measurement runs.

    Parameters
    ----------
    fast_s : float
        Log length for the compiled paths, s of simulated time.
    numpy_s : float
        Log length for the readable (numpy) paths.
    ekf_s : float
        Log length for the EKF's readable (filterpy) path and bare filterpy.
    reproduce_scale : float
        Fraction of ``fmscal reproduce``'s scenario lengths (1: the real job).
    sweep_seeds : int
    sweep_s : float
        Length of each sweep run, s.
    spatial_s : float
        Length of the ``spatial-arm`` log (1 kHz) the spatial fits run on, s.
    """

    fast_s: float = 100.0
    numpy_s: float = 5.0
    ekf_s: float = 10.0
    reproduce_scale: float = 1.0
    sweep_seeds: int = 100
    sweep_s: float = 100.0
    spatial_s: float = 60.0

    @classmethod
    def quick(cls):
        """A short mode (a few seconds) that exercises every measurement; not for docs/speed.md."""
        return cls(fast_s=5.0, numpy_s=0.5, ekf_s=1.0, reproduce_scale=0.02, sweep_seeds=4, sweep_s=2.0,
                   spatial_s=2.0)


def machine_description():
    """CPU model, cores, Python and library versions, and the C compiler used."""
    import casadi               # their versions, for the report (filterpy is otherwise imported only when timed)
    import filterpy
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "numpy": np.__version__, "casadi": casadi.__version__, "filterpy": filterpy.__version__,
            "compiler": compiler() or "none (casadi virtual machine)", "platform": platform.platform()}


def _log(seconds, seed=0):
    log, truth, _ = get_scenario("paper").with_(duration=seconds).generate(seed)
    return log, truth


def _timed(fn):
    start = time.perf_counter()
    out = fn()
    return time.perf_counter() - start, out


def _best(fn, repeats):
    """The shortest of ``repeats`` timings (s): the machine's noise only ever adds time."""
    return min(_timed(fn)[0] for _ in range(repeats))


def _observer_speeds(s):
    """us per step: compiled (first run, with its build; then the best of 3) and readable (best of 2)."""
    fast_log, truth = _log(s.fast_s)
    numpy_log, _ = _log(s.numpy_s)
    rows = {}
    for name in _COMPILED:
        obs = make_observer(name, PAPER_PAYLOAD, truth.noise)
        first, _ = _timed(lambda: obs.run(fast_log, truth.S0))
        steady = _best(lambda: obs.run(fast_log, truth.S0), 3)
        readable = _best(lambda: obs.run(numpy_log, truth.S0, compiled=False), 2)
        rows[name] = {"first_run_us": 1e6 * first / len(fast_log), "compiled_us": 1e6 * steady / len(fast_log),
                      "numpy_us": 1e6 * readable / len(numpy_log)}
    return rows


def _bare_filterpy_us(n):
    """filterpy's ExtendedKalmanFilter predict + update, 15 states, 3 measurements, nothing else."""
    from filterpy.kalman import ExtendedKalmanFilter     # the bare filter timed, only here
    rng = np.random.default_rng(0)
    kf = ExtendedKalmanFilter(dim_x=15, dim_z=3)
    kf.F = np.eye(15) + 1e-3 * rng.standard_normal((15, 15))
    kf.Q = 1e-8 * np.eye(15)
    kf.R = 1e-6 * np.eye(3)
    H = np.zeros((3, 15))
    H[0, 0] = H[1, 2] = H[2, 4] = 1.0
    z = np.zeros((3, 1))
    elapsed = _best(lambda: [(kf.predict(), kf.update(z, lambda x: H, lambda x: H @ x)) for _ in range(n)], 2)
    return 1e6 * elapsed / n


def _ekf_speeds(s):
    """The EKF and the floor: whole runs against the adaptive default's (best of 3, the same log, interleaved),
    the readable path's step against bare filterpy, and the casadi call through buffers."""
    log, truth = _log(s.fast_s)
    runs = {"reference": make_observer(_REFERENCE, PAPER_PAYLOAD),
            "ekf_default": AugmentedEKF(PAPER_PAYLOAD, noise=truth.noise),
            "ekf_filter": AugmentedEKF(PAPER_PAYLOAD, noise=truth.noise, eiv=False),     # the filter of [3]
            "floor": make_observer(FLOOR_METHOD, PAPER_PAYLOAD, truth.noise)}
    for obs in runs.values():
        obs.run(log.head(10), truth.S0 if obs.online else None)                      # built once
    times = {name: [] for name in runs}
    for _ in range(3):            # interleaved: a slow spell of the shared machine slows every method alike
        for name, obs in runs.items():
            times[name].append(_timed(lambda: obs.run(log, truth.S0 if obs.online else None))[0])
    out = {f"{name}_run_s": min(t) for name, t in times.items()}
    slow_log, _ = _log(s.ekf_s)
    ekf = runs["ekf_default"]
    readable = _best(lambda: ekf.run(slow_log, truth.S0, compiled=False), 2)
    xs = np.concatenate([np.zeros(6), truth.S0.ravel()])
    w0, w1 = log.w_hat[0], log.w_hat[1]
    calls = 20000 if s.ekf_s >= 10 else 2000
    buffered = _best(lambda: [ekf.predict_matrices(xs, w0, w1, log.dt) for _ in range(calls)], 2)
    trigger = _best(lambda: [ekf._predict() for _ in range(calls)], 2)     # the compiled call alone
    fun = ekf._predict.fun
    var_w, S_Q, P_S, at_estimate, q_dt = np.ones(3), np.eye(3).ravel(), np.eye(9).ravel(), 1.0, 1e-8

    def ordinary():       # the EKF's predict: (xs, w0, w1, dt, var_w, S_Q, P_S, at_estimate, q_dt)
        res = fun(xs, w0, w1, log.dt, var_w, S_Q, P_S, at_estimate, q_dt)
        return [np.asarray(o) for o in res]

    plain = _best(lambda: [ordinary() for _ in range(calls // 10)], 2)
    out.update({"ekf_us": 1e6 * out["ekf_default_run_s"] / len(log), "ekf_numpy_us": 1e6 * readable / len(slow_log),
                "bare_filterpy_us": _bare_filterpy_us(len(slow_log)), "buffer_call_us": 1e6 * buffered / calls,
                "trigger_us": 1e6 * trigger / calls, "ordinary_call_us": 1e6 * plain / (calls // 10)})
    return out


def _simulator_speeds(s):
    excitation = PaperWrench()
    t_fast = np.arange(0.0, s.fast_s + 1e-9, 1e-3)
    t_numpy = np.arange(0.0, s.numpy_s + 1e-9, 1e-3)
    integrate(PAPER_PAYLOAD, excitation, t_fast[:10])            # build once
    fast = _best(lambda: integrate(PAPER_PAYLOAD, excitation, t_fast), 3)
    slow = _best(lambda: integrate(PAPER_PAYLOAD, excitation, t_numpy, compiled=False), 2)
    return {"compiled_us": 1e6 * fast / len(t_fast), "numpy_us": 1e6 * slow / len(t_numpy)}


def _numpy_us(name, observers, ekf):
    """Per-step cost of a method's readable path (the EKF's: filterpy's ``ExtendedKalmanFilter``).

    The maximum-likelihood floor has no plain path measured here: it counts
    0, so the estimates understate the plain time (the report says so).
    """
    if name in observers:
        return observers[name]["numpy_us"]
    if name == AugmentedEKF.name:
        return ekf["ekf_numpy_us"]
    return 0.0


def run_bench(settings=None, progress=True):
    """Run every measurement.

    Parameters
    ----------
    settings : BenchSettings, optional
        Default: the full benchmark (its run time: docs/speed.md).
    progress : bool
        Progress bars for the reproduction and the sweep.

    Returns
    -------
    dict
        ``machine``, ``settings``, ``observers`` (``{name: {first_run_us,
        compiled_us, numpy_us}}``), ``ekf`` (``reference_run_s`` (the adaptive default), ``ekf_default_run_s``,
        ``ekf_filter_run_s`` (``eiv=False``), ``floor_run_s``: whole runs on one log; ``ekf_us`` (compiled),
        ``ekf_numpy_us`` (filterpy), ``bare_filterpy_us``, ``buffer_call_us``, ``trigger_us``, ``ordinary_call_us``),
        ``simulator`` (``compiled_us``, ``numpy_us``), ``reproduce``
        and ``sweep`` (``wall_s``, ``numpy_estimate_s``, ``case_cpu_s`` (one case's processor time in
        this process), ``runs``, ``diverged``), ``spatial`` (``{method: s}``: whole fits of a
        ``spatial-arm`` log, the best of 2), ``spatial_online`` (``{method: {step_us, run_us}}``: the
        online methods' compiled step on that log, and their whole run, each a sample).
    """
    s = settings or BenchSettings()
    observers = _observer_speeds(s)
    ekf = _ekf_speeds(s)
    simulator = _simulator_speeds(s)

    with tempfile.TemporaryDirectory() as tmp:
        wall, _ = _timed(lambda: reproduce(tmp, seed=0, duration_scale=s.reproduce_scale, progress=progress))
    steps_est = 0.0
    for scenario in REPRODUCED_SCENARIOS:
        sc = get_scenario(scenario)
        n = sc.duration * s.reproduce_scale / sc.dt
        steps_est += n * simulator["numpy_us"]
        steps_est += sum(n * _numpy_us(name, observers, ekf) for name in REPRODUCED_OBSERVERS)
    cores = os.cpu_count() or 1
    repro = {"wall_s": wall, "numpy_estimate_s": steps_est * 1e-6 / cores}     # reproduce runs on every core
    # one case's processor time in this process: what the sweep costs on cores of its own, the machine's load aside
    run_case("paper", s.sweep_seeds, SWEEP_OBSERVERS, min(s.sweep_s, 2.0))                 # built once
    cpu = time.process_time()
    run_case("paper", s.sweep_seeds, SWEEP_OBSERVERS, s.sweep_s)
    case_cpu = time.process_time() - cpu
    wall, table = _timed(lambda: sweep(["paper"], s.sweep_seeds, observers=SWEEP_OBSERVERS, duration=s.sweep_s,
                                       n_jobs=-1, progress=progress))
    n = s.sweep_s / get_scenario("paper").dt
    per_case = n * (simulator["numpy_us"] + sum(_numpy_us(name, observers, ekf) for name in SWEEP_OBSERVERS))
    sweep_out = {"wall_s": wall, "numpy_estimate_s": s.sweep_seeds * per_case * 1e-6 / cores, "case_cpu_s": case_cpu,
                 "runs": len(table), "diverged": int(table["diverged"].sum())}
    return {"machine": machine_description(), "settings": s.__dict__, "observers": observers, "ekf": ekf,
            "simulator": simulator, "reproduce": repro, "sweep": sweep_out, "spatial": _spatial_speeds(s),
            "spatial_online": _spatial_steps(s)}


def _verdict(ok):
    return "met" if ok else "**missed**"


def bench_markdown(report):
    """The report of :func:`run_bench` as Markdown, each figure beside its target."""
    m, s = report["machine"], report["settings"]
    lines = ["# fmscal bench", "",
             f"Machine: {m['cpu']}, {m['cores']} cores; {m['platform']}; Python {m['python']}, "
             f"numpy {m['numpy']}, casadi {m['casadi']}, filterpy {m['filterpy']}; C compiler: {m['compiler']}.",
             "",
             "| measurement | fast path | plain numpy | ratio | target |", "|---|---|---|---|---|"]
    for name, r in report["observers"].items():
        ratio = r["numpy_us"] / r["compiled_us"]
        steps = 1e6 / r["compiled_us"]
        lines.append(f"| `{name}` step, one log ({s['fast_s']:g} s; numpy on {s['numpy_s']:g} s) | "
                     f"{r['compiled_us']:.3g} us ({steps:.3g} steps/s; first run with its build "
                     f"{r['first_run_us']:.3g} us) | {r['numpy_us']:.3g} us | {ratio:.0f}x | "
                     f">= {TARGETS['compiled_over_numpy']:g}x: {_verdict(ratio >= TARGETS['compiled_over_numpy'])}; "
                     f"1e6 steps/s: {_verdict(steps >= TARGETS['steps_per_s_stretch'])} |")
    e = report["ekf"]
    ref = e["reference_run_s"]
    for key, label, target in (
            ("ekf_default_run_s", "`ekf` run as by default (compiled, with the errors-in-variables compensation)",
             "ekf_over_adaptive"),
            ("ekf_filter_run_s", "`ekf` run, the filter of [3] (`eiv=False`, compiled)", None),
            ("floor_run_s", f"`{FLOOR_METHOD}` run (the floor)", "floor_over_adaptive")):
        ratio = e[key] / ref
        verdict = f"<= {TARGETS[target]:g}x: {_verdict(ratio <= TARGETS[target])}" if target else "-"
        lines.append(f"| {label}, against the `{_REFERENCE}` default's run on the same log ({s['fast_s']:g} s) | "
                     f"{e[key]:.3g} s | {ref:.3g} s (`{_REFERENCE}`) | {ratio:.2f}x | {verdict} |")
    lines.append(f"| `ekf` step: compiled against its readable path (`compiled=False`, filterpy's "
                 f"`ExtendedKalmanFilter`, {s['ekf_s']:g} s); filterpy's bare predict + update "
                 f"{e['bare_filterpy_us']:.3g} us | {e['ekf_us']:.3g} us | {e['ekf_numpy_us']:.3g} us | "
                 f"{e['ekf_numpy_us'] / e['ekf_us']:.0f}x | - |")
    lines.append(f"| casadi `x_next, F, Q` of the EKF: `Function.buffer()` against an ordinary call | "
                 f"{e['buffer_call_us']:.3g} us with the copies in and out ({e['trigger_us']:.3g} us the call "
                 f"alone) | {e['ordinary_call_us']:.3g} us (ordinary call) | "
                 f"{e['ordinary_call_us'] / e['buffer_call_us']:.0f}x | - |")
    sim = report["simulator"]
    lines.append(f"| simulator RK4 step | {sim['compiled_us']:.3g} us | {sim['numpy_us']:.3g} us | "
                 f"{sim['numpy_us'] / sim['compiled_us']:.0f}x | - |")
    r = report["reproduce"]
    full = s["reproduce_scale"] == 1.0
    label = "" if full else f" (x{s['reproduce_scale']:g} length)"
    lines.append(f"| `fmscal reproduce`{label} | "
                 f"{r['wall_s']:.1f} s | {r['numpy_estimate_s']:.0f} s (estimated) | "
                 f"{r['numpy_estimate_s'] / r['wall_s']:.0f}x | < {TARGETS['reproduce_s']:g} s: "
                 f"{_verdict(r['wall_s'] < TARGETS['reproduce_s']) if full else 'not the full job'} |")
    w = report["sweep"]
    full = s["sweep_seeds"] >= 100 and s["sweep_s"] >= 100
    verdict = _verdict(w["wall_s"] < TARGETS["sweep_s"]) if full else "not the full job"
    cores = report["machine"]["cores"] or 1
    lines.append(f"| sweep: {s['sweep_seeds']} seeds x {s['sweep_s']:g} s x {', '.join(SWEEP_OBSERVERS)} and the floor "
                 f"({w['runs']} runs, {w['diverged']} diverged), every core; one case's processor time "
                 f"{w['case_cpu_s']:.2f} s, x {s['sweep_seeds']} / {cores} cores = "
                 f"{w['case_cpu_s'] * s['sweep_seeds'] / cores:.0f} s | {w['wall_s']:.1f} s | "
                 f"{w['numpy_estimate_s']:.0f} s (estimated) | {w['numpy_estimate_s'] / w['wall_s']:.0f}x | "
                 f"< {TARGETS['sweep_s']:g} s: {verdict} |")
    sp = report.get("spatial", {})
    full = s.get("spatial_s", 0) >= 60
    for name, wall in sp.items():
        verdict = _verdict(wall < TARGETS["spatial_fit_s"]) if full else "not the full log"
        lines.append(f"| `{name}` on a {s['spatial_s']:g} s `spatial-arm` log at 1 kHz (6x6 `S` and the offset, "
                     f"whole fit) | {wall:.3g} s | - | - | < {TARGETS['spatial_fit_s']:g} s: {verdict} |")
    for name, us in report.get("spatial_online", {}).items():
        limit = TARGETS["spatial_adaptive_step_us"]
        target = "-" if name != _REFERENCE else (f"< {limit:g} us: {_verdict(us['step_us'] < limit)}" if full
                                                  else "not the full log")
        lines.append(f"| `{name}` step on that `spatial-arm` log (online, compiled; the run's own time over its "
                     f"samples) | {us['step_us']:.3g} us | - | - | {target} |")
        lines.append(f"| `{name}` whole run on that log over its samples (`run()` timed whole: the step, its "
                     f"setup and its checks) | {us['run_us']:.3g} us | - | - | - |")
    lines += ["", "Plain numpy: the same transition evaluated in numpy one step at a time "
              "(`run(compiled=False)`, `integrate(compiled=False)`; the EKF's: filterpy's `ExtendedKalmanFilter` "
              "with the casadi model). Run ratios: whole runs (`Observer.run`) on the same log in this process, "
              "interleaved, the best of 3 each. Estimated: the steps of the job times the per-step "
              "costs of the plain paths measured above (the "
              "maximum-likelihood floor, which `reproduce` and every sweep case also run, is left out, "
              "so the estimate understates), divided by the cores (`reproduce` and the sweep run on every core). "
              "The first-run figure includes building the observer "
              "(symbolic step, C generation, loading the cached library)."]
    return "\n".join(lines) + "\n"


def _spatial_steps(s):
    """The online methods on the ``spatial-arm`` log of :func:`_spatial_speeds`, us a sample, the best of 2 after a
    first run that builds the step: ``step_us``, the run's own cost (:attr:`observers.ObserverResult.wall_time`:
    without the build), and ``run_us``, the whole ``run`` timed from outside (its setup and its own checks;
    ``run`` fits nothing else to the log: the workflows ask for the evidence,
    :func:`observers.diagnostics.has_evidence`)."""
    scenario = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=s.spatial_s)
    log, truth, _ = scenario.generate(0)
    model = SpatialModel(scenario.payload, scenario.gravity)
    out = {}
    for name in method_names(calibrates=True, online=True, model=model):
        obs = make_observer(name, model, truth.noise, {"offset": True})
        obs.run(log)
        runs = [_timed(lambda: obs.run(log)) for _ in range(2)]
        out[name] = {"step_us": min(r.wall_time for _, r in runs) / len(log) * 1e6,
                     "run_us": min(t for t, _ in runs) / len(log) * 1e6}
    return out


def _spatial_speeds(s):
    """Whole fits of a ``spatial-arm`` log by every method that calibrates in 3D, the best of 2 each, s."""
    scenario = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=s.spatial_s)
    log, _, _ = scenario.generate(0)
    model = SpatialModel(scenario.payload, scenario.gravity)
    out = {}
    for name in method_names(calibrates=True, online=False, model=model):
        out[name] = _best(lambda: make_observer(name, model, settings={"offset": True}).run(log), 2)
    return out
