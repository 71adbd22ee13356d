"""What every ``fmscal`` command checks about its files before it starts the work.

A missing input is named first, before any other check of the command's options or files
(:func:`check_inputs`): a user who mistyped a file's name is told so, not about an option that
depends on what the file would have held. An output may not be one of the command's inputs (``fmscal apply LOG --out
LOG`` would replace the raw readings), may not replace an existing file
unless ``--overwrite`` is given, and must go to a folder that exists or can
be created and that is writable. Every check runs before any computation, so
a refusal costs nothing and leaves every file as it was. The writing itself is
atomic, and without ``--overwrite`` never replaces a file that appeared while
the command worked (:mod:`plant.io._files`).
"""

import os
from pathlib import Path

from fmscal.plant.io import (atomic_write, atomic_write_many, atomic_write_text, claim_folder, exclusive, not_a_file,
                             not_an_output)

from ._common import CliError

__all__ = ["check_inputs", "check_outputs", "check_output_dir", "same_file", "atomic_write", "atomic_write_many",
           "atomic_write_text", "claim_folder", "exclusive"]


def same_file(a, b):
    """True if paths ``a`` and ``b`` name the same file (links and ``..`` resolved)."""
    try:
        return os.path.samefile(a, b)
    except OSError:                       # one is missing, or a symlink loop: compare the names
        return os.path.realpath(a) == os.path.realpath(b)


def _writable_folder(folder, label):
    """Raise unless ``folder`` exists and is writable, or could be created (its nearest existing ancestor is)."""
    folder = Path(folder).absolute()
    probe = folder
    while not_a_file(probe, folder_ok=True) in ("no such file", "a link to a missing file"):
        probe = probe.parent
    problem = not_a_file(probe, folder_ok=True)
    if problem not in (None, "a folder"):
        raise CliError(f"{label}: {probe} is {problem}, not a folder")
    if not probe.is_dir():
        raise CliError(f"{label}: {probe} is a file, not a folder")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise CliError(f"{label}: cannot write in {probe} (permission denied)")


def check_inputs(inputs, folder_ok=()):
    """Refuse a missing input file, naming it and what it is: the first check a command makes.

    Parameters
    ----------
    inputs : sequence of (str or Path, str)
        Each input file and what it is (``"the log"``); None entries are skipped.
    folder_ok : sequence of str
        The ``what`` of inputs that may be folders (a ROS 2 bag).

    Raises
    ------
    CliError
        ``"<path>: no such file (<what>)"``, or a link to a missing file. Any other problem of the file
        (a folder, a FIFO, its contents) is left to the reader that reads it.
    """
    for path, what in inputs:
        if path is None:
            continue
        problem = not_a_file(path, folder_ok=what in folder_ok)
        if problem in ("no such file", "a link to a missing file"):
            kind = "file or folder" if what in folder_ok else "file"
            raise CliError(f"{path}: {'no such ' + kind if problem == 'no such file' else problem} ({what})")


def check_outputs(outputs, inputs=(), overwrite=False):
    """Refuse outputs that are inputs, that exist (without ``overwrite``), or that cannot be written.

    Parameters
    ----------
    outputs : sequence of (str or Path, str)
        Each output file and the option that named it (``"--save"``).
    inputs : sequence of (str or Path, str)
        Each input file and what it is (``"the log"``); None entries are skipped.
    overwrite : bool
        Allow replacing existing outputs (never inputs).

    Raises
    ------
    CliError
        One line naming the output and the problem.
    """
    inputs = [(p, what) for p, what in inputs if p is not None]
    seen = []
    for path, option in outputs:
        if path is None:
            continue
        path = Path(path)
        for source, what in inputs:
            if same_file(path, source):
                raise CliError(f"{option} {path} is {what}, an input; choose another file")
        for other, other_option in seen:
            if same_file(path, other):
                raise CliError(f"{option} {path} is also {other_option}; choose two different files")
        seen.append((path, option))
        problem = not_an_output(path)
        if problem is not None and problem != "a folder":
            raise CliError(f"{option} {path} is {problem}; remove it or choose another name")
        if path.is_dir():
            raise CliError(f"{option} {path} is a folder; give a file name")
        if path.exists() and not overwrite:
            raise CliError(f"{option} {path} exists; add --overwrite to replace it")
        if path.exists() and not os.access(path, os.W_OK):
            raise CliError(f"{option} {path}: cannot replace it (permission denied)")
        _writable_folder(path.parent, option)


def check_output_dir(folder, names, option="--out", inputs=(), overwrite=False):
    """Like :func:`check_outputs` for a folder that will receive the files ``names``."""
    folder = Path(folder)
    problem = not_an_output(folder)
    if problem not in (None, "a folder"):
        raise CliError(f"{option} {folder} is {problem}, not a folder")
    if folder.exists() and not folder.is_dir():
        raise CliError(f"{option} {folder} is a file, not a folder")
    _writable_folder(folder, option)
    check_outputs([(folder / name, f"{option} {folder}:") for name in names], inputs, overwrite)
