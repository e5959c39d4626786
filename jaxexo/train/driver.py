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

Model selection: after every chunk the greedy policy is scored (strict success) on validation
layouts drawn from the training distribution; the best parameters are exported (later chunks win
ties). The held-out test obstacles are never used for this choice.

Resume: the same chunk program runs from the restored state, so a resumed run ends bit-identical to
an uninterrupted one (tests/test_train.py checks it).
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import jax
import numpy as np
from flax import serialization

from jaxexo.config import Config, ConfigError, config_from_dict
from jaxexo.config.toml_io import config_to_toml
from jaxexo.env.exo_step import LENGTH_SCALE, THESIS_OBS_CENTER
from jaxexo.physics import dynamics
from jaxexo.storage.atomic import atomic_write as _atomic_write  # module-level name: tests patch it
from jaxexo.storage.policy_file import save_policy
from jaxexo.train.evaluate import evaluate, make_validator
from jaxexo.train.network import dense_layers, norm_layers
from jaxexo.train.trainer import METRICS, Hyperparams, Trainer

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


def _chunk_row(m: np.ndarray, ts, chunk: int, wall: float, seconds: float) -> dict:
    d = dict(zip(METRICS, m.sum(0).tolist()))
    n_upd = max(1, int((m[:, METRICS.index("env_steps")] > 0).sum()))
    eps = max(d["episodes"], 1.0)
    return {
        "chunk": chunk,
        "updates": int(ts.update),
        "env_steps": int(ts.env_steps),
        "episodes": int(ts.episodes),
        "chunk_episodes": int(d["episodes"]),
        "return_mean": d["return_sum"] / eps,
        "success_raw_rate": d["successes"] / eps,    # behaviour policy, raw moves
        "accuracy": d["accurate"] / eps,
        "loss": d["loss"] / n_upd,
        "q_mean": d["q_mean"] / n_upd,
        "epsilon": d["epsilon"] / n_upd,
        "env_steps_per_s": d["env_steps"] / max(seconds, 1e-9),
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
        "action_angles_rad": dynamics.action_angles(env.num_actions).tolist(),
        "layers": [env.obs_dim, *cfg.train.hidden, env.num_actions],
        "layer_norm": cfg.train.layer_norm,
        "activation": "relu",
        "config_toml": config_to_toml(cfg),
    }
    return save_policy(path, [w for w, _ in dense], [b for _, b in dense],
                       [s for s, _ in norms], [b for _, b in norms], meta)


