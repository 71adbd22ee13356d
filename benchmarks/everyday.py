"""The everyday job's targets (issue 44): ``python benchmarks/everyday.py [--seeds 10] [--sensor both]``.

A factory-calibrated sensor (``S = I``), or one whose force gains are off by up to 5 % (``S = diag(1, 1, 1, g)``,
``g`` uniform in [0.95, 1.05] per axis, seeded), and a tool; per seed, on the command line as a user runs it:

1. 8 held attitudes of the tool (each row the mean of 500 readings), ``fmscal identify-payload TABLE --save
   tool.json --tolerance N NM`` with the sensor's noise per reading (its datasheet's): by default a table is held
   to twice its rows' scatter, 11 times less here, and 8 poses leave the payload beyond that on some seeds
   (``python benchmarks/identify.py``), while its effect is a tenth of what a running robot's reading shows;
2. ``fmscal compensate tool.json LOG --out c.csv`` (offline, and ``--causal``) on a 20 s ``spatial-arm`` log of
   the same rig with a 1 N push on the tool for 1 s.

Printed per seed and as medians: the residual's rms per channel over the reading's noise times ``S`` on the
contact-free rows (targets: 1.3 offline, 2 causal), the rms of the z-scores there (target [0.7, 1.4]), the share
flagged there against the stated 0.1 % (target at most twice), and the share of the push's samples flagged (target
at least 90 %). tests/test_everyday.py holds the behaviours on one seed; the slow test
``test_everyday_targets`` holds these over 10 seeds. About 2 min a seed on 2 cores.
"""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from fmscal.analysis.cli import main
from fmscal.plant import SPATIAL_SCENARIOS
from fmscal.plant.io import simulate_table, write_pose_table
from fmscal.plant.scenarios import contact_wrench, same_rig, with_contact

ARM = SPATIAL_SCENARIOS["spatial-arm"].with_(crosstalk=0.0, duration=20.0)
PUSH = (8.0, 1.0)                               # s: the 1 N push's start and length


def run(seed, gains, folder):
    """One seed: ``(offline, causal)`` each a dict of the figures."""
    log, truth, _ = ARM.generate(seed)
    rng = np.random.default_rng(1000 + seed)
    S = np.diag(np.r_[np.ones(3), rng.uniform(0.95, 1.05, 3) if gains else np.ones(3)])
    b = truth.offset
    sensor = same_rig(log, truth.S_at(0.0), b, np.linalg.inv(S), b)       # readings w_hat = S^-1 w + b
    sd = np.asarray(truth.noise.wrench_sd)
    table = simulate_table(ARM.payload, n=8, seed=2000 + seed, S=np.linalg.inv(S), offset=b,
                           wrench_sd=sd / np.sqrt(500))
    write_pose_table(table, folder / "table.csv")
    touched, on = with_contact(sensor, np.linalg.inv(S), contact_wrench(1.0), *PUSH)
    touched.write(folder / "log.csv")
    tool = folder / "tool.json"
    tolerance = [f"{sd[3]:g}", f"{sd[0]:g}"]       # the sensor's noise per reading, N and N m, as its datasheet gives
    if main(["identify-payload", str(folder / "table.csv"), "--save", str(tool), "--overwrite",
             "--tolerance", *tolerance]) != 0:
        raise SystemExit(f"seed {seed}: identify-payload refused the table")
    noise = sd                                     # the readings' noise S^-1 n through S: the scenario's own
    out = []
    for causal in (False, True):
        csv = folder / ("c_causal.csv" if causal else "c.csv")
        args = ["compensate", str(tool), str(folder / "log.csv"), "--out", str(csv), "--overwrite", "--sd"]
        if main(args + (["--causal"] if causal else [])) != 0:
            raise SystemExit(f"seed {seed}: compensate failed")
        rows = np.loadtxt(csv, delimiter=",", skiprows=1)
        t, w, contact = rows[:, 0], rows[:, 1:7], rows[:, 7] > 0.5
        sdw = rows[:, 8:14]
        push = (t > PUSH[0] + 0.05) & (t < PUSH[0] + PUSH[1] - 0.05)
        free = (t < PUSH[0] - 0.1) | (t > PUSH[0] + PUSH[1] + 0.1)
        out.append(dict(ratio=np.sqrt(np.mean(w[free] ** 2, axis=0)) / noise,
                        z=np.sqrt(np.mean((w[free] / sdw[free]) ** 2, axis=0)),
                        false=contact[free].mean(), found=contact[push].mean()))
    return out


def main_(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--sensor", choices=("identity", "gains", "both"), default="both",
                        help="S = I, force gains off by up to 5 %%, or both (default)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        for gains in {"identity": (False,), "gains": (True,), "both": (False, True)}[args.sensor]:
            print(f"\n## S {'with force gains off by up to 5 %' if gains else '= I'}\n")
            print("| seed | path | residual / noise (tx ty tz fx fy fz) | rms z | flagged free % | push flagged % |")
            print("|---|---|---|---|---|---|")
            results = {False: [], True: []}
            for seed in range(args.seeds):
                for causal, r in zip((False, True), run(seed, gains, Path(tmp))):
                    results[causal].append(r)
                    print(f"| {seed} | {'causal' if causal else 'offline'} | "
                          + " ".join(f"{v:.2f}" for v in r["ratio"]) + f" | {r['z'].min():.2f}-{r['z'].max():.2f} | "
                          f"{100 * r['false']:.3f} | {100 * r['found']:.1f} |", flush=True)
            for causal in (False, True):
                rs = results[causal]
                found = [100 * r["found"] for r in rs]
                print(f"| median | {'causal' if causal else 'offline'} | "
                      + " ".join(f"{v:.2f}" for v in np.median([r["ratio"] for r in rs], axis=0))
                      + f" (worst {np.max([r['ratio'] for r in rs]):.2f}) | "
                      f"{np.median([r['z'] for r in rs]):.2f} | {100 * np.median([r['false'] for r in rs]):.3f} | "
                      f"{np.median(found):.1f} (least {np.min(found):.1f}) |")
    return 0


if __name__ == "__main__":
    sys.exit(main_())
