"""A moving offset and a tilted gravity seen in 3D, then named (issue 46 item 6; eqs. (C1)-(C4) of
observers/diagnostics/_causes.py).

Each case is a row: a ramp of the offset on one channel, the robot's base tilted; the clean log is the
false-alarm side, over seeds. fmscal's own ``spatial-arm`` logs (poses at 1 kHz) run in the fast suite; the
logs MuJoCo writes (tests/mujoco_log.py, the issue's independent engine, where both faults were saved as
converged) in the slow one.
"""

import dataclasses
import re

import numpy as np
import pytest

from fmscal.analysis import calibrate
from fmscal.observers.diagnostics import DRIFT_PARTS, fit_causes
from fmscal.plant import SpatialModel
from fmscal.plant.physics import GRAVITY
from fmscal.plant.scenarios._spatial import SPATIAL_SCENARIOS

ARM = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=20.0)
#: The issue's MuJoCo case: a 1.8 kg payload, 20 s at 1 kHz.
HEAVY = ARM.with_(payload=dataclasses.replace(ARM.payload, mass=1.8))
TILT_DEG = 5.0
#: A ramp of this many noise sd on fx over the log (the issue's case).
RAMP_SD = 10.0
#: The reading's gain on fz falls by this share over a "gainz" log (a sensor warming up): ``S``'s gain on fz rises
#: by ``1 / (1 - GAIN_FALL) - 1``, 5.3 %.
GAIN_FALL = 0.05


def _tilted(degrees):
    """Gravity of a base tilted ``degrees`` about x: what the pose frame sees where the user gives -z."""
    a = np.radians(degrees)
    return (0.0, 9.81 * np.sin(a), -9.81 * np.cos(a))


def _case(scenario, kind, seed, engine="fmscal", ramp_sd=RAMP_SD):
    """The log of ``kind`` ("clean", "ramp", "tilt"; "rampz" and "gainz" on fz, below) and its truth ``S``; the
    ramp ``ramp_sd`` noise sd on fx (on fz for "rampz"); "gainz" the reading's gain on fz falling by
    :data:`GAIN_FALL` over the log about its offset."""
    if kind == "tilt":
        scenario = scenario.with_(gravity=_tilted(TILT_DEG))
    if engine == "mujoco":
        pytest.importorskip("mujoco")                 # the [test] extra installs it
        from mujoco_log import mujoco_log
        log, S, _ = mujoco_log(scenario, seed)
    else:
        log, truth, _ = scenario.generate(seed)
        S = truth.S_at(0.0)
    u = (log.t - log.t[0]) / (log.t[-1] - log.t[0])
    if kind in ("ramp", "rampz"):
        log.w_hat[:, 3 if kind == "ramp" else 5] += ramp_sd * scenario.force_sd * u
    elif kind == "gainz":
        b = truth.offset[5]
        log.w_hat[:, 5] = b + (log.w_hat[:, 5] - b) * (1 - GAIN_FALL * u)
    return log, S


@pytest.mark.parametrize("seed", range(4))
def test_a_clean_log_names_no_cause(seed):
    """The false-alarm side: a constant offset under the gravity given is named neither moving nor tilted."""
    log, _ = _case(ARM, "clean", seed)
    causes = fit_causes(log, SpatialModel(ARM.payload, GRAVITY))
    assert causes.warnings == []
    assert causes.offset.constant and not causes.gravity.tilted
    assert causes.blocks >= 84                          # tested, not passed for want of blocks


@pytest.mark.parametrize("seed", [0, 1])
def test_a_ramping_offset_is_named_on_its_channel(seed):
    log, _ = _case(ARM, "ramp", seed)
    causes = fit_causes(log, SpatialModel(ARM.payload, GRAVITY))
    assert not causes.offset.constant and not causes.gravity.tilted
    line = causes.offset.warning
    assert "the sensor's offset moves" in line and "offset of fx drifts by +" in line
    size = float(line.split("drifts by ")[1].split(" N")[0])
    ramp = RAMP_SD * ARM.force_sd
    assert 0.5 * ramp < size < 1.2 * ramp                # the ramp's size, roughly (two-sided)


def test_the_issue_s_small_ramp_is_named():
    """The issue's 0.1 N ramp (twice the noise) over 20 s: its levels spread 1.6 of the residual's rms, over eq.
    (C4)'s size, at p about 1e-40: named first, on its channel, and not converged (before, "record a longer log"
    came first, and the mass was suspected)."""
    log, _ = _case(ARM, "ramp", 0, ramp_sd=2.0)
    cal = calibrate(log, ARM.payload)
    assert not cal.converged and cal.why_unconverged == "the sensor's offset moves during the log"
    assert "offset of fx drifts by +" in cal.warnings[0]
    size = float(cal.warnings[0].split("drifts by ")[1].split(" N")[0])
    assert 0.5 * 0.1 < size < 1.2 * 0.1


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(10))
def test_the_mocap_logs_pose_noise_is_not_a_moving_offset(seed):
    """``spatial-mocap`` (poses at 0.1 degree, 200 Hz, 20 s, aligned at its latency as ``calibrate`` aligns it): the
    pose noise, differentiated twice into eq. (C1)'s payload columns, once shifted clean logs' levels at p down to
    1e-9; with those columns smoothed over ``PAYLOAD_WINDOW`` no clean log is named, and the issue's 0.1 N ramp on
    the same log is. ``python benchmarks/causes.py --clean 0 100`` runs 100 clean seeds."""
    mocap = SPATIAL_SCENARIOS["spatial-mocap"].with_(duration=20.0)
    model = SpatialModel(mocap.payload, GRAVITY)
    clean = fit_causes(_case(mocap, "clean", seed)[0].shift_poses(mocap.latency), model)
    assert clean.offset.constant and clean.blocks >= 84
    if seed < 3:
        ramp = fit_causes(_case(mocap, "ramp", seed, ramp_sd=2.0)[0].shift_poses(mocap.latency), model)
        assert not ramp.offset.constant and "offset of fx drifts by +" in ramp.offset.warning


