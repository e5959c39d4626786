"""A run's checkpoint: written (checksummed, jaxexo.storage.checkpoint), read and checked against the
state it must fill. One format for any number of agents K: the state and the best parameters with a
leading agent axis [K, ...], each agent's best chunk and divergence in ``members``, the bookkeeping in
``book`` (docs/training.md)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from flax import serialization

from jaxexo.config.input_files import MAX_CHECKPOINT_BYTES, InputFileError, read_input
from jaxexo.storage.atomic import atomic_write
from jaxexo.storage.checkpoint import CheckpointError, unpack_checkpoint
from jaxexo.train.records import Track

# The checkpoint and bookkeeping writes (a name of its own so tests can interrupt between them;
# callers look it up on this module at each call).
checkpoint_write = atomic_write

BOOK_FIELDS = {
    "seed": int,
    "chunks_done": int,
    "best_score": float,
    "best_chunk": int,
    "devices": int,
    "population": int,
}


def read_checkpoint(path: Path) -> dict:
    """The verified checkpoint: its checksum, then its msgpack content; CheckpointError naming the
    file otherwise (never a bare msgpack or flax traceback), and naming the format of a checkpoint
    an earlier jaxexo wrote for one agent (no agent axis, no ``members``), which is not resumed."""
    try:
        data = read_input(path, "checkpoint", MAX_CHECKPOINT_BYTES, follow_links=False)
    except InputFileError as e:
        raise CheckpointError(str(e)) from None
    payload = unpack_checkpoint(data, path)
    try:
        raw = serialization.msgpack_restore(payload)
    except Exception as e:  # msgpack raises several unrelated types on a bad payload
        raise CheckpointError(
            f"{path}: the checkpoint's content cannot be decoded ({type(e).__name__}: {e})"
        ) from None
    if not isinstance(raw, dict) or not {"state", "best_params", "book"} <= set(raw):
        raise CheckpointError(
            f"{path}: not a training checkpoint (expected state, best_params and book)"
        )
    if "members" not in raw:
        raise CheckpointError(
            f"{path}: was written by the single-agent format of an earlier jaxexo (no agent axis), "
            "which this jaxexo does not resume; its policy.npz and eval.json stay usable: train "
            "again in a new directory"
        )
    book = raw["book"]
    if not isinstance(book, dict):
        raise CheckpointError(f"{path}: the checkpoint's bookkeeping is damaged")
    out = {}
    for k, typ in BOOK_FIELDS.items():
        v = book.get(k, 1 if k == "devices" else None)
        v = v.item() if hasattr(v, "item") else v
        if not isinstance(v, (int, float)) or isinstance(v, bool):
            raise CheckpointError(
                f"{path}: the checkpoint's bookkeeping lacks {k!r} (or it is not a number)"
            )
        out[k] = typ(v)
    raw["book"] = out
    return raw


def write_checkpoint(ckpt: Path, book_path: Path, payload: bytes, book: dict, wall: float) -> None:
    """The checkpoint (``payload``, packed) and its readable bookkeeping copy ``book_path`` (with the
    wall time, which differs run to run and so stays out of the checkpoint)."""
    checkpoint_write(ckpt, payload)
    checkpoint_write(book_path, json.dumps({**book, "train_seconds": wall}, indent=1).encode())


def restored(raw: dict, fresh, ckpt: Path) -> tuple:
    """(the saved TrainState [K, ...], the Track) of checkpoint ``raw``, checked against ``fresh``
    (this config's new state [K, ...]): a checkpoint of another network or state layout (another
    config's, a foreign file) must not be poured into it, as flax accepts mismatched shapes silently.
    Host copies: msgpack's arrays are read-only."""
    template = serialization.to_state_dict(fresh)
    state = with_empty_fields(template, raw["state"])
    for name, want, got in (
        ("state", template, state),
        ("best_params", serialization.to_state_dict(fresh.params), raw["best_params"]),
    ):
        bad = tree_mismatch(want, got)
        if bad:
            raise CheckpointError(
                f"{ckpt}: does not fit this config's training state ({name}{bad})"
            )
    members, k = raw["members"], len(np.asarray(fresh.update))
    for name in ("best_score", "best_chunk", "diverged"):
        if not isinstance(members, dict) or np.shape(members.get(name)) != (k,):
            raise CheckpointError(
                f"{ckpt}: the checkpoint's per-agent bookkeeping lacks {name!r} for {k} agents"
            )
    track = Track(
        serialization.from_state_dict(fresh.params, raw["best_params"]),
        np.array(members["best_score"], np.float64),
        np.array(members["best_chunk"], np.int64),
        np.array(members["diverged"], np.int64),
    )
    return serialization.from_state_dict(fresh, state), track


def with_empty_fields(template, loaded):
    """``loaded`` (a nested dict read from a checkpoint) with every key whose ``template`` value is
    None (a field with no leaves, as env_state.change with [env] obstacle_change off) added as
    None where it is missing: a checkpoint written before such a field existed fits it."""
    if not isinstance(template, dict) or not isinstance(loaded, dict):
        return loaded
    out = dict(loaded)
    for k, v in template.items():
        if k not in out and v is None:
            out[k] = None
        elif k in out:
            out[k] = with_empty_fields(v, out[k])
    return out


def tree_mismatch(template, loaded, where: str = "") -> str | None:
    """Where two state dicts (nested dicts of arrays) differ in keys, shapes or dtypes; None if they agree."""
    if isinstance(template, dict):
        if not isinstance(loaded, dict):
            return f"{where or '/'}: expected a table, found {type(loaded).__name__}"
        if set(template) != set(loaded):
            missing, extra = (
                sorted(set(template) - set(loaded)),
                sorted(set(loaded) - set(template)),
            )
            return f"{where or '/'}: keys differ (missing {missing[:4]}, unexpected {extra[:4]})"
        for k in template:
            bad = tree_mismatch(template[k], loaded[k], f"{where}/{k}")
            if bad:
                return bad
        return None
    if template is None:  # a field with no leaves (env_state.change with obstacle changes off)
        return (
            None if loaded is None else f"{where}: expected nothing, found {type(loaded).__name__}"
        )
    t, x = np.asarray(template), loaded
    if not isinstance(x, np.ndarray) and not np.isscalar(x):
        return f"{where}: expected an array, found {type(x).__name__}"
    x = np.asarray(x)
    if x.shape != t.shape or x.dtype != t.dtype:
        return f"{where}: {x.dtype}{list(x.shape)} where this config's network has {t.dtype}{list(t.shape)}"
    return None


def resumed_clock(ckpt: Path, book: Path, chunks_done: int, total_chunks: int) -> float:
    """A resumed run's wall time so far (s), after checking the checkpoint's ``chunks_done`` against the
    run's chunks. The time comes from the readable copy ``book`` when it matches the checkpoint (it is
    informational: a missing or stale copy only restarts the clock)."""
    if not 0 <= chunks_done <= total_chunks:
        raise CheckpointError(
            f"{ckpt}: chunks_done {chunks_done} is outside this run's 0..{total_chunks}"
        )
    try:
        readable = json.loads(book.read_text())
        return readable["train_seconds"] if readable.get("chunks_done") == chunks_done else 0.0
    except (OSError, ValueError, KeyError, TypeError):
        return 0.0
