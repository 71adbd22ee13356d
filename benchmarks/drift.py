"""The offset's drift followed without eating a contact: ``python benchmarks/drift.py [SEEDS] [--why]``.

A calibration from one 60 s ``spatial-arm`` log (seed 1, the default method) is used on ten other 60 s logs of
the same rig (seeds 2-11, the readings moved onto the first sensor, ``fmscal.plant.scenarios.same_rig``), each
given a temperature-like offset drift (``d (1 - exp(-t / 15 s))``, 2 N and 0.05 N m per channel, seeded signs;
``fmscal.plant.scenarios.drift_contact_log``) and:

- a 15 N contact of 2 s from 30 s: issue 38's targets at each path's default intensity (offline: fitted to
  each log by the innovations' likelihood, eq. D5 of analysis/_compensate.py; causal:
  :data:`fmscal.analysis._compensate.DRIFT_INTENSITY` times the reading's noise sd, per sqrt(s); and offline at
  that fixed intensity too): the residual after the first 5 s (outside the contact) within 2x the noise times
  S; the offset's 95 % intervals covering 93-97 % of samples; the contact within 10 %;
- a slow push, 10 N over 10 s from 40 s, instead of the contact: the share of it the offset has taken for
  drift at its end, and the share of its samples flagged;

then the intensities the offline fit chose, and the trade-off the drift's intensity sets (the offline fit and
causal at several intensities): the residual, the coverage, the push taken, and the coverage on the push's log.
docs/guide/compensation.md quotes it. A few minutes on 2 cores. The calibration takes the simulator's payload as
exact (``PayloadStd.exact()``): compensation with the payload the calibration took is spared the payload's error
that ``S`` absorbed, which ``cov`` counts in full otherwise (``--payload-defaults``: the defaults in ``cov``, as a
default ``fmscal calibrate`` saves them).

``--why``: why the offline intervals at a fixed intensity cover more than 95 % (docs/guide/compensation.md,
"How well it follows"). The offline coverage at the fixed default intensity, mean over seeds, with the contact
log: as published; with the calibration's covariance of ``[S | c]`` left out of (C3); with no drift at all (the
offset constant); the offset tracker's forward pass re-run here beside a Rauch-Tung-Striebel smoother over it
(both from ``P0 = 0``); then the offline coverage at each intensity and at the fitted one (D5); and the limits the
intervals reach on an offset that does not move or moves at a constant rate: a random walk's
(``2 Phi(1.96 sqrt(2)) - 1``) and an integrated random walk's (the offset and its rate the state), each from its
steady-state filter (the Riccati equation; the noise's share of ``P`` by a Lyapunov equation). About as long again.
"""

import argparse
import dataclasses
import sys
import time
from functools import partial
from multiprocessing import Pool
from pathlib import Path

import numpy as np
from scipy.linalg import solve_discrete_are, solve_discrete_lyapunov
from scipy.stats import chi2, norm

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from fmscal.analysis import calibrate, compensate  # noqa: E402
from fmscal.analysis._compensate import DRIFT_INTENSITY, FALSE_ALARM  # noqa: E402
from fmscal.plant import SPATIAL_SCENARIOS, PayloadStd  # noqa: E402
from fmscal.plant.scenarios import contact_wrench, drift_contact_log, same_rig  # noqa: E402
from live_rig import DRIFT_CONTACT, drift_run  # noqa: E402

ARM = SPATIAL_SCENARIOS["spatial-arm"]
MULTIPLES = (0.25, 0.5, 1.0, 2.0, 4.0)
#: The offline path's default: the intensity fitted (D5).
FIT = "fit"


def one(seed, cal, S, b, jobs):
    """Every (multiple, causal) of ``jobs`` on the log of ``seed`` (``multiple`` :data:`FIT`: fitted, offline)."""
    log, truth, _ = ARM.generate(seed)
    sd = np.asarray(truth.noise.wrench_sd, dtype=float)
    return {(m, causal): dict(drift_run(cal, S, b, log, truth.S_at(0.0), truth.offset, sd, seed,
                                        None if m == FIT else m * sd, causal), sd=sd) for m, causal in jobs}