@pytest.mark.parametrize("seed", [0, 1])
def test_a_tilted_base_is_named_with_its_tilt(seed):
    log, _ = _case(ARM, "tilt", seed)
    causes = fit_causes(log, SpatialModel(ARM.payload, GRAVITY))
    tilt = causes.gravity
    assert tilt.tilted and causes.offset.constant
    assert abs(tilt.tilt_deg - TILT_DEG) < 4 * tilt.std_deg + 0.05
    assert "--gravity estimate" in tilt.warning and "base is tilted" in tilt.warning
    np.testing.assert_allclose(tilt.gravity, _tilted(TILT_DEG), atol=0.15)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(10))
def test_a_short_mocap_log_s_pose_noise_is_not_a_tilt(seed):
    """10 s of ``spatial-mocap``, its gravity's direction tested with two parts of the log: the pose noise in eq.
    (C1)'s payload columns, differentiated twice over the reference fit's window, had clean logs named tilted
    (seeds 1 and 4 of these); over ``PAYLOAD_WINDOW`` none is, and the base tilted 1 degree is, at its angle."""
    short = SPATIAL_SCENARIOS["spatial-mocap"].with_(duration=10.0)
    model = SpatialModel(short.payload, GRAVITY)
    clean = fit_causes(short.generate(seed)[0].shift_poses(short.latency), model)
    assert clean.tested and clean.warnings == []
    tilted = short.with_(gravity=_tilted(1.0))
    tilt = fit_causes(tilted.generate(seed)[0].shift_poses(short.latency), model).gravity
    assert tilt.tilted and abs(tilt.tilt_deg - 1.0) < min(0.15, 4 * tilt.std_deg + 0.02)


@pytest.mark.parametrize("name", ["spatial-arm", "spatial-mocap"])
@pytest.mark.parametrize("degrees", [1.0, 5.0])
def test_a_short_log_names_a_tilted_base(name, degrees):
    """Issue 46's 10 s logs, the base tilted 1 or 5 degrees: gravity was not tested under about 17 s, and the tilt
    was called the inertia's shape, a fit that did not settle, or the sensor turned 32 degrees about z. Now named
    first with its angle and the gravity to give (at the size given), and nothing else advised: the fit not
    settling is a note, and no turn is named."""
    short = SPATIAL_SCENARIOS[name].with_(duration=10.0, gravity=_tilted(degrees))
    log, _, _ = short.generate(1)
    tilt = fit_causes(log.shift_poses(short.latency), SpatialModel(short.payload, GRAVITY)).gravity
    assert tilt.tilted and not tilt.ambiguous
    assert abs(tilt.tilt_deg - degrees) < min(0.15, 4 * tilt.std_deg + 0.02)
    np.testing.assert_allclose(tilt.gravity, _tilted(degrees), atol=0.02)
    cal = calibrate(log, short.payload)
    assert not cal.converged and cal.why_unconverged == "gravity's direction is not the one given"
    assert "gravity tilted" in cal.warnings[0] and "--gravity " in cal.warnings[0]
    assert not any(words in w for w in cal.warnings for words in ("turned", "record a longer log", "--latency",
                                                                   "mass may be wrong", "try the inertia"))
    assert any(n.startswith("after the cause named: ") and "did not settle" in n for n in cal.notes)


@pytest.mark.parametrize("kind, seed, duration", [("ramp", 14, 8.0), ("ramp", 18, 8.0), ("ramp", 7, 10.0),
                                                  ("tilt", 0, 8.0)])
