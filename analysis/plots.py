"""Figures: entries of S_hat against time (the paper's Figs. 2-4)."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .metrics import display_name  # noqa: E402
from plant.files import atomic_write  # noqa: E402

__all__ = ["plot_S_entries", "plot_error_histories"]


def plot_S_entries(results, truth, path, title):
    """Plot the nine entries of ``S_hat`` against time, one panel each.

    Parameters
    ----------
    results : list of observers.ObserverResult
    truth : plant.Truth or None
        Its true ``S(t)`` is drawn dashed, where given.
    path : str or Path
        PNG file to write.
    title : str
    """
    fig, axes = plt.subplots(3, 3, figsize=(11, 7.5), sharex=True)
    t_all = max((r.t for r in results), key=len)
    step = max(1, len(t_all) // 2000)
    S_true = None if truth is None else truth.S_at(t_all[::step])
    for i in range(3):
        for j in range(3):
            ax = axes[i, j]
            for r in results:
                ax.plot(r.t[::step], r.S_hat_history[::step, i, j], lw=1, label=display_name(r.observer))
            ax.set_title(f"s_{i + 1}{j + 1}", fontsize=9)
            if S_true is not None:
                ax.plot(t_all[::step], S_true[:, i, j], "k--", lw=1, label="true")
                lo, hi = np.min(S_true[:, i, j]), np.max(S_true[:, i, j])
                ax.set_ylim(lo - 1.0, hi + 1.0)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    try:
        atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=90))
    finally:
        plt.close(fig)


def plot_error_histories(curves, path, title):
    """E against time, log scale, one line per observer.

    Parameters
    ----------
    curves : dict
        ``{observer name: (t, E)}`` with ``t`` in s.
    path : str or Path
        PNG file to write.
    title : str
    """
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for name, (t, E) in curves.items():
        ax.semilogy(t, np.maximum(E, 1e-12), lw=1, label=display_name(name))
    ax.set_xlabel("t [s]")
    ax.set_ylabel("E = ||I - S_hat S^-1||_2")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    try:
        atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110))
    finally:
        plt.close(fig)
