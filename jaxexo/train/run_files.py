"""The run directory's files, for one agent (jaxexo.train.driver) and a population
(jaxexo.train.population): their names, the chunking of a budget, a chunk's metrics row, the
checkpoint (read, checked against the state it must fill, written), the exported policy, and the
checks a new or resumed run makes of its directory (formats: docs/training.md)."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import jax
import numpy as np
from flax import serialization, struct

from jaxexo.config import Config, ConfigError, config_from_dict, load_config
from jaxexo.config.input_files import (
    MAX_CHECKPOINT_BYTES,
    MAX_LOG_BYTES,
    InputFileError,
    read_input,
)
from jaxexo.config.toml_io import config_to_toml
from jaxexo.env.exo_step import LENGTH_SCALE, THESIS_OBS_CENTER
from jaxexo.physics import actions
from jaxexo.storage.atomic import atomic_write, stale_temps
from jaxexo.storage.checkpoint import CheckpointError, unpack_checkpoint
from jaxexo.storage.policy_file import save_policy
from jaxexo.storage.rundir import RunDirError, contents, describe
from jaxexo.train.network import dense_layers, norm_layers
from jaxexo.train.trainer import METRICS, Trainer, UpdateMetrics  # noqa: F401 (METRICS read as run_files.METRICS)

CHECKPOINT = "checkpoint.msgpack"
BOOKKEEPING = "checkpoint.json"
# Aim for chunks of about this many env steps: frequent enough for a live progress bar.
CHUNK_ENV_STEPS = 1_000_000


def chunking(cfg: Config, trainer: Trainer) -> tuple[int, int]:
    """(updates per chunk, chunks): every chunk has the same length, so one program is compiled;
    updates past the budget are masked inside the program."""
    per = cfg.train.num_envs * cfg.train.rollout_steps
    target = cfg.train.chunk_updates or max(1, CHUNK_ENV_STEPS // per)
    chunks = math.ceil(trainer.num_updates / min(target, trainer.num_updates))
    return math.ceil(trainer.num_updates / chunks), chunks


# The checkpoint and bookkeeping writes, for one agent and a population (a name of its own so tests
# can interrupt between them; callers look it up on this module at each call).
checkpoint_write = atomic_write


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


def export_policy(path: Path, cfg: Config, trainer: Trainer, params) -> Path:
    env = trainer.env
    dense = [(np.asarray(w), np.asarray(b)) for w, b in dense_layers(params)]
    norms = [(np.asarray(s), np.asarray(b)) for s, b in norm_layers(params)]
    meta = {
        "obs_mode": cfg.env.obs_mode,
        "obs_dim": env.obs_dim,
        "length_scale": LENGTH_SCALE,
        "thesis_obs_center": list(THESIS_OBS_CENTER),
        "num_actions": env.num_actions,
        "action_angles_rad": actions.action_angles(env.num_actions).tolist(),
        "layers": [env.obs_dim, *cfg.train.hidden, env.num_actions],
        "layer_norm": cfg.train.layer_norm,
        "activation": "relu",
        "config_toml": config_to_toml(cfg),
    }
    return save_policy(
        path,
        [w for w, _ in dense],
        [b for _, b in dense],
        [s for s, _ in norms],
        [b for _, b in norms],
        meta,
    )


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


BOOK_FIELDS = {
    "seed": int,
    "chunks_done": int,
    "best_score": float,
    "best_chunk": int,
    "devices": int,
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


def read_checkpoint(path: Path) -> dict:
    """The verified checkpoint: its checksum (jaxexo.storage.checkpoint), then its msgpack content;
    CheckpointError naming the file otherwise (never a bare msgpack or flax traceback)."""
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


# What a run writes before its first checkpoint: a run stopped then (killed, a full disk) is resumed
# from the beginning.
BEFORE_FIRST_CHECKPOINT = {"config.toml", "metrics.jsonl", BOOKKEEPING}
WRITTEN = (
    "config.toml",
    "metrics.jsonl",
    CHECKPOINT,
    BOOKKEEPING,
    "policy.npz",
    "training_curve.png",
    "eval.json",
)


def prepare_dir(out: Path, cfg: Config, seed: int, resume: bool):
    """Check the (locked) run directory; return the checkpoint's content on resume, its ``rows`` the
    metrics.jsonl rows it proves (read_metrics_rows), else None (a new run, or a resume of a run
    stopped before its first checkpoint: it starts again from scratch)."""
    cfg_path, ckpt = out / "config.toml", out / CHECKPOINT
    if resume:
        # Temporary files of a killed writer (atomic_write removes its own on an error, not on SIGKILL);
        # with the lock held nobody else is writing them.
        for name in WRITTEN:
            for tmp in stale_temps(out / name):
                tmp.unlink(missing_ok=True)
    present = contents(out)
    if resume:
        if not ckpt.exists():
            done = _chunks_recorded(out)
            if done:
                raise ConfigError(
                    f"--resume: {out} has no {CHECKPOINT} but {done}; its checkpoint was deleted, "
                    "so the run cannot be continued: start a new run in another directory"
                )
            if "config.toml" in present and set(present) <= BEFORE_FIRST_CHECKPOINT:
                _check_same_config(load_config(cfg_path), cfg, cfg_path)
                return None  # stopped before its first checkpoint: nothing to keep, start again
            raise ConfigError(
                f"--resume: {out} has no checkpoint to resume from (no {CHECKPOINT}"
                + (f"; it holds {describe(present)})" if present else "; it is empty)")
            )
        if not cfg_path.exists():
            raise ConfigError(
                f"--resume: {out} has {CHECKPOINT} but no config.toml (the run's resolved config, "
                f"which resume checks the config against); put it back, or start a new run elsewhere"
            )
        _check_same_config(load_config(cfg_path), cfg, cfg_path)
        raw = read_checkpoint(ckpt)
        started = raw.get("config_toml")
        if isinstance(started, bytes):
            started = started.decode()
        if isinstance(started, str):
            # config.toml may have been edited together with the config passed: the checkpoint's
            # own copy is what the state was trained with.
            try:
                first = config_from_dict(tomllib.loads(started))
            except (tomllib.TOMLDecodeError, ConfigError) as e:
                raise CheckpointError(f"{ckpt}: its config cannot be read ({e})") from None
            if first != cfg:
                name, given, run = _first_difference(first, cfg)
                raise ConfigError(
                    f"--resume: {name} differs from the value the run in {out} started with (given "
                    f"{given}, the run started with {run}; its checkpoint records the config); the "
                    "training state depends on it: resume with the run's config, or start a new run"
                )
        if raw["book"]["seed"] != seed:
            raise ConfigError(f"--resume: the run used --seed {raw['book']['seed']}, not {seed}")
        # The log checked against the checkpoint before anything is compiled or written.
        raw["rows"] = read_metrics_rows(out / "metrics.jsonl", raw["book"]["chunks_done"])
        return raw
    if ckpt.exists():
        raise ConfigError(
            f"--out: {out} already holds a run; pass --resume to continue it or pick a new folder"
        )
    if present:
        stale = {tmp.name for name in WRITTEN for tmp in stale_temps(out / name)}
        hint = (
            " (a run stopped before its first checkpoint: --resume starts it again)"
            if "config.toml" in present
            and set(present) - stale <= BEFORE_FIRST_CHECKPOINT
            and not _chunks_recorded(out)
            else ""
        )
        raise RunDirError(
            f"--out: {out} is not empty ({describe(present)}) and has no {CHECKPOINT} to resume "
            f"from{hint}; a new run needs an empty or absent directory, so that nothing there is "
            "overwritten: pick another --out, or move those files away"
        )
    atomic_write(cfg_path, config_to_toml(cfg))
    return None


def _chunks_recorded(out: Path) -> str:
    """What shows that a run got past its first checkpoint (checkpoint.json, or more than one row in
    metrics.jsonl: row k is appended just before checkpoint k), in words; "" if nothing does."""
    if (out / BOOKKEEPING).exists():
        return f"{BOOKKEEPING} records a checkpoint"
    try:
        rows = (out / "metrics.jsonl").read_bytes().count(b"\n")
    except OSError:
        return ""
    return f"metrics.jsonl records {rows} finished chunks" if rows > 1 else ""


def _first_difference(a: Config, b: Config) -> tuple[str, str, str]:
    """The first field whose value differs between the run's config ``a`` and the given ``b``:
    (``section.name``, the given value, the run's value)."""
    import dataclasses

    for section in ("env", "kinematics", "reward", "layout", "train", "device"):
        x, y = getattr(a, section), getattr(b, section)
        for f in dataclasses.fields(x):
            if getattr(x, f.name) != getattr(y, f.name):
                return f"{section}.{f.name}", _short(getattr(y, f.name)), _short(getattr(x, f.name))
    return "the config", "", ""


def _short(v) -> str:
    text = repr(v)
    return text if len(text) <= 60 else text[:57] + "..."


def _check_same_config(saved: Config, cfg: Config, cfg_path: Path) -> None:
    """A resume's config must be the run's config.toml; ConfigError naming the first differing field."""
    if saved != cfg:
        name, given, run = _first_difference(saved, cfg)
        raise ConfigError(
            f"--resume: the config differs from the run's config {cfg_path} in {name} (given {given}, "
            f"the run has {run}); resume with that config (--resume without a config path uses it)"
        )