def test_a_short_log_s_tilt_beside_an_offset_names_both_and_gives_no_gravity(kind, seed, duration):
    """Two parts of a short log follow a ramp of 10 noise sd on fx badly, and the tilt's columns take up a share:
    at 8 s (seeds 14, 18 of ``spatial-arm``) a tilt of 0.16-0.29 degrees where fx's test alone was not significant,
    at 10 s (seed 7 of ``spatial-mocap``) 0.35 degrees beside the offset named. Each gave the gravity found to pass
    as ``--gravity``, the wrong way. The line now names both, the length of log that tells them apart, and no
    gravity; a tilted base on such a log, with no offset near significance, is named a tilt with its gravity."""
    scenario = (SPATIAL_SCENARIOS["spatial-mocap"] if duration == 10.0 else ARM).with_(duration=duration)
    log, _ = _case(scenario, kind, seed)
    causes = fit_causes(log.shift_poses(scenario.latency), SpatialModel(scenario.payload, GRAVITY))
    assert causes.parts < DRIFT_PARTS
    line = causes.gravity.warning
    if kind == "tilt":
        assert causes.gravity.tilted and not causes.gravity.ambiguous and "give the gravity found" in line
        return
    assert causes.gravity.ambiguous and "give the gravity found" not in line
    assert re.search(r"or the offset of [a-z ]*\bfx\b[a-z ]* moves", line)
    assert 14 <= float(re.search(r"record a log of (\d+) s or more", line).group(1)) <= 20
    cal = calibrate(log, scenario.payload)
    assert not cal.converged and cal.why_unconverged in ("the sensor's offset moves during the log",
                                                         "gravity's direction is not the one given, or the offset "
                                                         "moves (the log is too short to tell)")
    assert not any("give the gravity found" in w for w in cal.warnings)


@pytest.mark.parametrize("name, duration", [("spatial-arm", 12.0), ("spatial-arm", 10.0), ("spatial-mocap", 10.0)])
def test_a_short_log_tests_its_offset_with_fewer_parts(name, duration):
    """10-12 s at 1 kHz (issue 46's logs were 10 s): too few blocks of time for six parts' 43 columns, enough for
    two or three parts': a ramp of 10 noise sd on fx is named on fx, in the first warning of ``calibrate``, and not
    converged (on ``spatial-mocap`` too, whose ramp the residual of two parts leaves long-correlated: the blocks'
    length is the most parts' fit's); gravity's direction is tested there too, and not found tilted; a clean log
    names nothing."""
    short = SPATIAL_SCENARIOS[name].with_(duration=duration)
    model = SpatialModel(short.payload, GRAVITY)
    for seed in (0, 1):
        clean = fit_causes(_case(short, "clean", seed)[0].shift_poses(short.latency), model)
        assert clean.warnings == [] and clean.tested and clean.parts < DRIFT_PARTS
    log, _ = _case(short, "ramp", 0)
    causes = fit_causes(log.shift_poses(short.latency), model)
    assert causes.tested and 2 <= causes.parts < DRIFT_PARTS
    assert causes.gravity.p_value < 1.0 and not causes.gravity.tilted
    assert "offset of fx" in causes.offset.warning
    assert not causes.gain.tested and causes.gain.rows == []       # too short for eq. (C5): named as found
    cal = calibrate(log, short.payload)
    assert not cal.converged and cal.why_unconverged == "the sensor's offset moves during the log"
    assert "offset of fx" in cal.warnings[0]


def test_a_log_a_sample_shorter_is_fitted_with_the_same_parts():
    """A 10 s log's blocks of 0.2 s end in a sliver of one sample: counted as a block of its own, it gave 50 blocks,
    enough for three parts, where the same log shifted by a twentieth of a sample (as ``calibrate`` aligns it at
    the latency it estimates) had 49 and two parts, and its 0.1 N ramp went from named (p 5e-11) to not (p 2e-3).
    A last block under half the length joins the one before: both are fitted alike. (A log whose span ends half
    a block past a whole one, 10.1 s here, still has the choice of parts at one sample: any count of blocks
    steps somewhere.)"""
    short = ARM.with_(duration=10.0)
    log, _ = _case(short, "ramp", 0, ramp_sd=2.0)
    model = SpatialModel(short.payload, GRAVITY)
    found = [fit_causes(log.shift_poses(s), model) for s in (0.0, -5e-5)]
    assert found[0].blocks == found[1].blocks and found[0].parts == found[1].parts
    assert found[0].row_p_values[3] == pytest.approx(found[1].row_p_values[3], rel=0.5)


@pytest.mark.parametrize("seed", [0, 2])
def test_a_short_log_s_small_ramp_is_suggested_beside_the_payload(seed):
    """The issue's 0.1 N ramp on a 10 s log: two parts, too few to tell it from a payload given wrong (a centre of
    mass's columns follow the motion's slow changes), so not named; but its test leans to it (p 0.002, 0.012), and
    ``calibrate``, not converged, says so first (an offset that moves, or the payload, and the length that tells
    them apart), where it had said only "did not settle" and "check the payload's mass properties". The clean
    logs of the same length lean to nothing."""
    from fmscal.analysis._calibrate import _OFFSET_OR_PAYLOAD
    short = ARM.with_(duration=10.0)
    model = SpatialModel(short.payload, GRAVITY)
    for clean_seed in range(4):
        clean = fit_causes(_case(short, "clean", clean_seed)[0], model)
        assert clean.suggested == [] and clean.suggestion is None and not clean.gravity.suggestive
    log, _ = _case(short, "ramp", seed, ramp_sd=2.0)
    causes = fit_causes(log, model)
    assert causes.offset.constant and causes.parts == 2 and causes.suggested == [3]
    cal = calibrate(log, short.payload)
    assert not cal.converged and cal.why_unconverged == _OFFSET_OR_PAYLOAD
    first = cal.warnings[0]
    assert first.startswith("the sensor's offset may move, or the payload is given wrong: the level of fx")
    assert re.search(r"record a log of \d+ s or more \(6 parts\)", first)


