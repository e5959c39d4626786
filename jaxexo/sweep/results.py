"""A sweep directory's files (NumPy only): plan.json, sweep.json, results.csv (one row per agent,
appended as chunks finish, sorted when complete) and chunks/chunk_NNNN.npz (each chunk's agents,
learning curves and final parameters). The files: docs/training.md, "Hyperparameter sweeps".
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from jaxexo.config import HYPER_FIELDS, RewardConfig
from jaxexo.storage.atomic import append_line, atomic_write  # noqa: F401 (the one atomic write; R.atomic_write)
from jaxexo.sweep.spec import Sweep

PLAN, SWEEP_FILE, RESULTS, CHUNKS = "plan.json", "sweep.json", "results.csv", "chunks"
IDENTITY = ("config_id", "seed", "group", "chunk", "label")
# The results of one agent, reduced inside the compiled program (jaxexo.sweep.program):
# success/accuracy: greedy rollouts on the fixed test layouts (the five thesis obstacles x the three
# pivot conditions; held_out_*: triangle and half-circle only, never trained on by default), judged
# by jaxexo.physics.outcome on the agent's raw moves: eval.json's ``success_raw``, on the same scenes
# as ``jaxexo eval`` (whose ``success`` is of the smoothed trajectories). The column names are kept so
# that existing results.csv files resume;
# eval_return: their mean return; train_success/train_return: the last tenth of training (behaviour
# policy); episodes_to_90: episodes finished when training success first reached 90 % (nan: never);
# diverged: 1 if the parameters or the loss became NaN or infinite.
SCALARS = (
    "success",
    "accuracy",
    "held_out_success",
    "held_out_accuracy",
    "eval_return",
    "train_success",
    "train_return",
    "episodes_to_90",
    "episodes",
    "env_steps",
    "updates",
    "diverged",
)
INTEGER = ("episodes", "env_steps", "updates", "diverged")


def hyper_columns(sweep: Sweep) -> list[str]:
    """The axes, then every hyperparameter (train.* vmappable ones, every reward.* field)."""
    cols = [a.path for a in sweep.axes]
    cols += [
        c
        for c in [f"train.{f}" for f in HYPER_FIELDS]
        + [f"reward.{f.name}" for f in fields(RewardConfig)]
        if c not in cols
    ]
    return cols


def columns(sweep: Sweep) -> list[str]:
    return [*IDENTITY, *hyper_columns(sweep), *SCALARS, "wall_s"]


def _config_value(cfg, path: str):
    section, _, name = path.partition(".")
    name, _, index = name.partition("[")
    v = getattr(getattr(cfg, section), name)
    return v[int(index[:-1])] if index else v


def _text(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return json.dumps([list(x) if isinstance(x, tuple) else x for x in v])
    return str(v)


@dataclass(frozen=True)
class ChunkResult:
    """One finished chunk (jaxexo.sweep.program.run_chunk), NumPy arrays of its n real agents."""

    chunk_id: int
    agents: list  # [config_id, seed] of each agent
    scalars: dict  # SCALARS name -> [n] float64
    curves: np.ndarray  # [n, CURVE_POINTS, len(metrics)]: per-update metrics summed in bins
    metrics: list  # the curves' columns (jaxexo.train.trainer.METRICS)
    params: dict  # flattened state dict, leaves [n, ...]
    wall_s: float  # the call, compilation included when it happened there


def chunk_rows(sweep: Sweep, result: ChunkResult, group_of: dict) -> list[dict]:
    """results.csv rows (strings) of one finished chunk (``jaxexo.sweep.program.run_chunk``'s result)."""
    rows = []
    hcols = hyper_columns(sweep)
    for i, (cid, seed) in enumerate(result.agents):
        m = sweep.members[cid]
        row = {
            "config_id": str(cid),
            "seed": str(seed),
            "group": str(group_of[cid]),
            "chunk": str(result.chunk_id),
            "label": m.label,
        }
        row.update((c, _text(_config_value(m.config, c))) for c in hcols)
        for k in SCALARS:
            x = float(result.scalars[k][i])
            row[k] = str(int(x)) if k in INTEGER else repr(x)
        row["wall_s"] = f"{result.wall_s:.3f}"
        rows.append(row)
    return rows


def _csv_text(cols, rows, header: bool) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    if header:
        w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def write_rows(path: Path, cols, rows) -> None:
    """The whole file, atomically."""
    atomic_write(path, _csv_text(cols, rows, header=True))


def append_rows(path: Path, cols, rows) -> None:
    """One chunk's rows in one write, flushed to disk (never through a symbolic link)."""
    append_line(path, _csv_text(cols, rows, header=False))


def read_rows(path: Path) -> list[dict]:
    """results.csv's rows as strings; a torn last line (an interrupted write) is dropped."""
    if not path.exists():
        return []
    text = path.read_text()
    lines = text.splitlines(keepends=True)
    if lines and not lines[-1].endswith("\n"):
        lines = lines[:-1]
    rows = list(csv.DictReader(io.StringIO("".join(lines))))
    return [r for r in rows if None not in r and all(v is not None for v in r.values())]


def chunk_path(out: Path, chunk_id: int) -> Path:
    return out / CHUNKS / f"chunk_{chunk_id:04d}.npz"


def save_chunk(out: Path, result: ChunkResult) -> None:
    """The chunk's learning curves and final parameters (before its rows: a row implies its file)."""
    path = chunk_path(out, result.chunk_id)
    path.parent.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    np.savez(
        buf,
        agents=np.asarray(result.agents, np.int64),
        curves=result.curves,
        metrics=np.asarray(result.metrics, dtype=str),
        **{f"params/{k}": v for k, v in result.params.items()},
    )
    atomic_write(path, buf.getvalue())


def load_chunk(out: Path, chunk_id: int) -> dict:
    with np.load(chunk_path(out, chunk_id), allow_pickle=False) as z:
        return {
            "agents": [tuple(a) for a in z["agents"].tolist()],
            "curves": z["curves"],
            "metrics": [str(m) for m in z["metrics"]],
            "params": {k[len("params/") :]: z[k] for k in z.files if k.startswith("params/")},
        }
