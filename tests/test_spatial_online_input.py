"""Bad input to the online methods' step in 3D: one FmscalError each, for the adaptive observer and the EKF alike."""

import numpy as np
import pytest

from fmscal.observers import AdaptiveObserver, AugmentedEKF
from fmscal.plant import FmscalError, SPATIAL_SCENARIOS, SpatialModel

ARM = SPATIAL_SCENARIOS["spatial-arm"]
MODEL = SpatialModel(ARM.payload, ARM.gravity)
REST = [1, 0, 0, 0, 0, 0, 0]


@pytest.mark.parametrize("cls", [AdaptiveObserver, AugmentedEKF])
@pytest.mark.parametrize("call, match", [
    (lambda o: o.step(1e-3, [1.2, 0, 0, 0, 0, 0, 0], np.zeros(6)), "unit quaternion"),
    (lambda o: o.step(1e-3, [1, 0, 0, 0, 0, np.nan, 0], np.zeros(6)), "7 finite numbers"),
    (lambda o: o.step(1e-3, REST, np.r_[np.zeros(5), np.nan]), "6 finite numbers"),
    (lambda o: o.step(1e-3, [1, 0, 0, 0, 0, 0], np.zeros(6)), "7 finite numbers"),
    (lambda o: o.step(1e-3, REST, np.zeros(3)), "6 finite numbers"),
    (lambda o: o.step(0.0, REST, np.zeros(6)), "dt must be positive"),
    (lambda o: o.step(-1e-3, None, np.zeros(6)), "dt must be positive"),
])
def test_bad_samples_are_one_error_each(cls, call, match):
    obs = cls(MODEL)
    obs.reset()
    obs.step(None, REST, np.zeros(6))
    with pytest.raises(FmscalError, match=match):
        call(obs)


@pytest.mark.parametrize("cls", [AdaptiveObserver, AugmentedEKF])
def test_a_first_sample_with_a_zero_quaternion_is_refused(cls):
    obs = cls(MODEL)
    obs.reset()
    with pytest.raises(FmscalError, match="unit quaternion"):
        obs.step(None, [0, 0, 0, 0, 0, 0, 0], np.zeros(6))
