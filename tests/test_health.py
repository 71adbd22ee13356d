"""observers.diagnostics._health: one constant S or not, and a divergence bound of the data's own size."""

import numpy as np
import pytest

from fmscal import plant
from fmscal.observers.core._convergence import divergence_bound
from fmscal.observers.diagnostics._health import consistency_check


@pytest.fixture(scope="module")
def logs():
    out = {}
    for name in ("paper", "time-varying"):
        sc = plant.get_scenario(name).with_(duration=150.0)
        log, truth, _ = sc.generate(0)
        out[name] = (sc, log, truth)
    return out


def test_a_constant_S_is_consistent(logs):
    sc, log, _ = logs["paper"]
    c = consistency_check(log, sc.payload)
    assert c.consistent and c.warning is None and c.change_time is None
    assert 2 < c.statistic < 25            # about chi-square with 9 dof (measured 8.6): neither 0 nor huge


def test_a_step_in_S_is_found_and_placed(logs):
    sc, log, _ = logs["time-varying"]          # S steps at t = 100 s (Table 1)
    c = consistency_check(log, sc.payload)
    assert not c.consistent and c.p_value < 1e-6
    assert 90 <= c.change_time <= 110
    assert "S changed" in c.warning and "t = 100 s" in c.warning and "\n" not in c.warning


def test_divergence_bound_follows_the_scale_of_the_data(logs):
    sc, log, truth = logs["paper"]
    S0 = np.eye(3)
    bound = divergence_bound(S0, log, sc.payload)
    assert 5 < bound < 200                           # S of order one: a bound of tens
    assert bound > np.abs(truth.S_at(0)).max()
    small_units = plant.Log(log.t, log.pose, log.w_hat * 1e-4)          # S near 1e4
    assert 1e4 < divergence_bound(S0, small_units, sc.payload) < 1e7
    counts = plant.Log(log.t, log.pose, log.w_hat * 1e4)               # S near 1e-4: S0 sets the bound
    assert divergence_bound(S0, counts, sc.payload) == pytest.approx(20.0)
