"""The payload file, format ``fmscal-payload/2``: everything compensation needs, checked on load (issue 44).

A round trip of a table's fit and a log's, the covariance over ``PAYLOAD_PARAMETERS`` (the delta method of
the fits, turned exactly into the tracked frame's axes, honest over seeds), files of the first format still
read, and every field of a bad file refused in one line.
"""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fmscal.analysis import calibrate
from fmscal.observers.payload import (PAYLOAD_FORMAT, PAYLOAD_PARAMETERS, PayloadEstimate, PayloadFileError,
                                      fit_static, identify_payload)
from fmscal.observers.payload._estimate import inertia_turn, propagate_covariance
from fmscal.observers.payload._payload_fit import _physical, _report
from fmscal.observers.payload._static_fit import _exp
from fmscal.plant import SPATIAL_SCENARIOS, FmscalError
from fmscal.plant.io import simulate_table
from fmscal.plant.physics import inertia_matrix
from fmscal.plant.scenarios import TOOL

V1 = Path(__file__).parent / "data" / "payload-v1"
OFFSET = np.array([0.01, -0.02, 0.03, 0.5, -0.3, 0.2])       # N m, N
MOUNT = _exp(np.radians(7.0) * np.array([0.3, 1.0, 0.5]) / np.linalg.norm([0.3, 1.0, 0.5]))    # a sensor askew
TILT = _exp(np.radians(5.0) * np.array([1.0, 0.3, 0.0]) / np.linalg.norm([1.0, 0.3, 0.0]))     # a tilted base
G = np.array([0.0, 0.0, -9.81])
S_TRUE = np.diag([1.02, 0.98, 1.01, 1.03, 0.97, 1.0]) + 0.01 * np.eye(6, k=1)     # a calibration, not the identity


@pytest.fixture(scope="module")
def askew():
    """A table of a sensor bolted askew on a tilted base, read in the load convention, and its fit."""
    table = simulate_table(TOOL, n=16, seed=4, offset=OFFSET, mounting=MOUNT, gravity=TILT @ G, reading="load")
    return table, fit_static(table, estimate_gravity=True, estimate_mounting=True, reading="load")


@pytest.fixture(scope="module")
def log_fit():
    """8 s of spatial-arm with S = I: the inertia determined."""
    log = SPATIAL_SCENARIOS["spatial-arm"].with_(crosstalk=0.0, duration=8.0).generate(seed=2)[0]
    return identify_payload(log)


def _saved(tmp_path, fit, name="payload.json"):
    fit.save(tmp_path / name)
    return json.loads((tmp_path / name).read_text()), PayloadEstimate.load(tmp_path / name)


def test_a_tables_payload_round_trips_with_everything_compensation_needs(tmp_path, askew):
    _, fit = askew
    document, loaded = _saved(tmp_path, fit)
    tracked = fit.tracked()
    assert document["format"] == PAYLOAD_FORMAT == "fmscal-payload/2" and document["axes"] == "tracked"
    assert document["parameters"] == list(PAYLOAD_PARAMETERS) and len(PAYLOAD_PARAMETERS) == 16
    # the inertia: null with its reason, and its rows and columns of cov null (infinite in memory)
    assert document["inertia"] is None and document["inertia_std"] is None and "held poses" in document["inertia_note"]
    assert all(v is None for row in document["cov"][4:10] for v in row)
    assert all(row[k] is None for row in document["cov"] for k in range(4, 10))
    assert np.all(np.isinf(loaded.cov[4:10])) and np.all(np.isinf(loaded.cov[:, 4:10]))
    keep = np.r_[0:4, 10:16]
    np.testing.assert_array_equal(loaded.cov[np.ix_(keep, keep)], tracked.cov[np.ix_(keep, keep)])
    for name in ("mass", "mass_std", "com", "com_std", "b", "b_std", "gravity", "gravity_std_deg", "mounting",
                 "mounting_std_deg", "noise_sd"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(tracked, name), err_msg=name)
    np.testing.assert_allclose(loaded.mounting_deg, fit.mounting_deg, rtol=1e-9)
    np.testing.assert_allclose(loaded.mounting_axis, fit.mounting_axis, rtol=1e-9)
    assert loaded.reading == "load" and loaded.noise_of == "pose"
    np.testing.assert_array_equal(loaded.gains, fit.gains)              # the force gains, estimated with the payload
    assert loaded.gravity_given is None and loaded.gravity_std is None and loaded.axes == "tracked"
    np.testing.assert_array_equal(loaded.gravity_used, fit.gravity)
    # the offset is the reading's, not turned; the noise the fit weighed by (each group's, torques and forces)
    np.testing.assert_array_equal(loaded.b, fit.b)
    assert len(set(loaded.noise_sd[:3])) == 1 and len(set(loaded.noise_sd[3:])) == 1
    assert 0.5 < loaded.noise_sd[3] / 0.05 < 2 and 0.5 < loaded.noise_sd[0] / 0.005 < 2     # simulate_table's sd
    # turned by M, the file's centre of mass is the tracked frame's; M^T turns it back to the sensor's axes
    np.testing.assert_allclose(loaded.mounting.T @ loaded.com, fit.com, rtol=0, atol=1e-15)