def test_a_short_log_s_suggested_tilt_names_the_offset_too_and_a_tiny_one_is_not_suggested():
    """A base tilted 0.6 degrees on a 10 s mocap log (seed 2): its test leans to it (p about 1e-3, 0.62 degrees)
    without naming it. On a log fitted with fewer parts than asked a drift's share can also leave a tilt, so the
    suggestion names the offset too, and the length of log that tells them apart. The 0.1 N ramp's share on a
    10 s `spatial-arm` log (seed 1: 0.08 degrees at p about 0.03) is under SUGGESTED_TILT_DEG, and not suggested:
    no gravity blamed for a drift, nor for a payload given wrong."""
    from fmscal.observers.diagnostics._causes import SUGGESTED_TILT_DEG
    mocap = SPATIAL_SCENARIOS["spatial-mocap"]
    short = mocap.with_(duration=10.0, gravity=_tilted(0.6))
    log, _, _ = short.generate(2)
    causes = fit_causes(log.shift_poses(short.latency), SpatialModel(mocap.payload, GRAVITY))
    assert causes.warnings == [] and causes.gravity.suggestive and causes.parts < causes.asked
    assert causes.suggestion.startswith("gravity's direction may not be the one given, or the offset may move: "
                                        "the data lean to gravity tilted 0.6")
    assert re.search(r"record a log of \d+ s or more \(6 parts\)", causes.suggestion)
    arm = ARM.with_(duration=10.0)
    log, _ = _case(arm, "ramp", 1, ramp_sd=2.0)
    causes = fit_causes(log, SpatialModel(arm.payload, GRAVITY))
    assert causes.gravity.p_value < 0.05 and causes.gravity.tilt_deg < SUGGESTED_TILT_DEG
    assert not causes.gravity.suggestive and causes.suggestion is None


@pytest.mark.parametrize("fault", ["saturated", "centre of mass"])
def test_a_suggestion_does_not_go_before_another_check_s_cause(fault):
    """A review of the suggestion: on the 10 s log of the 0.1 N ramp (seed 0) with fz clipped at its 97th
    percentile, the saturation is why it did not converge, and its line came second, after the suggestion; a
    clean 10 s log (seed 1) fitted with the centre of mass 1 cm off along x was told gravity may be tilted
    (0.05 degrees at p 0.008), with no word of the payload, in place of the misfit. Now a suggestion is put first
    only in place of "did not settle" or the misfit's why; a tilt that small is not suggested."""
    short = ARM.with_(duration=10.0)
    payload = short.payload
    if fault == "saturated":
        log, _ = _case(short, "ramp", 0, ramp_sd=2.0)
        log.w_hat[:, 5] = np.minimum(log.w_hat[:, 5], np.percentile(log.w_hat[:, 5], 97))
    else:
        log, _ = _case(short, "clean", 1)
        payload = dataclasses.replace(payload, com=tuple(np.add(payload.com, (0.01, 0.0, 0.0))))
    if fault == "saturated":                            # the log leans to the offset: a suggestion to keep second
        assert fit_causes(log, SpatialModel(payload, GRAVITY)).suggestion is not None
    cal = calibrate(log, payload)
    assert not cal.converged
    if fault == "saturated":
        assert cal.why_unconverged.startswith("the reading saturates") and "saturat" in cal.warnings[0]
        assert not any(w.startswith("the sensor's offset may move") for w in cal.warnings)
    else:
        assert "gravity" not in cal.why_unconverged and not cal.warnings[0].startswith("gravity's direction")


@pytest.mark.parametrize("offset, tilt, short, why, expected", [
    (True, False, True, "unsettled", "offset or payload"),
    (True, True, True, "misfit", "all"),
    (False, True, True, "misfit", "misfit"),             # a tilt alone keeps the misfit's why: the payload misfits too
    (False, True, True, "unsettled", "tilt or offset"),
    (False, True, False, "unsettled", "tilt")])
def test_the_why_of_a_suggestion(offset, tilt, short, why, expected):
    """What ``calibrate`` gives as why a run did not converge where it puts a suggestion first (in place of "did not
    settle" or the misfit): each combination of an offset suggested, a tilt suggested and a short log."""
    from fmscal.analysis import _calibrate as c
    from fmscal.observers.diagnostics import Causes, GravityTilt, OffsetDrift
    causes = Causes(offset=OffsetDrift(True, 1.0, 0.5, np.zeros((0, 6)), np.zeros(0)),
                    gravity=GravityTilt(np.array(GRAVITY), 1.0, 0.5, 5.0, 0.01, False, suggestive=tilt), blocks=50,
                    parts=2 if short else 6, asked=6, suggested=[3] if offset else [])
    given = {"unsettled": c._UNSETTLED, "misfit": c._MISFIT}[why]
    assert c._suggested_why(causes, given) == {"offset or payload": c._OFFSET_OR_PAYLOAD, "all": c._ALL_SUGGESTED,
                                                "misfit": c._MISFIT, "tilt or offset": c._TILT_OR_OFFSET,
                                                "tilt": c._TILT_SUGGESTED}[expected]
    assert causes.short == short