def limits():
    """The coverage of a steady-state tracker's 95 % intervals on an offset the model's process noise does not
    move (a constant for the random walk; a constant rate for the integrated one): the noise's share ``r`` of
    the offset's ``P`` (a Lyapunov equation for the error of ``e <- (I - K H) F e + K v``), ``2 Phi(1.96 /
    sqrt(r)) - 1``. One channel, unit noise, dt = 1 ms, ``q`` the noise sd per sqrt(s) (the share barely
    depends on it)."""
    dt, q, out = 1e-3, 1.0, {}
    for name, F, Q in (("random walk", np.eye(1), np.array([[q * q * dt]])),
                       ("integrated random walk", np.array([[1.0, dt], [0.0, 1.0]]),
                        q * q * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]]))):
        H, R = np.eye(1, len(F)), np.eye(1)
        prior = solve_discrete_are(F.T, H.T, Q, R)
        K = prior @ H.T @ np.linalg.inv(H @ prior @ H.T + R)
        posterior = (np.eye(len(F)) - K @ H) @ prior
        noise = solve_discrete_lyapunov((np.eye(len(F)) - K @ H) @ F, K @ R @ K.T)
        share = noise[0, 0] / posterior[0, 0]
        out[name] = (share, 2 * norm.cdf(1.959964 / np.sqrt(share)) - 1)
    return out


def summary(runs):
    keys = runs[0].keys()
    return {k: np.array([r[k] for r in runs]) for k in keys}


def forward_and_smoothed(c, S_hat, b0, q2):
    """The offset tracker's (D1)-(D3) re-run on an untracked compensation ``c`` (``w_e0`` and Cov (C3) with the
    calibration's offset ``b0``; ``w_e = w_e0 + S (b - b0)``) from ``P0 = 0``, and a Rauch-Tung-Striebel smoother
    over it: ``G_k = P_k P_{k+1|k}^-1``, ``b^s_k = b_k + G_k (b^s_{k+1} - b_k)``,
    ``P^s_k = P_k + G_k (P^s_{k+1} - P_{k+1|k}) G_k^T`` (a random walk predicts ``b_{k+1|k} = b_k``).
    Returns ``(b, sd)`` of each, shape (N, n_w)."""
    n, m = len(c.t), len(b0)
    threshold = chi2.ppf(1.0 - FALSE_ALARM, m)
    b, P = b0.copy(), np.zeros((m, m))
    bf, Pf, Pp = np.empty((n, m)), np.empty((n, m, m)), np.empty((n, m, m))
    for k in range(n):
        if k:
            P = P + np.diag(q2 * (c.t[k] - c.t[k - 1]))
        Pp[k] = P
        w_e = c.wrench[k] + S_hat @ (b - b0)
        SP = S_hat @ P
        total = c.cov[k] + SP @ S_hat.T
        solved = np.linalg.solve(0.5 * (total + total.T), np.c_[w_e, SP])
        if w_e @ solved[:, 0] <= threshold:
            K = solved[:, 1:].T
            b = b - K @ w_e
            P = P - K @ SP
            P = 0.5 * (P + P.T)
        bf[k], Pf[k] = b, P
    bs, Ps = bf.copy(), Pf.copy()
    for k in range(n - 2, -1, -1):
        G = np.linalg.solve(Pp[k + 1], Pf[k]).T                  # P_k P_{k+1|k}^-1 (both symmetric)
        bs[k] = bf[k] + G @ (bs[k + 1] - bf[k])
        Ps[k] = Pf[k] + G @ (Ps[k + 1] - Pp[k + 1]) @ G.T
    sd = lambda P: np.sqrt(np.maximum(np.einsum("nii->ni", P), 0.0))  # noqa: E731
    return (bf, sd(Pf)), (bs, sd(Ps))


