"""Run directories (``jaxexo train``, ``jaxexo sweep``): one writer at a time (``run_lock``, an
exclusive flock the OS releases when its holder dies), no mixing of runs (``contents``), and
``TrainingDiverged``, defined here without JAX so that the CLI can catch it (docs/reliability.md).
"""

from __future__ import annotations

import contextlib
import os
import stat
from pathlib import Path

from jaxexo.config import ConfigError

LOCK_NAME = ".jaxexo.lock"


class RunDirError(ConfigError):
    """A run directory (the --out option) that is in use, or cannot hold a new run."""


class TrainingDiverged(RuntimeError):
    """The loss or the parameters became NaN or infinite (the message says where, and what was kept)."""


def blocking_file(folder: str | Path) -> Path | None:
    """The nearest existing ancestor of ``folder`` (itself included) when it is a file, not a folder:
    nothing can be written below it (``afile/t.csv``). None when the path can be created."""
    q = Path(folder)
    while not q.exists() and q != q.parent:
        q = q.parent
    return q if q.exists() and not q.is_dir() else None


def contents(directory: Path) -> list[str]:
    """Names in ``directory`` other than the lock file, sorted (empty if it does not exist)."""
    directory = Path(directory)
    if not directory.is_dir():
        return []
    return sorted(p.name for p in directory.iterdir() if p.name != LOCK_NAME)


def describe(names: list[str], limit: int = 6) -> str:
    shown = ", ".join(names[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")


def _missing_folders(directory: Path) -> list[Path]:
    """``directory`` and its ancestors that do not exist yet, innermost first."""
    out, q = [], directory
    while not q.exists() and q != q.parent:
        out.append(q)
        q = q.parent
    return out


def _undo(made: list[Path], scratch: tuple[str, ...]) -> None:
    """Remove a run directory this process made when it holds nothing but its lock and ``scratch``
    files: no half-made folder is left to refuse the next attempt. Anything else in it is kept."""
    directory = made[0]
    names = contents(directory)
    if not set(names) <= set(scratch):
        return
    for name in [*names, LOCK_NAME]:
        p = directory / name
        if p.is_file() and not p.is_symlink():
            p.unlink()
    for d in made:
        try:
            d.rmdir()
        except OSError:
            return


@contextlib.contextmanager
def run_lock(directory: str | Path, what: str, create: bool = True, scratch: tuple[str, ...] = ()):
    """Hold the exclusive lock of ``directory`` while the block runs. ``create``: make the directory if
    it is absent (a new run); else (a resume) its absence is an error. When this call made the
    directory and the block refuses its input (a ValueError: a bad seed, config or checkpoint), the
    directory is removed again if it holds only ``scratch`` files. A failed write or an interrupt
    keeps it (docs/reliability.md: a run stopped before its first checkpoint is resumed)."""
    directory = Path(directory)
    made = _missing_folders(directory) if create else []
    try:
        with _locked(directory, what, create):
            yield directory
    except ValueError:
        if made:
            _undo(made, scratch)
        raise


@contextlib.contextmanager
def _locked(directory: Path, what: str, create: bool):
    import fcntl

    if directory.exists() and not directory.is_dir():
        raise RunDirError(f"--out: {directory} is a file, not a directory")
    if not create and not directory.is_dir():
        missing = "no sweep to resume" if what == "sweep" else "no checkpoint to resume from"
        raise RunDirError(f"--resume: {directory} does not exist: {missing}")
    q = blocking_file(directory.parent)
    if q is not None:
        raise RunDirError(f"--out: {q} is a file, not a folder (for {directory})")
    lock = directory / LOCK_NAME
    try:
        directory.mkdir(parents=True, exist_ok=True)
        # O_NOFOLLOW: a symbolic link planted at the lock's name is never followed (the pid line
        # would overwrite whatever file it points to).
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
    except OSError as e:
        if lock.is_symlink():
            raise RunDirError(
                f"--out: {lock} is a symbolic link; jaxexo writes no file through a link it did "
                "not make: remove the link"
            ) from None
        raise RunDirError(
            f"--out: cannot use {directory} as a run directory ({e.strerror})"
        ) from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise RunDirError(f"--out: {lock} is not a regular file; remove it")
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 200, 0).decode(errors="replace").strip() or "unknown"
            raise RunDirError(
                f"--out: {directory} is in use by another jaxexo process ({holder}); wait for "
                "it to finish (or stop it) and pass --resume, or pick another directory"
            ) from None
        # Who holds it, for the message above (informational: the flock is the lock).
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()}, jaxexo {what}\n".encode(), 0)
        yield directory
    finally:
        os.close(fd)  # releases the flock
