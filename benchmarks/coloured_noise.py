"""Coloured reading noise over seeds (issue 46 item 2).

Usage: ``python benchmarks/coloured_noise.py [SEEDS] [DURATION] [--ekf | --live | --offset]``.

On ``spatial-arm`` logs (default 5 seeds, 10 s at 1 kHz) whose reading noise is the scenario's white noise
passed through a filter, its standard deviation kept at the scenario's (:data:`FILTERS`: white, a first-order
low-pass at 300, 100 and 30 Hz, and moving averages of 2 and 4 samples), each log is calibrated by
``fmscal.analysis.calibrate(log, payload, payload_std=PayloadStd.exact())`` (the default method, the floor; the
payload exact, so that ``S_std`` is the statistical part alone). Printed per filter, medians over the seeds:

* ``z rms``: the rms of ``z = (S_hat - S) / S_std`` over ``S``'s 36 entries, its median over the seeds (target:
  within [0.7, 1.4]), its rms over every seed's entries (pooled), and the largest seed's;
* ``converged``: the seeds converged (a log whose noise is correlated holds less information, and a 10 s log
  may then not pin ``S`` down to the 5 % ``converged`` asks; the duration is the second argument);
* the readings' noise the calibration recorded (fz's sd, against the scenario's) and its correlation time
  (``tau``, 1 for white noise; the noise model's, eq. (N2) of plant/io/_noise.py);
* the contact test on the log itself compensated offline (``fmscal.analysis.compensate``; free motion, no
  contact anywhere), by the true ``S`` and offset (the noise model then the log's own) and by the calibration
  (its recorded noise model): the rms of the output's z (each component over its stated sd) and the share of
  samples flagged, against the stated false-alarm probability (``fmscal.analysis.FALSE_ALARM``).

``--ekf``: the EKF's median rms z of ``S`` per filter instead.

``--live``: the live :class:`fmscal.analysis.Compensator` of a payload file instead (:func:`live`): the tool
identified from 8 held poses (``fit_static`` of a simulated table, each row the mean of 500 readings: its noise a held
pose's, so that the Compensator learns the readings' noise from its first readings), on ``spatial-arm`` with
``S = I``; per filter, medians over the seeds of the output's rms z (each component over its stated sd) and the
share of the output flagged (no contact anywhere; pooled over the seeds in brackets), with the noise learned by
default (its colour measured from the first 4 s, eqs. N1-N3) and from the first ``NOISE_SAMPLES`` readings taken as
white (the Compensator before it measured the colour, to the bit).

``--offset``: the same live Compensator with ``track_offset=True`` (the offset a random walk, eqs. D1-D6 of
analysis/_compensate.py): per filter, medians over the seeds of the offset's rms z after the first 2 s of output
(``(b - b_true) / sd(b)`` sample by sample), on the force and on the torque channels, the output's rms z, and the
inertia's diagonal at the end (the payload file's, a guess where held poses leave it bounded, plus what eq. L1
learned from the motion). The
true offset is constant, so the random walk's sd leans wide (the module docstring of analysis/_compensate.py: about
0.7 expected).

tests/test_coloured_noise.py holds the targets (seeded; the 20-seed target in a slow test). A few minutes on
2 cores at 5 seeds.
"""

import sys

import numpy as np
from scipy.signal import lfilter

from fmscal.analysis import FALSE_ALARM, Compensator, calibrate, compensate
from fmscal.analysis._compensate import NOISE_SAMPLES
from fmscal.observers.payload import fit_static
from fmscal.plant import SPATIAL_SCENARIOS, Calibration, PayloadStd
from fmscal.plant.io import simulate_table

ARM = SPATIAL_SCENARIOS["spatial-arm"]
#: The everyday job's sensor (``--live``): ``spatial-arm`` with ``S = I``, as a payload file takes it.
EVERYDAY = ARM.with_(crosstalk=0.0)

#: The filters on the reading's noise: a name and ``(b, a)`` of :func:`scipy.signal.lfilter`, scaled so that
#: white noise of unit variance comes out of unit variance.
FILTERS = {"white": None, "low-pass 300 Hz": ("lowpass", 300.0), "low-pass 100 Hz": ("lowpass", 100.0),
           "low-pass 30 Hz": ("lowpass", 30.0), "average 2": ("average", 2), "average 4": ("average", 4)}


def coloured(noise, kind, dt):
    """``noise`` (N, c), white, through the filter ``kind`` (a value of :data:`FILTERS`), its variance kept.

    A first-order low-pass at ``fc``: ``y_k = a y_k-1 + sqrt(1 - a^2) n_k``, ``a = exp(-2 pi fc dt)``, started
    in its steady state; a moving average of ``m`` samples: ``sum_{j<m} n_k-j / sqrt(m)``.
    """
    if kind is None:
        return noise
    name, value = kind
    if name == "lowpass":
        a = np.exp(-2.0 * np.pi * value * dt)
        y, _ = lfilter([np.sqrt(1.0 - a * a)], [1.0, -a], noise[1:], axis=0, zi=a * noise[:1])
        return np.vstack([noise[:1], y])
    m = int(value)
    padded = np.vstack([noise[-(m - 1):] if m > 1 else noise[:0], noise])     # wrapped: every row m terms
    return lfilter(np.ones(m) / np.sqrt(m), [1.0], padded, axis=0)[m - 1:]


