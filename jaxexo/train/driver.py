"""``jaxexo train``: drive the compiled trainer in chunks, with progress, metrics, checkpoints and resume.

Run directory:
- config.toml        the resolved config
- checkpoint.msgpack the TrainState after the last finished chunk, the best parameters so far and the
                     bookkeeping (chunks done, wall time, best score), in one atomic write
- checkpoint.json    a readable copy of that bookkeeping (informational; resume reads the msgpack)
- metrics.jsonl      one line per chunk: counters and rates reduced inside the compiled scan
- policy.npz         the exported greedy policy (jaxexo.storage.policy_file; NumPy-only to load)
- training_curve.png return and success rate against episodes (thesis Fig. 3.4)
- eval.json          greedy rollouts on the test layouts (jaxexo.train.evaluate)
(names, checkpoint reading and checks, rows, export: jaxexo.train.run_files, shared with populations)

Population (``[train] population = K > 1``): K seeds of the config trained together, the best member's
best chunk exported; jaxexo.train.population has the program and the per-member files.

Model selection: after every chunk the greedy policy is scored (strict success) on validation
layouts drawn from the training distribution; the best parameters are exported (later chunks win
ties). The held-out test obstacles are never used for this choice.

Resume: the same chunk program runs from the restored state, so a resumed run ends bit-identical to
an uninterrupted one (tests/test_driver.py checks it). metrics.jsonl is cut back to the checkpoint's
chunks first (rows written after it are recomputed identically).

Reliability (docs/reliability.md; tests/test_reliability.py):
- the run holds an exclusive lock on the directory (jaxexo.storage.rundir) from start to end: a second
  ``jaxexo train``/``sweep`` there is refused; a killed run's lock vanishes with it;
- a new run needs an empty or absent directory (a finished policy.npz, a sweep's best/, the remains of a
  crashed run are never overwritten or appended to);
- the checkpoint carries a sha256 (jaxexo.storage.checkpoint) and its trees must match this config's
  network and state in structure, shape and dtype, or resume is refused naming the file;
- the checkpoint records the config the run started with: a resume with any other config (config.toml
  edited along with it) is refused naming the first differing field; a run past its first chunk
  whose checkpoint was deleted (checkpoint.json, or more than one metrics row, remain) is refused;
- a chunk whose loss or parameters are not finite marks the run diverged: the row says so, training
  stops, no checkpoint is written for it, only the best finite parameters (if a chunk produced any)
  are exported, and TrainingDiverged is raised (the CLI exits 3).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import jax
import numpy as np
from flax import serialization

from jaxexo.config import Config, ConfigError, check_seed
from jaxexo.config.toml_io import config_to_toml
from jaxexo.storage.atomic import append_line, atomic_write
from jaxexo.storage.checkpoint import CheckpointError, pack_checkpoint
from jaxexo.storage.rundir import TrainingDiverged, run_lock
from jaxexo.train import run_files
from jaxexo.train.evaluate import evaluate, make_validator
from jaxexo.train.trainer import Hyperparams, Trainer


def run_training(cfg: Config, out: str | Path, seed: int = 0, resume: bool = False, progress: bool = True,
                 eval_episodes: int | None = None) -> dict:
    """Train, write the run directory, and return eval.json's content. Holds the directory's lock
    throughout; raises TrainingDiverged (after writing what can be trusted) if the run diverged."""
    out = Path(out)
    check_seed(seed, "--seed", cfg.train.population)   # before anything is made (PRNGKey overflows past it)
    with run_lock(out, "train", create=not resume, scratch=("config.toml",)):
        if cfg.train.population > 1:
            # K agents as one compiled program, the best on validation exported (jaxexo.train.population).
            from jaxexo.train.population import run_population

            return run_population(cfg, out, seed, resume, progress, eval_episodes)
        return _run_locked(cfg, out, seed, resume, progress, eval_episodes)


def _all_finite(tree) -> bool:
    return all(bool(np.all(np.isfinite(np.asarray(x)))) for x in jax.tree.leaves(tree)
               if np.issubdtype(np.asarray(x).dtype, np.inexact))


def _run_locked(cfg: Config, out: Path, seed: int, resume: bool, progress: bool, eval_episodes) -> dict:
    ckpt, book = out / run_files.CHECKPOINT, out / run_files.BOOKKEEPING
    raw = run_files.prepare_dir(out, cfg, seed, resume)
    state_book = raw["book"] if raw is not None else None

    t_start = time.perf_counter()
    # Data parallel over the CPU cores exposed as JAX devices (jaxexo.train.devices; the CLI sets this up).
    # The device count changes the random streams: a run is reproducible on the same count.
    trainer = Trainer(cfg, devices=jax.local_devices())
    n_dev = len(trainer.devices or [0])
    if raw is not None and state_book["devices"] != n_dev:
        raise ConfigError(f"--resume: the run used {state_book['devices']} device(s), this process has "
                          f"{n_dev}; resume it on the same number of CPU devices")
    hyper = Hyperparams.from_config(cfg)
    ts = jax.jit(trainer.init)(jax.random.PRNGKey(seed), hyper)
    n_chunk, total_chunks = run_files.chunking(cfg, trainer)
    rows: list[dict] = []
    chunks_done, wall_before = 0, 0.0
    metrics_path = out / "metrics.jsonl"
    best = {"params": ts.params, "score": -1.0, "chunk": 0}
    if resume and raw is None:
        atomic_write(metrics_path, "")   # rows of a run that never reached its first checkpoint
    if raw is not None:
        # A checkpoint of another network or state layout (another config's, a foreign file) must not
        # be poured into this one: flax would accept mismatched shapes silently.
        for name, template in (("state", serialization.to_state_dict(ts)),
                               ("best_params", serialization.to_state_dict(ts.params))):
            bad = run_files.tree_mismatch(template, raw[name])
            if bad:
                raise CheckpointError(f"{ckpt}: does not fit this config's training state ({name}{bad})")
        ts = serialization.from_state_dict(ts, raw["state"])
        best["params"] = serialization.from_state_dict(ts.params, raw["best_params"])
        best.update(score=state_book["best_score"], chunk=state_book["best_chunk"])
        chunks_done = state_book["chunks_done"]
        wall_before = run_files.resumed_clock(ckpt, book, chunks_done, total_chunks)
        rows = run_files.read_metrics_rows(metrics_path, chunks_done)
        # Lines written after the checkpoint are recomputed identically: drop them (a torn last line too).
        atomic_write(metrics_path, "".join(json.dumps(r) + "\n" for r in rows))
    # The state laid out as the chunks return it, so that every chunk calls one compiled program
    # (Trainer.place: else the second chunk, on a state split over the devices, compiles it again).
    ts = trainer.place(ts)
    run = jax.jit(trainer.run, static_argnums=2)
    active = jax.jit(trainer.active)
    validate = make_validator(cfg, trainer.net)

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=total_chunks, initial=chunks_done, unit="chunk", dynamic_ncols=True,
                   desc=f"train {cfg.train.trace} {cfg.train.control}")
    diverged = None
    try:
        while chunks_done < total_chunks and bool(active(ts, hyper)):
            t0 = time.perf_counter()
            ts, m = run(ts, hyper, n_chunk)
            m = np.asarray(m)
            chunks_done += 1
            wall = wall_before + time.perf_counter() - t_start
            row = run_files.chunk_row(m, ts, trainer.env_steps(ts), chunks_done, wall, time.perf_counter() - t0)
            finite = bool(np.all(np.isfinite(m))) and _all_finite(ts.params)
            row["diverged"] = not finite
            row["validation_success_raw"] = validate(ts.params) if finite else None
            rows.append(row)
            append_line(metrics_path, json.dumps(row) + "\n")
            if not finite:
                # No checkpoint of a diverged state: a resume would only diverge again.
                diverged = chunks_done
                if bar is not None:
                    bar.set_postfix(diverged=f"chunk {chunks_done}", loss=row["loss"])
                break
            if row["validation_success_raw"] >= best["score"]:
                best.update(params=ts.params, score=row["validation_success_raw"], chunk=chunks_done)
            bookkeeping = {"seed": seed, "chunks_done": chunks_done, "best_score": best["score"],
                           "best_chunk": best["chunk"], "devices": n_dev}
            # State, best parameters and bookkeeping in one atomic write, checksummed: a run stopped at
            # any point resumes from a consistent checkpoint (wall time, which differs run to run, stays out).
            run_files.checkpoint_write(ckpt, pack_checkpoint(serialization.msgpack_serialize({
                "state": serialization.to_state_dict(ts),
                "best_params": serialization.to_state_dict(best["params"]),
                "book": bookkeeping, "config_toml": config_to_toml(cfg)})))
            run_files.checkpoint_write(book, json.dumps({**bookkeeping, "train_seconds": wall}, indent=1).encode())
            if bar is not None:
                bar.update(1)
                bar.set_postfix(episodes=row["episodes"], steps_per_s=f"{row['env_steps_per_s']:.3g}",
                                ret=f"{row['return_mean']:.2f}", success_raw=f"{row['success_raw_rate']:.3f}",
                                eps=f"{row['epsilon']:.3f}", val=f"{row['validation_success_raw']:.3f}")
    finally:
        if bar is not None:
            bar.close()
    train_seconds = wall_before + time.perf_counter() - t_start

    if rows:
        run_files.plot_training_curve(out / "training_curve.png", [r for r in rows if not r["diverged"]] or rows)
    if diverged is not None and best["chunk"] == 0:
        raise TrainingDiverged(
            f"training diverged in chunk {diverged} (non-finite loss or parameters; {metrics_path} row "
            f"{diverged} has \"diverged\": true); no chunk finished with finite parameters, so no policy was "
            f"exported. Lower train.lr (it is {cfg.train.lr:g}) or train.max_grad_norm")
    run_files.export_policy(out / "policy.npz", cfg, trainer, best["params"])
    result = evaluate(cfg, trainer.net, best["params"], eval_episodes or cfg.train.eval_episodes)
    result.update({"episodes": int(ts.episodes), "env_steps": int(trainer.env_steps(ts)),
                   "train_seconds": round(train_seconds, 3), "seed": seed,
                   "selected_chunk": best["chunk"], "validation_success_raw": best["score"], "devices": n_dev})
    if diverged is not None:
        result["diverged_chunk"] = diverged
    atomic_write(out / "eval.json", json.dumps(result, indent=2) + "\n")
    if diverged is not None:
        raise TrainingDiverged(
            f"training diverged in chunk {diverged} (non-finite loss or parameters; {metrics_path} row "
            f"{diverged} has \"diverged\": true); policy.npz and eval.json hold the best finite parameters, "
            f"from chunk {best['chunk']} (validation success on raw moves {best['score']:.3f}). Lower train.lr "
            f"(it is {cfg.train.lr:g}) or train.max_grad_norm")
    return result