def test_a_short_log_s_tilt_that_turns_s_names_both():
    """A 10 s mocap log of a base tilted 3 degrees (seed 3): the tilt's test at the latency ``calibrate`` finds
    leans to it (p about 2e-3, 2.7 +- 2 degrees) without naming it, and ``S`` turned 46 degrees about z to take it up;
    that turn alone was named (mount the sensor anew). Now the line names both, and how to tell them apart."""
    from fmscal.analysis._calibrate import _TURN_TILT_OR_OFFSET
    short = SPATIAL_SCENARIOS["spatial-mocap"].with_(duration=10.0, gravity=_tilted(3.0))
    log, _, _ = short.generate(3)
    cal = calibrate(log, short.payload)
    assert not cal.converged
    line, = [w for w in cal.warnings if "turned" in w]
    assert "or gravity's direction is not the one given (the data lean to gravity tilted" in line
    assert ", or the offset moves: S turns" in line           # two parts of 10 s: a drift's share, too
    assert cal.why_unconverged == _TURN_TILT_OR_OFFSET
    assert "--gravity estimate" in line


@pytest.mark.parametrize("duration, tested", [(6.0, False), (8.0, True)])
def test_a_short_log_s_ramp_is_not_blamed_on_the_payload(duration, tested):
    """6 s: too short for even two parts (38 blocks of time); 8 s: tested, and this ramp (10 noise sd on fx) named
    on fx. Untested, the ramp leaves the force gains uneven (fx's low), which no mass or unit does: the gains' line
    names fx's offset and the length the test would take, not the mass."""
    short = ARM.with_(duration=duration)
    log, _ = _case(short, "ramp", 0)
    causes = fit_causes(log, SpatialModel(short.payload, GRAVITY))
    assert causes.tested == tested
    cal = calibrate(log, short.payload)
    assert not cal.converged
    assert not any(words in w for w in cal.warnings for words in ("mass may be wrong", "check the payload's mass",
                                                                   "try the inertia"))
    if tested:
        assert "offset of fx" in causes.offset.warning and not causes.gravity.tilted
        assert cal.why_unconverged == "the sensor's offset moves during the log" and "offset of fx" in cal.warnings[0]
        return
    assert causes.warnings == [] and 6.0 < causes.needed_duration < 12.0
    line, = [w for w in cal.warnings if "force gains" in w]
    assert "fx's offset may move" in line and "too short to test" in line


@pytest.mark.parametrize("shift", [(0.01, 0.0, 0.0), (0.0, 0.0, 0.03)])
def test_a_centre_of_mass_given_wrong_is_not_one_channel_s_reading(shift):
    """A centre of mass given 1 cm off along x, or 3 cm along z, on 10 s: its misfit (the slow and fast halves'
    ``S`` apart, the residual near the noise) and its uneven force gains (3 cm: fx and fy 0.44, fz 1.04, the
    torque gains far too) point at the payload, not at one channel's reading."""
    short = ARM.with_(duration=10.0)
    log, _ = _case(short, "clean", 0)
    cal = calibrate(log, dataclasses.replace(short.payload, com=np.asarray(short.payload.com) + shift))
    assert not cal.converged
    assert any("check the payload's mass properties" in w for w in cal.warnings)
    assert not any("alone" in w or "offset may move" in w for w in cal.warnings)


@pytest.mark.parametrize("seed", [0, 2])
def test_a_latency_step_of_a_centre_of_mass_given_wrong_is_named_the_centre_of_mass(seed):
    """A centre of mass given 1 cm off along x on 10 s (its stated sd CAD's 1 mm): the latency's search along the
    log read a step (seeds 0, 2, 3, 4 of 0-5), and the advice was to cut the log or fix its stamps. The step is
    gone at the centre of mass the log prefers (eq. M5): named the payload's, with that centre of mass, within 3
    of its sd of the true one, and the advice to check it or the poses' frame."""
    short = ARM.with_(duration=10.0)
    log, _ = _case(short, "clean", seed)
    true = np.asarray(short.payload.com)
    shift = np.array([0.01, 0.0, 0.0])
    cal = calibrate(log, dataclasses.replace(short.payload, com=true + shift))
    assert not cal.converged and cal.why_unconverged.startswith("the payload's centre of mass is not the one given")
    assert "gone at the centre of mass the log prefers" in cal.warnings[0]
    assert not any("fix the stamps" in w or "try the inertia" in w for w in cal.warnings)
    found = re.findall(r"([-+.\d]+) \+- ([.\d]+) mm", cal.warnings[0])
    delta, sd = (np.array([float(v[k]) for v in found]) * 1e-3 for k in (0, 1))
    assert len(found) == 3 and np.all(sd < 0.3 * 0.01)
    assert np.all(np.abs(delta + shift) < 3 * sd)       # the change the log asks for undoes the one given