def test_a_logs_payload_round_trips_with_its_inertia_and_the_gravity_given(tmp_path, log_fit):
    document, loaded = _saved(tmp_path, log_fit)
    assert log_fit.converged and log_fit.inertia is not None and document["inertia_note"] is None
    np.testing.assert_array_equal(loaded.inertia, log_fit.inertia)           # no mounting: the same axes
    np.testing.assert_allclose(np.sqrt(np.diag(loaded.cov)), np.r_[loaded.mass_std, loaded.com_std,
                                                                    loaded.inertia_std, loaded.b_std], rtol=1e-12)
    assert np.all(np.isfinite(loaded.cov)) and loaded.noise_of == "sample" and loaded.reading == "reaction"
    # gravity given, not estimated: written, with no direction's sd, and read back as given
    assert document["gravity"] == [0.0, 0.0, -9.81] and document["gravity_std_deg"] is None
    assert loaded.gravity is None and list(loaded.gravity_given) == [0.0, 0.0, -9.81]
    np.testing.assert_array_equal(loaded.mounting, np.eye(3))
    assert document["mounting_std_deg"] is None                            # not estimated: the identity taken
    # the noise the fit weighed by is of one sample: the scenario's, at its 1 kHz
    sd = SPATIAL_SCENARIOS["spatial-arm"]
    np.testing.assert_allclose(loaded.noise_sd, [sd.torque_sd] * 3 + [sd.force_sd] * 3, rtol=0.3)


def test_the_covariance_is_the_delta_method_of_the_fit():
    """(E1) in a log's fit: from the covariance of its parameters (pi = (m, h, I_O), c = S b) to (m, com, I_c, b).

    Draws of the fit's parameters mapped by the nonlinear map itself (``com = h / m``, ``I_c = I_O + m
    [com]x^2``, ``b = S^-1 c``) have the covariance the report states, to the draws' sampling error.
    """
    rng = np.random.default_rng(0)
    theta = np.r_[TOOL.inertial_parameters, S_TRUE @ OFFSET]
    A = rng.normal(size=(16, 16))
    D = np.diag(2e-3 * np.maximum(np.abs(theta), 1e-3))   # each to about 0.2 %: the first-order map holds
    cov = D @ (A @ A.T / 16) @ D                          # correlated, as a fit's are
    report = _report(theta, cov, S_TRUE, np.ones(6))
    assert report.inertia is not None
    draws = rng.multivariate_normal(theta, cov, size=40000)
    mapped = np.column_stack([_physical_rows(draws[:, :10]), np.linalg.solve(S_TRUE, draws[:, 10:].T).T])
    sampled = np.cov(mapped.T)
    np.testing.assert_allclose(_physical_rows(theta[None, :10])[0], _physical(theta[:10]), rtol=1e-12)
    np.testing.assert_allclose(np.sqrt(np.diag(report.cov)), np.sqrt(np.diag(sampled)), rtol=0.03)
    corr = lambda C: C / np.sqrt(np.outer(np.diag(C), np.diag(C)))             # noqa: E731
    np.testing.assert_allclose(corr(report.cov), corr(sampled), atol=0.03)
    np.testing.assert_allclose(np.sqrt(np.diag(report.cov)), np.r_[report.mass_std, report.com_std,
                                                                   report.inertia_std, report.b_std], rtol=1e-12)


