"""Writing files so that a failure never leaves a half-written or lost file.

Every file the toolkit writes goes to a temporary file in the destination's
folder first and then replaces the destination with :func:`os.replace` (atomic
on POSIX and Windows within one file system): a full disk or a crash leaves
the old file intact and at worst a stray temporary file, never a truncated one.
"""

import os
import tempfile
from pathlib import Path

__all__ = ["atomic_write", "atomic_write_text", "atomic_write_many"]


def _temporary(path):
    """A new empty temporary file beside ``path`` with the same suffix (writers infer formats from it)."""
    path = Path(path)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix or ".tmp", dir=path.parent)
    os.close(fd)
    umask = os.umask(0)                  # mkstemp makes 0600: give the file the mode open() would
    os.umask(umask)
    os.chmod(name, 0o666 & ~umask)
    return Path(name)


def atomic_write_many(writers):
    """Write several files all-or-nothing (as far as the file system allows).

    Each writer writes its temporary file; only when every one has been
    written are the destinations replaced, in the order given (put the file
    that must never be alone last: ``simulate`` replaces the sidecar, then
    the log). If a replacement fails, the destinations already replaced by
    this call get their old content back (kept as a hard link beside them
    until every replacement is done), or are removed where there was none,
    so that no file is left without its companion and none is lost.

    Parameters
    ----------
    writers : list of (path, callable)
        ``callable(tmp_path)`` writes the whole content to ``tmp_path``.

    Raises
    ------
    OSError
        From the writers or the file system; the temporary files are removed.
    """
    temps, done, backups = [], [], {}
    try:
        for path, write in writers:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            tmp = _temporary(path)
            temps.append(tmp)
            write(tmp)
            with open(tmp, "rb+") as f:       # on disk before the rename
                os.fsync(f.fileno())
        for (path, _), tmp in zip(writers, temps):
            path = Path(path)
            if path.is_file():                # the old content, until every file is in place
                backup = _temporary(path)
                backup.unlink()
                os.link(path, backup)
                backups[path] = backup
            os.replace(tmp, path)
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
