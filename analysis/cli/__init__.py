"""The ``fmscal`` command line: a thin printer of the library's calls.

``main(argv)`` runs one command and returns its exit code; ``console`` is the
installed ``fmscal`` script; ``python -m fmscal.analysis.cli`` runs it too.
"""

from ._main import build_parser, console, main

__all__ = ["main", "console", "build_parser"]
