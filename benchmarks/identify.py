"""Identification that ends in a payload (issue 44): the force gains, the effect rule and its tolerance, over seeds.

Usage (from the repository's root)::

    python benchmarks/identify.py                       # 10 seeds: tables of 8, 12, 16 and 24 poses, logs of 20 s
    python benchmarks/identify.py --seeds 20 --poses 8 12 --durations 10 20

For each source (pose tables of ``--poses`` held poses, each row a 1 s hold of spatial-arm's noise at 1 kHz;
spatial-arm logs of ``--durations`` s with no cross-talk) and each sensor (``S = I``, and force gains drawn
uniformly within 5 % of one, ``S = I`` taken), over the seeds (:func:`fmscal.observers.payload.identify_payload`
with its defaults):

- ``determined``: the share whose payload is determined (its effect on the compensated wrench within the
  default tolerance, one sd of the reading's noise: a table's rows' scatter, a log's sample-to-sample scatter);
- ``z gains``: the rms of the gains' z-scores (the force gains relative to their mean; a log's torques' common
  gain too, where its motion tells it from one);
- ``z mass``: the mass's, against the truth in the force gains' mean units (``m / mean(g)``);
- ``err/tol``, ``err/effect``: the rms over the seeds, and over 50 held attitudes within the data's cone each, of
  the compensated wrench's error (no contact, noise-free readings) over the tolerance and over the stated effect,
  forces and torques (the tolerance promises the first within 1; the effect is the cone's largest sd, so the
  second is below 1).

The helpers are the tests' (``tests/test_payload_identify.py``), so that the benchmark and the slow test measure
the same thing.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from test_payload_identify import OFFSET, _gain_log, _gain_table, _scored  # noqa: E402

from fmscal.observers.payload import identify_payload  # noqa: E402
from fmscal.plant.scenarios import TOOL  # noqa: E402


def run(source, size, off, seeds):
    """One row: the statistics of ``seeds`` fits of ``source`` (``"table"``: ``size`` poses; ``"log"``: ``size``
    s), force gains within ``off`` of one."""
    rng = np.random.default_rng(44)
    determined, z_gains, z_mass, over_tol, over_effect = [], [], [], [], []
    for seed in range(seeds):
        gains = 1.0 + rng.uniform(-off, off, 3)
        k = gains.mean()
        if source == "table":
            data, b = _gain_table(size, seed, gains), OFFSET
            q = data.q
        else:
            data, truth = _gain_log(seed, gains, size)
            b, q = truth.offset, data.pose[::50, :4]
        fit = identify_payload(data)
        determined.append(fit.payload_determined)
        zs, tol, eff = _scored(fit, q, gains, b, rng)
        z_gains.extend(zs)
        z_mass.append((fit.mass - TOOL.mass / k) / fit.mass_std)
        over_tol.append(tol)
        over_effect.append(eff)

    def rms(v, axis=None):
        return np.sqrt(np.mean(np.square(v), axis=axis))
    return (np.mean(determined), rms(z_gains), rms(z_mass), rms(over_tol, 0), rms(over_effect, 0))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=10)
    p.add_argument("--poses", type=int, nargs="*", default=[8, 12, 16, 24])
    p.add_argument("--durations", type=float, nargs="*", default=[20.0])
    args = p.parse_args(argv)
    print("| source | sensor | determined | z gains | z mass | err/tol (N, N m) | err/effect (N, N m) |")
    print("|---|---|---|---|---|---|---|")
    cases = [("table", n) for n in args.poses] + [("log", d) for d in args.durations]
    for source, size in cases:
        for off in (0.0, 0.05):
            share, zg, zm, tol, eff = run(source, size, off, args.seeds)
            what = f"{size} poses" if source == "table" else f"{size:g} s log"
            sensor = "S = I" if off == 0 else "gains within 5 %"
            print(f"| {what} | {sensor} | {share:.0%} | {zg:.2f} | {zm:.2f} | {tol[0]:.2f}, {tol[1]:.2f} | "
                  f"{eff[0]:.2f}, {eff[1]:.2f} |", flush=True)


if __name__ == "__main__":
    main()
