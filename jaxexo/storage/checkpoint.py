"""The checkpoint file's envelope: a header line ``jaxexo-checkpoint <version> sha256=<hex>`` before
the payload (flax's msgpack of the training state), verified before any byte is decoded; a bad file
is a CheckpointError naming it (docs/reliability.md). NumPy-free, JAX-free.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

MAGIC = b"jaxexo-checkpoint"
VERSION = 1


class CheckpointError(ValueError):
    """A checkpoint that is missing, truncated, corrupt, foreign or from another version."""


def pack_checkpoint(payload: bytes) -> bytes:
    digest = hashlib.sha256(payload).hexdigest().encode()
    return MAGIC + b" %d sha256=" % VERSION + digest + b"\n" + payload


def unpack_checkpoint(data: bytes, path: str | Path) -> bytes:
    """The verified payload of a checkpoint file's bytes; CheckpointError naming ``path`` otherwise."""
    head, sep, payload = data.partition(b"\n")
    if not data.startswith(MAGIC + b" ") or not sep:
        raise CheckpointError(
            f"{path}: not a jaxexo checkpoint (no '{MAGIC.decode()}' header: empty, "
            "random, or written by an older jaxexo); it cannot be resumed, start a new run"
        )
    parts = head.split(b" ")
    if len(parts) != 3 or not parts[2].startswith(b"sha256=") or len(parts[2]) != 7 + 64:
        raise CheckpointError(f"{path}: damaged checkpoint header {head[:80]!r}")
    if parts[1] != str(VERSION).encode():
        raise CheckpointError(
            f"{path}: checkpoint version {parts[1].decode(errors='replace')} is not "
            f"supported (this jaxexo reads version {VERSION})"
        )
    if hashlib.sha256(payload).hexdigest().encode() != parts[2][7:]:
        raise CheckpointError(
            f"{path}: checksum mismatch: the checkpoint is truncated or corrupt "
            f"({len(payload)} payload bytes do not match the sha256 in its header)"
        )
    return payload