def coloured_log(seed, kind, duration=10.0, scenario=ARM):
    """A ``scenario`` log of ``seed`` whose reading noise went through ``kind``; ``(log, truth)``.

    The noise the scenario drew is recovered exactly (the noise-free log of the same seed makes the same
    draws) and replaced by its filtered self, so that the motion, ``S``, the offset and the poses are the
    white log's.
    """
    scenario = scenario.with_(duration=duration)
    log, truth, _ = scenario.generate(seed)
    if kind is None:
        return log, truth
    clean, _, _ = scenario.generate(seed, noise_free=True)
    log.w_hat = clean.w_hat + coloured(log.w_hat - clean.w_hat, kind, log.dt)
    return log, truth


def truth_calibration(truth):
    """The true ``S`` and offset as a calibration holding no noise model: compensated with it, the contact test
    takes the log's own (``compensate``'s ``noise`` default)."""
    return Calibration(S=truth.S_at(0.0), payload=truth.payload, method="truth", b=truth.offset,
                       gravity=np.asarray(ARM.gravity, dtype=float))


def contact_test(setup, log):
    """The contact test on a log of free motion compensated offline by ``setup``: ``(rms z, share flagged)``."""
    out = compensate(setup, log)
    return float(np.sqrt(np.mean(np.square(out.wrench / out.sd)))), float(np.mean(out.contact))


def measure(seed, kind, duration=10.0):
    """One log's figures: a dict of ``z_rms``, ``converged``, ``fz_sd``, ``tau``, and the contact test's by the
    truth and the calibration."""
    log, truth = coloured_log(seed, kind, duration)
    S = truth.S_at(log.t[-1])
    cal = calibrate(log, ARM.payload, payload_std=PayloadStd.exact())
    z = (np.asarray(cal.S) - S) / np.asarray(cal.S_std)
    noise = cal.noise
    tau = getattr(noise, "wrench_tau", None)          # None: white (or a noise model without a correlation)
    return {"z_rms": float(np.sqrt(np.mean(z ** 2))), "z_max": float(np.abs(z).max()), "converged": cal.converged,
            "fz_sd": float(noise.wrench_sd[5]), "tau": 1.0 if tau is None else float(np.max(tau)),
            "truth": contact_test(truth_calibration(truth), log), "calibration": contact_test(cal, log)}


def live(seed, kind, duration=10.0, noise_samples=None, track_offset=False):
    """The live Compensator of a payload file on an :data:`EVERYDAY` log of ``seed`` whose reading noise went
    through ``kind``: the tool's payload fitted to 8 held poses (a table's fit, whose noise is a held pose's: the
    Compensator learns the readings' from its first ``noise_samples``, default as many as the colour needs).

    Returns ``(log, stream, outputs, figures)``: the outputs the stream's ``ContactSample`` list; the figures a dict
    of ``z`` (the output's rms z, each component over its stated sd), ``flagged`` (the share of the output flagged;
    no contact anywhere), ``n`` (outputs) and ``first`` (the first output's reading time, s); with ``track_offset``
    also ``offset_z``: the offset's rms z after the first 2 s of output, per channel (torques first), (6,), and
    ``inertia``: the payload's inertia at the end (the file's, plus what eq. L1 learned), (6,).
    """
    log, truth = coloured_log(seed, kind, duration, EVERYDAY)
    sd = np.asarray(truth.noise.wrench_sd)
    table = simulate_table(EVERYDAY.payload, n=8, seed=100 + seed, S=truth.S_at(0.0), offset=truth.offset,
                           wrench_sd=sd / np.sqrt(500))
    stream = Compensator(fit_static(table), log.dt, noise_samples=noise_samples, track_offset=track_offset)
    out = stream.push_many(log.t, log.w_hat, log.pose)
    w = np.array([o.wrench for o in out])
    z = w / np.sqrt(np.array([np.diag(o.cov) for o in out]))
    figures = {"z": float(np.sqrt(np.mean(z ** 2))), "flagged": float(np.mean([o.contact for o in out])),
               "n": len(out), "first": out[0].t}
    if track_offset:
        late = np.array([o.t for o in out]) > out[0].t + 2.0
        b = np.array([o.offset for o in out])[late]
        sd = np.array([o.offset_sd for o in out])[late]
        figures["offset_z"] = np.sqrt(np.mean(((b - np.asarray(truth.offset)) / sd) ** 2, axis=0))
        tracker = stream._tracker                        # the inertia learned from the motion (L1), where it is
        figures["inertia"] = np.asarray(stream.model.payload.inertia, dtype=float) + (
            tracker.dI if tracker is not None and tracker.k else 0.0)
    return log, stream, out, figures


