"""The one atomic file write: every file jaxexo writes that a reader may load (checkpoints, the policy,
sweep results, trajectory exports) goes through ``atomic_write``, so that an interrupted write never
leaves half a file in place of a good one.

The data goes to a temporary file in the target's own directory (``os.replace`` is atomic only within
one file system), is flushed and fsync'ed, then replaces the target; on any failure (including
KeyboardInterrupt) the temporary file is removed and the target is left as it was.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def atomic_write(path: str | Path, data: bytes | str) -> Path:
    """Write ``data`` (str: UTF-8) to ``path`` atomically, creating its directory; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(payload)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path
