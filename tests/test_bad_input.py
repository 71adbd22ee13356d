"""The fmscal command line over bad input: one line, exit status 2, no traceback, no file touched.

Every case runs ``analysis.cli._main.main`` in-process on a copy of a small folder
(a 5 s simulated log, its sidecar, a saved calibration and a gallery of bad
files) and checks that the folder is exactly as it was afterwards: no file
created, removed or changed.
"""

import hashlib
import json
import os
import shutil
import socket
import sys
from pathlib import Path

import numpy as np
import pytest

from fmscal import plant
from fmscal.analysis.cli import main
from fmscal.plant import Calibration

PAYLOAD = ["--mass", "2.5", "--inertia", "0.75", "--rho", "0.2", "0.25"]


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A folder of inputs, good and bad, made once."""
    d = tmp_path_factory.mktemp("inputs")
    assert main(["simulate", "--duration", "5", "--out", str(d / "log.csv")]) == 0
    log = plant.read_log(d / "log.csv")
    truth = plant.read_truth(d / "log.truth.json")
    Calibration(S=truth.S_at(0), payload=truth.payload, method="least-squares").save(d / "cal.json")
    text = (d / "log.csv").read_text()
    header, body = text.split("\n", 1)
    (d / "latin1.csv").write_bytes((header + ",commentaire\n").encode() + "1,2,3,4,5,6,7,été\n".encode("latin-1"))
    (d / "nul.csv").write_bytes(b"t,theta,x,y,M,fx,fy\n0,\x00,0,0,0,0,0\n")
    (d / "dup.csv").write_text(header + ",x\n" + "\n".join(r + ",0" for r in body.splitlines()) + "\n")
    (d / "hugeheader.csv").write_text("t,theta,x,y,M,fx,fy," + "h" * 2_000_000 + "\n" + body)
    rows = body.splitlines()
    rows[3] = ",".join(rows[3].split(",")[:4] + ["1e30", "0", "0"])
    (d / "big.csv").write_text(header + "\n" + "\n".join(rows) + "\n")
    rows = body.splitlines()
    rows[3] = ",".join(rows[3].split(",")[:4] + ["nan", "0", "0"])
    (d / "nan.csv").write_text(header + "\n" + "\n".join(rows) + "\n")
    (d / "short.csv").write_text(header + "\n" + "\n".join(body.splitlines()[:3]) + "\n")
    (d / "words.csv").write_text(header + "\n" + "a,b,c,d,e,f,g\n" * 20)
    cal = json.loads((d / "cal.json").read_text())
    (d / "cal_logstr.json").write_text(json.dumps({**cal, "log": "run.csv"}))
    (d / "cal_forced.json").write_text(json.dumps({**cal, "forced": "yes"}))
    (d / "cal_deep.json").write_text("[" * 100_000 + "]" * 100_000)
    (d / "cal_huge.json").write_text(json.dumps({**cal, "pad": "x" * 2_000_000}))
    (d / "cal_notjson.json").write_text("S = 1\n")
    (d / "cal_singular.json").write_text(json.dumps({**cal, "S": [[1, 0, 0], [0, 0, 0], [0, 0, 1]]}))
    (d / "cal_other.json").write_text(json.dumps({**cal, "format": "something/2"}))
    (d / "folder.json").mkdir()
    (d / "existing.json").write_text("{}\n")
    (d / "existing.png").write_bytes(b"png")
    (d / "existing.csv").write_text("a\n")
    (d / "existing.md").write_text("# old\n")
    (d / "other.truth.json").write_text("{}\n")          # the sidecar of other.csv, which does not exist
    (d / "done").mkdir()
    (d / "done" / "summary.md").write_text("old\n")
    assert len(log) == 5001
    return d


def _snapshot(folder):
    """Every file and folder under ``folder``: size, modification time and content hash."""
    out = {}
    for root, dirs, files in os.walk(folder):
        for name in dirs:
            out[os.path.relpath(os.path.join(root, name), folder)] = "dir"
        for name in files:
            path = os.path.join(root, name)
            st = os.stat(path)
            with open(path, "rb") as f:
                out[os.path.relpath(path, folder)] = (st.st_size, st.st_mtime_ns, hashlib.sha256(f.read()).hexdigest())
    return out


@pytest.fixture
def folder(base, tmp_path):
    d = tmp_path / "work"
    shutil.copytree(base, d)
    return d


@pytest.fixture(scope="module")
def silent_scheduler():
    """A listener on loopback that accepts connections and never says anything."""
    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    yield f"tcp://127.0.0.1:{srv.getsockname()[1]}"
    srv.close()


def _closed_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


CAL = ["calibrate", "{d}/log.csv", *PAYLOAD]

# (argv with {d} for the folder and {silent} for the silent scheduler, words the one line must hold)
CASES = [
    # files: never onto an input, never over an output without --overwrite, checked before the work
    (["apply", "{d}/cal.json", "{d}/log.csv", "--out", "{d}/log.csv"], "is the readings, an input"),
    (["apply", "{d}/cal.json", "{d}/existing.csv", "--out", "{d}/existing.csv", "--overwrite"], "an input"),
    (["apply", "{d}/cal.json", "{d}/log.csv", "--out", "{d}/existing.csv"], "add --overwrite"),
    (["apply", "{d}/cal.json", "{d}/log.csv", "--out", "{d}/cal.json"], "--out must end in .csv"),
    ([*CAL, "--truth", "{d}/log.truth.json", "--save", "{d}/log.truth.json"], "is the --truth file, an input"),
    ([*CAL, "--save", "{d}/existing.json"], "add --overwrite"),
    ([*CAL, "--save", "{d}/log.csv/cal.json"], "is a file, not a folder"),
    ([*CAL, "--save", "{d}/folder.json"], "is a folder"),
    ([*CAL, "--save", "{d}/new.txt"], "--save must end in .json"),
    ([*CAL, "--plot", "{d}/existing.png"], "add --overwrite"),
    ([*CAL, "--plot", "{d}/p.png", "--save", "{d}/p.png"], "--save must end in .json"),
    ([*CAL, "--force"], "--force applies to --save"),
    (["simulate", "--duration", "1", "--out", "{d}/log.csv"], "add --overwrite"),
    (["simulate", "--duration", "1", "--out", "{d}/other.csv"], "sidecar"),
    (["simulate", "--duration", "1", "--out", "{d}/log.csv/x.csv"], "is a file, not a folder"),
    (["sweep", "--out", "{d}/existing.csv", "--duration", "1", "--seeds", "1"], "add --overwrite"),
    (["compare", "--out", "{d}/done", "--duration", "1"], "summary.md exists"),
    (["compare", "--out", "{d}/log.csv", "--duration", "1"], "is a file, not a folder"),
    (["reproduce", "--out", "{d}/done", "--quick", "0.01"], "summary.md exists"),
    (["reproduce", "--out", "{d}/existing.md", "--quick", "0.01"], "is a file, not a folder"),
    (["bench", "--quick", "--out", "{d}/existing.md"], "add --overwrite"),
    # inputs named for what they are
    (["calibrate", "{d}/latin1.csv", *PAYLOAD], "not UTF-8"),
    (["calibrate", "{d}/nul.csv", *PAYLOAD], "NUL byte"),
    (["calibrate", "{d}/dup.csv", *PAYLOAD], "more than once"),
    (["calibrate", "{d}/hugeheader.csv", *PAYLOAD], "not a CSV header"),
    (["calibrate", "{d}", *PAYLOAD], "is a folder"),
    (["calibrate", "{d}/missing.csv", *PAYLOAD], "no such file"),
    (["calibrate", "{d}/big.csv", *PAYLOAD], "1e+30"),
    (["calibrate", "{d}/nan.csv", *PAYLOAD], "NaN"),
    (["calibrate", "{d}/short.csv", *PAYLOAD], "too few rows"),
    (["calibrate", "{d}/words.csv", *PAYLOAD], "not a number"),
    (["calibrate", "{d}/log.csv", "--mass", "nan", "--inertia", "0.75", "--rho", "0.2", "0.25"], "--mass"),
    ([*CAL, "--wrench-noise", "nan", "0", "0"], "--wrench-noise"),
    ([*CAL, "--latency", "nan"], "--latency"),
    (["apply", "{d}/cal.json", "{d}/latin1.csv", "--out", "{d}/w.csv"], "not UTF-8"),
    (["apply", "{d}/cal_logstr.json", "{d}/log.csv", "--out", "{d}/w.csv"], "log must be an object"),
    (["apply", "{d}/cal_forced.json", "{d}/log.csv", "--out", "{d}/w.csv"], "forced must be true or false"),
    (["apply", "{d}/cal_deep.json", "{d}/log.csv", "--out", "{d}/w.csv"], "nested too deeply"),
    (["apply", "{d}/cal_huge.json", "{d}/log.csv", "--out", "{d}/w.csv"], "too large"),
    (["apply", "{d}/cal_notjson.json", "{d}/log.csv", "--out", "{d}/w.csv"], "not a JSON"),
    (["apply", "{d}/cal_singular.json", "{d}/log.csv", "--out", "{d}/w.csv"], "singular"),
    (["apply", "{d}/cal_other.json", "{d}/log.csv", "--out", "{d}/w.csv"], "not an fmscal calibration"),
    (["apply", "{d}/folder.json", "{d}/log.csv", "--out", "{d}/w.csv"], "is a folder"),
    (["apply", "{d}/cal.json", "{d}/log.csv", "--out", "{d}/w.csv", "--mass", "1", "--inertia", "1", "--rho",
      "0", "0"], "another payload"),
    # sweep --set read strictly
    (["sweep", "--set", "adaptive:offset=maybe", "--duration", "1", "--seeds", "1"], "true or false"),
    (["sweep", "--jobs", "0", "--duration", "1", "--seeds", "1"], "--jobs must be a positive number"),
    (["reproduce", "--jobs", "0", "--out", "{d}/rep0", "--quick", "0.01"], "--jobs must be a positive number"),
    (["sweep", "--set", "adaptive:offset=true", "--set", "adaptive:offset=false", "--duration", "1"], "twice"),
    (["sweep", "--set", "adaptive-offset", "--duration", "1"], "OBSERVER:PARAM"),
    (["sweep", "--scheduler", "{silent}", "--scheduler-timeout", "1", "--duration", "1", "--seeds", "1"],
     "no answer from the Dask scheduler"),
    (["sweep", "--scheduler", "tcp://127.0.0.1:{closed}", "--scheduler-timeout", "1", "--duration", "1"],
     "cannot reach"),
    (["sweep", "--scheduler", "tcp://nowhere", "--duration", "1"], "tcp://HOST:PORT"),
    (["sweep", "--scheduler-timeout", "0", "--duration", "1"], "--scheduler-timeout"),
    # limits instead of crashes
    (["simulate", "--duration", "1e9", "--out", "{d}/long.csv"], "samples"),
    (["simulate", "--dt", "1e-12", "--out", "{d}/fine.csv"], "samples"),
    (["compare", "--duration", "1e9"], "samples"),
    (["sweep", "--duration", "1e9", "--seeds", "1"], "samples"),
    (["check-gains", "--config", "high-gain", "--lam", "1e308"], "--lam must be at most"),
    (["simulate", "--seed", "-1", "--duration", "1", "--out", "{d}/m.csv"], "--seed must be a non-negative"),
    (["compare", "--seeds", "1000000000000", "--duration", "1"], "--seeds must be at least 1 and at most"),
    (["sweep", "--seeds", "1000000000000", "--duration", "1"], "--seeds must be at least 1 and at most"),
    (["compare", "--seeds", "2", "--duration", "1e-9"], "a log needs at least"),
    (["simulate", "--mass", "inf", "--duration", "1", "--out", "{d}/m.csv"], "--mass"),
    (["simulate", "--drop-rate", "1", "--duration", "1", "--out", "{d}/m.csv"], "--drop-rate"),
]


@pytest.mark.parametrize("argv, words", CASES, ids=[" ".join(a[:1] + a[-2:]) for a, _ in CASES])
def test_bad_input_gives_one_line_and_touches_nothing(argv, words, folder, silent_scheduler, capsys):
    argv = [a.format(d=folder, silent=silent_scheduler, closed=_closed_port()) for a in argv]
    before = _snapshot(folder)
    assert main(argv) == 2
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err and words in lines[0] and len(lines[0]) < 500
    assert _snapshot(folder) == before


def test_many_cases(folder):
    assert len(CASES) >= 40


def test_scheduler_without_the_distributed_extra_is_one_line(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "dask.distributed", None)          # import fails as if not installed
    assert main(["sweep", "--scheduler", "tcp://127.0.0.1:1", "--duration", "1", "--seeds", "1"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "distributed extra" in lines[0]


@pytest.mark.slow
def test_no_runtime_warning_reaches_stderr(folder, capsys):
    """An all-zero wrench: numpy would warn about the degenerate fit; the user sees the toolkit's words only."""
    log = plant.read_log(folder / "log.csv")
    plant.Log(log.t, log.pose, np.zeros_like(log.w_hat)).write(folder / "zero.csv")
    import subprocess                 # a subprocess: pytest would catch the warnings before stderr
    proc = subprocess.run([sys.executable, "-m", "fmscal.analysis.cli", "calibrate", str(folder / "zero.csv"), *PAYLOAD,
                           "--json"], capture_output=True, text=True, env={**os.environ, "PYTHONWARNINGS": "default"})
    assert proc.returncode == 2, proc.stderr
    assert "RuntimeWarning" not in proc.stderr and "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "never change" in lines[0]           # refused before any method runs (issue 37)
    proc = subprocess.run([sys.executable, "-m", "fmscal.analysis.cli", "calibrate", str(folder / "zero.csv"), *PAYLOAD,
                           "--observer", "ekf", "--json"], capture_output=True, text=True,
                          env={**os.environ, "PYTHONWARNINGS": "default"})
    assert proc.returncode == 2 and proc.stdout == "", proc.stderr  # the EKF's prior is no answer either: refused
    assert "RuntimeWarning" not in proc.stderr and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_set_reads_booleans_strictly_and_numbers_as_numbers():
    from fmscal.analysis.cli._scale import parse_settings
    grid = parse_settings(["adaptive:offset=no,YES,0,1,false,True", "high-gain:lam=1,2.5"])
    assert grid == {"adaptive": {"offset": [False, True, False, True, False, True]},
                    "high-gain": {"lam": [1, 2.5]}}
    assert isinstance(grid["high-gain"]["lam"][0], int) and isinstance(grid["adaptive"]["offset"][1], bool)
    assert parse_settings(["high-gain:t_decay=none,20"]) == {"high-gain": {"t_decay": [None, 20]}}    # a constant gain


