"""Figures a person reads: E against time beside the entries of S_hat, and a calibration's fit.

Every figure is drawn on its own :class:`matplotlib.figure.Figure` and
written with the Agg renderer; importing this module does not touch
matplotlib's backend (a notebook's inline backend stays as it is).

Legends sit outside the axes, never over a curve. A method whose estimate
wanders far from the others (the paper's literal configuration under noise)
does not set the scale: the y-limits come from the well-behaved methods, the
wandering curve is clipped at the frame, and the title says which method was
clipped. A method that does not wander but ends far above the best one (the
high-gain observer of [4] as the seed paper describes it, whose estimate
chatters about the truth) is drawn thin, lighter and behind the others, so
that its noisy trace does not hide theirs.
"""

import numpy as np

from fmscal.plant.io import atomic_write
from fmscal.plant.physics import PAPER_PAYLOAD, PlanarModel

from fmscal.observers import method_label

from ._metrics import error_history

__all__ = ["plot_S_entries", "plot_error_histories", "plot_comparison", "plot_calibration", "thinned",
           "wandering_methods"]

_MAX_POINTS = 2000        # points drawn per curve
#: A method whose median E over the second half of the run exceeds this factor times the
#: methods' median (and 0.1) wanders: it is clipped rather than setting the scale.
WANDER_FACTOR = 10.0
#: A method (not clipped) whose median E over the second half of the run exceeds this factor
#: times the best method's is drawn thin, lighter and behind the others.
_BEHIND_FACTOR = 5.0


def _figure(figsize):
    from matplotlib.figure import Figure          # heavy: only a figure needs it, not the CLI's start
    return Figure(figsize=figsize)