def _physical_rows(pi):
    """``(m, com, I_c)`` of rows of ``pi = (m, h, I_O)``: ``com = h / m``, ``I_c = I_O + m [com]x^2``."""
    m, com = pi[:, 0], pi[:, 1:4] / pi[:, :1]
    x, y, z = com.T
    # m [com]x^2 = m (com com^T - |com|^2 I), its six entries
    parallel = m[:, None] * np.column_stack([x * x, y * y, z * z, x * y, x * z, y * z])
    parallel[:, :3] -= (m * np.sum(com ** 2, axis=1))[:, None]
    return np.column_stack([m, com, pi[:, 4:10] + parallel])


def test_tracked_turns_the_covariance_exactly(log_fit):
    turned = replace(log_fit, mounting=MOUNT).tracked()
    C, T = log_fit.cov, turned.cov
    L = inertia_turn(MOUNT)
    np.testing.assert_allclose(T[1:4, 1:4], MOUNT @ C[1:4, 1:4] @ MOUNT.T, rtol=1e-12, atol=1e-24)
    np.testing.assert_allclose(T[4:10, 4:10], L @ C[4:10, 4:10] @ L.T, rtol=1e-12, atol=1e-24)
    np.testing.assert_allclose(T[1:4, 10:], MOUNT @ C[1:4, 10:], rtol=1e-12, atol=1e-24)
    np.testing.assert_array_equal(T[10:, 10:], C[10:, 10:])                # the offset is the reading's
    np.testing.assert_array_equal(T[0, 0], C[0, 0])
    np.testing.assert_allclose(turned.com_std, np.sqrt(np.diag(T)[1:4]), rtol=1e-15)
    np.testing.assert_allclose(turned.inertia_std, np.sqrt(np.diag(T)[4:10]), rtol=1e-15)
    # L(M) is I -> M I M^T on the six entries, for any tensor
    I = inertia_matrix(log_fit.inertia)
    turned_tensor = MOUNT @ I @ MOUNT.T
    np.testing.assert_allclose(turned.inertia, [turned_tensor[0, 0], turned_tensor[1, 1], turned_tensor[2, 2],
                                                turned_tensor[0, 1], turned_tensor[0, 2], turned_tensor[1, 2]],
                               rtol=1e-12)
    assert turned.tracked().com is not turned.com and np.array_equal(turned.tracked().com, turned.com)   # once


def test_an_infinite_variance_reaches_every_output_that_depends_on_it():
    cov = np.diag([1.0, np.inf, 4.0])
    T = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 2.0]])
    out = propagate_covariance(T, cov)
    assert out[0, 0] == 1.0 and out[2, 2] == 16.0 and out[0, 2] == 0.0
    assert np.all(np.isinf(out[1])) and np.all(np.isinf(out[:, 1]))
    assert np.all(np.isinf(propagate_covariance(np.eye(3), np.diag([1.0, 1.0, 1.0]), unknown=[2])[2]))


@pytest.mark.slow
def test_the_turned_covariance_is_honest_over_seeds():
    """Over 20 seeds of a sensor askew: the mass, centre of mass (tracked axes) and offset's errors against
    their full covariance, the Mahalanobis distance ~ chi-square of 10 degrees of freedom (1.00 measured)."""
    d2 = []
    for seed in range(20):
        table = simulate_table(TOOL, n=16, seed=seed, offset=OFFSET, mounting=MOUNT)
        tracked = fit_static(table, estimate_mounting=True).tracked()
        e = np.r_[tracked.mass - TOOL.mass, tracked.com - MOUNT @ np.array(TOOL.com), tracked.b - OFFSET]
        keep = np.r_[0:4, 10:16]
        d2.append(float(e @ np.linalg.solve(tracked.cov[np.ix_(keep, keep)], e)))
    ratio = np.mean(d2) / 10                      # its sd over 20 seeds of chi2(10): 0.10
    assert 0.7 < ratio < 1.4, ratio


