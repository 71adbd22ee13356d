"""Issue 24, items 3-7: no hang, no traceback on a symlink loop, no output lost to a race, settings typed.

Like :mod:`tests.test_bad_input`: every refusal is one line on stderr with exit
status 2, and the folder is exactly as it was (symbolic links compared as
links, so that loops can sit in it).
"""

import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from fmscal import plant
from fmscal.analysis.cli import main
from fmscal.plant import Calibration, FmscalError

PAYLOAD = ["--mass", "2.5", "--inertia", "0.75", "--rho", "0.2", "0.25"]


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A 5 s log, its sidecar and a calibration, made once."""
    d = tmp_path_factory.mktemp("inputs2")
    assert main(["simulate", "--duration", "5", "--out", str(d / "log.csv")]) == 0
    truth = plant.read_truth(d / "log.truth.json")
    Calibration(S=truth.S_at(0), payload=truth.payload, method="least-squares").save(d / "cal.json")
    return d


def _snapshot(folder):
    """Every entry under ``folder``: links as their targets, files as size and hash (no link followed)."""
    out = {}
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            path = os.path.join(root, name)
            key = os.path.relpath(path, folder)
            if os.path.islink(path):
                out[key] = ("link", os.readlink(path))
            elif os.path.isdir(path):
                out[key] = "dir"
            elif os.path.isfile(path):
                with open(path, "rb") as f:
                    out[key] = (os.stat(path).st_mtime_ns, hashlib.sha256(f.read()).hexdigest())
            else:
                out[key] = "special"
    return out


@pytest.fixture
def folder(base):
    """A copy of the inputs, with symlink loops (``loop``, ``loop.csv``, ``loop.json``, ...) and a FIFO.

    Under a short path: messages echo at most 80 characters of a path (its start and its end), and
    the expected words hold the whole path (pytest's own temporary folders run longer under xdist).
    """
    d = Path(tempfile.mkdtemp(prefix="fm"))
    yield _filled(base, d)
    shutil.rmtree(d, ignore_errors=True)


def _filled(base, d):
    for f in base.iterdir():
        (d / f.name).write_bytes(f.read_bytes())
    for name in ("loop", "loop.csv", "loop.json", "loop.png", "loop.mcap"):
        os.symlink(d / f"{name}.2", d / name)
        os.symlink(d / name, d / f"{name}.2")
    os.mkfifo(d / "fifo.csv")
    lines = (d / "log.csv").read_text().split("\n")
    (d / "wide.csv").write_text("\n".join([lines[0], lines[1] + ",0" * 1_000_000, *lines[2:]]))
    (d / "wide_late.csv").write_text("\n".join(lines[:3000] + [lines[3000] + ",0"] + lines[3001:]))
    (d / "narrow_late.csv").write_text("\n".join(lines[:4000] + [lines[4000].rsplit(",", 1)[0]] + lines[4001:]))
    return d


CAL = ["calibrate", "{d}/log.csv", *PAYLOAD]
IMPORT = ["import", "--wrench-topic", "/w", "--pose-topic", "/p"]

# (argv with {d} for the folder, words the one line must hold)
CASES = [
    # item 3: --jobs, and rows of the wrong width
    (["sweep", "--jobs", "-2", "--duration", "1", "--seeds", "1"], "--jobs must be a positive number"),
    (["reproduce", "--jobs", "-5", "--out", "{d}/rep", "--quick", "0.01"], "--jobs must be a positive number"),
    (["calibrate", "{d}/wide.csv", *PAYLOAD], "line 2 has 1000007 fields (row 1); the header has 7"),
    (["calibrate", "{d}/wide_late.csv", *PAYLOAD], "line 3001 has 8 fields"),
    (["calibrate", "{d}/narrow_late.csv", *PAYLOAD], "line 4001 has 6 fields"),
    (["apply", "{d}/cal.json", "{d}/wide.csv", "--out", "{d}/w.csv"], "line 2 has 1000007 fields"),
    # item 4: a symlink loop as an input or an output, in every command
    (["apply", "{d}/loop.json", "{d}/log.csv", "--out", "{d}/w.csv"], "loop.json: is a symlink loop"),
    (["apply", "{d}/cal.json", "{d}/loop.csv", "--out", "{d}/w.csv"], "loop.csv: is a symlink loop"),
    (["apply", "{d}/cal.json", "{d}/log.csv", "--out", "{d}/loop.csv"], "--out {d}/loop.csv is a symlink loop"),
    (["apply", "{d}/cal.json", "{d}/log.csv", "--out", "{d}/loop.csv", "--overwrite"], "is a symlink loop"),
    (["calibrate", "{d}/loop.csv", *PAYLOAD], "loop.csv: is a symlink loop, not a log file"),
    ([*CAL, "--save", "{d}/loop.json"], "--save {d}/loop.json is a symlink loop"),
    ([*CAL, "--plot", "{d}/loop.png"], "--plot {d}/loop.png is a symlink loop"),
    ([*CAL, "--save", "{d}/loop/cal.json"], "is a symlink loop, not a folder"),
    ([*CAL, "--truth", "{d}/loop.json"], "is a symlink loop"),
    (["simulate", "--duration", "1", "--out", "{d}/loop.csv"], "--out {d}/loop.csv is a symlink loop"),
    (["simulate", "--duration", "1", "--out", "{d}/loop.csv", "--overwrite"], "is a symlink loop"),
    ([*IMPORT, "{d}/loop.mcap", "--out", "{d}/b.csv"], "loop.mcap: is a symlink loop, not a ROS bag"),
    ([*IMPORT, "{d}/log.csv", "--out", "{d}/loop.csv"], "--out {d}/loop.csv is a symlink loop"),
    (["compare", "--duration", "1", "--out", "{d}/loop"], "--out {d}/loop is a symlink loop"),
    (["sweep", "--duration", "1", "--seeds", "1", "--out", "{d}/loop.csv"], "--out {d}/loop.csv is a symlink loop"),
    (["sweep", "--duration", "1", "--seeds", "1", "--out", "{d}/loop.csv", "--overwrite"], "is a symlink loop"),
    (["reproduce", "--quick", "0.01", "--out", "{d}/loop"], "--out {d}/loop is a symlink loop"),
    (["bench", "--quick", "--out", "{d}/loop.csv"], "is a symlink loop"),
    # item 4: what a log that is not a file is
    (["calibrate", "{d}/fifo.csv", *PAYLOAD], "is a FIFO (named pipe), not a log file"),
    (["calibrate", "/dev/null", *PAYLOAD], "/dev/null: is a character device, not a log file"),
    (["apply", "{d}/cal.json", "/dev/null", "--out", "{d}/w.csv"], "is a character device, not a readings file"),
    (["bench", "--quick", "--out", "/dev/null", "--overwrite"], "--out /dev/null is a character device"),
    (["sweep", "--duration", "1", "--out", "{d}/fifo.csv", "--overwrite"], "is a FIFO (named pipe)"),
]


@pytest.mark.parametrize("argv, words", CASES, ids=[" ".join(a[:1] + a[-2:]) for a, _ in CASES])
def test_bad_input_gives_one_line_and_touches_nothing(argv, words, folder, capsys):
    argv = [a.format(d=folder) for a in argv]
    before = _snapshot(folder)
    assert main(argv) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err and words.format(d=folder) in lines[0], lines[0]
    assert _snapshot(folder) == before


def test_the_wide_row_is_refused_before_pandas_reads_anything(folder, monkeypatch):
    import pandas as pd

    def never(*args, **kwargs):
        raise AssertionError("pandas read the file")
    monkeypatch.setattr(pd, "read_csv", never)
    with pytest.raises(plant.LogError, match="line 2 has 1000007 fields"):
        plant.read_log(folder / "wide.csv")


def test_crlf_and_blank_lines_are_not_wrong_widths(folder):
    text = (folder / "log.csv").read_text()
    (folder / "crlf.csv").write_bytes(text.replace("\n", "\r\n").encode() + b"\r\n\r\n")
    a, b = plant.read_log(folder / "log.csv"), plant.read_log(folder / "crlf.csv")
    np.testing.assert_array_equal(a.w_hat, b.w_hat)


# --- item 3: workers -------------------------------------------------------------------------------------------

def _square(x):
    return x * x


@pytest.mark.slow
def test_workers_are_capped_at_the_items_and_the_cores(monkeypatch):
    import joblib
    from tqdm import tqdm
    from fmscal.analysis._sweep import run_local, worker_count
    cores = os.cpu_count() or 1
    assert worker_count(1000, 1) == 1
    assert worker_count(1000, 3) == min(3, cores)
    assert worker_count(-1, 1000) == cores
    assert worker_count(2, 1000) == min(2, cores)
    for bad in (0, -2, 1.5, True, "4"):
        with pytest.raises(FmscalError, match="n_jobs"):
            worker_count(bad, 3)
    asked = []
    real = joblib.Parallel

    def recording(*args, n_jobs=None, **kwargs):
        asked.append(n_jobs)
        return real(*args, n_jobs=n_jobs, **kwargs)
    monkeypatch.setattr(joblib, "Parallel", recording)
    with tqdm(disable=True) as bar:
        assert list(run_local(_square, [3], 1000, bar)) == [9]         # one item: in this process
        assert asked == []
        assert sorted(run_local(_square, [1, 2, 3], 1000, bar)) == [1, 4, 9]
    assert asked == ([min(3, cores)] if min(3, cores) > 1 else [])


# --- item 5: races ---------------------------------------------------------------------------------------------

def test_an_output_that_appears_meanwhile_is_not_replaced(tmp_path):
    from fmscal.plant.io._files import OutputExistsError, atomic_write_many, atomic_write_text, exclusive
    target = tmp_path / "out.json"

    def slow_writer(tmp):                # another run places its file while this one writes
        target.write_text("theirs\n")
        Path(tmp).write_text("mine\n")
    with exclusive():
        with pytest.raises(OutputExistsError, match="appeared while this run worked"):
            atomic_write_many([(tmp_path / "side.json", lambda tmp: Path(tmp).write_text("s\n")),
                               (target, slow_writer)])
    assert target.read_text() == "theirs\n"
    assert not (tmp_path / "side.json").exists()                  # no companion left alone
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]     # no temporary left
    atomic_write_text(target, "replaced\n")                       # outside exclusive(): --overwrite
    assert target.read_text() == "replaced\n"


def test_without_hard_links_the_name_is_still_claimed_exclusively(tmp_path, monkeypatch):
    import errno
    from fmscal.plant.io._files import OutputExistsError, atomic_write_text, exclusive

    def no_links(src, dst):
        raise OSError(errno.EPERM, "Operation not permitted")
    monkeypatch.setattr(os, "link", no_links)
    with exclusive():
        atomic_write_text(tmp_path / "a.txt", "first\n")
        with pytest.raises(OutputExistsError):
            atomic_write_text(tmp_path / "a.txt", "second\n")
    assert (tmp_path / "a.txt").read_text() == "first\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]


def test_an_output_that_cannot_be_made_names_itself_not_its_temporary_file(capsys):
    """A folder that takes no new file (Linux's /proc: not a permission, so the CLI's writable check passes it):
    the error names the file asked for, where it named the hidden temporary file beside it (a hostile review's
    case). One line, exit 2."""
    from fmscal.plant.io._files import atomic_write_text

    with pytest.raises(OSError) as raised:
        atomic_write_text("/proc/fmscal-out.txt", "x\n")
    assert raised.value.filename == "/proc/fmscal-out.txt"
    capsys.readouterr()
    assert main(["simulate", "--scenario", "paper", "--duration", "2", "--out", "/proc/fmscal-log.csv"]) == 2
    err = capsys.readouterr().err.strip()            # the log or its sidecar, whichever is written first
    assert len(err.splitlines()) == 1 and "'/proc/fmscal-log." in err and "/proc/." not in err, err


def test_a_folder_is_claimed_by_one_run(tmp_path):
    from fmscal.plant.io._files import LOCK_NAME, claim_folder
    out = tmp_path / "new" / "d"
    with claim_folder(out):
        assert (out / LOCK_NAME).read_text().strip() == str(os.getpid())
        with pytest.raises(FmscalError, match="in use by another fmscal run"):
            with claim_folder(out):
                pass
    assert not out.exists()                                        # created here, nothing written: removed
    out.mkdir(parents=True)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    (out / LOCK_NAME).write_text(dead.stdout)                      # a crashed run's claim
    with claim_folder(out):
        (out / "x").write_text("1")
    assert sorted(p.name for p in out.iterdir()) == ["x"]


def _concurrent(argvs):
    """Run ``fmscal`` argument lists at once in separate processes; their exit codes and stderr."""
    procs = [subprocess.Popen([sys.executable, "-m", "fmscal.analysis.cli", *argv], stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, text=True) for argv in argvs]
    return [(p.wait(timeout=300), p.stderr.read()) for p in procs]


@pytest.mark.slow
def test_two_saves_at_once_one_succeeds(folder):
    out = folder / "same.json"
    results = _concurrent([["calibrate", str(folder / "log.csv"), *PAYLOAD, "--observer", "least-squares",
                            "--latency", "0", "--save", str(out)]] * 2)
    codes = sorted(code for code, _ in results)
    assert codes == [0, 2], results
    err = next(e for code, e in results if code == 2)
    assert ("appeared while this run worked" in err or "exists" in err) and "Traceback" not in err
    Calibration.load(out)


@pytest.mark.parametrize("command", [
    [*CAL, "--observer", "least-squares", "--latency", "0", "--save", "{d}/same.json"],
    ["simulate", "--duration", "1", "--out", "{d}/same.csv"],
    ["sweep", "--duration", "2", "--seeds", "1", "--observer", "least-squares", "--jobs", "1", "--json",
     "--out", "{d}/same.csv"],
])
def test_two_runs_past_their_checks_place_one_output(command, folder, monkeypatch, capsys):
    """Both runs pass the existence check, then both place their file: exactly one succeeds."""
    import threading
    from fmscal.plant.io import _files as files
    barrier, real, waited = threading.Barrier(2, timeout=60), files._place, set()

    def together(tmp, path):
        if threading.get_ident() not in waited:
            waited.add(threading.get_ident())
            barrier.wait()                   # each holds its finished files, the names still free
        real(tmp, path)
    monkeypatch.setattr(files, "_place", together)
    codes = []
    argv = [a.format(d=folder) for a in command]
    threads = [threading.Thread(target=lambda: codes.append(main(argv))) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(codes) == [0, 2]
    assert "appeared while this run worked; not replaced" in capsys.readouterr().err


@pytest.mark.slow
def test_two_simulations_at_once_one_succeeds(folder):
    out = folder / "s.csv"
    results = _concurrent([["simulate", "--duration", "2", "--seed", str(seed), "--out", str(out)]
                           for seed in (1, 2)])
    assert sorted(code for code, _ in results) == [0, 2], results
    truth = plant.read_truth(folder / "s.truth.json")
    assert plant.read_log(out).w_hat.shape == (2001, 3)
    # the log and its sidecar come from the same run
    log, _, _ = plant.get_scenario("paper").with_(duration=2).generate(truth.seed)
    np.testing.assert_array_equal(plant.read_log(out).w_hat, log.w_hat)


@pytest.mark.slow
def test_two_compares_into_one_folder_at_once_one_succeeds(folder):
    out = folder / "cmp"
    results = _concurrent([["compare", "--duration", "1", "--observer", "least-squares", "--seeds", "1",
                            "--out", str(out)]] * 2)
    assert sorted(code for code, _ in results) == [0, 2], results
    err = next(e for code, e in results if code == 2)
    assert any(w in err for w in ("in use by another fmscal run", "exists", "appeared")), err
    assert sorted(p.name for p in out.iterdir()) == ["E_paper.png", "runs.csv", "summary.md"]


# --- item 6: settings ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("name, settings, words", [
    ("ekf", {"adapt_q": "false"}, "ekf setting adapt_q must be True or False; got 'false'"),
    ("ekf", {"eiv": 0}, "eiv must be True or False"),
    ("adaptive", {"offset": "no"}, "offset must be True or False; got 'no'"),
    ("adaptive", {"track": "false"}, "track must be True or False"),
    ("least-squares", {"offset": None}, "offset must be True or False"),
    ("high-gain", {"lam": "20"}, "lam must be a number; got '20'"),
    ("high-gain", {"gamma": True}, "gamma must be a number"),
    ("adaptive", {"gain": 1}, "gain must be text"),
    ("ekf", {"adapt": True}, "ekf: no setting 'adapt'"),
])
def test_settings_are_checked_for_type(name, settings, words):
    from fmscal.observers import make_observer
    with pytest.raises(FmscalError, match=words.replace("(", r"\(").replace(")", r"\)")):
        make_observer(name, plant.PAPER_PAYLOAD, settings=settings)


def test_constructors_take_booleans_only_and_settings_still_work():
    from fmscal.observers import AdaptiveObserver, AugmentedEKF, make_observer
    with pytest.raises(FmscalError, match="adapt_q must be True or False"):
        AugmentedEKF(plant.PAPER_PAYLOAD, adapt_q="false")
    with pytest.raises(FmscalError, match="track must be True or False"):
        AdaptiveObserver(plant.PAPER_PAYLOAD, track="false")
    ekf = make_observer("ekf", plant.PAPER_PAYLOAD, settings={"adapt_q": np.bool_(False), "q_S": 0})
    assert ekf.adapt_q is False and ekf.level is None
    assert make_observer("high-gain", plant.PAPER_PAYLOAD, settings={"t_decay": None, "lam": 10}).lam == 10.0


@pytest.mark.parametrize("name", ["adaptive", "adaptive-paper", "high-gain", "ekf"])
def test_reset_and_step_raise_the_toolkits_errors(name):
    from fmscal.observers import MAX_S0, make_observer
    obs = make_observer(name, plant.PAPER_PAYLOAD, plant.NoiseSpec((0.01, 0.1, 0.1)))
    with pytest.raises(FmscalError, match="S0 entries must be at most"):
        obs.reset(1e200 * np.eye(3))
    obs.reset(MAX_S0 * np.eye(3))                                  # the bound itself is taken
    obs.reset()
    with pytest.raises(FmscalError, match="pose must be 3 finite numbers"):
        obs.step(None, ["0", "0", "0"], [1.0, 2.0, 3.0])
    obs.step(None, [0.0, 0.0, 0.0], [1.0, 2.0, 3.0])
    with pytest.raises(FmscalError, match="dt must be a number; got '0.001'"):
        obs.step("0.001", [0.0, 0.0, 0.0], [1.0, 2.0, 3.0])
    with pytest.raises(FmscalError, match="w_hat must be 3 finite numbers"):
        obs.step(0.001, [0.0, 0.0, 0.0], "123")
    obs.step(np.float32(0.001), [0.0, 0.0, 0.0], [1.0, 2.0, 3.0])     # a numpy number is a number


# --- item 7: smaller ------------------------------------------------------------------------------------------

def _write(path, log, pose=None, w_hat=None, t=None):
    """A log CSV written as given (no unwrapping on the way), with numpy."""
    data = np.column_stack([log.t if t is None else t, log.pose if pose is None else pose,
                            log.w_hat if w_hat is None else w_hat])
    np.savetxt(path, data, delimiter=",", fmt="%.17g", header=",".join(plant.COLUMNS), comments="")


@pytest.fixture
def logs(folder):
    """Misleading logs: a still pose, theta in [0, 2 pi), readings x 1e-8, x and y in mm, t in ms."""
    log = plant.read_log(folder / "log.csv")
    still = np.tile(log.pose[0], (len(log), 1))
    _write(folder / "still.csv", log, pose=still)
    pose = log.pose.copy()
    pose[:, 0] = np.mod(pose[:, 0] - 1.0, 2 * np.pi)           # crosses 0: wrapped into [0, 2 pi)
    _write(folder / "twopi.csv", log, pose=pose)
    pose = log.pose.copy()
    pose[:, 0] -= 1.0
    _write(folder / "minus1.csv", log, pose=pose)               # the same angle, continuous
    _write(folder / "tiny.csv", log, w_hat=log.w_hat * 1e-8)
    pose = log.pose.copy()
    pose[:, 1:] *= 1000
    _write(folder / "mm.csv", log, pose=pose)
    _write(folder / "ms.csv", log, t=log.t * 1000)
    return folder


CASES_7 = [
    (["simulate", "--latency", "100", "--duration", "5", "--out", "{d}/q.csv"], "--latency must be less than half"),
    (["simulate", "--latency", "2.5", "--duration", "5", "--out", "{d}/q.csv"], "--latency must be less than half"),
    (["ablation", "--seeds", "0", "--duration", "1"], "--seeds must be at least 1"),
    (["ablation", "--quick", "--seeds", "0"], "--seeds must be at least 1"),
    (["calibrate", "{d}/still.csv", *PAYLOAD], "the pose stream does not move, a stalled tracker"),
    (["calibrate", "{d}/still.csv", *PAYLOAD, "--observer", "least-squares"], "the pose stream does not move"),
    (["calibrate", "{d}/ms.csv", *PAYLOAD], "is t in milliseconds?"),
    (["calibrate", "{d}/" + "x" * 300 + ".csv", *PAYLOAD], "(File name too long)"),
    (["compare", "--scenario", "y" * 300], "unknown scenario"),
    (["calibrate", "{d}/log.csv", "--mass", "z" * 300, "--inertia", "1", "--rho", "0", "0"], "invalid float value"),
]


@pytest.mark.parametrize("argv, words", CASES_7, ids=[" ".join(a[:1] + a[-2:])[:40] for a, _ in CASES_7])
def test_smaller_cases_give_one_right_line(argv, words, logs, capsys):
    argv = [a.format(d=logs) for a in argv]
    before = _snapshot(logs)
    assert main(argv) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and words in lines[0], lines
    assert "S is singular" not in lines[0] and "too short" not in lines[0]
    assert max((len(w) for w in lines[0].split()), default=0) <= 80 + len("...")        # 80 echoed, "..."
    assert _snapshot(logs) == before


def test_apply_refuses_a_wrench_that_is_not_finite(folder, capsys):
    import json
    cal = json.loads((folder / "cal.json").read_text())
    (folder / "huge.json").write_text(json.dumps({**cal, "S": [[2, 0, 0], [0, 2, 0], [0, 0, 2]], "b": [1e308] * 3}))
    assert main(["apply", str(folder / "huge.json"), str(folder / "log.csv"), "--out", str(folder / "w.csv")]) == 2
    assert "not finite" in capsys.readouterr().err
    assert not (folder / "w.csv").exists()
    assert main(["apply", str(folder / "cal.json"), str(folder / "log.csv"), "--out", str(folder / "w.csv")]) == 0


def test_theta_in_zero_to_two_pi_is_unwrapped_not_taken_for_degrees(logs, capsys):
    wrapped = plant.read_log(logs / "twopi.csv")
    assert wrapped.notes and "[0, 2 pi)" in wrapped.notes[0]
    np.testing.assert_allclose(wrapped.pose[:, 0], plant.read_log(logs / "minus1.csv").pose[:, 0] + 2 * np.pi,
                               atol=1e-9)
    assert main(["calibrate", str(logs / "twopi.csv"), *PAYLOAD, "--latency", "0"]) == 0
    assert "degrees" not in capsys.readouterr().err


def test_readings_far_from_si_are_not_taken_for_millimetres(logs):
    from fmscal.plant.io._units import COUNTS, diagnose_units
    payload = plant.read_truth(logs / "log.truth.json").payload
    tiny = diagnose_units(plant.read_log(logs / "tiny.csv"), payload)
    assert [f.kind for f in tiny] == [COUNTS] and "millimetres" not in tiny[0].message
    assert 0.5e8 < float(tiny[0].message.split("near ")[1].split()[0]) < 2e8         # S's entries near 1e8
    mm = diagnose_units(plant.read_log(logs / "mm.csv"), payload)
    assert [f.kind for f in mm] == ["millimetres"]
    assert diagnose_units(plant.read_log(logs / "log.csv"), payload) == []


def test_an_unroutable_scheduler_is_not_said_to_accept_connections(monkeypatch):
    import socket
    from fmscal.analysis._sweep import _probe

    def unroutable(address, timeout):
        raise socket.timeout("timed out")
    monkeypatch.setattr(socket, "create_connection", unroutable)
    with pytest.raises(FmscalError, match="nothing accepted the connection") as err:
        _probe("tcp://10.255.255.1:8786", 1.0)
    assert "accepts connections" not in str(err.value)


def test_ablation_help_prints_no_doubled_percent(capsys):
    assert main(["ablation", "--help"]) == 0
    out = capsys.readouterr().out
    assert "%%" not in out and "10 %" in " ".join(out.split())


_BASE_NS = 1_700_000_000_000_000_000


def _wrench_messages(n=200, step_ns=1_000_000):
    return [(_BASE_NS + k * step_ns, (1.0, 2.0, 3.0, 0.0, 0.0, 0.0)) for k in range(n)]


def test_import_refuses_a_clock_jumping_back_and_zero_stamps():
    from fmscal.plant.io._bag import BagError, _stream
    messages = _wrench_messages()
    assert _stream(messages, "wrench", "b.mcap")[3]["duplicate_stamps"] == 0
    jumped = messages[:120] + [(s - 5_000_000_000, v) for s, v in messages[120:]]
    with pytest.raises(BagError, match=r"the wrench clock jumps back by 4\.99\d* s at message 121 as recorded"):
        _stream(jumped, "wrench", "b.mcap")
    unstamped = [(0, v) for _, v in messages[:5]] + messages[5:]
    with pytest.raises(BagError, match=r"5 pose message\(s\) have the header stamp 0 \(unstamped\), "
                                       r"the first message 1 "):
        _stream(unstamped, "pose", "b.mcap")
    swapped = messages[:50] + [messages[51], messages[50]] + messages[52:]      # reordered in transport: sorted
    assert _stream(swapped, "wrench", "b.mcap")[3]["out_of_order"] == 1


def test_a_singular_estimate_is_named_for_its_cause_not_as_a_bad_matrix(folder, monkeypatch):
    """An estimate with a zero row (a spike that swamps the fit): not 'S is singular' as if the user gave S."""
    from dataclasses import replace
    from fmscal.analysis._calibrate import calibrate
    from fmscal.observers import LeastSquares
    real = LeastSquares.run

    def zero_row(self, log, S0=None, **kwargs):
        result = real(self, log, S0, **kwargs)
        S = result.S_hat.copy()
        S[1] = 0.0
        return replace(result, S_hat=S)
    monkeypatch.setattr(LeastSquares, "run", zero_row)
    log = plant.read_log(folder / "log.csv")
    with pytest.raises(FmscalError, match=r"the least-squares estimate of S is singular \(condition number inf\): "
                                          r"the log does not excite every entry of S, or holds an outlier") as err:
        calibrate(log, plant.read_truth(folder / "log.truth.json").payload, method="least-squares", latency=0.0)
    assert not isinstance(err.value, plant.SingularCalibrationError)
