"""Write the golden inputs of ``tests/test_golden.py`` and, with ``--expected``, the outputs they pin.

Usage (from anywhere; the files land beside this script)::

    python tests/data/golden/make.py              # the input files (deterministic, seeded)
    python tests/data/golden/make.py --expected   # expected/CASE.json: today's output of each case

(with the arithmetic's kernel the suite pins: it runs the repository's ``conftest.py`` first.)

The inputs are small logs and tables (each well under 300 KB), written by
the toolkit's own writers (``fmscal simulate``, :meth:`fmscal.plant.Log.write`,
:func:`fmscal.plant.io._pose_table.write_pose_table`; the joint-angle table as
the tests write one), every draw seeded:

- ``planar.csv``: the paper's scenario, 10 s at 100 Hz, the poses 30 ms late;
- ``spatial.csv``: ``spatial-arm``, 12 s at 50 Hz; ``spatial_late.csv``: 10 s,
  the poses 40 ms late (both at a tenth of the scenario's reading noise, so
  that logs this short converge);
- ``held.csv`` (16 held poses, ``S`` off the identity, an offset, the load's
  sign), ``table.csv`` (12 poses, ``S = I``), ``tilted.csv`` (30 poses, the
  base tilted by 15 degrees, the sensor bolted 5 degrees askew);
- ``joints.csv``: the UR5's joint angles at 16 poses (example-robot-data's URDF).

The calibrations of the logs converge; a table's never does (held poses
never determine ``S``), nor does identify-payload with ``S = I`` on the
spatial log (its ``S`` is not the identity). :data:`CASES` names the commands
run on them; the expected file of a case holds its commands, the last one's
exit status and the JSON it printed.

When to re-run it
-----------------
Only on an **intended** change of the outputs (a fixed bug, a better
default), and say why in the commit's message: the expected files are the
current code's outputs, never edited by hand, and a refactor that moves code
must reproduce them as they are. ``--expected`` runs the commands on the
inputs checked in (it does not re-write them). Re-write the inputs only when
their format changes; their outputs then change too, so run ``--expected``
after.
"""

import argparse
import contextlib
import io
import json
import os
import runpy
import shutil
import sys
import sysconfig
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
# the arithmetic's kernel the suite pins, set before numpy loads: the repository's conftest.py (test_golden.py's
# docstring, Machine dependence)
runpy.run_path(str(HERE.parents[2] / "conftest.py"))
EXPECTED = HERE / "expected"

#: The payload of the planar paper scenario (``fmscal simulate --scenario paper``).
PLANAR = ["--mass", "2.5", "--inertia", "0.75", "--rho", "0.2", "0.25"]
#: The spatial scenarios' tool (:data:`fmscal.plant.scenarios._spatial.TOOL`).
TOOL = ["--mass", "1.2", "--com", "0.01", "-0.005", "0.06"]
TOOL_INERTIA = ["--inertia", "4e-3", "5e-3", "2.5e-3", "2e-4", "-1e-4", "1.5e-4"]
#: The pose stream's delay behind the sensor in the planar log and in the late spatial log, s.
PLANAR_LATENCY = 0.03
SPATIAL_LATENCY = 0.04
#: Stands for the UR5's URDF in a command line (its path is the machine's).
UR5 = "{UR5}"
UR5_FRAME = ["--urdf", UR5, "--frame", "tool0"]

#: The input files, beside this script.
INPUTS = ["planar.csv", "planar.truth.json", "spatial.csv", "spatial.truth.json", "spatial_late.csv",
          "spatial_late.truth.json", "held.csv", "table.csv", "tilted.csv", "joints.csv"]

