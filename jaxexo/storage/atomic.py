"""Atomic file writes: a file is either its old content or its complete new content, never a torn mix.

The data goes to a temporary file beside the target, is flushed to disk (fsync), and replaces the
target by a rename (atomic on POSIX within one filesystem). If anything fails (a full disk, a file-size
limit, an interrupt) the temporary file is removed and the target is untouched; the OSError raised
names the target file.
"""

from __future__ import annotations

import os
from pathlib import Path


def atomic_write(path: str | Path, data: bytes | str) -> Path:
    """Replace ``path`` with ``data`` (str is written as UTF-8) in one step."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    try:
        with open(tmp, "wb") as f:
            f.write(raw)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as e:
        try:
            tmp.unlink()
        except OSError:
            pass
        if isinstance(e, OSError) and e.filename is None:
            # write() errors (ENOSPC, EFBIG) carry no file name: name the file being written.
            raise OSError(e.errno, f"could not write {path}: {e.strerror}") from None
        raise
    return path


def append_line(path: str | Path, text: str) -> None:
    """Append ``text`` (one or more whole lines) and flush it to disk; an OSError names the file.

    A failed append can leave a torn last line: readers of append-only logs must drop lines past the
    last checkpoint (jaxexo.train.driver does)."""
    path = Path(path)
    try:
        with open(path, "a", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
    except OSError as e:
        if e.filename is None:
            raise OSError(e.errno, f"could not append to {path}: {e.strerror}") from None
        raise
