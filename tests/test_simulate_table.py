"""``fmscal simulate`` writes a pose table (``--poses``) and takes a 6-axis payload (``--mass --com --inertia``).

What the command writes is what :meth:`fmscal.plant.scenarios.SpatialScenario.generate_table` and
``generate`` return: the table reads back as a pose table, its sidecar holds the payload given, and a
noise-free table is the weight's wrench through the drawn ``S`` and offset exactly.
"""

import json

import numpy as np
import pytest

from fmscal.analysis.cli import main
from fmscal.plant import SPATIAL_SCENARIOS, FmscalError, SpatialPayload, read_truth
from fmscal.plant.io import read_pose_table
from fmscal.plant.physics import rotation_matrix

ARM = SPATIAL_SCENARIOS["spatial-arm"]


def test_a_noise_free_table_is_the_weights_wrench_through_S_and_the_offset():
    tool = SpatialPayload(2.0, (1e-2, 1e-2, 1e-2, 0.0, 0.0, 0.0), (0.02, 0.0, 0.1))
    table, truth = ARM.with_(payload=tool).generate_table(seed=3, poses=7, noise_free=True)
    assert len(table) == 7 and truth.payload == tool and truth.settings["poses"] == 7
    R = np.moveaxis(rotation_matrix(table.q.T), -1, 0)
    f = tool.mass * np.einsum("nkj,k->nj", R, -np.asarray(ARM.gravity))
    w = np.hstack([np.cross(tool.com, f), f])
    S, b = truth.S_at(0.0), truth.offset
    np.testing.assert_allclose(table.w_hat, np.linalg.solve(S, w.T).T + b, atol=1e-12)
    assert not np.allclose(S, np.eye(6), atol=1e-3)               # the scenario's cross-talk, drawn
    again, _ = ARM.with_(payload=tool).generate_table(seed=3, poses=7, noise_free=True)
    np.testing.assert_array_equal(again.w_hat, table.w_hat)        # seeded


def test_the_tables_noise_is_the_scenarios_averaged_over_the_hold():
    _, truth = ARM.generate_table(seed=0, poses=6, hold=0.25)
    np.testing.assert_allclose(truth.noise.wrench_sd, np.r_[[ARM.torque_sd] * 3, [ARM.force_sd] * 3] / np.sqrt(250))
    for bad in (3, 4.5, True):
        with pytest.raises(FmscalError, match="at least 4 poses"):
            ARM.generate_table(poses=bad)
    with pytest.raises(FmscalError, match="hold must be a positive"):
        ARM.generate_table(poses=6, hold=0.0)
    with pytest.raises(FmscalError, match="at most 100000 poses"):
        ARM.generate_table(poses=100_001)


def test_simulate_poses_writes_a_table_that_identify_payload_reads(tmp_path, capsys):
    out = tmp_path / "held.csv"
    assert main(["simulate", "--scenario", "spatial-arm", "--poses", "12", "--seed", "2", "--mass", "2.0",
                 "--com", "0", "0", "0.1", "--out", str(out)]) == 0
    assert "12 held poses" in capsys.readouterr().out
    assert out.read_text().splitlines()[0] == "qw,qx,qy,qz,tx,ty,tz,fx,fy,fz"
    table = read_pose_table(out)
    truth = read_truth(tmp_path / "held.truth.json")
    assert len(table) == 12 and truth.payload.mass == 2.0 and truth.payload.com == (0.0, 0.0, 0.1)
    assert truth.payload.inertia == ARM.payload.inertia                       # not given: the scenario's
    assert main(["identify-payload", str(out), "--json"]) == 0
    fit = json.loads(capsys.readouterr().out)
    assert 1.8 < fit["mass"] < 2.2 and 0.08 < fit["com"][2] < 0.12             # the tool given, not the scenario's


def test_simulate_takes_a_spatial_payload_for_a_log(tmp_path):
    out = tmp_path / "log.csv"
    assert main(["simulate", "--scenario", "spatial-weak", "--duration", "1", "--mass", "0.5", "--inertia", "1e-3",
                 "2e-3", "3e-3", "0", "0", "0", "--out", str(out)]) == 0
    truth = json.loads((tmp_path / "log.truth.json").read_text())
    assert truth["mass"] == 0.5 and truth["inertia"] == [1e-3, 2e-3, 3e-3, 0.0, 0.0, 0.0]
    assert truth["com"] == list(SPATIAL_SCENARIOS["spatial-weak"].payload.com)


@pytest.mark.parametrize("words, says", [
    (["--scenario", "spatial-arm", "--rho", "0.1", "0.2"], "takes --com X Y Z"),
    (["--scenario", "paper", "--com", "0", "0", "0.1"], "takes --rho RX RY"),
    (["--scenario", "spatial-arm", "--inertia", "1", "2"], "--inertia IXX IYY IZZ IXY IXZ IYZ (6 numbers"),
    (["--scenario", "spatial-arm", "--com", "0", "0"], "--com X Y Z (3 numbers"),
    (["--scenario", "spatial-arm", "--mass", "-1"], "--mass must be positive"),
    (["--scenario", "spatial-arm", "--offset", "1", "2", "3"], "draws its own offset"),
    (["--scenario", "paper", "--poses", "6"], "--poses is for the spatial scenarios"),
    (["--scenario", "spatial-arm", "--poses", "3"], "at least 4 poses"),
    (["--scenario", "spatial-arm", "--poses", "1e8"], "at most 100000 poses; got 100000000"),
    (["--scenario", "spatial-arm", "--poses", "2.5"], "--poses: must be a whole number"),
    (["--scenario", "spatial-arm", "--duration", "1e4"], "1e+07 samples; a simulated spatial log has 10 to 2e+06"),
    (["--scenario", "spatial-arm", "--poses", "6", "--duration", "3"], "--duration is for a log"),
    (["--scenario", "spatial-arm", "--hold", "2"], "--hold applies to --poses"),
])
def test_bad_simulate_options_are_one_line(tmp_path, capsys, words, says):
    assert main(["simulate", *words, "--out", str(tmp_path / "x.csv")]) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1
    assert not list(tmp_path.iterdir())