#: Each case: its id (what it pins) and its commands, run in turn in a folder holding :data:`INPUTS`; the last
#: one's output is pinned, those before it (a calibration saved for it) must succeed.
CASES = {
    # planar: the paper's scenario with the poses 30 ms late
    "planar-calibrate-floor-latency-given": [
        ["calibrate", "planar.csv", *PLANAR, "--latency", repr(PLANAR_LATENCY), "--truth", "planar.truth.json",
         "--json"]],
    "planar-calibrate-floor-latency-estimated": [
        ["calibrate", "planar.csv", *PLANAR, "--truth", "planar.truth.json", "--json"]],
    "planar-calibrate-least-squares-latency-given": [
        ["calibrate", "planar.csv", *PLANAR, "--observer", "least-squares", "--latency", repr(PLANAR_LATENCY),
         "--truth", "planar.truth.json", "--json"]],
    # the online methods on the same log (pinned after issue 36's one EKF and one adaptive observer: the outputs
    # of the merged classes, for the next refactor to reproduce)
    "planar-calibrate-ekf-latency-given": [
        ["calibrate", "planar.csv", *PLANAR, "--observer", "ekf", "--latency", repr(PLANAR_LATENCY),
         "--truth", "planar.truth.json", "--json"]],
    "planar-calibrate-adaptive-latency-given": [
        ["calibrate", "planar.csv", *PLANAR, "--observer", "adaptive", "--latency", repr(PLANAR_LATENCY),
         "--truth", "planar.truth.json", "--json"]],
    # spatial: a tool on a wrist, no latency
    "spatial-calibrate-floor-latency-estimated": [
        ["calibrate", "spatial.csv", *TOOL, *TOOL_INERTIA, "--truth", "spatial.truth.json", "--json"]],
    "spatial-calibrate-least-squares-latency-given": [
        ["calibrate", "spatial.csv", *TOOL, *TOOL_INERTIA, "--observer", "least-squares", "--latency", "0",
         "--truth", "spatial.truth.json", "--json"]],
    "spatial-identify-payload-S-identity": [
        ["identify-payload", "spatial.csv", "--truth", "spatial.truth.json", "--json"]],
    "spatial-identify-payload-with-saved-calibration": [
        ["calibrate", "spatial.csv", *TOOL, *TOOL_INERTIA, "--save", "cal.json"],
        ["identify-payload", "spatial.csv", "--calibration", "cal.json", "--truth", "spatial.truth.json", "--json"]],
    # spatial: the same motion with the poses 40 ms late
    "spatial-late-calibrate-floor-latency-estimated": [
        ["calibrate", "spatial_late.csv", *TOOL, *TOOL_INERTIA, "--truth", "spatial_late.truth.json", "--json"]],
    "spatial-late-calibrate-least-squares-latency-estimated": [
        ["calibrate", "spatial_late.csv", *TOOL, *TOOL_INERTIA, "--observer", "least-squares",
         "--truth", "spatial_late.truth.json", "--json"]],
    # pose tables
    "table-calibrate-load-reading": [
        ["calibrate", "held.csv", *TOOL, "--reading", "load", "--json"]],
    "table-identify-payload": [
        ["identify-payload", "table.csv", "--json"]],
    "table-identify-payload-gravity-and-mounting-estimated": [
        ["identify-payload", "tilted.csv", "--gravity", "estimate", "--mounting", "estimate", "--json"]],
    # a table of the UR5's joint angles
    "joints-urdf-calibrate": [
        ["calibrate", "joints.csv", *UR5_FRAME, *TOOL, "--json"]],
    "joints-urdf-identify-payload": [
        ["identify-payload", "joints.csv", *UR5_FRAME, "--json"]],
}


def ur5_urdf():
    """The UR5's URDF as example-robot-data (a test dependency) installs it."""
    roots = {Path(sysconfig.get_paths()[k]) for k in ("purelib", "platlib")}
    for root in sorted(roots):
        path = root / "cmeel.prefix/share/example-robot-data/robots/ur_description/urdf/ur5_robot.urdf"
        if path.exists():
            return path
    raise FileNotFoundError(f"example-robot-data's UR5 URDF not found under {sorted(map(str, roots))}: "
                            "pip install -e \".[test]\"")


def commands(case):
    """The command lines of ``case`` with the UR5's URDF path filled in."""
    return [[str(ur5_urdf()) if a == UR5 else a for a in argv] for argv in CASES[case]]


def run(case, main):
    """Run ``case``'s commands in-process (``main`` the CLI's) in the current folder.

    Returns
    -------
    code : int
        The last command's exit status.
    output : object
        The JSON the last command printed on stdout, parsed.
    """
    *setup, last = commands(case)
    for argv in setup:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            code = main(argv)
        if code != 0:
            raise RuntimeError(f"{case}: {' '.join(argv)} exited with {code}")
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        code = main(last)
    return code, json.loads(out.getvalue())


def _exp(rotvec):
    from scipy.spatial.transform import Rotation
    return Rotation.from_rotvec(rotvec).as_matrix()


