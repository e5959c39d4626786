"""The one read of an input file (a config, a sweep file, a policy, a checkpoint, a run's own files):
regular files only, up to a size cap, judged by ``fstat`` of the descriptor it reads, opened with
O_NONBLOCK so that a FIFO never waits; ``follow_links=False`` refuses a link in place of a run's own
file. The rules: docs/reliability.md. NumPy-free.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from jaxexo.config.checks import ConfigError

MiB = 2**20
# Caps, in bytes. A config or sweep file is a few kB (the largest shipped one is under 4 kB);
# a policy of the default network is about 100 kB; a run's metrics log grows by ~0.5 kB a chunk.
MAX_TEXT_BYTES = 16 * MiB  # TOML: configs, sweep files, a run's config.toml
MAX_POLICY_BYTES = 1024 * MiB  # policy.npz
MAX_LOG_BYTES = 1024 * MiB  # metrics.jsonl, checkpoint.json
MAX_CHECKPOINT_BYTES = 64 * 1024 * MiB


class InputFileError(ConfigError):
    """An input that is not a regular file, too large, or cannot be read; names the file and the rule.
    ``reason`` is the message without the file's name."""

    def __init__(self, path, reason: str):
        super().__init__(f"{path}: {reason}")
        self.path, self.reason = path, reason


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def check_path_type(path, what: str) -> Path:
    """``path`` as a Path when it is a str or os.PathLike; TypeError naming ``what`` otherwise (bytes,
    an open file, None: a file is named by its path). An empty path (Path("") is the current folder)
    or one with a NUL byte (no file system takes it) is a ConfigError naming ``what``."""
    if isinstance(path, (bytes, bytearray)) or not isinstance(path, (str, os.PathLike)):
        raise TypeError(
            f"{what}: expected a file's path (str or os.PathLike), got {type(path).__name__} (an open "
            "file or the file's bytes are not read: name the file)"
        )
    text = os.fspath(path)
    if isinstance(text, bytes):
        raise TypeError(f"{what}: expected a file's path as text, got bytes {text!r}")
    if not text:
        raise ConfigError(f"{what}: the path is empty; name a file")
    if "\0" in text:
        raise ConfigError(f"{what}: {text!r} contains a NUL byte, which no file's name can hold")
    return Path(path)


def read_input(path, what: str, cap: int, follow_links: bool = True) -> bytes:
    """The bytes of the regular file ``path`` (at most ``cap`` bytes). ``what`` names the file's role
    in messages ("config", "policy file"). InputFileError otherwise: missing, a folder, a FIFO, a
    device, a socket, a link loop, a link where ``follow_links`` is False, larger than ``cap``."""
    path = check_path_type(path, what)
    flags = os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
    if not follow_links:
        flags |= os.O_NOFOLLOW
    try:
        fd = os.open(path, flags)
    except OSError as e:
        if e.errno == errno.ENOENT:
            raise InputFileError(path, f"cannot read {what}: no such {what}") from None
        if e.errno == errno.ELOOP:
            if not follow_links and path.is_symlink():
                raise InputFileError(
                    path,
                    f"is a symbolic link; jaxexo reads no {what} through a link it did "
                    "not make: remove the link",
                ) from None
            raise InputFileError(
                path, f"a symbolic link loop (too many levels of links); not a {what}"
            ) from None
        raise InputFileError(path, f"cannot read {what} ({e.strerror})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InputFileError(
                path,
                f"{_kind(st.st_mode)}, not a regular file; jaxexo reads a {what} only from "
                "a regular file",
            )
        if st.st_size > cap:
            raise InputFileError(
                path, f"{st.st_size:,} bytes, more than the {cap:,} bytes a {what} may have"
            )
        os.set_blocking(fd, True)
        chunks, total = [], 0
        while True:  # a file that grows while it is read is still held to the cap
            b = os.read(fd, min(cap + 1 - total, 1 << 24))
            if not b:
                break
            chunks.append(b)
            total += len(b)
            if total > cap:
                raise InputFileError(path, f"more than the {cap:,} bytes a {what} may have")
        return b"".join(chunks)
    except OSError as e:
        raise InputFileError(path, f"cannot read {what} ({e.strerror})") from None
    finally:
        os.close(fd)


def read_text_input(path, what: str, cap: int = MAX_TEXT_BYTES, follow_links: bool = True) -> str:
    """``read_input`` decoded as UTF-8 text; a leading byte-order mark (which some editors write) is
    dropped. InputFileError naming the first byte that is not UTF-8."""
    data = read_input(path, what, cap, follow_links)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputFileError(
            path,
            f"not UTF-8 text (byte {e.start}: {data[e.start : e.start + 1]!r}); "
            f"a {what} is UTF-8 text",
        ) from None
    return text[1:] if text.startswith("\ufeff") else text