def plot_training_curve(path: Path, rows: list[dict]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ep = [r["episodes"] for r in rows]
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
    a1.plot(ep, [r["return_mean"] for r in rows], color="tab:blue")
    a1.set_ylabel("mean episode return")
    a1.set_title("Training (thesis Fig. 3.4): return and success per chunk")
    a1.grid(alpha=0.3)
    a2.plot(ep, [r["success_raw_rate"] for r in rows], label="strict success, raw moves", color="tab:green")
    a2.plot(ep, [r["accuracy"] for r in rows], label="accuracy (eq 3.1)", color="tab:orange")
    a2.set_ylim(-0.02, 1.02)
    a2.set_xlabel("episodes")
    a2.set_ylabel("share of finished episodes")
    a2.legend(loc="lower right")
    a2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_training(cfg: Config, out: str | Path, seed: int = 0, resume: bool = False, progress: bool = True,
                 eval_episodes: int | None = None) -> dict:
    """Train, write the run directory, and return eval.json's content."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cfg_path, ckpt, book = out / "config.toml", out / CHECKPOINT, out / BOOKKEEPING
    if resume:
        if not ckpt.exists() or not cfg_path.exists():
            raise ConfigError(f"--resume: {out} has no checkpoint to resume from")
        import tomllib

        saved = config_from_dict(tomllib.loads(cfg_path.read_text()))
        if saved != cfg:
            raise ConfigError(f"--resume: the config differs from the one in {cfg_path}; resume with that config")
        raw = serialization.msgpack_restore(ckpt.read_bytes())
        state_book = {k: (v.item() if hasattr(v, "item") else v) for k, v in raw["book"].items()}
        if state_book["seed"] != seed:
            raise ConfigError(f"--resume: the run used --seed {state_book['seed']}, not {seed}")
    elif ckpt.exists():
        raise ConfigError(f"--out: {out} already holds a run; pass --resume to continue it or pick a new folder")
    else:
        cfg_path.write_text(config_to_toml(cfg))

    t_start = time.perf_counter()
    # Data parallel over the CPU cores exposed as JAX devices (jaxexo.train.devices; the CLI sets this up).
    # The device count changes the random streams: a run is reproducible on the same count.
    trainer = Trainer(cfg, devices=jax.local_devices())
    n_dev = len(trainer.devices or [0])
    if resume and state_book.get("devices", 1) != n_dev:
        raise ConfigError(f"--resume: the run used {state_book.get('devices', 1)} device(s), this process has "
                          f"{n_dev}; resume it on the same number of CPU devices")
    hyper = Hyperparams.from_config(cfg)
    ts = jax.jit(trainer.init)(jax.random.PRNGKey(seed), hyper)
    n_chunk, total_chunks = chunking(cfg, trainer)
    rows: list[dict] = []
    chunks_done, wall_before = 0, 0.0
    metrics_path = out / "metrics.jsonl"
    best = {"params": ts.params, "score": -1.0, "chunk": 0}
    if resume:
        ts = serialization.from_state_dict(ts, raw["state"])
        best["params"] = serialization.from_state_dict(ts.params, raw["best_params"])
        best.update(score=state_book["best_score"], chunk=state_book["best_chunk"])
        chunks_done = state_book["chunks_done"]
        # Wall time so far comes from the readable copy when it matches the checkpoint (it is
        # informational: a missing or stale copy only restarts the clock).
        try:
            readable = json.loads(book.read_text())
            wall_before = readable["train_seconds"] if readable.get("chunks_done") == chunks_done else 0.0
        except (OSError, ValueError, KeyError):
            wall_before = 0.0
        lines = metrics_path.read_text().splitlines() if metrics_path.exists() else []
        rows = [json.loads(x) for x in lines[:chunks_done]]
        # Lines written after the checkpoint are recomputed identically: drop them.
        metrics_path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    run = jax.jit(trainer.run, static_argnums=2)
    active = jax.jit(trainer.active)
    validate = make_validator(cfg, trainer.net)

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=total_chunks, initial=chunks_done, unit="chunk", dynamic_ncols=True,
                   desc=f"train {cfg.train.trace} {cfg.train.control}")
    with metrics_path.open("a") as mf:
        while chunks_done < total_chunks and bool(active(ts, hyper)):
            t0 = time.perf_counter()
            ts, m = run(ts, hyper, n_chunk)
            m = np.asarray(m)
            chunks_done += 1
            wall = wall_before + time.perf_counter() - t_start
            row = _chunk_row(m, ts, chunks_done, wall, time.perf_counter() - t0)
            row["validation_success_raw"] = validate(ts.params)
            if row["validation_success_raw"] >= best["score"]:
                best.update(params=ts.params, score=row["validation_success_raw"], chunk=chunks_done)
            rows.append(row)
            mf.write(json.dumps(row) + "\n")
            mf.flush()
            bookkeeping = {"seed": seed, "chunks_done": chunks_done, "best_score": best["score"],
                           "best_chunk": best["chunk"], "devices": n_dev}
            # State, best parameters and bookkeeping in one atomic write: a run stopped at any point
            # resumes from a consistent checkpoint (wall time, which differs run to run, stays out).
            _atomic_write(ckpt, serialization.msgpack_serialize({
                "state": serialization.to_state_dict(ts),
                "best_params": serialization.to_state_dict(best["params"]),
                "book": bookkeeping}))
            _atomic_write(book, json.dumps({**bookkeeping, "train_seconds": wall}, indent=1).encode())
            if bar is not None:
                bar.update(1)
                bar.set_postfix(episodes=row["episodes"], steps_per_s=f"{row['env_steps_per_s']:.3g}",
                                ret=f"{row['return_mean']:.2f}", success_raw=f"{row['success_raw_rate']:.3f}",
                                eps=f"{row['epsilon']:.3f}", val=f"{row['validation_success_raw']:.3f}")
    if bar is not None:
        bar.close()
    train_seconds = wall_before + time.perf_counter() - t_start

    export_policy(out / "policy.npz", cfg, trainer, best["params"])
    if rows:
        plot_training_curve(out / "training_curve.png", rows)
    result = evaluate(cfg, trainer.net, best["params"], eval_episodes or cfg.train.eval_episodes)
    result.update({"episodes": int(ts.episodes), "env_steps": int(ts.env_steps),
                   "train_seconds": round(train_seconds, 3), "seed": seed,
                   "selected_chunk": best["chunk"], "validation_success_raw": best["score"], "devices": n_dev})
    _atomic_write(out / "eval.json", json.dumps(result, indent=2) + "\n")
    return result
