"""Frozen readings (issue 46 item 3): the whole reading held at its last value, found beyond chance (eqs. (F1),
(F2) of observers/core/_frozen.py), bridged when the log shows a bridge that long holds (F3), else a warning
and not converged; a clean log, a coarsely quantised one among them, shows none."""

import copy
import json

import numpy as np
import pytest

from fmscal.analysis import calibrate
from fmscal.observers import make_observer
from fmscal.observers.core import Glitches, find_glitches
from fmscal.plant import SPATIAL_SCENARIOS, PayloadStd, SpatialModel

ARM = SPATIAL_SCENARIOS["spatial-arm"]


def frozen(log, runs):
    """``log`` with the reading held at its value before each ``(start, length)`` of ``runs`` (a copy)."""
    out = copy.copy(log)
    out.w_hat = log.w_hat.copy()
    for start, length in runs:
        out.w_hat[start:start + length] = log.w_hat[start - 1]
    return out


def quantised(log, step):
    """``log`` with every channel rounded to ``step`` times its own noise (a coarse converter)."""
    out = copy.copy(log)
    sd = np.std(np.diff(log.w_hat, axis=0), axis=0) / np.sqrt(2)
    out.w_hat = np.round(log.w_hat / (step * sd)) * (step * sd)
    return out


@pytest.fixture(scope="module")
def arm():
    """A 20 s spatial-arm log (1 kHz) and its truth (10 s is too short for least squares to settle)."""
    log, truth, _ = ARM.with_(duration=20.0).generate(3)
    return log, truth


@pytest.mark.slow
def test_frozen_runs_of_a_few_lengths_are_found_bridged_and_counted(arm):
    """Runs of 3-100 held samples (1.4 % of the log): each found where it is, bridged, counted; the calibration
    converged, within its stated sd of the truth and within 2 sd of the clean log's (the held samples' noise
    is gone: S moves as by another draw of it there)."""
    log, truth = arm
    runs = [(1500, 3), (3000, 8), (4500, 20), (6000, 50), (8000, 100), (12000, 30), (15000, 60)]
    clean = calibrate(log, ARM.payload, method="least-squares", latency=0.0, truth=truth)
    cal = calibrate(frozen(log, runs), ARM.payload, method="least-squares", latency=0.0, truth=truth)
    found = cal.glitches["frozen"]
    assert [(run["start"], run["length"]) for run in found["runs"]] == runs
    assert found["count"] == sum(length for _, length in runs) and cal.glitches["count"] == 0
    assert all(run["bridged"] for run in found["runs"])
    assert json.loads(cal.to_json())["glitches"]["frozen"]["runs"][2]["time"] == pytest.approx(log.t[4500])
    assert any("7 frozen stretch(es)" in note for note in cal.notes)
    S = truth.S_at(log.t[-1])
    assert clean.converged and cal.converged and np.abs((cal.S_hat - S) / cal.S_std).max() < 4
    assert np.abs((cal.S_hat - clean.S_hat) / clean.S_std).max() < 2
    left = calibrate(frozen(log, runs), ARM.payload, method="least-squares", latency=0.0, truth=truth)
    assert left.glitches == cal.glitches                                # the same rule, the same answer


def test_frozen_runs_left_in_would_steer_the_fit(arm):
    """The rule matters: the same log with the held samples not bridged (a run given no glitches) is further
    from the truth than the bridged one."""
    log, truth = arm
    bad = frozen(log, [(2000 + 700 * i, 100) for i in range(10)])
    cal = calibrate(bad, ARM.payload, method="least-squares", latency=0.0, truth=truth)
    assert cal.glitches["frozen"]["count"] == 1000
    none = Glitches(np.zeros(0, dtype=int), np.zeros(0), [], np.zeros(0))
    kept = make_observer("least-squares", SpatialModel(ARM.payload), None, {"offset": True}).run(bad, glitches=none)
    S = truth.S_at(log.t[-1])
    assert np.abs(kept.S_hat - S).max() > np.abs(cal.S_hat - S).max()


def test_a_long_freeze_is_a_warning_and_not_converged(arm):
    """A second of the reading held (1000 samples at 1 kHz): too long to bridge (F3), named with its time and
    length, converged False."""
    log, truth = arm
    cal = calibrate(frozen(log, [(5000, 1000)]), ARM.payload, method="least-squares", latency=0.0, truth=truth)
    run, = cal.glitches["frozen"]["runs"]
    assert (run["start"], run["length"], run["bridged"]) == (5000, 1000, False)
    assert not cal.converged and "too long to bridge" in cal.why_unconverged
    assert any("1000 at t = 5.000 s" in w and "too long to bridge" in w for w in cal.warnings)


