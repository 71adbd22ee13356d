"""Issue 37's latency targets, on fewer seeds than the benchmark (``python benchmarks/latency.py --seeds 20`` runs
the full 20 per source and latency and prints the table): E within 1.15x of the E at the known latency, the
z-scores' rms within [0.8, 1.25], every seed converged; on ``simulate``'s spatial-arm and spatial-mocap logs and
on MuJoCo's, with true latencies of either sign and fractions of a sample, and on MuJoCo's with the wrench held over
each step (issue 46: its poses line up half a sample later than their delay, the known latency there)."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

_SPEC = importlib.util.spec_from_file_location("latency_bench", Path(__file__).parents[1] / "benchmarks" / "latency.py")
bench = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(bench)


@pytest.mark.slow
@pytest.mark.parametrize("source, latencies", [("spatial-arm", (-1.0, 2.5)), ("spatial-mocap", (0.4,)),
                                               ("mujoco-arm", (0.0, 5.0)), ("mujoco-held", (0.0, 2.5))])
def test_the_latency_targets_hold(source, latencies):
    """Two seeds of 10 s per source and latency. The z-scores' rms within [0.8, 1.25], or, where the method with
    the latency given is already above that (the floor on short spatial-mocap logs), within 1.05x of
    it: the latency's estimate adds nothing."""
    rows = bench.targets(seeds=2, duration=10.0, sources=(source,), latencies=latencies)
    assert max(r["E_ratio_max"] for r in rows) <= 1.15
    z_rms = np.sqrt(np.mean([r["z_rms"] ** 2 for r in rows]))
    z_known = np.sqrt(np.mean([r["z_rms_known"] ** 2 for r in rows]))
    assert 0.8 <= z_rms <= max(1.25, 1.05 * z_known)
    assert all(r["converged"] == 1.0 for r in rows)


@pytest.mark.slow
def test_the_issues_timing_cases_are_not_saved_sigma_off():
    """The issue's first case (spatial-mocap, seed 1, 10 s, 5 ms late): no entry of S 5 sigma off, E near the
    known latency's; the second (MuJoCo, 1 kHz, no latency: 1 ms before, E 3.6x; here 10 s): E within 1.15x of
    --latency 0."""
    from fmscal.analysis import calibrate, calibration_error
    from fmscal.plant import SPATIAL_SCENARIOS, PayloadStd
    sc = SPATIAL_SCENARIOS["spatial-mocap"].with_(duration=10.0)
    log, truth, _ = sc.generate(1)
    cal = calibrate(log, truth.payload, payload_std=PayloadStd.exact())
    known = calibrate(log, truth.payload, latency=0.005, payload_std=PayloadStd.exact())
    S = truth.S_at(log.t[-1])
    assert np.max(np.abs((np.asarray(cal.S) - S) / np.asarray(cal.S_std))) < 5
    assert calibration_error(cal.S, S) <= 1.15 * calibration_error(known.S, S)
    make = bench._source("mujoco-arm", 10.0)
    log, S, payload, _ = make(4, 0.0)
    cal, known = calibrate(log, payload), calibrate(log, payload, latency=0.0)
    assert abs(cal.latency) < 0.5e-3 and cal.converged == known.converged          # the latency adds no doubt
    assert not any("latency" in w for w in cal.warnings)
    assert calibration_error(cal.S, S) <= 1.15 * calibration_error(known.S, S)


@pytest.mark.slow
def test_a_noisy_planar_latency_is_covered_or_not_determined():
    """Issue 46: 12 seeds of 20 s paper logs at the scenario's noise, twice it and thirty times it
    (``python benchmarks/latency.py --noisy --seeds 12``). No seed is determined more than 3 of its standard
    deviations off; at 30x none is determined (the review's 42 +- 0.7 ms for a true 0), at 1x every one is (the
    rule does not refuse what the log determines). The latency's z-scores pooled over the determined seeds (15
    of them) have their rms within [0.5, 1.35]: a right std gives [0.65, 1.35] with 95 % over 15 seeds, the upper
    bound taken from it; the lower allows the std's known lean to the wide side (the scores' variance over
    blocks, eq. L3, counts the smoothed noise's edges, and eq. L5 adds the windows' difference), and fails a std
    1.3x wider than it is now (rms 0.66)."""
    rows = {r["noise_scale"]: r for r in bench.noisy(seeds=12, duration=20.0, scales=(1.0, 2.0, 30.0))}
    assert rows[1.0]["determined"] == 12 and rows[30.0]["determined"] == 0
    z = np.concatenate([r["z"] for r in rows.values()])
    assert np.max(np.abs(z)) <= 3
    assert 0.5 <= np.sqrt(np.mean(z ** 2)) <= 1.35
