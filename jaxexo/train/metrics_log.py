"""metrics.jsonl, a run's log: one line per chunk, the same for any number of agents K (each agent's
row in ``members``, docs/training.md), strict JSON; read back on resume up to the checkpoint's chunks
and checked against them."""

from __future__ import annotations

import json
import math
from pathlib import Path

import jax
import numpy as np
from flax import struct

from jaxexo.config import ConfigError
from jaxexo.config.input_files import MAX_LOG_BYTES, InputFileError, read_input
from jaxexo.train.trainer import UpdateMetrics


@struct.dataclass
class Counters:
    """The agents' totals after a chunk (host integers [K], or one agent's scalars), named as
    TrainState's counters (Trainer.active reads them)."""

    update: np.ndarray  # updates done
    episodes: np.ndarray
    steps_per_update: int = struct.field(pytree_node=False)

    @property
    def env_steps(self) -> np.ndarray:
        """Env steps done, exactly (int64)."""
        return np.asarray(self.update).astype(np.int64) * self.steps_per_update


def chunk_row(m: UpdateMetrics, counts: Counters, chunk: int, wall: float, seconds: float) -> dict:
    """metrics.jsonl's row of one agent's chunk: ``m`` its UpdateMetrics [n_chunk]."""
    # Summed in float64 in update order (cumsum: np.sum of a lone column is pairwise and rounds
    # differently from the rows' order the rows have always been summed in).
    d = jax.tree.map(lambda x: np.cumsum(np.asarray(x, np.float64))[-1], m)
    n_upd = max(1, int((np.asarray(m.env_steps) > 0).sum()))
    eps = max(float(d.episodes), 1.0)
    return {
        "chunk": chunk,
        "updates": int(counts.update),
        "env_steps": int(counts.env_steps),
        "episodes": int(counts.episodes),
        "chunk_episodes": int(d.episodes),
        "return_mean": float(d.return_sum) / eps,
        "success_raw_rate": float(d.successes) / eps,  # behaviour policy, raw moves
        "accuracy": float(d.accurate) / eps,
        "loss": float(d.loss) / n_upd,
        "q_mean": float(d.q_mean) / n_upd,
        "epsilon": float(d.epsilon) / n_upd,
        "env_steps_per_s": float(d.env_steps) / max(seconds, 1e-9),
        "wall_s": wall,
    }


# chunk_row's float fields: a diverged chunk's may be NaN or inf, written as null (JSON has no NaN)
# and read back as NaN.
FLOAT_FIELDS = frozenset(
    (
        "return_mean",
        "success_raw_rate",
        "accuracy",
        "loss",
        "q_mean",
        "epsilon",
        "env_steps_per_s",
        "wall_s",
    )
)


def json_safe(x):
    """``x`` with every non-finite float replaced by None, so that json.dumps writes valid JSON
    (null) instead of the bare NaN/Infinity that no strict JSON reader accepts."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    return x


def metrics_line(row: dict) -> str:
    """metrics.jsonl's line for ``row``: strict JSON, a non-finite number written as null."""
    return json.dumps(json_safe(row), allow_nan=False) + "\n"


def _nan_for_null(d: dict) -> dict:
    return {k: (math.nan if v is None and k in FLOAT_FIELDS else v) for k, v in d.items()}


def read_metrics_rows(metrics_path: Path, chunks_done: int) -> list[dict]:
    """The rows of a run's metrics.jsonl up to its checkpoint's ``chunks_done`` (later lines, a torn
    last line among them, are recomputed by the resumed run). ConfigError naming the file when it is
    damaged within those rows, when they are not the checkpoint's chunks 1..``chunks_done`` in order
    (rows deleted, the file cut short or emptied: the log no longer matches the checkpoint), or when
    it is not a regular file (a symbolic link in its place is named)."""
    if not metrics_path.exists() and not metrics_path.is_symlink():
        if chunks_done:
            raise ConfigError(
                f"--resume: {metrics_path} is missing, but the checkpoint holds {chunks_done} "
                "chunk(s) whose rows it must hold; it cannot be rebuilt, start a new run"
            )
        return []
    try:
        data = read_input(metrics_path, "metrics log", MAX_LOG_BYTES, follow_links=False)
    except InputFileError as e:
        raise ConfigError(f"--resume: {e}; it cannot be rebuilt, start a new run") from None
    try:
        rows = [
            json.loads(x, object_hook=_nan_for_null)
            for x in data.decode("utf-8").splitlines()[:chunks_done]
        ]
    except UnicodeDecodeError as e:
        raise ConfigError(
            f"--resume: {metrics_path} is damaged (not UTF-8 text at byte {e.start}); it cannot "
            "be rebuilt, start a new run"
        ) from None
    except ValueError:
        raise ConfigError(
            f"--resume: {metrics_path} is damaged within the checkpoint's {chunks_done} "
            "chunk(s); it cannot be rebuilt, start a new run"
        ) from None
    _check_rows(metrics_path, rows, chunks_done)
    return rows


def _check_rows(metrics_path: Path, rows: list, chunks_done: int) -> None:
    """The log's first rows must be the checkpoint's chunks 1..``chunks_done``, one each, in order: a
    resume appends to them, and a log with a gap would describe another run than the checkpoint's."""
    numbers = [r.get("chunk") if isinstance(r, dict) else None for r in rows]
    if numbers == list(range(1, chunks_done + 1)):
        return
    missing = sorted(set(range(1, chunks_done + 1)) - set(numbers))
    if not rows:
        what = "holds no rows"
    elif missing:
        what = f"lacks the rows of chunk(s) {_spans(missing)} (rows deleted, or the file cut short)"
    else:
        i = next(i for i, n in enumerate(numbers) if n != i + 1)
        what = f"has chunk {numbers[i]!r} on line {i + 1}, where chunk {i + 1} belongs"
    raise ConfigError(
        f"--resume: {metrics_path} {what}, but the checkpoint holds chunks 1..{chunks_done}: the "
        "log no longer matches the checkpoint; put the run's own metrics.jsonl back, or start a "
        "new run"
    )


def _spans(numbers: list[int]) -> str:
    """Sorted chunk numbers as runs: ``1..3, 5``."""
    out, start = [], numbers[0]
    for a, b in zip(numbers, [*numbers[1:], None], strict=True):
        if b != a + 1:
            out.append(str(a) if a == start else f"{start}..{a}")
            start = b
    return ", ".join(out)