def write_inputs(folder):
    """Write :data:`INPUTS` into ``folder`` (deterministic: every draw seeded)."""
    import numpy as np

    from fmscal.analysis.cli import main
    from fmscal.plant import SPATIAL_SCENARIOS
    from fmscal.plant.io._kinematics import RobotKinematics
    from fmscal.plant.io._pose_table import simulate_table, write_pose_table
    from fmscal.plant.scenarios._spatial import TOOL as TOOL_PAYLOAD
    # planar: the paper's scenario, 10 s at 100 Hz (1001 samples), the poses three samples late
    assert main(["simulate", "--scenario", "paper", "--seed", "0", "--duration", "10", "--dt", "0.01",
                 "--latency", repr(PLANAR_LATENCY), "--out", str(folder / "planar.csv"), "--overwrite"]) == 0
    # spatial: spatial-arm at 50 Hz, 12 s (601 samples) and, the poses two samples late, 10 s (501). At the
    # scenario's own reading noise logs this short do not converge; at a tenth of it (as 100 times the samples) they do
    arm = SPATIAL_SCENARIOS["spatial-arm"]
    quiet = arm.with_(dt=0.02, torque_sd=arm.torque_sd / 10, force_sd=arm.force_sd / 10)
    for name, scenario, seed in (("spatial", quiet.with_(duration=12.0), 2),
                                 ("spatial_late", quiet.with_(duration=10.0, latency=SPATIAL_LATENCY), 5)):
        log, truth, _ = scenario.generate(seed=seed)
        truth.write(folder / f"{name}.truth.json")
        log.write(folder / f"{name}.csv")
    # pose tables: 16 held attitudes read by a sensor with S off the identity, an offset and the load's sign;
    # 12 read with S = I; 30 on a base tilted by 15 degrees, the sensor bolted 5 degrees askew
    offset = np.array([0.01, -0.02, 0.03, 0.5, -0.3, 0.2])
    S = np.eye(6) + 0.03 * np.random.default_rng(7).normal(size=(6, 6))
    write_pose_table(simulate_table(TOOL_PAYLOAD, n=16, seed=4, S=S, offset=offset, reading="load"),
                     folder / "held.csv")
    write_pose_table(simulate_table(TOOL_PAYLOAD, n=12, seed=2, offset=offset), folder / "table.csv")
    tilt, mount = _exp(np.radians(15.0) * np.array([0.0, 1.0, 0.0])), _exp(np.radians(5.0) * np.array([1.0, 0, 0]))
    write_pose_table(simulate_table(TOOL_PAYLOAD, n=30, seed=5, gravity=tilt @ [0, 0, -9.81], mounting=mount,
                                    offset=offset), folder / "tilted.csv")
    # the UR5's joint angles at 16 random poses (columns q1..q6), the readings of the tool held at each
    ur5 = RobotKinematics(ur5_urdf(), "tool0")
    joints = np.random.default_rng(2).uniform(-np.pi, np.pi, (16, 6))
    table = simulate_table(TOOL_PAYLOAD, n=16, seed=2, offset=offset, q=ur5.poses(joints)[:, :4])
    rows = np.hstack([joints, table.w_hat])
    (folder / "joints.csv").write_text("q1,q2,q3,q4,q5,q6,tx,ty,tz,fx,fy,fz\n"
                                       + "\n".join(",".join(f"{v:.17g}" for v in row) for row in rows) + "\n")


@contextlib.contextmanager
def _inside(folder):
    """Work in ``folder`` for a while (``contextlib.chdir`` from Python 3.11 on)."""
    before = os.getcwd()
    os.chdir(folder)
    try:
        yield
    finally:
        os.chdir(before)


def write_expected():
    """Run every case on a fresh copy of the inputs checked in; write ``expected/CASE.json`` (and no other)."""
    from fmscal.analysis.cli import main
    EXPECTED.mkdir(exist_ok=True)
    for stale in set(EXPECTED.glob("*.json")) - {EXPECTED / f"{case}.json" for case in CASES}:
        stale.unlink()
    for case in CASES:
        with tempfile.TemporaryDirectory() as tmp, _inside(tmp):
            for name in INPUTS:
                shutil.copy(HERE / name, tmp)
            code, output = run(case, main)
        record = {"commands": CASES[case], "exit": code, "output": output}
        (EXPECTED / f"{case}.json").write_text(json.dumps(record, indent=1) + "\n")
        print(f"wrote expected/{case}.json (exit {code})")


def main(args=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--expected", action="store_true",
                        help="write the expected outputs (from the inputs checked in) instead of the inputs")
    if parser.parse_args(args).expected:
        write_expected()
    else:
        write_inputs(HERE)
        for name in INPUTS:
            print(f"wrote {name} ({(HERE / name).stat().st_size / 1e3:.0f} kB)")


if __name__ == "__main__":
    sys.exit(main())
