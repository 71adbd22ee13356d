"""A progress bar for long runs: a method over a long log (the EKF, the compiled observers, the floor).

:func:`progress_bar` is a :class:`tqdm.tqdm` on stderr that shows itself only
where it helps: when the run is long (at least :data:`MIN_SAMPLES` samples),
stderr is a terminal, and the caller has not asked for machine-readable
output. Anywhere else it is a silent object with the same methods, so a
loop calls ``bar.update(n)`` unconditionally.
"""

import sys

from tqdm import tqdm

__all__ = ["progress_bar", "MIN_SAMPLES", "EVERY"]

#: Logs shorter than this (samples) run in a few seconds: no bar.
MIN_SAMPLES = 200_000
#: A loop over samples should update the bar every this many samples (cheap beside the work).
EVERY = 10_000


def progress_bar(total, desc, enabled=True, stream=None, min_samples=MIN_SAMPLES):
    """A progress bar over ``total`` samples, or a silent one.

    Parameters
    ----------
    total : int
        Samples the run will process.
    desc : str
        What runs (``"ekf"``, ``"least squares"``).
    enabled : bool
        False for ``--json`` or a library caller that wants silence.
    stream : file, optional
        Where the bar goes; default ``sys.stderr``.
    min_samples : int
        Shorter runs get no bar.

    Returns
    -------
    tqdm.tqdm
        Use as a context manager, call ``update(n)`` every :data:`EVERY`
        samples or so; disabled bars cost nothing.

    Examples
    --------
    >>> from fmscal.observers.core import EVERY, progress_bar
    >>> samples = 25_000
    >>> with progress_bar(samples, "ekf") as bar:       # on a terminal, a bar; here, silent
    ...     for k in range(samples):
    ...         if k % EVERY == 0:
    ...             _ = bar.update(min(EVERY, samples - bar.n))
    >>> bar.disable                     # not a terminal: no bar, and it costs nothing
    True
    """
    stream = sys.stderr if stream is None else stream
    show = bool(enabled) and total >= min_samples and getattr(stream, "isatty", lambda: False)()
    return tqdm(total=int(total), desc=desc, unit="sample", unit_scale=True, file=stream, disable=not show,
                leave=False, mininterval=0.5)