def _save(fig, path, dpi=100):
    """Write the figure as PNG, atomically (a failed write leaves no half file)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg        # heavy (as in _figure)
    FigureCanvasAgg(fig)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=dpi, bbox_inches="tight", format="png"))


def _thin(n):
    return max(1, n // _MAX_POINTS)


def thinned(t, E, S_hat_history):
    """A run's curves decimated as :func:`plot_comparison` draws them (about 2000 points).

    Parameters
    ----------
    t, E : ndarray, shape (N,)
    S_hat_history : ndarray, shape (N, 3, 3)

    Returns
    -------
    tuple of ndarray
        ``(t, E, S_hat_history)``, every ``k``-th sample; drawn again they are not thinned further
        (:func:`wandering_methods` then judges the thinned ``E``: a median over the same curve's
        points, equal to the full one's to within the curve's sample-to-sample spread).
    """
    k = _thin(len(t))
    return np.asarray(t)[::k], np.asarray(E)[::k], np.asarray(S_hat_history)[::k]


def wandering_methods(E_curves):
    """Methods whose E wanders far above the others'.

    Parameters
    ----------
    E_curves : dict
        ``{method: E}``, each ``E`` an array over time (eq. 16).

    Returns
    -------
    set of str
        Methods whose median E over the second half of the run exceeds
        :data:`WANDER_FACTOR` times the median of the methods' medians, and 0.1.
    """
    late = {name: float(np.nanmedian(E[len(E) // 2:])) if len(E) else np.inf for name, E in E_curves.items()}
    finite = [v for v in late.values() if np.isfinite(v)]
    if not finite:
        return set()
    reference = float(np.median(finite))
    return {name for name, v in late.items() if not np.isfinite(v) or (v > WANDER_FACTOR * reference and v > 0.1)}


def _clip_note(clipped):
    if not clipped:
        return ""
    names = ", ".join(method_label(n) for n in sorted(clipped))
    return f"\n({names} wanders far: drawn faded and clipped at the frame; the others set the scale)"


def _behind(E_curves, clipped):
    """Methods, not in ``clipped``, whose median E over the second half of the run exceeds
    :data:`_BEHIND_FACTOR` times the best method's: drawn behind the others (:func:`_style`)."""
    late = {name: float(np.nanmedian(E[len(E) // 2:])) if len(E) else np.inf for name, E in E_curves.items()}
    finite = [v for v in late.values() if np.isfinite(v) and v > 0]
    if not finite:
        return set()
    best = min(finite)
    return {name for name, v in late.items() if name not in clipped and np.isfinite(v) and v > _BEHIND_FACTOR * best}


def _style(name, clipped, behind=()):
    """A clipped method drawn thin and faded, under the others; a method far above the best (``behind``) thin and
    lighter, under the well-behaved ones, so that a noisy trace does not cover them."""
    if name in clipped:
        return {"lw": 0.6, "alpha": 0.45, "zorder": 1}
    if name in behind:
        return {"lw": 0.6, "alpha": 0.55, "zorder": 1.5}
    return {"lw": 1.0, "zorder": 2}


def _label(name, clipped):
    return method_label(name) + (" (clipped)" if name in clipped else "")


def _E_panel(ax, curves, clipped, behind=()):
    """E against time on a log scale, one line per method; limits from the unclipped ones."""
    kept = []
    for name, (t, E) in curves.items():
        E = np.maximum(np.asarray(E, dtype=float), 1e-12)
        ax.semilogy(t, E, label=_label(name, clipped), **_style(name, clipped, behind))
        if name not in clipped:
            kept.append(E)
    if kept:
        values = np.concatenate(kept)
        values = values[np.isfinite(values)]
        if len(values):
            ax.set_ylim(max(values.min() / 2, 1e-8), values.max() * 2)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("E = ||I - S_hat S^-1||_2")
    ax.grid(True, which="both", alpha=0.3)


def _S_limits(histories, S_true, clipped, i, j, bands=None):
    """y-limits of entry (i, j): the well-behaved methods' 1st-99th percentiles and the truth, padded.

    With ``bands`` (a calibration's figure) only the second half of each
    history counts, and three sigma about the final estimate: the start's
    transient is clipped so that the band and the settled estimate are seen.
    """
    parts = [h[len(h) // 2 if bands else 0:, i, j] for name, h in histories.items() if name not in clipped]
    values = np.concatenate(parts) if parts else np.zeros(0)
    values = values[np.isfinite(values)]
    extremes = [] if S_true is None else [S_true[:, i, j].min(), S_true[:, i, j].max()]
    for name, sd in (bands or {}).items():
        if sd is not None and name in histories:
            extremes += [histories[name][-1, i, j] - 3 * sd[i][j], histories[name][-1, i, j] + 3 * sd[i][j]]
    extremes = [v for v in extremes if np.isfinite(v)]
    if not len(values) and not extremes:
        return None
    lo, hi = np.percentile(values, [1, 99]) if len(values) else (np.inf, -np.inf)
    lo, hi = min([lo, *extremes]), max([hi, *extremes])
    pad = max(0.15 * (hi - lo), 0.05 if not bands else 1e-6 + 1e-3 * abs(hi))
    return lo - pad, hi + pad


def _S_panels(fig, spec, times, histories, S_true, t_true, clipped, bands=None, behind=()):
    """The entries of S_hat in an n x n block of ``spec`` (3 x 3 in the plane); returns the axes."""
    n = next(iter(histories.values())).shape[-1]
    axes = spec.subgridspec(n, n, hspace=0.35, wspace=0.3).subplots(sharex=True, squeeze=False)
    for i in range(n):
        for j in range(n):
            ax = axes[i, j]
            for name, h in histories.items():
                line, = ax.plot(times[name], h[:, i, j], label=_label(name, clipped),
                                **_style(name, clipped, behind))
                if bands is not None and bands.get(name) is not None:
                    centre, sd = h[-1, i, j], bands[name][i][j]
                    ax.axhspan(centre - sd, centre + sd, color=line.get_color(), alpha=0.25, lw=0,
                               label="final estimate +- one sigma" if (i, j) == (0, 0) else None)
            if S_true is not None:
                ax.plot(t_true, S_true[:, i, j], "k--", lw=1, label="true S" if (i, j) == (0, 0) else None)
            limits = _S_limits(histories, S_true, clipped, i, j, bands)
            if limits is not None:
                ax.set_ylim(*limits)
            ax.set_title(f"s_{i + 1}{j + 1}", fontsize=9)
            ax.tick_params(labelsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]", fontsize=8)
    return axes


def plot_comparison(runs, truth, path, title):
    """E against time for every method in one panel, beside the nine entries of ``S_hat``.

    Parameters
    ----------
    runs : dict
        ``{method: (t, E, S_hat_history)}``: ``t`` (N,) in s, ``E`` (N,) of
        eq. (16), ``S_hat_history`` (N, 3, 3).
    truth : plant.Truth or None
        Its ``S(t)`` is drawn dashed in the entries' panels.
    path : str or Path
        PNG file to write.
    title : str

    Returns
    -------
    set of str
        The methods clipped (:func:`wandering_methods`).
    """
    drawn = {name: thinned(*run) for name, run in runs.items()}
    curves = {name: (t, E) for name, (t, E, _) in drawn.items()}
    histories = {name: S for name, (_, _, S) in drawn.items()}
    clipped = wandering_methods({name: np.asarray(E) for name, (_, E, _) in runs.items()})
    behind = _behind({name: np.asarray(E) for name, (_, E, _) in runs.items()}, clipped)
    fig = _figure((15, 6.2))
    outer = fig.add_gridspec(1, 2, width_ratios=[1.0, 1.55], wspace=0.18)
    ax = fig.add_subplot(outer[0])
    _E_panel(ax, curves, clipped, behind)
    ax.set_title("E against time (log scale)", fontsize=10)
    t_true = max(curves.values(), key=lambda c: len(c[0]))[0]
    S_true = None if truth is None else truth.S_at(t_true)
    _S_panels(fig, outer[1], {n: c[0] for n, c in curves.items()}, histories, S_true, t_true, clipped,
              behind=behind)
    handles, labels = ax.get_legend_handles_labels()
    if S_true is not None:
        from matplotlib.lines import Line2D     # heavy (as in _figure)
        handles.append(Line2D([], [], color="k", ls="--", lw=1))
        labels.append("true S")
    fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=min(len(labels), 6),
               fontsize=9, frameon=False)
    fig.suptitle(title + _clip_note(clipped), fontsize=11)
    _save(fig, path)
    return clipped


def plot_error_histories(curves, path, title):
    """E against time, log scale, one line per method; the legend beside the axes.

    Parameters
    ----------
    curves : dict
        ``{method: (t, E)}`` or ``{method: (t, E, S_hat_history)}`` with
        ``t`` in s.
    path : str or Path
        PNG file to write.
    title : str

    Returns
    -------
    set of str
        The methods clipped (:func:`wandering_methods`).
    """
    curves = {name: (np.asarray(c[0]), np.asarray(c[1])) for name, c in curves.items()}
    clipped = wandering_methods({name: E for name, (_, E) in curves.items()})
    fig = _figure((9, 4.5))
    ax = fig.add_subplot()
    _E_panel(ax, curves, clipped, _behind({name: E for name, (_, E) in curves.items()}, clipped))
    ax.set_title(title + _clip_note(clipped), fontsize=10)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    _save(fig, path, dpi=110)
    return clipped


def plot_S_entries(results, truth, path, title):
    """The nine entries of ``S_hat`` against time, one panel each (the paper's Figs. 2-4).

    Parameters
    ----------
    results : list of observers.ObserverResult
    truth : plant.Truth or None
        Its true ``S(t)`` is drawn dashed, where given.
    path : str or Path
        PNG file to write.
    title : str
    """
    times = {r.observer: r.t[::_thin(len(r.t))] for r in results}
    histories = {r.observer: r.S_hat_history[::_thin(len(r.t))] for r in results}
    t_true = max(times.values(), key=len)
    S_true = None if truth is None else truth.S_at(t_true)
    if truth is not None:
        errors = {r.observer: error_history(r.S_hat_history[::_thin(len(r.t))], truth.S_at(times[r.observer]))
                  for r in results}
        clipped = wandering_methods(errors)
        behind = _behind(errors, clipped)
    else:
        clipped, behind = set(), set()
    fig = _figure((11, 7.5))
    axes = _S_panels(fig, fig.add_gridspec(1, 1)[0], times, histories, S_true, t_true, clipped, behind=behind)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=min(len(labels), 6),
               fontsize=9, frameon=False)
    fig.suptitle(title + _clip_note(clipped))
    _save(fig, path, dpi=90)


def plot_calibration(result, log, path, title, truth=None, model=None):
    """A calibration's figure: each entry of ``S_hat`` with its one-sigma band, and the pose residual.

    Parameters
    ----------
    result : observers.ObserverResult
        The run over ``log``; its final ``S_std`` (where the method gives
        one) is drawn as a band of one sigma about the final estimate.
    log : plant.Log
        The log the method ran on (with its poses moved back by the
        latency), so that ``result.x_hat_history`` lines up with its poses.
    path : str or Path
        PNG file to write.
    title : str
    truth : plant.Truth, optional
        Its ``S(t)`` is drawn dashed.
    model : plant.Model, optional
        The problem; default the planar model (a spatial run needs its
        model: the residual is the position's and the attitude's, a turn
        about the sensor's axes).
    """
    n = len(result.t)
    step = _thin(n)
    t = result.t[::step]
    n_w = result.S_hat.shape[0]
    fig = _figure((11, 9.5) if n_w <= 3 else (16, 15))
    outer = fig.add_gridspec(2, 1, height_ratios=[3.0 if n_w <= 3 else 5.0, 1.0], hspace=0.3)
    S_true = None if truth is None else truth.S_at(t)
    bands = {result.observer: result.S_std}
    axes = _S_panels(fig, outer[0], {result.observer: t}, {result.observer: result.S_hat_history[::step]},
                     S_true, t, set(), bands)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    has = log.has_pose[:n]
    panels = _pose_residuals(result, log, model, n)
    row = outer[1].subgridspec(1, len(panels), wspace=0.3).subplots(squeeze=False)[0]
    for ax, (name, unit, values) in zip(row, panels):
        for k in range(values.shape[1]):
            ax.plot(log.t[:n][has], values[:, k], ".", ms=1.5, color="tab:gray" if values.shape[1] == 1 else None)
        ax.set_title(f"pose residual {name} [{unit}] (rms {np.sqrt(np.mean(values ** 2)):.3g})", fontsize=9)
        ax.set_xlabel("t [s]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.3)
    if result.S_std is None:
        labels = [lab + " (no uncertainty from this method)" for lab in labels]
    fig.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=min(len(labels), 4),
               fontsize=9, frameon=False)
    fig.suptitle(title + "\n(each entry's scale: the second half of the run and three sigma; "
                 "the start's transient runs off it)", fontsize=11)
    _save(fig, path, dpi=90)


def _pose_residuals(result, log, model, n):
    """``[(name, unit, values (M, k))]``: the measured pose less the one the fit shows, at the pose samples."""
    has = log.has_pose[:n]
    model = PlanarModel(PAPER_PAYLOAD) if model is None else model      # the planar default (no payload is read)
    residual = model.pose_residuals(result.x_hat_history[:n][has], log.pose[:n][has]) * 1e3
    return [(name, unit, residual[:, list(columns)]) for name, unit, columns in model.residual_panels]
