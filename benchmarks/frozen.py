"""Frozen readings over seeds (issue 46 item 3): ``python benchmarks/frozen.py [SEEDS] [DURATION]``.

On ``spatial-arm`` logs (default 5 seeds, 10 s at 1 kHz), as recorded and with every channel quantised to
1-8 times its own noise sd: the frozen runs found on the clean logs (false alarms, eqs. (F1), (F2) of
observers/core/_frozen.py), the share of freezes of 20, 50 and 100 samples found (the reading held at its
last value from 2, 5 and 8 s), and the share of repeated samples in the clean log (how often the reading
repeats by chance). tests/test_frozen.py holds the false-alarm side and the detection of float readings;
this prints the figures, the quantised detection among them. About a minute on 2 cores.
"""

import sys

import numpy as np

from fmscal.observers.core import find_glitches
from fmscal.plant import SPATIAL_SCENARIOS

ARM = SPATIAL_SCENARIOS["spatial-arm"]
LENGTHS = (20, 50, 100)
STARTS = (0.2, 0.5, 0.8)


def quantised(w, step):
    """``w`` with every channel rounded to ``step`` times its own noise sd (from its first differences)."""
    q = step * np.std(np.diff(w, axis=0), axis=0) / np.sqrt(2)
    return np.round(w / q) * q


def held(w, start, length):
    out = w.copy()
    out[start:start + length] = w[start - 1]
    return out


def main(seeds, duration):
    print(f"{'step':>5} {'repeats':>8} {'false':>6} " + " ".join(f"{f'found {L}':>10}" for L in LENGTHS))
    for step in (0, 1, 2, 3, 4, 6, 8):
        false, found, repeats = 0, dict.fromkeys(LENGTHS, 0), []
        for seed in range(seeds):
            log, _, _ = ARM.with_(duration=duration).generate(200 + seed)
            w = quantised(log.w_hat, step) if step else log.w_hat
            repeats.append(np.mean(np.all(w[1:] == w[:-1], axis=1)))
            false += len(find_glitches(log.t, w)[0].frozen)
            for L in LENGTHS:
                for share in STARTS:
                    a = int(share * len(w))
                    runs = find_glitches(log.t, held(w, a, L))[0].frozen
                    found[L] += any(r["start"] <= a and r["start"] + r["length"] >= a + L for r in runs)
        tries = seeds * len(STARTS)
        print(f"{step:>5} {np.mean(repeats):>8.4f} {false:>6} "
              + " ".join(f"{f'{found[L]}/{tries}':>10}" for L in LENGTHS))


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 5, float(sys.argv[2]) if len(sys.argv) > 2 else 10.0)
