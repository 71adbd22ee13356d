"""The file's real problem named, from Python and from the command line (issue 46, items 6-8).

Each case of a file, a payload or a save that used to end in a traceback or in a message naming the wrong
cause ends now in a right answer (a compressed log read, Unix-epoch stamps taken from the first), or in a
one-line refusal naming the real cause: in Python the library's :class:`fmscal.plant.FmscalError`, on the
command line exit status 2 with one ``error:`` line and no traceback. Every file is made from the examples
(``examples/arm.csv``, a 12 s spatial log at 25 Hz, and ``examples/table.csv``, 12 held poses) or from a
short simulated planar log, in a folder made once.
"""

import bz2
import gzip
import json
import lzma
import zipfile
from pathlib import Path

import numpy as np
import pytest

from fmscal.analysis import calibrate, read_data
from fmscal.analysis._metrics import calibration_error
from fmscal.analysis.cli import main
from fmscal.observers import AugmentedEKF
from fmscal.observers.batch._max_likelihood import fit_max_likelihood
from fmscal.observers.core import divergence_bound
from fmscal.plant import (PAPER_PAYLOAD, Calibration, FmscalError, SpatialModel, estimate_noise, get_scenario,
                          read_log, read_truth)
from fmscal.plant.io import NotSavedError, read_pose_table
from fmscal.plant.scenarios import TOOL

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
COM = ["0.01", "-0.005", "0.06"]
INERTIA = ["--inertia", "4e-3", "5e-3", "2.5e-3", "2e-4", "-1e-4", "1.5e-4"]
PAY = ["--mass", "1.2", "--com", *COM, *INERTIA]


