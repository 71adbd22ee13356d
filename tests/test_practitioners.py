"""The practitioners' estimators reimplemented for comparison (observers/payload/_practitioners.py, issue 28)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fmscal.observers.payload._practitioners import CALIB_FORCE_G, calib_force, plain_fit
from fmscal.observers.payload._static_fit import _exp
from fmscal.plant.numerics._errors import FmscalError
from fmscal.plant.io._pose_table import simulate_table
from fmscal.plant.scenarios._spatial import TOOL

OFFSET = np.array([0.01, -0.02, 0.03, 0.5, -0.3, 0.2])
MOUNT = _exp(np.radians(7.0) * np.array([0.3, 1.0, 0.5]) / np.linalg.norm([0.3, 1.0, 0.5]))
TILT = _exp(np.radians(10.0) * np.array([1.0, 0.3, 0.0]) / np.linalg.norm([1.0, 0.3, 0.0]))
EXACT = (0.0,) * 6


def _degrees(R):
    return float(np.degrees(Rotation.from_matrix(R).magnitude()))


def test_the_plain_fit_is_exact_where_its_assumptions_hold():
    """Gravity along -z, the sensor square, no noise: eqs. (P1) and (P2) return the truth (to 1e-9)."""
    for reading in ("reaction", "load"):
        table = simulate_table(TOOL, n=12, seed=0, offset=OFFSET, wrench_sd=EXACT, reading=reading)
        fit = plain_fit(table.q, table.w_hat, reading=reading)
        assert fit.mass == pytest.approx(TOOL.mass, abs=1e-9) and fit.mounting is None
        np.testing.assert_allclose(fit.com, TOOL.com, atol=1e-9)
        np.testing.assert_allclose(fit.b, OFFSET, atol=1e-9)
        assert fit.force_rms < 1e-9


def test_calib_force_recovers_the_mounting_from_any_mass_guess():
    """calibForce's eq. (P3), noiseless, load reading, sensor 7 degrees askew, gravity 9.82 along -z: the mass,
    ``Rf`` and the force offset exact (1e-9) from guesses 1e-3 and 1e3 times the mass (its docstring claims
    five orders of magnitude); a reaction reading told so gives the same."""
    table = simulate_table(TOOL, n=24, seed=1, offset=OFFSET, reading="load", gravity=(0, 0, -CALIB_FORCE_G),
                           mounting=MOUNT, wrench_sd=EXACT)
    for m0 in (1.2e-3, 1.2e3):
        fit = calib_force(table.q, table.w_hat, m0=m0)
        assert fit.mass == pytest.approx(TOOL.mass, abs=1e-9) and fit.com is None
        np.testing.assert_allclose(fit.mounting, MOUNT, atol=1e-9)
        np.testing.assert_allclose(fit.b[3:], OFFSET[3:], atol=1e-9)
        assert np.isnan(fit.b[:3]).all() and fit.force_rms < 1e-9
    flipped = calib_force(table.q, -table.w_hat, reading="reaction")
    assert flipped.mass == pytest.approx(TOOL.mass, abs=1e-9)


def test_a_tilted_base_goes_unnoticed_into_their_estimates():
    """A base tilted 10 degrees, noiseless, square sensor. Measured: the plain fit's centre of mass off by
    4.7 mm and its force offset by 0.69 N; calibForce's ``Rf`` turned 7.0 degrees (the sensor is square) and its
    force offset off by 0.35 N, its mass within 1e-4 kg; the force residual 0.9-1.1 N with no noise."""
    table = simulate_table(TOOL, n=24, seed=1, offset=OFFSET, reading="load", gravity=TILT @ [0, 0, -CALIB_FORCE_G],
                           wrench_sd=EXACT)
    plain = plain_fit(table.q, table.w_hat, reading="load", g=CALIB_FORCE_G)
    assert 3e-3 < np.abs(plain.com - TOOL.com).max() < 7e-3 and 0.4 < np.abs(plain.b - OFFSET).max() < 1.0
    bagge = calib_force(table.q, table.w_hat)
    assert 5.0 < _degrees(bagge.mounting) < 9.0 and abs(bagge.mass - TOOL.mass) < 1e-3
    assert 0.2 < np.abs(bagge.b[3:] - OFFSET[3:]).max() < 0.5
    assert 0.5 < plain.force_rms < 1.5 and 0.5 < bagge.force_rms < 1.5


def test_bad_input_is_refused_in_one_line():
    table = simulate_table(TOOL, n=6, seed=0)
    with pytest.raises(FmscalError, match="q has the wrong shape"):
        plain_fit(table.q[:, :3], table.w_hat)
    with pytest.raises(FmscalError, match="w_hat has the wrong shape"):
        calib_force(table.q, table.w_hat[:5])
    with pytest.raises(FmscalError, match="at least 4 poses; got 3"):
        plain_fit(table.q[:3], table.w_hat[:3])
    with pytest.raises(FmscalError, match="reading"):
        calib_force(table.q, table.w_hat, reading="up")
