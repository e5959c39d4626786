"""Trainer throughput and time-to-result benchmarks (issue targets for the TD(lambda) trainer).

- throughput: env-steps/s of whole training updates (rollout + lambda-returns + Adam steps) for the
  thesis network (2 -> 64 -> 32 -> 32 -> 32 -> 36) at 4096 environments, forward view and backward
  view, medians of repeated compiled chunks after a warm-up;
- default model: wall time (compilation included) and eval.json figures of `jaxexo train` on
  configs/default.toml.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import jax
import numpy as np

from jaxexo.config import Config
from jaxexo.train.trainer import Hyperparams, Trainer


def throughput(cfg: Config, updates_per_call: int, repeats: int = 3, devices=None) -> dict:
    tr = Trainer(cfg, devices=devices)
    hyper = Hyperparams.from_config(cfg)
    # laid out as the chunks return it: one compilation (Trainer.place)
    ts = tr.place(jax.jit(tr.init)(jax.random.PRNGKey(0), hyper))
    run = jax.jit(tr.run, static_argnums=2)
    t0 = time.perf_counter()
    ts, _ = jax.block_until_ready(run(ts, hyper, updates_per_call))
    compile_s = time.perf_counter() - t0
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        ts, _ = jax.block_until_ready(run(ts, hyper, updates_per_call))
        times.append(time.perf_counter() - t0)
    steps = updates_per_call * cfg.train.num_envs * cfg.train.rollout_steps
    med = float(np.median(times))
    return {"trace": cfg.train.trace, "control": cfg.train.control, "num_envs": cfg.train.num_envs,
            "hidden": list(cfg.train.hidden), "rollout_steps": cfg.train.rollout_steps,
            "env_steps_per_call": steps, "median_s": med, "env_steps_per_s": steps / med,
            "compile_s": compile_s, "repeats": repeats, "devices": len(tr.devices or [0])}


def thesis_network_config(base: Config, trace: str, num_envs: int = 4096) -> Config:
    tc = dataclasses.replace(base.train, trace=trace, num_envs=num_envs, hidden=(64, 32, 32, 32),
                             layer_norm=False, rollout_steps=16, num_minibatches=4, num_epochs=1,
                             budget_env_steps=10**9, budget_episodes=0)
    env = dataclasses.replace(base.env, obs_mode="thesis")
    return dataclasses.replace(base, train=tc, env=env)


def run_train_benchmark(out_dir, default_config: str = "configs/default.toml", thesis_configs=(),
                        progress=print) -> dict:
    """Throughput (thesis network, 4096 envs, forward view with 4 and 1 minibatches, backward view)
    and time-to-result of the default model and of the thesis configs, each through the real
    `jaxexo train` driver (compilation included in the wall time)."""
    import tempfile

    from jaxexo.evaluation.machine import write_result
    from jaxexo.config import load_config
    from jaxexo.train.driver import run_training

    base = load_config(default_config)
    rows = []
    devices = jax.local_devices()
    for trace, minibatches, updates in (("forward", 4, 10), ("forward", 1, 10), ("backward", 4, 1)):
        cfg = thesis_network_config(base, trace)
        cfg = dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, num_minibatches=minibatches))
        r = throughput(cfg, updates, repeats=3 if trace == "forward" else 2, devices=devices)
        r["num_minibatches"] = minibatches
        progress(f"thesis network, {trace} view, {minibatches} minibatch(es), 4096 envs, {r['devices']} device(s): "
                 f"{r['env_steps_per_s'] / 1e6:.3f} M env-steps/s")
        rows.append(r)
    runs = {}
    for name in [default_config, *thesis_configs]:
        with tempfile.TemporaryDirectory() as d:
            res = run_training(load_config(name), d, seed=0, progress=False)
        runs[name] = {k: res[k] for k in ("success_raw", "accuracy", "held_out", "by_obstacle", "train_seconds",
                                          "episodes", "env_steps")}
        progress(f"{name}: trained in {res['train_seconds']:.1f} s, success_raw {res['success_raw']:.3f}, "
                 f"held-out success_raw {(res['held_out'] or {}).get('success_raw')}")
    lines = ["# Trainer benchmarks", "", "| what | figure |", "|---|---:|"]
    for r in rows:
        mb = "" if r["trace"] == "backward" else f", {r['num_minibatches']} minibatch(es)/update"
        lines.append(f"| thesis network, {r['trace']} view{mb}, {r['num_envs']} envs, {r['devices']} CPU devices | "
                     f"{r['env_steps_per_s'] / 1e6:.3f} M env-steps/s |")
    for name, r in runs.items():
        held = (r["held_out"] or {}).get("success_raw")
    lines += ["", "| config | train wall s (incl. compile) | episodes | env steps | accuracy (eq 3.1) | "
              "strict success, raw moves | held-out, raw moves |", "|---|---:|---:|---:|---:|---:|---:|"]
    for name, r in runs.items():
        held = (r["held_out"] or {}).get("success_raw")
        lines.append(f"| `{Path(name).relative_to(Path(name).parents[1]) if 'thesis' in name else Path(name).name}` | "
                     f"{r['train_seconds']:.1f} | {r['episodes']} | {r['env_steps']:,} | {r['accuracy']:.3f} | "
                     f"{r['success_raw']:.3f} | {held:.3f} |")
    md = "\n".join(lines)
    write_result("train", {"throughput": rows, "runs": runs}, md, out_dir)
    progress(md)
    return {"throughput": rows, "runs": runs}