# --- files of the first format ------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["table-v1.json", "tilted-v1.json", "log-v1.json"])
def test_a_first_format_file_still_reads(name):
    document = json.loads((V1 / name).read_text())
    assert document["format"] == "fmscal-payload/1"
    estimate = PayloadEstimate.load(V1 / name)
    assert estimate.mass == document["mass"] and list(estimate.com) == document["com"]
    assert estimate.b is None and estimate.cov is None and estimate.reading is None and estimate.mounting is None
    if document["gravity"] is None:                # the format's null: the default was used
        assert estimate.gravity is None and list(estimate.gravity_given) == [0.0, 0.0, -9.81]
    else:
        assert list(estimate.gravity) == document["gravity"] and estimate.gravity_given is None
    assert (estimate.inertia is None) == (document["inertia"] is None)
    with pytest.raises(FmscalError, match="holds no b, b_std, reading .* identify the payload again"):
        estimate.save(Path("never-written.json"))
    assert not Path("never-written.json").exists()


def test_a_first_format_file_stands_for_its_payload_in_calibrate():
    table = simulate_table(TOOL, n=12, seed=0, offset=[0.01, -0.02, 0.005, 0.3, -0.2, 0.1])
    by_file = calibrate(table, PayloadEstimate.load(V1 / "table-v1.json"))
    document = json.loads((V1 / "table-v1.json").read_text())
    by_numbers = calibrate(table, (document["mass"], document["com"]))
    np.testing.assert_array_equal(by_file.S_hat, by_numbers.S_hat)


def test_calibrate_takes_the_file_as_it_takes_the_fit(tmp_path, askew):
    """The file keeps the centre of mass in the tracked frame's axes: calibrate gets the same payload from the
    fit, from its tracked estimate and from the file, and tracked() of a tracked estimate turns nothing."""
    table, fit = askew
    _, loaded = _saved(tmp_path, fit)
    by_fit, by_file = calibrate(table, fit, reading="load"), calibrate(table, loaded, reading="load")
    np.testing.assert_allclose(by_file.S_hat, by_fit.S_hat, rtol=0, atol=1e-12)


# --- bad files ------------------------------------------------------------------------------------------------------

def _nulls(document, rows):
    cov = [list(row) for row in document["cov"]]
    for k in rows:
        cov[k] = [None] * 16
        for row in cov:
            row[k] = None
    return cov


def _asymmetric(document):
    cov = [list(row) for row in document["cov"]]
    cov[0][1], cov[1][0] = 1e-6, -1e-6
    return cov


def _indefinite(document):
    cov = [list(row) for row in document["cov"]]
    cov[0][1] = cov[1][0] = 2 * np.sqrt(cov[0][0] * cov[1][1])           # a correlation of 2
    return cov


