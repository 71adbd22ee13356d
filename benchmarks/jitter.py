"""Stamps off the grid (issue 45): ``python benchmarks/jitter.py [SEEDS] [--even]``.

The UR5 carrying its tool (tests/robot_rig.py), 2 s at 1 kHz taken from a 10 kHz run, the joint angles with a
noise of 1e-5 rad (no noise model for them: the ``Compensator`` estimates it as they come) and the readings with
``NOISE``'s; each stamp moved off its grid uniformly by up to ``jitter`` of a step (0, 0.1, 0.2, 0.3), default 3
seeds. Printed per jitter and seed: the readings, the outputs, the compensator's events, the outputs' rms z and
largest |z| against the truth (no contact), and the joints' noise sd the running estimate found. ``--even``: the
windows read as evenly spaced (``GRID_SLIP`` set beyond any interval), as the compensator read them before it
fitted uneven windows at their samples' own times (the module docstring of ``analysis/_compensate.py``, Stamps).
A few seconds a seed.
"""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import robot_rig  # noqa: E402
import fmscal.analysis._compensate as compensate_module  # noqa: E402
from fmscal.analysis import Compensator  # noqa: E402
from fmscal.plant import Calibration, NoiseSpec  # noqa: E402
from fmscal.plant.scenarios._spatial import TOOL  # noqa: E402

NOISE = NoiseSpec((0.005,) * 3 + (0.1,) * 3, 1e-4, 1e-4)
JITTERS = (0.0, 0.1, 0.2, 0.3)
JOINT_SD = 1e-5


def main(argv):
    even = "--even" in argv
    seeds = int(next((a for a in argv if not a.startswith("-")), 3))
    if even:
        compensate_module.GRID_SLIP = np.inf
    run = robot_rig.ur5_run(2.0, 1e-4)
    calibration = Calibration(S=np.eye(6), payload=TOOL, method="truth", b=np.zeros(6), gravity=(0.0, 0.0, -9.81))
    print("windows read as evenly spaced" if even else "uneven windows fitted at their samples' own times")
    print("jitter  seed  readings  outputs  events                 rms z   max |z|  joint noise sd")
    for jitter in JITTERS:
        for seed in range(seeds):
            rows, rng = robot_rig.jittered_rows(run, jitter, seed)
            t = run["t"][rows]
            W = run["W"][rows] + rng.normal(0.0, 1.0, (len(rows), 6)) * np.asarray(NOISE.wrench_sd)
            q = run["q"][rows] + rng.normal(0.0, JOINT_SD, (len(rows), 6))
            stream = Compensator(calibration, 1e-3, noise=NOISE, motion=run["motion"])
            out = stream.push_many(t, W, joints=(q, None, None))
            z = np.array([o.wrench / np.sqrt(np.diag(o.cov)) for o in out])
            sd = float(np.sqrt(stream._running.variance()).mean())
            events = ", ".join(f"{k} {v}" for k, v in sorted(stream.events.items())) or "none"
            print(f"{jitter:6.1f}  {seed:4d}  {len(t):8d}  {len(out):7d}  {events:21s}  {np.sqrt(np.mean(z ** 2)):5.3f}"
                  f"  {np.abs(z).max():7.2f}  {sd:.2e}")


if __name__ == "__main__":
    main(sys.argv[1:])