def test_a_freeze_at_the_end_cannot_be_bridged(arm):
    """The reading held over the log's last 30 samples: one side only, named, not converged."""
    log, truth = arm
    cal = calibrate(frozen(log, [(len(log) - 30, 30)]), ARM.payload, method="least-squares", latency=0.0)
    run, = cal.glitches["frozen"]["runs"]
    assert run["length"] == 30 and not run["bridged"] and not cal.converged


@pytest.mark.parametrize("step", [0.0, 0.5, 2.0, 4.0], ids=["float", "fine", "coarse", "coarser"])
def test_clean_logs_show_no_frozen_run(step):
    """The false-alarm side (F2): clean spatial-arm logs over 4 seeds, as recorded and quantised to 0.5-4
    noise sd per channel, have no frozen run, and the fit is untouched by the rule."""
    for seed in range(4):
        log, _, _ = ARM.with_(duration=10.0).generate(10 + seed)
        if step:
            log = quantised(log, step)
        glitches, _ = find_glitches(log.t, log.w_hat)
        assert glitches.frozen == [], (seed, step, glitches.frozen)
        if step >= 2:                                                   # the quantised reading does repeat
            assert np.all(log.w_hat[1:] == log.w_hat[:-1], axis=1).sum() > 10


def test_a_coarse_reading_still_shows_a_long_freeze():
    """On a reading quantised to 4 noise sd (it repeats by chance), a freeze of 100 samples is still found."""
    log, _, _ = ARM.with_(duration=10.0).generate(20)
    bad = frozen(quantised(log, 4.0), [(4000, 100)])
    glitches, _ = find_glitches(bad.t, bad.w_hat)
    run, = glitches.frozen                          # a neighbour may repeat it by chance: the run may be longer
    assert run["start"] <= 4000 and run["start"] + run["length"] >= 4100 and run["length"] <= 104
    assert run["bridged"]                           # the bridge judged against the reading's scatter, eq. (F3)


def test_the_command_line_prints_the_frozen_runs(tmp_path, capsys):
    """A planar log through ``fmscal calibrate --json``: a bridged run in the note and the report, a run of 2 s
    in a warning with converged False."""
    from fmscal.analysis.cli import main
    from fmscal.plant import get_scenario
    log, _, _ = get_scenario("paper").with_(duration=10.0).generate(0)
    payload = get_scenario("paper").payload
    for name, runs in (("short", [(3000, 40)]), ("long", [(4000, 2000)])):
        frozen(log, runs).write(tmp_path / f"{name}.csv")
        args = ["calibrate", str(tmp_path / f"{name}.csv"), "--mass", repr(payload.mass), "--inertia",
                repr(payload.inertia), "--rho", *map(repr, payload.rho), "--observer", "least-squares",
                "--latency", "0", "--json"]
        main(args)
        out, err = capsys.readouterr()
        report = json.loads(out)
        run, = report["glitches"]["frozen"]["runs"]
        assert (run["start"], run["length"]) == runs[0]
        assert "1 frozen stretch(es) of the reading" in err
        if name == "short":
            assert run["bridged"] and report["converged"]
        else:
            assert not run["bridged"] and not report["converged"]
            assert any("too long to bridge" in w and "2000 at t = " in w for w in report["warnings"])


@pytest.mark.slow
def test_frozen_runs_of_20_to_100_samples_over_seeds():
    """Issue 46's case: four freezes of 20-100 samples in a 10 s spatial-arm log, the default method, 8 seeds.
    Every run found at its rows; the z-scores' rms over S's entries and the seeds in [0.6, 1.5] as the clean
    logs', and S within 1.5 of the clean log's sd of it on every seed (the held samples' noise is gone: S moves
    as by another draw of it there)."""
    z, clean_z = [], []
    for seed in range(8):
        log, truth, _ = ARM.with_(duration=10.0).generate(seed)
        rng = np.random.default_rng(seed)
        starts = np.sort(rng.choice(np.arange(500, 9400, 150), 4, replace=False))
        runs = [(int(a), int(rng.integers(20, 101))) for a in starts]
        S = truth.S_at(log.t[-1])
        exact = PayloadStd.exact()          # the simulator's payload: S_std's statistical part is what is tested
        clean = calibrate(log, ARM.payload, truth=truth, payload_std=exact)
        cal = calibrate(frozen(log, runs), ARM.payload, truth=truth, payload_std=exact)
        assert [(run["start"], run["length"]) for run in cal.glitches["frozen"]["runs"]] == runs
        assert cal.converged == clean.converged
        assert np.abs((cal.S_hat - clean.S_hat) / clean.S_std).max() < 1.5
        z.append((cal.S_hat - S) / cal.S_std)
        clean_z.append((clean.S_hat - S) / clean.S_std)
    rms, clean_rms = np.sqrt(np.mean(np.square(z))), np.sqrt(np.mean(np.square(clean_z)))
    assert 0.6 < rms < 1.5 and 0.6 < clean_rms < 1.5, (rms, clean_rms)
