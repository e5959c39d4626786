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

import jax
import numpy as np

from jaxexo.config import Config
from jaxexo.train.trainer import Hyperparams, Trainer


def throughput(cfg: Config, updates_per_call: int, repeats: int = 3) -> dict:
    tr = Trainer(cfg)
    hyper = Hyperparams.from_config(cfg)
    ts = jax.jit(tr.init)(jax.random.PRNGKey(0), hyper)
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
            "compile_s": compile_s, "repeats": repeats}


def thesis_network_config(base: Config, trace: str, num_envs: int = 4096) -> Config:
    tc = dataclasses.replace(base.train, trace=trace, num_envs=num_envs, hidden=(64, 32, 32, 32),
                             layer_norm=False, rollout_steps=16, num_minibatches=4, num_epochs=1,
                             budget_env_steps=10**9, budget_episodes=0)
    env = dataclasses.replace(base.env, obs_mode="thesis")
    return dataclasses.replace(base, train=tc, env=env)
