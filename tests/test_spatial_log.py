"""The spatial log format: t,qw,qx,qy,qz,x,y,z,tx,ty,tz,fx,fy,fz (issue 22), read and validated in one place."""

import numpy as np
import pytest

from fmscal.plant import LogError, read_log
from fmscal.plant.io._log import SPATIAL_COLUMNS, Log


def _spatial(n=50, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    angle = 0.5 * np.sin(2 * np.pi * t)
    q = np.c_[np.cos(angle / 2), np.sin(angle / 2)[:, None] * np.array([[0.6, 0.0, 0.8]])]
    pose = np.c_[q, rng.normal(size=(n, 3))]
    return t, pose, rng.normal(size=(n, 6))


def test_a_spatial_log_round_trips_through_its_csv(tmp_path):
    t, pose, w_hat = _spatial()
    pose[7] = np.nan                                  # a dropped frame: all seven cells empty
    Log(t, pose, w_hat, "x").write(tmp_path / "log.csv")
    text = (tmp_path / "log.csv").read_text().splitlines()
    assert text[0] == ",".join(SPATIAL_COLUMNS)
    assert text[8].split(",")[1:8] == [""] * 7
    log = read_log(tmp_path / "log.csv")
    assert log.kind == "spatial" and log.columns == SPATIAL_COLUMNS and not log.has_pose[7]
    np.testing.assert_array_equal(log.w_hat, w_hat)
    np.testing.assert_allclose(log.pose[log.has_pose], pose[log.has_pose], rtol=0, atol=1e-15)


def test_a_planar_log_stays_planar():
    n = 20
    log = Log(np.arange(n) * 1e-3, np.zeros((n, 3)), np.ones((n, 3)))
    assert log.kind == "planar" and log.columns == ("t", "theta", "x", "y", "M", "fx", "fy")


def test_q_and_minus_q_are_one_attitude_made_continuous_with_a_note():
    t, pose, w_hat = _spatial()
    flipped = pose.copy()
    flipped[20:, :4] *= -1
    log = Log(t, flipped, w_hat, "flip")
    np.testing.assert_allclose(log.pose, pose, atol=1e-15)
    assert any("changes sign 1 time" in note for note in log.notes)


def test_a_quaternion_within_rounding_is_normalised():
    t, pose, w_hat = _spatial()
    pose[:, :4] *= 1 + 5e-4
    log = Log(t, pose, w_hat)
    np.testing.assert_allclose(np.linalg.norm(log.pose[:, :4], axis=1), 1.0, atol=1e-15)


@pytest.mark.parametrize("change, message", [
    (lambda p: p.__setitem__((3, slice(0, 4)), p[3, :4] * 1.01), "row 4 has norm 1.01; expected a unit quaternion"),
    (lambda p: p.__setitem__((5, slice(0, 4)), 0.0), "row 6 has norm 0"),
    (lambda p: p.__setitem__((9, 5), np.nan), "some but not all of qw,qx,qy,qz,x,y,z"),
])
def test_a_bad_pose_is_one_line(change, message):
    t, pose, w_hat = _spatial()
    change(pose)
    with pytest.raises(LogError, match=message):
        Log(t, pose, w_hat, "bad")


def test_mixed_shapes_are_refused():
    t, pose, w_hat = _spatial()
    with pytest.raises(LogError, match=r"pose \(N, 7\), w_hat \(N, 6\) \(spatial\)"):
        Log(t, pose, w_hat[:, :3])


def test_a_spatial_header_with_a_missing_column_names_it(tmp_path):
    t, pose, w_hat = _spatial()
    Log(t, pose, w_hat).write(tmp_path / "log.csv")
    text = (tmp_path / "log.csv").read_text().replace(",fz", ",fq", 1)
    (tmp_path / "bad.csv").write_text(text)
    with pytest.raises(LogError, match="missing column"):
        read_log(tmp_path / "bad.csv")
