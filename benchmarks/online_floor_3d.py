"""The online methods in 3D against the floor, seed by seed: ``python benchmarks/online_floor_3d.py [SEEDS]``.

For each seed of a 20 s ``spatial-arm`` log (default seeds 0-8), the adaptive observer's and the EKF's E (the
median over the run's last tenth, :func:`fmscal.analysis.tail_median`) over the floor's E, the floor
fitted on the samples that median has seen (:func:`fmscal.analysis.tail_seen`) and on the whole log.
The tests assert seeds 0-2 (``tests/test_spatial_adaptive.py``, ``tests/test_spatial_ekf.py``); this prints
the seeds beside them, as docs/comparison.md quotes them. About a minute on 2 cores.
"""

import sys

import numpy as np

from fmscal.analysis._metrics import calibration_error, error_history, tail_median, tail_seen
from fmscal.observers import make_observer
from fmscal.plant import SpatialModel
from fmscal.plant.scenarios._spatial import SPATIAL_SCENARIOS


def main(seeds):
    scenario = SPATIAL_SCENARIOS["spatial-arm"].with_(duration=20.0)
    model = SpatialModel(scenario.payload, scenario.gravity)
    print("| seed | adaptive / floor seen | adaptive / floor whole | ekf / floor seen | ekf / floor whole |")
    print("|---|---|---|---|---|")
    rows = []
    for seed in seeds:
        log, truth, _ = scenario.generate(seed)
        S = truth.S_at(log.t[-1])
        floor = [calibration_error(make_observer("max-likelihood", model, settings={"offset": True}).run(part).S_hat,
                                   S) for part in (log.head(tail_seen(len(log))), log)]
        adaptive = make_observer("adaptive", model, settings={"offset": True}).run(log)
        ekf = make_observer("ekf", model, truth.noise, {"offset": True}).run(log)
        row = [tail_median(error_history(r.S_hat_history, S)) / f for r in (adaptive, ekf) for f in floor]
        rows.append(row)
        print(f"| {seed} | " + " | ".join(f"{v:.2f}" for v in row) + " |", flush=True)
    rows = np.array(rows)
    print("| range | " + " | ".join(f"{lo:.2f}-{hi:.2f}" for lo, hi in zip(rows.min(0), rows.max(0))) + " |")


if __name__ == "__main__":
    main([int(s) for s in sys.argv[1:]] or range(9))
