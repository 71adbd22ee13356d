"""What the spatial commands share: the payload from the flags, a truth checked for the case, the report printed.

``fmscal calibrate`` on a spatial log or held poses is :func:`fmscal.analysis.calibrate`
(which picks the case from the file and refuses the options it does not
take); this module prints its report (:func:`print_spatial`).
``fmscal identify-payload`` reads its truth with :func:`_spatial_truth`.
"""

import numpy as np

from fmscal.plant import SpatialModel, read_truth
from fmscal.plant.physics import find_model

from ._common import CliError

__all__ = ["print_spatial", "latency_line", "print_std_parts"]
#: The spatial model's reading: what identify-payload's truth and the report's rows and columns are of.
_NAMES = SpatialModel.wrench_names


def _spatial_truth(path):
    """The truth sidecar at ``path`` (None without one), refused if it is not a spatial log's (its reading's size)."""
    truth = read_truth(path) if path else None
    if truth is not None and truth.schedule.size != len(_NAMES):
        other = getattr(find_model(n_w=truth.schedule.size), "name", "another")
        raise CliError(f"{path} is the truth of a {other} log; this log is spatial")
    return truth


def print_spatial(args, summary, out):
    """The human-readable report of ``fmscal calibrate`` on a spatial log or held poses (``out``: its JSON)."""
    print(summary)
    S = np.array(out["S"])
    if out["S_std"] is None:
        print(f"S_hat (rows and columns tx ty tz fx fy fz; {out['observer']} reports no uncertainty):")
        for i in range(6):
            print("  " + "  ".join(f"{S[i, j]:+.4f}" for j in range(6)))
    else:
        S_std = np.array(out["S_std"])
        print("S_hat +- one sigma (rows and columns tx ty tz fx fy fz; inf: not determined):")
        for i in range(6):
            print("  " + "  ".join(f"{S[i, j]:+.4f}+-{S_std[i, j]:.0e}" for j in range(6)))
        print_std_parts(out, out.get("kind"))
    b_std = out["b_std"] if out["b_std"] is not None else [np.nan] * 6
    print("offset b [N m, N]: " + "  ".join(f"{n} {b:+.4g} +- {s:.1e}" for n, b, s in zip(_NAMES, out["b"], b_std)))
    print(f"reading: {out['reading']}")
    if out["latency"] is not None:
        print(latency_line(out))
    undetermined = len(out["undetermined"])
    print(f"converged: {'yes' if out['converged'] else 'no'}"
          + (f" ({undetermined} direction(s) of the reading not determined)" if undetermined else ""))
    if "E" in out:
        print(f"E = ||I - S_hat S^-1||_2 = {out['E']:.4g} (SI units); torque block {out['E_torque']:.4g}, "
              f"force block {out['E_force']:.4g}")
    if out["saved"]:
        print(f"saved the calibration to {args.save}")


def print_std_parts(out, kind):
    """The two parts of ``S_std`` (in quadrature), where the report holds them: the statistical one (the log's noise,
    the latency, a misfit's widening) and the payload's, with the payload's standard deviations it carries."""
    if out.get("S_std_payload") is None or out.get("S_std_statistical") is None:      # a method without S_std
        return
    model = next(m for m in find_model(every=True) if m.name == kind)
    sd = out["payload_std"]
    groups = [(("mass",), "kg"), (model.payload_position_names, "m"), (model.inertia_names, "kg m^2"),
              (("gravity",), "m/s^2")]
    stds = "; ".join(f"{' '.join(names)} {' '.join(f'{sd[n]:.2g}' for n in names)} {unit}" for names, unit in groups
                     if all(n in sd for n in names))
    print(f"S_std: its statistical part and the payload's, in quadrature; the payload's one sigma: {stds}")
    for title, key in (("statistical part (the log's noise, the latency, a misfit)", "S_std_statistical"),
                       ("the payload's part", "S_std_payload")):
        values = np.array([[np.inf if v is None else v for v in row] for row in out[key]], dtype=float)
        print(f"  S_std, {title}:")
        for row in values:
            print("    " + "  ".join(f"{v:.0e}" for v in row))


def latency_line(out):
    """The report's line of the pose stream's latency: ms, with its std where estimated."""
    std = f" +- {out['latency_std'] * 1e3:.2g}" if out.get("latency_std") is not None else ""
    return f"pose latency: {out['latency'] * 1e3:.3g}{std} ms ({'estimated' if out['latency_estimated'] else 'given'})"
