"""``python -m fmscal.analysis.cli``: the ``fmscal`` command line."""

from ._main import console

console()
