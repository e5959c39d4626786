"""The one atomic file write: every file a reader may load goes through ``atomic_write`` (a
temporary file in the target's directory, fsync'ed, then ``os.replace``), so an interrupted write
never leaves half a file; append-only logs go through ``append_line``; ``stale_temps`` finds what
a SIGKILL left. Modes, symbolic links and special outputs (``-``, devices, FIFOs):
docs/reliability.md.
"""

from __future__ import annotations

import errno
import io
import os
import stat
import sys
import tempfile
from pathlib import Path

STDOUT = "-"  # an output named "-" is standard output


def _temp_prefix(path: Path) -> str:
    return f".{path.name}."


TEMP_SUFFIX = ".tmp"


class SymlinkRefused(ValueError):
    """A file jaxexo would write through a symbolic link it did not create."""


def _named(e: OSError, path: Path, what: str) -> OSError:
    # write() errors (ENOSPC, EFBIG) carry no file name: name the file being written.
    return OSError(e.errno, f"could not {what} {path}: {e.strerror}") if e.filename is None else e


def _fd_link(path: Path) -> bool:
    """Whether ``path`` is a symbolic link whose chain passes through /dev or /proc (``/dev/stdout``,
    ``/proc/self/fd/1``, a link to either): it names an open file descriptor, not a file to replace."""
    p = str(path)
    for _ in range(40):
        if not os.path.islink(p):
            return False
        target = os.readlink(p)
        p = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(p)), target))
        if p.startswith(("/dev/", "/proc/")):
            return True
    return False


def direct_output(path: str | Path) -> bool:
    """Whether an output is written into directly rather than replaced (module note): ``-``, an
    existing non-regular file other than a folder, or a link to a file descriptor."""
    if str(path) == STDOUT:
        return True
    try:
        mode = os.stat(path).st_mode  # follows links: a link to a FIFO is a FIFO
    except OSError:
        return False
    return (not stat.S_ISREG(mode) and not stat.S_ISDIR(mode)) or _fd_link(Path(path))


def writes_to_stdout(path: str | Path | None) -> bool:
    """Whether an output goes to this process's standard output (``-``, /dev/stdout, a link to fd 1):
    a command then prints its messages to standard error instead."""
    if path is None:
        return False
    if str(path) == STDOUT:
        return True
    try:
        a, b = os.stat(path), os.fstat(1)
    except OSError:
        return False
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino) and direct_output(path)


def _write_direct(path: str | Path, payload: bytes) -> None:
    if str(path) == STDOUT:
        out = sys.stdout.buffer
        out.write(payload)
        out.flush()
        return
    path = Path(path)
    try:
        regular = stat.S_ISREG(os.stat(path).st_mode)  # a descriptor link to a regular file
        fd = os.open(
            path, os.O_WRONLY | (os.O_TRUNC if regular else 0) | getattr(os, "O_CLOEXEC", 0)
        )
    except OSError as e:
        raise _named(e, path, "write") from None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(payload)
    except OSError as e:
        raise _named(e, path, "write") from None


def _umask() -> int:
    """The process's umask, read without changing it where Linux shows it (/proc/self/status)."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _output_mode(path: Path) -> int:
    """The mode a written file gets: an existing regular file's own, else 0666 & ~umask (what Unix
    tools create; mkstemp's temporary file is 0600 until set)."""
    try:
        st = os.lstat(path)
        if stat.S_ISREG(st.st_mode):
            return stat.S_IMODE(st.st_mode)
    except OSError:
        pass
    return 0o666 & ~_umask()


def atomic_write(path: str | Path, data: bytes | str) -> Path:
    """Write ``data`` (str: UTF-8) to ``path`` atomically, creating its directory; returns the path.
    A special output (``-``, a device, a FIFO, a descriptor link) is written into directly."""
    payload = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    if direct_output(path):
        _write_direct(path, payload)
        return Path(path)
    path = Path(path)
    if path.is_dir():
        # A folder, or a link to one: never replaced by a file (the CLI refuses it up front).
        raise IsADirectoryError(errno.EISDIR, f"could not write {path}: it is a directory")
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=_temp_prefix(path), suffix=TEMP_SUFFIX)
    except OSError as e:
        raise _as_target(e, path) from None
    try:
        with os.fdopen(fd, "wb") as f:
            os.fchmod(f.fileno(), _output_mode(path))
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
            raise _as_target(e, path) from None
        raise
    return path


def _as_target(e: OSError, path: Path) -> OSError:
    """An error of atomic_write named by the file asked for: the temporary file is an internal
    name (``os.replace`` onto a folder said "Is a directory: '.adir.x1y2.tmp' -> 'adir'")."""
    if e.filename is not None and not Path(e.filename).name.startswith(_temp_prefix(path)):
        return e
    return OSError(e.errno, f"could not write {path}: {e.strerror}")


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
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW, 0o666)
    except OSError as e:
        if path.is_symlink():
            raise SymlinkRefused(
                f"{path} is a symbolic link; jaxexo writes no file through a link it did not "
                "make: remove the link"
            ) from None
        raise _named(e, path, "append to") from None
    try:
        with os.fdopen(fd, "a", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
    except OSError as e:
        raise _named(e, path, "append to") from None


def write_figure(path: str | Path, fig, dpi: int = 110) -> Path:
    """A matplotlib figure written by ``atomic_write`` (so by the special-output rule too), in the
    format its name's suffix gives (PNG for no suffix, ``-`` and special outputs of another suffix)."""
    suffix = Path(str(path)).suffix.lstrip(".").lower()
    supported = fig.canvas.get_supported_filetypes()
    fmt = (
        suffix if suffix in supported else ("png" if not suffix or direct_output(path) else suffix)
    )
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=dpi)
    return atomic_write(path, buf.getvalue())
