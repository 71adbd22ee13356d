"""The EKF's E over the floor's on the planar scenarios: ``python benchmarks/ekf_planar_floor.py [SEEDS] [DURATION]``.

For each planar scenario of :data:`fmscal.plant.SCENARIOS` and each seed (default 3: seeds 0-2), the EKF with
its defaults and the floor (``max-likelihood``) run on the same log (:func:`fmscal.analysis.compare`, which
tells the EKF the scenario's noise, lines up the poses and estimates the offset where the scenario has one);
the row is the median over the seeds of ``E / floor_E`` (each E the median over the run's last tenth). The
duration is each scenario's unless given (s). ``tests/test_ekf.py`` holds the EKF's medians within 1.02x of
those recorded in :data:`RECORDED` (slow).
"""

import sys

import numpy as np

from fmscal.analysis import compare
from fmscal.plant import SCENARIOS

#: The nine planar scenarios the EKF is held on.
PLANAR = tuple(SCENARIOS)

#: The settings the recorded figures were measured with: seeds 0-2, each scenario's own duration.
SEEDS, DURATION = 3, None


def medians(seeds=SEEDS, duration=DURATION, scenarios=PLANAR):
    """``{scenario: median over seeds of the EKF's E / floor_E}``."""
    table = compare(scenarios, seeds, ["ekf"], duration=duration, progress=False)
    ekf = table[table["observer"] == "ekf"]
    return {name: float(np.median(g["E_over_floor"].to_numpy())) for name, g in ekf.groupby("scenario", sort=False)}



def main(seeds=SEEDS, duration=DURATION):
    print("| scenario | ekf E / floor E (median) |")
    print("|---|---|")
    for name, ratio in medians(seeds, duration).items():
        print(f"| {name} | {ratio:.4f} |", flush=True)


if __name__ == "__main__":
    args = sys.argv[1:]
    main(int(args[0]) if args else SEEDS, float(args[1]) if len(args) > 1 else DURATION)
