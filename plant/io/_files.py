"""Writing files so that a failure never leaves a half-written or lost file.

Every file the toolkit writes goes to a temporary file in the destination's
folder first and then replaces the destination with :func:`os.replace` (atomic
on POSIX and Windows within one file system): a full disk or a crash leaves
the old file intact and at worst a stray temporary file, never a truncated one.

Inside :func:`exclusive` a write never replaces a file: the temporary file is
hard-linked to the final name, which fails if a file of that name appeared
while the work ran (another run, another program); ``fmscal`` writes so
unless ``--overwrite`` is given. :func:`claim_folder` makes a folder of
outputs one run's alone, and :func:`not_a_file` says what a path that is not a
regular file is (a symlink loop, a FIFO, a device).
"""

import contextlib
import contextvars
import errno
import os
import stat
import tempfile
from pathlib import Path

from fmscal.plant.numerics import FmscalError

__all__ = ["atomic_write", "atomic_write_text", "atomic_write_many", "exclusive", "claim_folder", "not_a_file",
           "not_an_output", "OutputExistsError", "LOCK_NAME"]

#: The file that marks a folder of outputs as claimed by one run (:func:`claim_folder`).
LOCK_NAME = ".fmscal.lock"
_EXCLUSIVE = contextvars.ContextVar("exclusive", default=False)


class OutputExistsError(FmscalError):
    """An output file appeared while the run worked, and it may not be replaced."""


@contextlib.contextmanager
def exclusive(on=True):
    """Inside this context (``on`` True), the writes of this module never replace an existing file.

    Parameters
    ----------
    on : bool
        False: writes replace files as usual (``--overwrite``).
    """
    token = _EXCLUSIVE.set(bool(on))
    try:
        yield
    finally:
        _EXCLUSIVE.reset(token)


def _kind(mode):
    """What a file of ``mode`` (``st_mode``) is, if not a regular file or a folder."""
    for test, what in ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return what
    return None if stat.S_ISREG(mode) or stat.S_ISDIR(mode) else "not a regular file"


def not_a_file(path, folder_ok=False):
    """Why ``path`` cannot be read as a regular file, in a few words, or None if it can.

    Parameters
    ----------
    path : str or Path
    folder_ok : bool
        A folder is acceptable (a ROS 2 bag).

    Returns
    -------
    str or None
        ``"no such file"``, ``"a symlink loop"``, ``"a link to a missing
        file"``, ``"a folder"``, ``"a FIFO (named pipe)"``, ``"a character
        device"`` (``/dev/null``), ... or None.
    """
    try:
        st = os.stat(path)
    except OSError as err:
        if err.errno == errno.ELOOP:
            return "a symlink loop"
        if err.errno == errno.ENOENT and os.path.islink(path):
            return "a link to a missing file"
        if err.errno in (errno.ENOENT, errno.ENOTDIR):
            return "no such file"
        return f"unreadable ({err.strerror or err})"
    if stat.S_ISDIR(st.st_mode):
        return None if folder_ok else "a folder"
    return _kind(st.st_mode)


def not_an_output(path):
    """Why ``path`` may not be written as a file even with ``--overwrite``, or None.

    A symlink loop, a link to a missing file (writing would replace the link),
    a folder, a FIFO or a device (``/dev/null``).
    """
    if not os.path.lexists(path):
        return None
    problem = not_a_file(path)
    return None if problem == "no such file" else problem


def _temporary(path):
    """A new empty temporary file beside ``path`` with the same suffix (writers infer formats from it)."""
    path = Path(path)
    try:
        fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix or ".tmp", dir=path.parent)
    except OSError as err:               # the error names the file asked for, not the temporary one
        raise OSError(err.errno, err.strerror, str(path)) from None
    os.close(fd)
    umask = os.umask(0)                  # mkstemp makes 0600: give the file the mode open() would
    os.umask(umask)
    os.chmod(name, 0o666 & ~umask)
    return Path(name)


def _place(tmp, path):
    """Move ``tmp`` to ``path``: replacing it, or inside :func:`exclusive` only where no file is."""
    if not _EXCLUSIVE.get():
        os.replace(tmp, path)
        return
    try:
        try:
            os.link(tmp, path)                # fails if the name exists, whatever made it meanwhile
        except OSError as err:                # no hard links here (some network or FAT file systems)
            if err.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK):
                raise
            os.close(os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY))     # claim the name, then fill it
            os.replace(tmp, path)
            return
    except FileExistsError:
        raise OutputExistsError(f"{path} appeared while this run worked; not replaced (add --overwrite to "
                                "replace it)") from None
    os.unlink(tmp)