BAD = [
    ("format", "fmscal-payload/3", "not an fmscal payload (format 'fmscal-payload/3'; expected 'fmscal-payload/1' or "
                                   "'fmscal-payload/2')"),
    ("mass", -1.0, "mass must be positive"),
    ("mass_std", "0.1", "mass_std must be 1 finite number(s)"),
    ("com_std", [0.1, -0.1, 0.1], "com_std must not be negative"),
    ("b", [0.0] * 5, "b must be 6 finite number(s)"),
    ("reading", "sideways", "reading must be one of reaction, load; got 'sideways'"),
    ("noise_sd", [0.01, 0.01, 0.01, 0.1, 0.1, 0.0], "noise_sd must be positive"),
    ("noise_of", "row", "noise_of must be one of sample, pose; got 'row'"),
    ("gains", [1.0, 1.0, 1.0, 1.0, 1.0], "gains must be 6 finite number(s) or null"),
    ("gains", [1.0, 1.0, 1.0, 1.0, 1.0, -1.0], "gains must be positive"),
    ("gravity", None, "gravity must be 3 finite number(s)"),
    ("gravity", [0.0, 0.0, 0.0], "gravity: gravity's size is 0, not Earth's 9.81 m/s^2"),
    ("gravity", [0.0, 0.0, -9810.0], "gravity: gravity's size is 9810, not Earth's 9.81 m/s^2: in mm/s^2? give "
                                     "gravity in m/s^2"),
    ("gravity", [0.0, 0.0, -1.0], "gravity: gravity's size is 1, not Earth's 9.81 m/s^2: in g (multiples of 9.81)?"),
    ("mounting", [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]], "mounting must be a rotation matrix"),
    ("mounting", [[1.1, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], "mounting must be a rotation matrix"),
    ("inertia_note", None, "inertia_note must say why the inertia is null"),
    ("inertia_std", [0.0] * 6, "inertia_std must be null where the inertia is"),
    ("parameters", list(reversed(PAYLOAD_PARAMETERS)), "parameters must be ['mass', 'com_x'"),
    ("cov", [[0.0] * 16] * 15, "cov must be 16 rows of 16 numbers"),
    ("cov", lambda d: _nulls(d, [0]), "cov must be null exactly in the rows and columns of an inertia that is null"),
    ("cov", lambda d: [[0.0 if v is None else v for v in row] for row in d["cov"]],
     "cov must be null exactly in the rows and columns"),
    ("cov", _asymmetric, "cov must be a symmetric positive semi-definite matrix"),
    ("cov", _indefinite, "cov must be a symmetric positive semi-definite matrix"),
    ("mass_std", lambda d: d["mass_std"] * 1.01, "mass_std disagrees with the square roots of cov's diagonal"),
    ("b_std", lambda d: [v * 1.01 for v in d["b_std"]], "b_std disagrees with the square roots of cov's diagonal"),
    ("axes", "sensor", "axes must be \"tracked\""),
    ("converged", "false", "converged must be true or false; got 'false'"),
]


@pytest.mark.parametrize("key, value, message", BAD, ids=[f"{k}-{i}" for i, (k, _, _) in enumerate(BAD)])
def test_a_bad_field_is_refused_in_one_line(tmp_path, askew, key, value, message):
    document, _ = _saved(tmp_path, askew[1])
    edited = {**document, key: value(document) if callable(value) else value}
    (tmp_path / "edited.json").write_text(json.dumps(edited))
    with pytest.raises(PayloadFileError) as err:
        PayloadEstimate.load(tmp_path / "edited.json")
    text = str(err.value)
    assert text.startswith(f"edited.json: {message}") and "\n" not in text, text


def test_a_hand_made_estimate_saves_without_covariance_or_noise(tmp_path):
    """An estimate made by hand (mass properties from CAD, the offset read at rest) saves: its file says the
    covariance and the noise were not recorded (null), and reads back so."""
    estimate = PayloadEstimate(mass=1.2, mass_std=0.01, com=np.array(TOOL.com), com_std=np.full(3, 1e-3),
                               inertia=np.array(TOOL.inertia), inertia_std=None, b=OFFSET, b_std=np.full(6, 1e-3),
                               residual_rms=None, converged=True, payload_determined=True)
    document, loaded = _saved(tmp_path, estimate)
    assert document["cov"] is None and document["noise_sd"] is None and document["inertia_std"] is None
    assert loaded.cov is None and loaded.noise_sd is None and loaded.reading == "reaction"
    np.testing.assert_array_equal(loaded.inertia, TOOL.inertia)


def test_the_gains_and_a_measured_gravity_size_round_trip(tmp_path, askew):
    """Fields a fit may fill (the reading's per-channel gains, gravity's size measured) are carried through."""
    gains = np.array([1.01, 0.99, 1.0, 1.04, 0.97, 1.02])
    _, loaded = _saved(tmp_path, replace(askew[1], gains=gains, gravity_std=0.002))
    np.testing.assert_array_equal(loaded.gains, gains)
    assert loaded.gravity_std == 0.002 and loaded.tracked().gains is not loaded.gains