def test_a_clean_log_prefers_the_centre_of_mass_given():
    """The false-alarm side: clean 10 s logs of the payload given converge, and no centre of mass is named."""
    short = ARM.with_(duration=10.0)
    for seed in (0, 1, 2):
        cal = calibrate(_case(short, "clean", seed)[0], short.payload)
        assert cal.converged and not any("centre of mass" in w for w in cal.warnings)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_drifting_gain_is_named_a_gain_not_an_offset(seed):
    """``S``'s gain on fz rising 5.3 % over 20 s: the needed force's mean on fz (the payload's weight) made it a
    moving offset of fz, and so it was named; its residual follows fz's needed wrench, which eq. (C5) tells from
    an offset's: the gain is named, with its size, and no offset; ``calibrate`` says why it did not converge."""
    log, _ = _case(ARM, "gainz", seed)
    causes = fit_causes(log, SpatialModel(ARM.payload, GRAVITY))
    assert causes.offset.constant and causes.offset.warning is None
    assert causes.gain.tested and causes.gain.rows == [5] and causes.gain.unresolved == []
    assert 0.035 < causes.gain.changes[0] < 0.07                      # 5.3 %, two-sided
    assert causes.warnings[0].startswith("S's gain moves during the log: its gain changes on fz by +")
    if seed == 0:
        cal = calibrate(log, ARM.payload)
        assert not cal.converged and cal.why_unconverged == "S's gain moves during the log"
        assert cal.warnings[0].startswith("S's gain moves")


@pytest.mark.parametrize("seed", [0, 1])
def test_a_moving_offset_on_a_loaded_channel_is_not_a_gain(seed):
    """The other side of eq. (C5): a ramp of 10 noise sd on fz, the channel the payload's weight loads, is named
    the offset of fz, and no gain."""
    log, _ = _case(ARM, "rampz", seed)
    causes = fit_causes(log, SpatialModel(ARM.payload, GRAVITY))
    assert not causes.offset.constant and "offset of fz drifts by +" in causes.offset.warning
    assert causes.gain.tested and causes.gain.rows == [] and "gain" not in causes.offset.warning


def test_a_gain_the_log_cannot_tell_from_an_offset_is_named_beside_it():
    """A step of 10 noise sd of fz's offset a third into a 20 s ``spatial-mocap`` log (seed 2): fz's offset and gain
    together move, and neither alone is determined (a step, which the ramps of eq. (C5) follow badly, leaves a
    share in the gain's columns): the offset is named as found, and its line names either."""
    mocap = SPATIAL_SCENARIOS["spatial-mocap"].with_(duration=20.0)
    log, _ = _case(mocap, "clean", 2)
    log.w_hat[:, 5] += RAMP_SD * mocap.force_sd * (log.t - log.t[0] > (log.t[-1] - log.t[0]) / 3)
    causes = fit_causes(log.shift_poses(mocap.latency), SpatialModel(mocap.payload, GRAVITY))
    assert causes.gain.rows == [] and causes.gain.unresolved == [5]
    assert "offset of fz steps by +" in causes.offset.warning
    assert "; fz's row moves by its offset or by S's gain on fz, which the log does not tell apart (p = " in \
        causes.offset.warning


def test_spatial_drift_s_gains_are_named():
    """``spatial-drift`` (every channel's gain drifting 5 %) was named a moving offset of fz: its gains are named."""
    drift = SPATIAL_SCENARIOS["spatial-drift"].with_(duration=20.0)
    log, truth, _ = drift.generate(1)
    causes = fit_causes(log, SpatialModel(drift.payload, GRAVITY))
    moved = np.diag(np.linalg.solve(truth.S_at(0.0), truth.S_at(log.t[-1]))) - 1
    assert {3, 5} <= set(causes.gain.rows)
    assert np.all(np.sign(causes.gain.changes) == np.sign(moved[causes.gain.rows]))
    assert np.all((0.5 * np.abs(moved[causes.gain.rows]) < np.abs(causes.gain.changes))
                  & (np.abs(causes.gain.changes) < 1.5 * np.abs(moved[causes.gain.rows])))      # its size, two-sided
    assert causes.warnings[0].startswith("S's gain moves during the log")                   # the gain first
    row = list(SpatialModel(drift.payload).wrench_names).index(
        causes.offset.warning.split("the offset of ")[1].split(" ")[0])
    assert f"p = {causes.row_p_values[row]:.2g})" in causes.offset.warning          # its own row's p, not fz's
    cal = calibrate(log, drift.payload)               # tx's row named an offset beside (the gains' cross-talk)
    assert not cal.converged and cal.why_unconverged == "the sensor's offset and S's gain move during the log"
    assert cal.warnings[0].startswith("S's gain moves")


