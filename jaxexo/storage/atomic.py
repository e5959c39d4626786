"""The one atomic file write: every file jaxexo writes that a reader may load (checkpoints, the policy,
sweep results, trajectory exports) goes through ``atomic_write``, so that an interrupted write never
leaves half a file in place of a good one; append-only logs go through ``append_line``.

The data goes to a temporary file in the target's own directory (``os.replace`` is atomic only within
one file system; ``tempfile.mkstemp`` gives every writer its own name), is flushed and fsync'ed, then
replaces the target. On any failure (a full disk, a file-size limit, KeyboardInterrupt) the temporary
file is removed and the target is left as it was; an OSError raised names the target file. Only a
SIGKILL can leave a temporary file behind: ``stale_temps`` finds those for a run's resume to remove.

Symbolic links: ``atomic_write`` replaces a link at the target's name (the file it points to is never
written); ``append_line`` opens with O_NOFOLLOW and refuses a link (SymlinkRefused, a ValueError).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def _temp_prefix(path: Path) -> str:
    return f".{path.name}."


TEMP_SUFFIX = ".tmp"


class SymlinkRefused(ValueError):
    """A file jaxexo would write through a symbolic link it did not create."""


def _named(e: OSError, path: Path, what: str) -> OSError:
    # write() errors (ENOSPC, EFBIG) carry no file name: name the file being written.
    return OSError(e.errno, f"could not {what} {path}: {e.strerror}") if e.filename is None else e


def atomic_write(path: str | Path, data: bytes | str) -> Path:
    """Write ``data`` (str: UTF-8) to ``path`` atomically, creating its directory; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=_temp_prefix(path), suffix=TEMP_SUFFIX)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(payload)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as e:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        if isinstance(e, OSError):
            raise _named(e, path, "write") from None
        raise
    return path


def stale_temps(path: str | Path) -> list[Path]:
    """Temporary files that a killed ``atomic_write`` of ``path`` left behind."""
    path = Path(path)
    if not path.parent.is_dir():
        return []
    return sorted(path.parent.glob(f"{_temp_prefix(path)}*{TEMP_SUFFIX}"))


def append_line(path: str | Path, text: str) -> None:
    """Append ``text`` (one or more whole lines) and flush it to disk; an OSError names the file.

    A failed append can leave a torn last line: readers of append-only logs must drop lines past the
    last checkpoint (jaxexo.train.driver does)."""
    path = Path(path)
    try:
        # O_NOFOLLOW: a log replaced by a symbolic link is never appended to through it.
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW, 0o644)
    except OSError as e:
        if path.is_symlink():
            raise SymlinkRefused(f"{path} is a symbolic link; jaxexo writes no file through a link it did not "
                                 "make: remove the link") from None
        raise _named(e, path, "append to") from None
    try:
        with os.fdopen(fd, "a", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
    except OSError as e:
        raise _named(e, path, "append to") from None