def atomic_write_many(writers):
    """Write several files all-or-nothing (as far as the file system allows).

    Each writer writes its temporary file; only when every one has been
    written are the destinations replaced, in the order given (put the file
    that must never be alone last: ``simulate`` replaces the sidecar, then
    the log). If a replacement fails, the destinations already replaced by
    this call get their old content back (kept as a hard link beside them
    until every replacement is done), or are removed where there was none,
    so that no file is left without its companion and none is lost. Inside
    :func:`exclusive`, a destination that exists by then is not replaced:
    :class:`OutputExistsError`, and the files this call placed are removed.

    Parameters
    ----------
    writers : list of (path, callable)
        ``callable(tmp_path)`` writes the whole content to ``tmp_path``.

    Raises
    ------
    OSError
        From the writers or the file system; the temporary files are removed.
    OutputExistsError
        Inside :func:`exclusive`, a destination exists.
    """
    temps, done, backups = [], [], {}
    try:
        for path, write in writers:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            tmp = _temporary(path)
            temps.append(tmp)
            token = _EXCLUSIVE.set(False)      # the writer fills its own temporary file
            try:
                write(tmp)
            finally:
                _EXCLUSIVE.reset(token)
            with open(tmp, "rb+") as f:       # on disk before the rename
                os.fsync(f.fileno())
        for (path, _), tmp in zip(writers, temps):
            path = Path(path)
            if path.is_file() and not _EXCLUSIVE.get():     # the old content, until every file is in place
                backup = _temporary(path)
                backup.unlink()
                os.link(path, backup)
                backups[path] = backup
            _place(tmp, path)
            done.append(path)
    except BaseException:
        for tmp in temps:
            tmp.unlink(missing_ok=True)
        if len(done) < len(writers):
            for path in done:                 # no file without its companion, and none lost
                if path in backups:
                    os.replace(backups.pop(path), path)
                else:
                    path.unlink(missing_ok=True)
        raise
    finally:
        for backup in backups.values():
            backup.unlink(missing_ok=True)


def atomic_write(path, write):
    """Write one file atomically: ``write(tmp_path)`` fills a temporary file that then replaces ``path``."""
    atomic_write_many([(path, write)])


def atomic_write_text(path, text):
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    atomic_write(path, lambda tmp: Path(tmp).write_text(text, encoding="utf-8"))


@contextlib.contextmanager
def claim_folder(folder):
    """Make ``folder`` (created if need be) this run's alone while the context lasts.

    The claim is a file :data:`LOCK_NAME` in the folder, created exclusively
    and holding this process's id; a second run that tries to claim the
    folder meanwhile is refused. A claim left by a process that no longer
    runs (a crash) is taken over. On leaving, the claim is removed, and the
    folder too if this call created it and nothing was written into it.

    Parameters
    ----------
    folder : str or Path

    Raises
    ------
    FmscalError
        Another running process holds the folder.
    """
    folder = Path(folder)
    created = not folder.exists()
    folder.mkdir(parents=True, exist_ok=True)
    lock = folder / LOCK_NAME
    for attempt in range(2):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            break
        except FileExistsError:
            holder = _holder(lock)
            if attempt or holder is None or _running(holder):
                raise FmscalError(f"{folder} is in use by another fmscal run (process {holder or 'unknown'}); "
                                  f"wait for it, or remove {lock} if no run is going") from None
            lock.unlink(missing_ok=True)          # its process is gone: a stale claim
    with os.fdopen(fd, "w") as f:
        f.write(f"{os.getpid()}\n")
    try:
        yield folder
    finally:
        lock.unlink(missing_ok=True)
        if created:
            with contextlib.suppress(OSError):
                folder.rmdir()                    # only if empty


def _holder(lock):
    """The process id written in a claim file, or None."""
    try:
        text = lock.read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _running(pid):
    """True if a process ``pid`` runs on this machine (or cannot be checked)."""
    if os.name != "posix":                        # os.kill(pid, 0) would end the process on Windows
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True