def test_the_offset_s_test_leaves_out_the_rows_a_gain_explains():
    """The offset's ``F`` and p-value are those of the rows named an offset, else of the rows no gain explains (none
    left: NaN and 1), not of a row named a gain."""
    from fmscal.observers.diagnostics._causes import _offset_drift
    tests = [(30.0, 2, 1e-9), (4.0, 2, 0.2), (2.0, 2, 0.5)]
    assert _offset_drift(tests, [], 100, among=[1, 2]).p_value == pytest.approx(3 * 0.2)
    assert _offset_drift(tests, [2], 100, among=[1, 2]).p_value == pytest.approx(1.0)          # 3 x 0.5, at most 1
    assert _offset_drift(tests, [], 100).p_value == pytest.approx(3e-9)
    none = _offset_drift(tests, [], 100, among=[])
    assert none.constant and none.p_value == 1.0 and np.isnan(none.statistic)


def test_a_log_too_short_to_test_names_nothing():
    """A 5 s log has too few blocks of time for the covariance of (C1)'s columns (19 at its fewest parts): nothing is
    named."""
    scenario = ARM.with_(duration=5.0, gravity=_tilted(TILT_DEG))
    log, _, _ = scenario.generate(0)
    causes = fit_causes(log, SpatialModel(ARM.payload, GRAVITY))
    assert causes.warnings == [] and causes.gravity.p_value == 1.0


@pytest.mark.parametrize("kind, why, named", [
    ("ramp", "the sensor's offset moves during the log", "the offset of fx drifts"),
    ("tilt", "gravity's direction is not the one given", "--gravity estimate")])
def test_calibrate_names_the_cause_and_does_not_converge(kind, why, named):
    """``calibrate`` runs the check on a spatial log: the cause's line first among the warnings, ``converged``
    False, and no advice on the mass (the gains are the cause's)."""
    log, _ = _case(ARM, kind, 2)
    cal = calibrate(log, ARM.payload)
    assert not cal.converged and cal.why_unconverged == why
    assert named in cal.warnings[0]
    assert not any("mass may be wrong" in w for w in cal.warnings)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["clean", "ramp", "tilt"])
@pytest.mark.parametrize("seed", [1, 2])
def test_the_independent_engines_log(kind, seed):
    """The issue's MuJoCo case (1.8 kg, 20 s, 1 kHz): a ramp of the offset and a base tilted 5 degrees were saved
    as converged with max |z| 14 and 23; each is now named and not converged, and the clean log converges with
    nothing named."""
    log, S = _case(HEAVY, kind, seed, engine="mujoco")
    cal = calibrate(log, HEAVY.payload)
    if kind == "clean":
        assert cal.converged, cal.warnings
        assert not any("offset moves" in w or "gravity's direction" in w for w in cal.warnings)
        assert np.abs((cal.S - S) / cal.S_std).max() < 5
    else:
        assert not cal.converged
        assert ("offset of fx drifts" if kind == "ramp" else "gravity tilted") in cal.warnings[0]


def _arm(seed=1, duration=10.0):
    return SPATIAL_SCENARIOS["spatial-arm"].with_(duration=duration).generate(seed)[0]


@pytest.mark.slow
@pytest.mark.parametrize("reading", ["reaction", "load"])
def test_too_little_rotation_names_that_not_the_sign(reading):
    """``spatial-weak``: the force gains undetermined: the line says the log cannot tell the sign, either way
    (it said "pass reading=load", then with load "pass reading=reaction")."""
    weak = SPATIAL_SCENARIOS["spatial-weak"].with_(duration=10.0)
    log, _, _ = weak.generate(1)
    cal = calibrate(log, weak.payload, reading=reading)
    assert not cal.converged and cal.why_unconverged == "the log holds too little rotation to tell the reading's sign"
    assert not any("pass reading" in w or "mass may be wrong" in w for w in cal.warnings)


@pytest.mark.slow
@pytest.mark.parametrize("reading", ["reaction", "load"])
def test_a_log_held_still_gives_no_advice_on_the_sign(reading):
    """A tool held all but still (turns of a milliradian): not converged, and no ``reading=`` advice either way."""
    still = ARM.with_(duration=10.0, angle_amplitude=(1e-3, 1e-3, 1e-3), position_amplitude=1e-3)
    log, _, _ = still.generate(1)
    cal = calibrate(log, still.payload, reading=reading)
    assert not cal.converged
    assert not any("pass reading" in w or "mass may be wrong" in w for w in cal.warnings)
    assert any("not determined" in w for w in cal.warnings)


@pytest.mark.parametrize("flip, named", [
    ([0, 1, 3, 4], "turned 1"),                          # 180 degrees about z: x and y negated
    ([1, 2, 4, 5], "turned 1"),                          # about x
    ([0, 1, 2, 3, 4, 5], "other sign convention")])      # every channel negated: the sign
def test_a_sensor_turned_about_an_axis_is_not_the_sign(flip, named):
    log = _arm()
    log.w_hat[:, flip] *= -1
    cal = calibrate(log, ARM.payload)
    assert not cal.converged and named in cal.warnings[0]
    if named.startswith("turned"):
        axis = "z" if flip == [0, 1, 3, 4] else "x"
        assert f"degrees about the sensor's {axis}" in cal.warnings[0] and "sign convention is not the cause" in \
            cal.warnings[0]
        assert cal.why_unconverged == "the sensor is turned from the frame the poses give"
    assert not any("mass may be wrong" in w for w in cal.warnings)