def main(seeds=5, duration=10.0):
    print(f"spatial-arm, {duration:g} s at 1 kHz, {seeds} seeds (medians); the payload exact; reading noise fz sd "
          f"{ARM.force_sd:g} N; contact test false alarm {FALSE_ALARM:g}\n")
    print("| noise | z rms (median) | z rms (pooled) | max z rms | converged | fz sd | tau | contact z rms (truth) | "
          "flagged (truth) | contact z rms (calibration) | flagged (calibration) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    rows = {}
    for name, kind in FILTERS.items():
        runs = [measure(seed, kind, duration) for seed in range(seeds)]
        med = {k: float(np.median([r[k] for r in runs])) for k in ("z_rms", "fz_sd", "tau")}
        truth = np.median([r["truth"] for r in runs], axis=0)
        cal = np.median([r["calibration"] for r in runs], axis=0)
        rows[name] = (med, runs)
        pooled = float(np.sqrt(np.mean([r["z_rms"] ** 2 for r in runs])))
        print(f"| {name} | {med['z_rms']:.2f} | {pooled:.2f} | {max(r['z_rms'] for r in runs):.2f} | "
              f"{sum(r['converged'] for r in runs)}/{seeds} | {med['fz_sd']:.3f} | {med['tau']:.2f} | "
              f"{truth[0]:.2f} | {truth[1]:.2g} | {cal[0]:.2f} | {cal[1]:.2g} |", flush=True)
    return rows


def ekf(seeds=5, duration=10.0):
    """``--ekf``: the EKF's median rms z of ``S`` per filter (its ``Q`` takes the noise's long-run variance too)."""
    print(f"the EKF on spatial-arm, {duration:g} s, {seeds} seeds; the payload exact\n")
    print("| noise | z rms (median) | max z rms | converged |\n|---|---|---|---|")
    for name, kind in FILTERS.items():
        z, converged = [], 0
        for seed in range(seeds):
            log, truth = coloured_log(seed, kind, duration)
            cal = calibrate(log, ARM.payload, method="ekf", payload_std=PayloadStd.exact())
            z.append(float(np.sqrt(np.mean(((np.asarray(cal.S) - truth.S_at(log.t[-1])) / cal.S_std) ** 2))))
            converged += bool(cal.converged)
        print(f"| {name} | {np.median(z):.2f} | {max(z):.2f} | {converged}/{seeds} |", flush=True)


def live_table(seeds=5, duration=10.0):
    """``--live``: the live Compensator of a payload file per filter (:func:`live`), its noise learned by default
    and from the first :data:`NOISE_SAMPLES` readings taken as white."""
    print(f"the live Compensator of a payload file on spatial-arm (S = I), {duration:g} s at 1 kHz, {seeds} seeds "
          f"(medians; pooled in brackets); no contact; false alarm {FALSE_ALARM:g}\n")
    print(f"| noise | z rms | flagged % | first output, s | z rms, white from {NOISE_SAMPLES} | flagged %, white from "
          f"{NOISE_SAMPLES} |\n|---|---|---|---|---|---|")
    for name, kind in FILTERS.items():
        cells = []
        for samples in (None, NOISE_SAMPLES):
            runs = [live(seed, kind, duration, samples)[3] for seed in range(seeds)]
            z, flagged = [r["z"] for r in runs], [r["flagged"] for r in runs]
            pooled = sum(r["flagged"] * r["n"] for r in runs) / sum(r["n"] for r in runs)
            cells.append(f"{np.median(z):.2f} ({np.sqrt(np.mean(np.square(z))):.2f}) | "
                         f"{100 * np.median(flagged):.3g} ({100 * pooled:.3g})")
            if samples is None:
                cells.append(f"{np.median([r['first'] for r in runs]):.3g}")
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)


def offset_table(seeds=5, duration=10.0):
    """``--offset``: the live Compensator's offset tracker per filter (:func:`live` with ``track_offset``)."""
    print(f"the live Compensator of a payload file on spatial-arm (S = I) tracking the offset, {duration:g} s at "
          f"1 kHz, {seeds} seeds (medians); the true offset constant\n")
    true = np.asarray(EVERYDAY.payload.inertia, dtype=float)[:3]
    print("| noise | offset z rms, forces | offset z rms, torques | output z rms | inertia's diagonal at the end, "
          f"kg m^2 (true {', '.join(f'{v:.2e}' for v in true)}) |\n|---|---|---|---|---|")
    for name, kind in FILTERS.items():
        runs = [live(seed, kind, duration, track_offset=True)[3] for seed in range(seeds)]
        z = np.array([r["offset_z"] for r in runs])
        forces, torques = np.sqrt(np.mean(z[:, 3:] ** 2, axis=1)), np.sqrt(np.mean(z[:, :3] ** 2, axis=1))
        diagonal = np.median([r["inertia"][:3] for r in runs], axis=0)
        print(f"| {name} | {np.median(forces):.2f} | {np.median(torques):.2f} | "
              f"{np.median([r['z'] for r in runs]):.2f} | {', '.join(f'{v:.2e}' for v in diagonal)} |", flush=True)


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if a not in ("--ekf", "--live", "--offset")]
    (ekf if "--ekf" in sys.argv else live_table if "--live" in sys.argv else
     offset_table if "--offset" in sys.argv else main)(
        int(args[0]) if args else 5, float(args[1]) if len(args) > 1 else 10.0)