def why(seed, cal, S, b):
    """The offline coverage (each a mean over the six channels) of the diagnostics of ``--why`` on ``seed``."""
    log, truth, _ = ARM.generate(seed)
    sd = np.asarray(truth.noise.wrench_sd, dtype=float)
    base = same_rig(log, truth.S_at(0.0), truth.offset, S, b)
    out = {}

    def coverage(c, change, offset=None, offset_sd=None):
        idx = np.searchsorted(base.t, np.round(c.t, 9))
        offset = c.offset if offset is None else offset
        offset_sd = c.offset_sd if offset_sd is None else offset_sd
        return float(np.mean(np.abs(offset - (b + change[idx])) <= 1.959964 * offset_sd))

    touched, change, _ = drift_contact_log(base, S, contact=contact_wrench(15.0), contact_at=DRIFT_CONTACT,
                                           seed=seed)
    q = DRIFT_INTENSITY * sd
    no_cov = dataclasses.replace(cal, cov=None)
    out["without the calibration's covariance"] = coverage(
        compensate(no_cov, touched, track_offset=True, drift_intensity=q), change)
    still, still_change, _ = drift_contact_log(base, S, size=np.zeros(6), contact=contact_wrench(15.0),
                                               contact_at=DRIFT_CONTACT, seed=seed)
    out["no drift (the offset constant)"] = coverage(compensate(cal, still, track_offset=True, drift_intensity=q),
                                                     still_change)
    plain = compensate(cal, touched)
    (bf, sf), (bs, ss) = forward_and_smoothed(plain, np.asarray(cal.S, dtype=float), np.asarray(cal.offset), q ** 2)
    check = compensate(cal, touched, track_offset=True, drift_intensity=q, offset_sd=0.0)
    assert np.allclose(bf, check.offset, atol=1e-9), "the forward pass re-run here is not the library's"
    out["forward pass (the library's), P0 = 0"] = coverage(plain, change, bf, sf)
    out["Rauch-Tung-Striebel smoother over it"] = coverage(plain, change, bs, ss)
    idx = np.searchsorted(base.t, np.round(plain.t, 9))
    out["offset rms error, forward / smoothed"] = float(np.sqrt(np.mean((bf - (b + change[idx])) ** 2))
                                                        / np.sqrt(np.mean((bs - (b + change[idx])) ** 2)))
    for m in MULTIPLES:
        out[f"intensity {m:g}"] = coverage(compensate(cal, touched, track_offset=True, drift_intensity=m * sd),
                                           change)
    fitted = compensate(cal, touched, track_offset=True)
    out["intensity fitted (D5), the offline default"] = coverage(fitted, change)
    out["the fitted intensity, x the noise sd per sqrt(s)"] = float(np.mean(fitted.drift_intensity / sd))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("seeds", nargs="?", type=int, default=10, help="how many logs (seeds 2 on); default 10")
    parser.add_argument("--why", action="store_true", help="only the diagnostics of the offline coverage")
    parser.add_argument("--payload-defaults", action="store_true",
                        help="calibrate with the payload's default standard deviations in cov (the calibration's "
                             "payload is the simulator's: taken as exact otherwise)")
    args = parser.parse_args()
    seeds = range(2, 2 + args.seeds)
    log, truth, _ = ARM.generate(1)
    t0 = time.perf_counter()
    cal = calibrate(log, ARM.payload, payload_std=None if args.payload_defaults else PayloadStd.exact())
    print(f"calibration: {cal.method} on {log.name} ({time.perf_counter() - t0:.0f} s), converged {cal.converged}; "
          f"{len(seeds)} seeds ({seeds.start}-{seeds.stop - 1})")
    if args.why:
        with Pool(2) as pool:
            results = pool.map(partial(why, cal=cal, S=truth.S_at(0.0), b=truth.offset), seeds)
        print(f"\noffline, the causal default intensity ({DRIFT_INTENSITY:g} x the noise sd per sqrt(s)) unless said; "
              "coverage of the offset's 95 % intervals, mean (min-max) over seeds\n")
        for key in results[0]:
            v = np.array([r[key] for r in results])
            scale = 1 if key.startswith(("offset rms", "the fitted")) else 100
            print(f"- {key}: {scale * v.mean():.{2 if scale == 1 else 1}f} "
                  f"({scale * v.min():.{2 if scale == 1 else 1}f}-{scale * v.max():.{2 if scale == 1 else 1}f})")
        print(f"- the limit on an offset that does not move: {100 * (2 * norm.cdf(1.959964 * np.sqrt(2)) - 1):.1f}")
        for name, (share, cover) in limits().items():
            print(f"- steady state, {name}: the noise's share of P {share:.3f}, the limit {100 * cover:.1f}")
        return
    jobs = [(FIT, False), (DRIFT_INTENSITY, False)] + [(m, True) for m in MULTIPLES]
    with Pool(2) as pool:
        results = pool.map(partial(one, cal=cal, S=truth.S_at(0.0), b=truth.offset, jobs=jobs), seeds)
    print("\neach path's default intensity (offline: fitted, D5; causal: "
          f"{DRIFT_INTENSITY:g} x the noise sd per sqrt(s)), and offline at that fixed one; worst seed and channel, "
          "and the mean over seeds\n")
    print("| path | residual / noise after 5 s, worst | coverage of the 95 % intervals, min-max (mean) | "
          "15 N contact error, worst, % | contact flagged, % | false alarms, % |")
    print("|---|---|---|---|---|---|")
    rows = (("offline, fitted (default)", (FIT, False)), (f"offline, {DRIFT_INTENSITY:g}x", (DRIFT_INTENSITY, False)),
            (f"causal, {DRIFT_INTENSITY:g}x (default)", (DRIFT_INTENSITY, True)))
    for name, key in rows:
        s = summary([r[key] for r in results])
        cover = s["coverage"].mean(axis=1)                     # each seed's share over the channels
        print(f"| {name} | {s['residual'].max():.2f} | "
              f"{100 * cover.min():.1f}-{100 * cover.max():.1f} ({100 * cover.mean():.1f}) | "
              f"{100 * s['contact_error'].max():.1f} | {100 * s['contact_flagged'].mean():.1f} | "
              f"{100 * s['false_alarm'].mean():.2f} |")
    for name, key in rows:
        print(f"\nper channel coverage, {name}, mean over seeds: "
              + ", ".join(f"{100 * v:.1f} %" for v in summary([r[key] for r in results])["coverage"].mean(axis=0)))
    s = summary([r[(FIT, False)] for r in results])
    scale, push_scale = (s[k] / s["sd"] for k in ("intensity", "push_intensity"))
    print(f"\nthe offline fit (D5), x the noise sd per sqrt(s), mean (min-max) over seeds and channels: on the log "
          f"with the contact {scale.mean():.3f} ({scale.min():.3f}-{scale.max():.3f}); on the log with the slow push "
          f"instead {push_scale.mean():.3f} ({push_scale.min():.3f}-{push_scale.max():.3f})")
    print("\nthe drift's intensity: following a drift against taking a slow push (10 N over 10 s) for it; the "
          "offset's coverage on the log with the contact and on the log with the push\n")
    print("| path, intensity x noise sd / sqrt(s) | residual / noise after 5 s, worst | coverage, mean (min) | "
          "push taken for drift at its end, mean (max), % | push flagged, % | coverage on the push's log, mean (min) |")
    print("|---|---|---|---|---|---|")
    for name, key in ((f"offline, fitted: {scale.mean():.2f} / {push_scale.mean():.2f}", (FIT, False)),
                      *((f"causal, {m:g}", (m, True)) for m in MULTIPLES)):
        s = summary([r[key] for r in results])
        cover, push_cover = s["coverage"].mean(axis=1), s["push_coverage"].mean(axis=1)
        print(f"| {name} | {s['residual'].max():.2f} | {100 * cover.mean():.1f} ({100 * cover.min():.1f}) | "
              f"{100 * s['push_taken'].mean():.0f} ({100 * s['push_taken'].max():.0f}) | "
              f"{100 * s['push_flagged'].mean():.0f} | {100 * push_cover.mean():.1f} ({100 * push_cover.min():.1f}) |",
              flush=True)

if __name__ == "__main__":
    main()