def test_a_centre_of_mass_in_mm_is_named():
    from fmscal.plant.io import UnitsError
    payload = dataclasses.replace(ARM.payload, com=tuple(1000 * c for c in ARM.payload.com))
    with pytest.raises(UnitsError, match=r"centre of mass given in mm\? give it in m \(--com 0.01 -0.005 0.06\)"):
        calibrate(_arm(), payload)


def test_gravity_jacobian_moves_the_wrench_exactly():
    """Eq. (G1): the needed wrench is affine in gravity, ``w(g') = w(g) + D (g' - g)``, to rounding."""
    from fmscal.plant.physics import gravity_jacobian, regressor
    rng = np.random.default_rng(0)
    n = 50
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    omega, alpha, p_ddot = (rng.normal(size=(n, 3)) for _ in range(3))
    pi = ARM.payload.inertial_parameters
    g0, g1 = np.array(GRAVITY), np.array(_tilted(7.0)) * 1.01
    w0 = regressor(q, omega, alpha, p_ddot, tuple(g0)) @ pi
    w1 = regressor(q, omega, alpha, p_ddot, tuple(g1)) @ pi
    D = gravity_jacobian(q, ARM.payload)
    np.testing.assert_allclose(w1, w0 + D @ (g1 - g0), rtol=0, atol=1e-12)
    assert np.abs(w1 - w0).max() > 0.1                  # the tilt moves it


@pytest.mark.parametrize("kind", ["clean", "ramp"])
def test_a_long_log_is_taken_at_a_stride_and_still_tested(kind):
    """60 s at 1 kHz: fitted at every 3rd sample (MAX_ROWS), its blocks of time the same; the ramp still named
    and the clean log not."""
    from fmscal.observers.diagnostics._causes import MAX_ROWS
    long = SPATIAL_SCENARIOS["spatial-arm"]
    log, _ = _case(long, kind, 0)
    assert len(log.t) > 2 * MAX_ROWS
    causes = fit_causes(log, SpatialModel(long.payload, GRAVITY))
    assert causes.blocks > 250                          # 0.2 s blocks over 60 s, as without the stride
    assert causes.offset.constant == (kind == "clean") and not causes.gravity.tilted


def test_a_misfit_s_covariance_from_fewer_blocks_than_numbers_is_no_traceback(monkeypatch):
    """A base tilted 5 degrees on 10 s of ``spatial-mocap``: the misfit's residual is so long-correlated that eq.
    (M4)'s five inertia shapes and (M5)'s eight numbers had six blocks of time; their covariance is then singular,
    and ``calibrate`` raised ``LinAlgError`` (``np.linalg.solve``) where rounding left it exactly so. Each statistic
    is now taken on the directions its covariance determines, and Hotelling's test over so few blocks says
    nothing: here with one block of time, forced."""
    from fmscal.observers.batch import hotelling
    from fmscal.observers.diagnostics import _misfit
    from fmscal.observers.diagnostics._misfit import _tests
    V = np.diag([1.0, 2.0, 3.0, 0.0, 0.0])              # exactly singular: solve raises on it
    a = np.array([1.0, 1.0, 1.0, 0.0, 0.0])
    statistic, dof, p_value, p_stated = _tests(a, V, np.eye(5), 40)
    assert statistic == pytest.approx(1.0 + 1.0 / 2 + 1.0 / 3) and dof == 3 and 0.0 < p_value < p_stated < 1.0
    assert hotelling(a, V, 40)[:2] == (pytest.approx(statistic), 3)     # the three directions V determines
    assert hotelling(a, V, 4)[2] == 1.0 and _tests(a, V, np.eye(5), 4)[2:] == (1.0, 1.0)
    monkeypatch.setattr(_misfit, "block_length", lambda residual, dt, window: 1e9)
    short = SPATIAL_SCENARIOS["spatial-mocap"].with_(duration=10.0, gravity=_tilted(5.0))
    cal = calibrate(short.generate(1)[0], short.payload)
    assert not cal.converged and "gravity tilted" in cal.warnings[0]
    assert not any("inertia" in line for line in cal.warnings + cal.notes)   # one block: its shape not tested


@pytest.mark.parametrize("channels, named", [([0, 1, 2, 3, 4, 5], "other sign convention"),
                                             ([0, 1, 3, 4], "degrees about the sensor's z")])
def test_a_moving_offset_does_not_hide_the_sign_or_a_half_turn(channels, named):
    """A cause named keeps a turn of ``S`` that the cause makes unnamed (a tilt of 5 degrees turned it 32), not the
    sign nor a turn no cause makes: a sensor warming up (a ramp of 10 noise sd on fx) whose reading follows the other
    convention, or that is mounted turned 180 degrees about z (x and y negated: a negative trace, not the sign), is
    told that beside the drift."""
    log, _ = _case(ARM, "ramp", 0)
    log.w_hat[:, channels] = -log.w_hat[:, channels]
    cal = calibrate(log, ARM.payload)
    assert not cal.converged and "offset of fx drifts" in cal.warnings[0]
    assert any(named in w for w in cal.warnings)
    assert not any("other sign convention" in w for w in cal.warnings if "about the sensor's z" in named)
