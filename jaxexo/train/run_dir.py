"""The run directory of ``jaxexo train``: the names of the files a run writes, and the checks a new or
resumed run makes of its (locked) directory before anything is compiled: what is there, the config
(compared once, with the one the run started with), the seed, and the log against the checkpoint
(docs/reliability.md)."""

from __future__ import annotations

import dataclasses
import tomllib
from pathlib import Path

from jaxexo.config import Config, ConfigError, config_from_dict, load_config
from jaxexo.config.toml_io import config_to_toml
from jaxexo.storage.atomic import atomic_write, stale_temps
from jaxexo.storage.checkpoint import CheckpointError
from jaxexo.storage.rundir import RunDirError, contents, describe
from jaxexo.train.checkpoints import read_checkpoint
from jaxexo.train.metrics_log import read_metrics_rows

CHECKPOINT = "checkpoint.msgpack"
BOOKKEEPING = "checkpoint.json"
LOG = "metrics.jsonl"
# What a run writes before its first checkpoint: a run stopped then (killed, a full disk) is resumed
# from the beginning.
BEFORE_FIRST_CHECKPOINT = {"config.toml", LOG, BOOKKEEPING}
WRITTEN = (
    "config.toml",
    LOG,
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
    if resume:
        return _resumed(out, cfg, seed)
    present = contents(out)
    if (out / CHECKPOINT).exists():
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
    atomic_write(out / "config.toml", config_to_toml(cfg))
    return None


def _resumed(out: Path, cfg: Config, seed: int) -> dict | None:
    """prepare_dir's checks of a resumed run."""
    cfg_path, ckpt = out / "config.toml", out / CHECKPOINT
    # Temporary files of a killed writer (atomic_write removes its own on an error, not on SIGKILL);
    # with the lock held nobody else is writing them.
    for name in WRITTEN:
        for tmp in stale_temps(out / name):
            tmp.unlink(missing_ok=True)
    present = contents(out)
    if not ckpt.exists():
        done = _chunks_recorded(out)
        if done:
            raise ConfigError(
                f"--resume: {out} has no {CHECKPOINT} but {done}; its checkpoint was deleted, "
                "so the run cannot be continued: start a new run in another directory"
            )
        if "config.toml" in present and set(present) <= BEFORE_FIRST_CHECKPOINT:
            _check_same_config(load_config(cfg_path), cfg, str(cfg_path))
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
    raw = read_checkpoint(ckpt)
    _check_same_config(_started_with(raw, ckpt), cfg, f"recorded in {ckpt}")
    if raw["book"]["seed"] != seed:
        raise ConfigError(f"--resume: the run used --seed {raw['book']['seed']}, not {seed}")
    # The log checked against the checkpoint before anything is compiled or written.
    raw["rows"] = read_metrics_rows(out / LOG, raw["book"]["chunks_done"])
    return raw


def _started_with(raw: dict, ckpt: Path) -> Config:
    """The config the checkpoint records (config.toml may have been edited together with the
    config passed: the checkpoint's own copy is what the state was trained with)."""
    started = raw.get("config_toml")
    if isinstance(started, bytes):
        started = started.decode()
    try:
        return config_from_dict(tomllib.loads(started))
    except (tomllib.TOMLDecodeError, ConfigError, TypeError) as e:
        raise CheckpointError(f"{ckpt}: its config cannot be read ({e})") from None


def _check_same_config(run: Config, cfg: Config, where: str) -> None:
    """A resume's config must be the run's; ConfigError naming the first differing field."""
    if run == cfg:
        return
    name, given, had = _first_difference(run, cfg)
    raise ConfigError(
        f"--resume: the config differs from the run's config {where} in {name} (given {given}, the "
        f"run has {had}); the training state depends on it: resume with the run's config (--resume "
        "without a config path uses it), or start a new run"
    )


def _chunks_recorded(out: Path) -> str:
    """What shows that a run got past its first checkpoint (checkpoint.json, or more than one row in
    metrics.jsonl: row k is appended just before checkpoint k), in words; "" if nothing does."""
    if (out / BOOKKEEPING).exists():
        return f"{BOOKKEEPING} records a checkpoint"
    try:
        rows = (out / LOG).read_bytes().count(b"\n")
    except OSError:
        return ""
    return f"{LOG} records {rows} finished chunks" if rows > 1 else ""


def _first_difference(a: Config, b: Config) -> tuple[str, str, str]:
    """The first field whose value differs between the run's config ``a`` and the given ``b``:
    (``section.name``, the given value, the run's value)."""
    for section in ("env", "kinematics", "reward", "layout", "train", "device"):
        x, y = getattr(a, section), getattr(b, section)
        for f in dataclasses.fields(x):
            if getattr(x, f.name) != getattr(y, f.name):
                return f"{section}.{f.name}", _short(getattr(y, f.name)), _short(getattr(x, f.name))
    return "the config", "", ""


def _short(v) -> str:
    text = repr(v)
    return text if len(text) <= 60 else text[:57] + "..."