# --- atomic writes --------------------------------------------------------------------------------------------

def _failing_replace(monkeypatch):
    def fail(src, dst):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(os, "replace", fail)


def test_a_failed_save_leaves_the_old_calibration_intact(folder, monkeypatch):
    old = (folder / "cal.json").read_bytes()
    truth = plant.read_truth(folder / "log.truth.json")
    new = Calibration(S=2 * truth.S_at(0), payload=truth.payload, method="ekf")
    _failing_replace(monkeypatch)
    with pytest.raises(OSError):
        new.save(folder / "cal.json", overwrite=True)
    assert (folder / "cal.json").read_bytes() == old
    assert sorted(p.name for p in folder.iterdir() if p.name.startswith(".")) == []      # no temporary left


def test_a_failed_calibrate_save_is_one_line_and_keeps_the_old_file(folder, monkeypatch, capsys):
    before = _snapshot(folder)
    _failing_replace(monkeypatch)
    assert main([*[a.format(d=folder) for a in CAL], "--save", str(folder / "existing.json"), "--overwrite"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("fmscal calibrate: error:") and "No space left" in err[-1]
    assert _snapshot(folder) == before


def test_simulate_never_leaves_a_log_without_its_sidecar(folder, monkeypatch, capsys):
    real, calls = os.link, []              # without --overwrite each file is linked into place

    def second_fails(src, dst):
        calls.append(dst)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        real(src, dst)
    monkeypatch.setattr(os, "link", second_fails)
    before = _snapshot(folder)
    assert main(["simulate", "--duration", "1", "--out", str(folder / "new.csv")]) == 2
    assert not (folder / "new.csv").exists() and not (folder / "new.truth.json").exists()
    assert _snapshot(folder) == before


def test_a_failed_overwrite_keeps_the_old_log_and_its_sidecar(folder, monkeypatch, capsys):
    assert main(["simulate", "--duration", "1", "--seed", "1", "--out", str(folder / "old.csv")]) == 0
    real, calls = os.replace, []

    def log_fails(src, dst):                    # the sidecar is replaced first, then the log fails
        calls.append(dst)
        if Path(dst) == folder / "old.csv":
            raise OSError(28, "No space left on device")
        real(src, dst)
    monkeypatch.setattr(os, "replace", log_fails)
    before = _snapshot(folder)
    assert main(["simulate", "--duration", "2", "--out", str(folder / "old.csv"), "--overwrite"]) == 2
    assert folder / "old.truth.json" in [Path(d) for d in calls]          # it had been replaced
    assert _snapshot(folder) == before          # the sidecar already replaced got its old content back


def test_a_failing_plot_leaves_no_saved_calibration(folder, monkeypatch, capsys):
    from fmscal.analysis import _plots as plots
    def broken(*args, **kwargs):
        raise OSError(5, "Input/output error")
    monkeypatch.setattr(plots, "plot_calibration", broken)
    assert main([*[a.format(d=folder) for a in CAL], "--plot", str(folder / "p.png"),
                 "--save", str(folder / "new.json")]) == 2
    assert not (folder / "new.json").exists()


# --- what is saved, and what the user is told ------------------------------------------------------------------

def test_a_log_in_degrees_is_named_and_not_saved_without_force(folder, capsys):
    log = plant.read_log(folder / "log.csv")
    pose = log.pose.copy()
    pose[:, 0] = np.rad2deg(pose[:, 0])
    plant.Log(log.t, pose, log.w_hat).write(folder / "deg.csv")
    assert main(["calibrate", str(folder / "deg.csv"), *PAYLOAD, "--save", str(folder / "deg.json")]) == 2
    err = capsys.readouterr().err
    assert "theta looks like degrees" in err and "--force" in err.strip().splitlines()[-1]
    assert not (folder / "deg.json").exists()
    assert main(["calibrate", str(folder / "deg.csv"), *PAYLOAD, "--save", str(folder / "deg.json"), "--force"]) == 0
    assert json.loads((folder / "deg.json").read_text())["forced"] is True
    assert Calibration.load(folder / "deg.json").forced
    assert main(["apply", str(folder / "deg.json"), str(folder / "log.csv"), "--out", str(folder / "w.csv")]) == 0
    assert "saved with --force" in capsys.readouterr().err


def test_a_wrapped_theta_is_unwrapped_with_a_note(folder, capsys):
    log = plant.read_log(folder / "log.csv")
    pose = log.pose.copy()
    pose[:, 0] = np.angle(np.exp(1j * (pose[:, 0] + 3.0)))      # wrapped into (-pi, pi] as a yaw from a quaternion
    assert log.has_pose.all()
    np.savetxt(folder / "wrapped.csv", np.column_stack([log.t, pose, log.w_hat]), delimiter=",", fmt="%.17g",
               header=",".join(plant.COLUMNS), comments="")
    plain = plant.read_log(folder / "log.csv")
    assert not plain.notes
    wrapped = plant.read_log(folder / "wrapped.csv")
    np.testing.assert_allclose(wrapped.pose[:, 0], plain.pose[:, 0] + 3.0 - 2 * np.pi * np.round(
        (wrapped.pose[0, 0] - plain.pose[0, 0] - 3.0) / (2 * np.pi)), atol=1e-9)
    np.savetxt(folder / "continuous.csv", np.column_stack([log.t, log.pose + [3.0, 0, 0], log.w_hat]),
               delimiter=",", fmt="%.17g", header=",".join(plant.COLUMNS), comments="")
    capsys.readouterr()
    assert main(["calibrate", str(folder / "wrapped.csv"), *PAYLOAD, "--json", "--latency", "0"]) == 0
    out, err = capsys.readouterr()
    assert "fmscal calibrate: note: wrapped.csv: theta is wrapped into (-pi, pi]" in err
    assert main(["calibrate", str(folder / "continuous.csv"), *PAYLOAD, "--json", "--latency", "0"]) == 0
    same = capsys.readouterr()
    assert "note" not in same.err
    np.testing.assert_allclose(json.loads(out)["S"], json.loads(same.out)["S"], atol=1e-9)


def test_python_api_raises_the_toolkits_errors(folder):
    with pytest.raises(plant.LogError, match="file name"):
        plant.read_log(None)
    with pytest.raises(plant.FmscalError, match="finite"):
        plant.NoiseSpec((0.1, 0.1, float("nan")))
    with pytest.raises(plant.FmscalError, match="angle_sd"):
        plant.NoiseSpec((0.1, 0.1, 0.1), angle_sd=float("inf"))
    with pytest.raises(TypeError, match="plant.Payload"):
        Calibration.load(folder / "cal.json", payload="x")
    from fmscal.observers import AugmentedEKF
    with pytest.raises(plant.FmscalError, match="S0_sd must be at most"):
        AugmentedEKF(plant.PAPER_PAYLOAD, S0_sd=1e200)