def _csv(path, columns, rows, fmt="%.9g"):
    """Write ``rows`` under the header ``columns`` (plain text, numpy's formatting)."""
    np.savetxt(path, rows, delimiter=",", header=",".join(columns), comments="", fmt=fmt)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The gallery of files, made once from the examples."""
    d = tmp_path_factory.mktemp("files")
    arm = read_log(EXAMPLES / "arm.csv")
    rows = np.column_stack([arm.t, arm.pose, arm.w_hat])
    text = (EXAMPLES / "arm.csv").read_bytes()
    (d / "arm.csv").write_bytes(text)
    (d / "arm.csv.gz").write_bytes(gzip.compress(text))
    (d / "arm.csv.bz2").write_bytes(bz2.compress(text))
    (d / "arm.csv.xz").write_bytes(lzma.compress(text))
    (d / "cut.csv.gz").write_bytes(gzip.compress(text)[:2000])                 # a download cut short
    with zipfile.ZipFile(d / "arm.zip", "w") as z:
        z.writestr("arm.csv", text)
    (d / "arm.csv.zst").write_bytes(b"\x28\xb5\x2f\xfd" + bytes(64))           # zstandard's first bytes
    table = (EXAMPLES / "table.csv").read_bytes()
    (d / "table.csv.gz").write_bytes(gzip.compress(table))
    (d / "empty.csv").write_bytes(b"")
    (d / "blank.csv").write_bytes(b"\n\n  \n")
    header, body = text.decode().split("\n", 1)
    (d / "capitals.csv").write_text(header.upper() + "\n" + body)
    table_header, table_body = table.decode().split("\n", 1)
    (d / "table_capitals.csv").write_text(table_header.upper() + "\n" + table_body)
    epoch = rows.copy()
    epoch[:, 0] += 1.7e9                                                    # 2023-11-14, in s
    _csv(d / "epoch.csv", arm.columns, epoch, fmt="%.17g")
    epoch_ms = rows.copy()
    epoch_ms[:, 0] = epoch_ms[:, 0] * 1e3 + 1.7e12
    _csv(d / "epoch_ms.csv", arm.columns, epoch_ms, fmt="%.17g")
    for name, scale in (("cm", 1e2), ("mm", 1e3)):
        scaled = rows.copy()
        scaled[:, 5:8] *= scale
        _csv(d / f"{name}.csv", arm.columns, scaled)
    stalled = rows.copy()
    stalled[:, 1:8] = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]                    # the identity at the origin
    _csv(d / "stalled.csv", arm.columns, stalled)
    still = stalled.copy()                                                  # the readings within their noise too
    noise = np.array(read_truth(EXAMPLES / "arm.truth.json").noise.wrench_sd)
    still[:, 8:] = rows[0, 8:] + np.random.default_rng(0).standard_normal((len(rows), 6)) * noise
    _csv(d / "still.csv", arm.columns, still)
    planar, _, _ = get_scenario("paper").with_(duration=2.0).generate(seed=0)
    flat = np.column_stack([planar.t, planar.pose, planar.w_hat])
    flat[:, 1:4] = flat[0, 1:4]
    _csv(d / "planar_stalled.csv", planar.columns, flat)
    return d


# --- refusals: (file, the planar payload's flags or none, what the message names, what it must not name) ---------

PLANAR = ["--mass", str(PAPER_PAYLOAD.mass), "--inertia", str(PAPER_PAYLOAD.inertia), "--rho",
          *map(str, PAPER_PAYLOAD.rho)]
REFUSALS = {
    "stalled tracker": ("stalled.csv", [], "a stalled tracker", "singular"),
    "stalled tracker, planar": ("planar_stalled.csv", PLANAR, "a stalled tracker", "noise standard"),
    "payload at rest": ("still.csv", [], "at rest", "stalled"),
    "empty file": ("empty.csv", [], "the file is empty (0 bytes)", "theta"),
    "blank lines": ("blank.csv", [], "the file is empty (only blank lines)", "theta"),
    "spatial header in capitals": ("capitals.csv", [], "named in another case", "theta"),
    "table header in capitals": ("table_capitals.csv", [], "named in another case", "theta"),
    "zip archive": ("arm.zip", [], "is a zip archive", "NUL"),
    "zstandard": ("arm.csv.zst", [], "zstandard-compressed", "NUL"),
    "gzip cut short": ("cut.csv.gz", [], "truncated or damaged", "NUL"),
    "Unix time in ms": ("epoch_ms.csv", [], "Unix time in ms", "not measurements"),
    "positions in cm": ("cm.csv", [], "look like centimetres", "millimetres"),
    "positions in mm": ("mm.csv", [], "look like millimetres", "centimetres"),
}


@pytest.mark.parametrize("case", REFUSALS)
def test_a_file_refused_names_its_real_problem_in_python(files, case):
    name, flags, names, wrong = REFUSALS[case]
    with pytest.raises(FmscalError) as err:
        calibrate(read_data(files / name), PAPER_PAYLOAD if flags else TOOL)
    message = str(err.value)
    assert names in message and wrong not in message and "\n" not in message, message


@pytest.mark.parametrize("case", REFUSALS)
def test_a_file_refused_names_its_real_problem_on_the_command_line(files, case, capsys):
    name, flags, names, wrong = REFUSALS[case]
    code = main(["calibrate", str(files / name), *(flags or PAY)])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("fmscal calibrate: error:"), err
    assert names in err and wrong not in err and "Traceback" not in err


def test_identify_payload_names_a_stalled_tracker(files, capsys):
    """identify-payload read 'no force that gravity or motion explains' on a stalled tracker."""
    assert main(["identify-payload", str(files / "stalled.csv")]) == 2
    assert "a stalled tracker" in capsys.readouterr().err


# --- read as they are: compressed logs, Unix-epoch stamps ----------------------------------------------------

@pytest.mark.parametrize("name", ["arm.csv.gz", "arm.csv.bz2", "arm.csv.xz"])
def test_a_compressed_log_reads_as_the_plain_one(files, name):
    plain, packed = read_log(files / "arm.csv"), read_data(files / name)
    for a, b in ((plain.t, packed.t), (plain.pose, packed.pose), (plain.w_hat, packed.w_hat)):
        np.testing.assert_array_equal(a, b)


def test_a_compressed_table_calibrates_as_the_plain_one(files, capsys):
    assert read_pose_table(files / "table.csv.gz").q.shape == (12, 4)
    outputs = []
    for name in ("table.csv.gz", EXAMPLES / "table.csv"):
        assert main(["calibrate", str(files / name), "--mass", "1.2", "--com", *COM, "--json"]) == 0
        outputs.append(json.loads(capsys.readouterr().out))
    np.testing.assert_array_equal(outputs[0]["S"], outputs[1]["S"])


def test_unix_epoch_stamps_are_taken_from_the_first(files):
    """A clock's stamps in s (2023 here): the log's time starts at 0 with a note; steps as written."""
    plain, epoch = read_log(files / "arm.csv"), read_log(files / "epoch.csv")
    assert epoch.t[0] == 0.0 and "Unix time" in epoch.notes[0] and "2023-11-14" in epoch.notes[0]
    np.testing.assert_allclose(epoch.t, plain.t, rtol=0, atol=1e-6)          # the double's resolution at 1.7e9
    np.testing.assert_array_equal(epoch.w_hat, plain.w_hat)


def test_unix_epoch_stamps_calibrate_on_the_command_line(files, capsys):
    assert main(["calibrate", str(files / "epoch.csv"), *PAY, "--observer", "least-squares", "--latency",
                 "0"]) == 0
    assert "note: epoch.csv: t is Unix time" in capsys.readouterr().err


# --- the payload: a mass of 0 as a tuple, a centre of mass in mm ---------------------------------------------

@pytest.mark.parametrize("mass, names", [(0.0, "positive number of kg"), (-1.0, "positive number of kg"),
                                         ("1.2", "must be a number")])
def test_a_held_poses_payload_is_checked_in_the_library(mass, names):
    """``calibrate(table, (0.0, com))`` divided by the mass (ZeroDivisionError) where --mass 0 was refused."""
    with pytest.raises(FmscalError, match=names):
        calibrate(read_data(EXAMPLES / "table.csv"), (mass, (0.01, -0.005, 0.06)))


def test_a_held_poses_mass_of_0_on_the_command_line(capsys):
    assert main(["calibrate", str(EXAMPLES / "table.csv"), "--mass", "0", "--com", *COM]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--mass must be positive" in err[0]


@pytest.mark.parametrize("data", ["arm.csv", "table.csv"])
@pytest.mark.parametrize("scale, unit", [(1e3, "mm"), (1e2, "cm")])
def test_a_centre_of_mass_in_mm_is_named(data, scale, unit, capsys):
    """``--com 10 -5 60`` (mm) read "S is singular ... or holds an outlier"."""
    com = [float(c) * scale for c in COM]
    payload = type(TOOL)(TOOL.mass, tuple(TOOL.inertia), tuple(com))
    with pytest.raises(FmscalError, match=f"given in {unit}"):
        calibrate(read_data(EXAMPLES / data), payload)
    code = main(["calibrate", str(EXAMPLES / data), "--mass", "1.2", "--com", *map(str, com), *INERTIA])
    err = capsys.readouterr().err
    assert code == 2 and f"given in {unit}" in err and len(err.strip().splitlines()) == 1


# --- Calibration.save: an unconverged calibration, an existing file ------------------------------------------

def _table_calibration():
    """Held poses never converge: a calibration to refuse."""
    return calibrate(read_data(EXAMPLES / "table.csv"), TOOL)


def test_save_refuses_an_unconverged_calibration_unless_forced(tmp_path):
    cal = _table_calibration()
    assert cal.converged is False
    with pytest.raises(NotSavedError, match="did not save .*held poses never determine S in full.*force=True") \
            as err:
        cal.save(tmp_path / "cal.json")
    assert err.value.option == "force=True" and not (tmp_path / "cal.json").exists()
    cal.save(tmp_path / "cal.json", force=True)
    saved = json.loads((tmp_path / "cal.json").read_text())
    assert saved["forced"] is True and saved["converged"] is False
    assert Calibration.load(tmp_path / "cal.json").forced


def test_save_refuses_an_existing_file_unless_told(tmp_path):
    cal = _table_calibration()
    path = tmp_path / "cal.json"
    path.write_text("a file of the user's")
    with pytest.raises(NotSavedError, match="exists; add overwrite=True") as err:
        cal.save(path, force=True)
    assert err.value.option == "overwrite=True" and path.read_text() == "a file of the user's"
    cal.save(path, force=True, overwrite=True)
    assert json.loads(path.read_text())["forced"] is True
    with pytest.raises(FmscalError, match="force must be True or False"):
        cal.save(tmp_path / "other.json", force="yes")


def test_the_command_line_refuses_through_the_library(tmp_path, capsys):
    """--save without --force on held poses: the library's refusal, its keyword as the flag."""
    code = main(["calibrate", str(EXAMPLES / "table.csv"), *PAY, "--save", str(tmp_path / "cal.json")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].startswith("fmscal calibrate: error: did not save") and "add --force" in err[-1]
    assert not (tmp_path / "cal.json").exists()


# --- the EKF on the shipped spatial example --------------------------------------------------------------------

@pytest.fixture(scope="module")
def example():
    """``examples/arm.csv``, its truth, the spatial model of its tool and the floor's E on it."""
    log, truth = read_log(EXAMPLES / "arm.csv"), read_truth(EXAMPLES / "arm.truth.json")
    model = SpatialModel(TOOL)
    floor = fit_max_likelihood(log, model, offset=True)
    return log, truth, model, calibration_error(floor.S_hat, truth.S_at(0))


def test_the_ekf_runs_on_the_shipped_spatial_example(example):
    """It diverged at t = 1 s (``DivergedError`` from ``calibrate``), from any ``S0``: it started its motion at
    rest, and at 25 Hz with poses to 1.6e-5 rad the first step missed by thousands of their sd. Started at the
    velocity the first poses show (eq. D1), it runs the log to its end, within 1.5x of the floor's E either way
    (measured: 0.311 against 0.25). Its ``S_std`` there is too small, as the floor's is (z-scores' rms 1.8 and
    1.6: the step's discretisation at 25 Hz, docs/status.md), so only its E is held here. The readable
    (filterpy) path, which starts where the compiled one does."""
    log, truth, model, floor_E = example
    ekf = AugmentedEKF(model, offset=True)
    result = ekf.run(log, compiled=False)
    assert not result.diverged and result.t[-1] == log.t[-1]
    assert 1 / 1.5 < calibration_error(result.S_hat, truth.S_at(0)) / floor_E < 1.5


def test_the_ekf_started_at_rest_diverges_there(example):
    """The cause, kept visible: the same filter started at rest (a live start, ``reset(velocity=0)``)."""
    log, _, model, _ = example
    ekf = AugmentedEKF(model, offset=True, noise=estimate_noise(log))
    ekf.reset(velocity=np.zeros(model.nv))
    bound = divergence_bound(np.eye(6))
    worst = 0.0
    for k in range(len(log)):
        _, S_hat = ekf.step(log.dt, log.pose[k], log.w_hat[k])
        worst = max(worst, float(np.max(np.abs(S_hat))))
        if k * log.dt >= 1.0:
            break
    assert worst > bound


@pytest.mark.slow
def test_the_ekf_calibrates_the_example_from_python_and_the_command_line(example, capsys):
    """``calibrate(log, tool, method="ekf")`` and ``fmscal calibrate --observer ekf`` on the example: no
    ``DivergedError``, one answer (the compiled step's build, about a minute, is why this is slow)."""
    log, truth, _, floor_E = example
    cal = calibrate(read_data(EXAMPLES / "arm.csv"), TOOL, method="ekf", truth=truth)
    assert 1 / 1.5 < cal.E / floor_E < 1.5 and (cal.converged or cal.warnings)
    code = main(["calibrate", str(EXAMPLES / "arm.csv"), *PAY, "--observer", "ekf", "--json"])
    out = capsys.readouterr()
    assert code == 0 and "Traceback" not in out.err
    np.testing.assert_allclose(json.loads(out.out)["S"], cal.S_hat, rtol=1e-9, atol=1e-12)
