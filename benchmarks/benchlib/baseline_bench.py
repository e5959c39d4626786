"""jaxexo's trainer against the thesis-style trainer (thesis_baseline) in one process: env-steps/s of
each and the wall time each needs to reach the same greedy success. Needs the ``bench`` extra.
Method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from jaxexo.config import Config, load_config
from jaxexo.physics.actions import NUM_ACTIONS
from jaxexo.summary import table

from benchlib.runner import Record
from benchlib.thesis_baseline import (
    BaselineSettings,
    NumpyExoEnv,
    SequentialTDLambda,
    layout_pool,
)

POOL = 20_000


def make_baseline(
    cfg: Config, pool: dict, eps_decay_steps: int, seed: int = 0
) -> SequentialTDLambda:
    """The sequential learner on cfg's environment, network and hyperparameters."""
    t = cfg.train
    env = NumpyExoEnv(cfg, pool, seed)
    obs_dim = len(env.reset())
    return SequentialTDLambda(
        env,
        obs_dim,
        NUM_ACTIONS,
        t.hidden,
        t.layer_norm,
        lr=t.lr,
        gamma=t.gamma,
        lam=t.lam,
        eps_start=t.eps_start,
        eps_end=t.eps_end,
        eps_decay_steps=eps_decay_steps,
        max_grad_norm=t.max_grad_norm,
        off_policy=t.control == "off_policy",
        settings=BaselineSettings(horizon=t.rollout_steps, seed=seed),
    )


@dataclasses.dataclass(frozen=True)
class BaselineThroughput(Record):
    """The thesis-style baseline's env-steps/s (and its environment's alone) and its settings."""

    env_steps: int
    seconds: float
    env_steps_per_s: float
    env_only_steps_per_s: float
    batch_size: int
    horizon: int
    torch_threads: int


def baseline_throughput(
    cfg: Config, pool: dict, seconds: float, warmup_steps: int = 500
) -> BaselineThroughput:
    learner = make_baseline(cfg, pool, eps_decay_steps=10**9)
    learner.train(env_steps=warmup_steps)
    res = learner.train(seconds=seconds, env_steps=10**12)
    steps = res["env_steps"] - warmup_steps
    # The environment alone (random actions), for the breakdown.
    env = NumpyExoEnv(cfg, pool, 1)
    env.reset()
    rng = np.random.default_rng(0)
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < min(5.0, seconds):
        _, _, term, trunc, _ = env.step(int(rng.integers(NUM_ACTIONS)))
        n += 1
        if term or trunc:
            env.reset()
    env_rate = n / (time.perf_counter() - t0)
    return BaselineThroughput(
        env_steps=steps,
        seconds=res["train_seconds"],
        env_steps_per_s=steps / res["train_seconds"],
        env_only_steps_per_s=env_rate,
        batch_size=learner.s.batch_size,
        horizon=learner.s.horizon,
        torch_threads=learner.s.torch_threads,
    )


def time_to_target(rows: list[dict], target: float, key: str = "validation_success") -> dict | None:
    for r in rows:
        if r[key] >= target:
            return r
    return None


@dataclasses.dataclass(frozen=True)
class Budgets:
    """The benchmark's settings: seconds of the baseline's throughput run and of its training, the
    validation success targets, env steps between the baseline's validations, where progress goes."""

    throughput_seconds: float
    baseline_seconds: float
    targets: tuple
    validate_every: int
    progress: Callable


def throughput_figures(base: Config, b: Budgets) -> dict:
    """Env-steps/s of jaxexo's trainer and of the baseline on the thesis network, and their ratio."""
    import jax

    from benchlib.train_bench import thesis_network_config, throughput

    tcfg = thesis_network_config(base, "forward")
    jx = throughput(tcfg, 10, repeats=3, devices=jax.local_devices()).to_dict()
    b.progress(
        f"jaxexo trainer, thesis network, 4096 envs: {jx['env_steps_per_s'] / 1e6:.3f} M env-steps/s"
    )
    bl = baseline_throughput(tcfg, layout_pool(tcfg, POOL), b.throughput_seconds).to_dict()
    b.progress(
        f"thesis-style baseline, thesis network: {bl['env_steps_per_s']:.0f} env-steps/s "
        f"(environment alone {bl['env_only_steps_per_s']:.0f}/s)"
    )
    ratio = jx["env_steps_per_s"] / bl["env_steps_per_s"]
    b.progress(f"ratio: {ratio:.0f}x (target >= 1000x)")
    return {"jaxexo": jx, "baseline": bl, "ratio": ratio}


def jaxexo_curve(base: Config, b: Budgets) -> tuple[list[dict], float]:
    """jaxexo's validation curve training the default model through the driver (wall time with
    compilation), and its training seconds."""
    from jaxexo.train.driver import run_training

    with tempfile.TemporaryDirectory() as d:
        res = run_training(base, d, seed=0, progress=False)
        lines = [json.loads(x) for x in (Path(d) / "metrics.jsonl").read_text().splitlines()]
    rows = [r["members"][res["exported_member"]] for r in lines]  # the exported agent's rows
    curve = [
        {
            "env_steps": r["env_steps"],
            "wall_s": r["wall_s"],
            "validation_success": r["validation_success_raw"],
        }
        for r in rows
    ]
    b.progress(
        f"jaxexo default model: {res['train_seconds']:.1f} s, final validation "
        f"{rows[-1]['validation_success_raw']:.3f}"
    )
    return curve, res["train_seconds"]


def baseline_curve(base: Config, b: Budgets) -> tuple[SequentialTDLambda, dict, list[dict]]:
    """The baseline trained on the default model for its time budget, validated every
    ``validate_every`` env steps (off the clock) until it reaches the highest target, and at its
    end: the learner, its training figures and its validation curve."""
    import jax

    from jaxexo.train.evaluate import make_validator
    from jaxexo.train.network import QNetwork

    pool = layout_pool(base, POOL)
    rate = baseline_throughput(base, pool, min(20.0, b.throughput_seconds)).env_steps_per_s
    planned = int(rate * b.baseline_seconds)
    learner = make_baseline(
        base, pool, eps_decay_steps=max(1, int(base.train.eps_decay_fraction * planned))
    )
    net = QNetwork(
        hidden=base.train.hidden, num_actions=NUM_ACTIONS, layer_norm=base.train.layer_norm
    )
    validate = make_validator(base, net)
    curve: list[dict] = []

    def on_eval(lr: SequentialTDLambda, train_s: float) -> bool:
        v = validate(jax.tree.map(np.asarray, lr.export_flax_params()))
        curve.append(
            {
                "env_steps": lr.env_steps,
                "train_s": train_s,
                "validation_success": v,
                "epsilon": lr.epsilon(),
            }
        )
        b.progress(
            f"  baseline {lr.env_steps} env steps, {train_s:.0f} s: validation {v:.3f}, eps {lr.epsilon():.2f}"
        )
        return v >= max(b.targets)

    bres = learner.train(
        seconds=b.baseline_seconds, callback=on_eval, callback_every=b.validate_every
    )
    if not curve or curve[-1]["env_steps"] != learner.env_steps:
        on_eval(learner, bres["train_seconds"])
    return learner, bres, curve


def reach(jx_curve: list[dict], bl_curve: list[dict], target: float, bl_rate: float) -> dict:
    """The wall seconds (and env steps) each trainer needed to reach ``target``, the baseline's
    extrapolated at its rate ``bl_rate`` where it did not reach it (module docstring), the speed-up."""
    j = time_to_target(jx_curve, target)
    b = time_to_target(bl_curve, target)
    entry = {
        "target": target,
        "jaxexo_s": j["wall_s"] if j else None,
        "jaxexo_env_steps": j["env_steps"] if j else None,
    }
    if b is not None:
        entry.update(
            baseline_s=b["train_s"],
            baseline_env_steps=b["env_steps"],
            baseline_extrapolated=False,
        )
    elif j is not None:
        entry.update(
            baseline_s=j["env_steps"] / bl_rate,
            baseline_env_steps=None,
            baseline_extrapolated=True,
        )
    else:
        entry.update(baseline_s=None, baseline_env_steps=None, baseline_extrapolated=None)
    if entry["jaxexo_s"] and entry["baseline_s"]:
        entry["speedup"] = entry["baseline_s"] / entry["jaxexo_s"]
    return entry


def run_baseline_benchmark(
    out_dir,
    default_config: str = "configs/default.toml",
    throughput_seconds: float = 60.0,
    baseline_seconds: float = 600.0,
    targets=(0.5, 0.9),
    validate_every: int = 20_000,
    progress=print,
) -> dict:
    import jax  # noqa: F401
    import torch

    from jaxexo.evaluation.machine import write_result

    b = Budgets(throughput_seconds, baseline_seconds, targets, validate_every, progress)
    base = load_config(default_config)
    # The load average before and after: other processes on the machine make every figure slower.
    result: dict = {
        "torch": torch.__version__,
        "targets": list(targets),
        "load_avg_before": os.getloadavg(),
    }
    # 1. Throughput, thesis network
    result["throughput"] = throughput_figures(base, b)
    # 2. Time to the same success rate, default model
    jx_curve, jx_seconds = jaxexo_curve(base, b)
    learner, bres, bl_curve = baseline_curve(base, b)
    result["time_to_success"] = {
        "config": Path(default_config).name,
        "jaxexo_curve": jx_curve,
        "baseline_curve": bl_curve,
        "baseline_budget_s": baseline_seconds,
        "baseline_env_steps_per_s": bres["env_steps_per_s"],
        "baseline_eps_decay_steps": learner.eps_decay_steps,
        "reach": {
            str(tgt): reach(jx_curve, bl_curve, tgt, bres["env_steps_per_s"]) for tgt in targets
        },
        "baseline_best_validation": max(r["validation_success"] for r in bl_curve),
        "jaxexo_train_seconds": jx_seconds,
    }
    result["load_avg_after"] = os.getloadavg()
    md = markdown(result)
    write_result("baseline", result, md, out_dir)
    progress(md)
    return result


def markdown(r: dict) -> str:
    t = r["throughput"]
    jx, bl = t["jaxexo"], t["baseline"]
    lines = [
        "# jaxexo trainer vs thesis-style sequential trainer (PyTorch)",
        "",
        *table(
            ("trainer (thesis network, thesis observation)", "env-steps/s"),
            [
                (
                    f"jaxexo, {jx['num_envs']} envs, forward view, {jx['devices']} CPU devices",
                    f"{jx['env_steps_per_s']:,.0f}",
                ),
                (
                    f"thesis-style: 1 env, 1 update/step, replay batch {bl['batch_size']}, "
                    f"lambda-return window {bl['horizon']}, torch {r['torch']} "
                    f"({bl['torch_threads']} thread)",
                    f"{bl['env_steps_per_s']:,.0f}",
                ),
                (
                    "(its NumPy environment alone, random actions)",
                    f"{bl['env_only_steps_per_s']:,.0f}",
                ),
                ("**ratio**", f"**{t['ratio']:,.0f}x**"),
            ],
        ),
        "",
    ]
    ts = r["time_to_success"]
    lines += [
        f"Time to the same greedy validation success (strict, 500 training layouts), `{ts['config']}`; "
        f"baseline budget {ts['baseline_budget_s']:.0f} s at {ts['baseline_env_steps_per_s']:.0f} env-steps/s, "
        f"best validation {ts['baseline_best_validation']:.3f}:",
        "",
    ]
    rows = []
    for e in ts["reach"].values():
        js = "-" if e["jaxexo_s"] is None else f"{e['jaxexo_s']:.1f} ({e['jaxexo_env_steps']:,})"
        if e["baseline_s"] is None:
            bs = "-"
        elif e["baseline_extrapolated"]:
            bs = f"~{e['baseline_s']:,.0f} (extrapolated: not reached in budget)"
        else:
            bs = f"{e['baseline_s']:.1f} ({e['baseline_env_steps']:,})"
        x = e.get("speedup")
        sp = "-" if not x else (f"{x:,.0f}x" if x >= 10 else f"{x:.2f}x")
        rows.append((f"{e['target']:.2f}", js, bs, sp))
    header = ("target", "jaxexo s (env steps)", "baseline s (env steps)", "speed-up")
    lines += table(header, rows, "rrrr")
    lines += [
        "",
        f"Load average (1, 5, 15 min) before / after: {_load(r['load_avg_before'])} / "
        f"{_load(r['load_avg_after'])} on {os.cpu_count()} CPUs.",
        "",
        "Extrapolated times assume the baseline learns as much per env step as jaxexo "
        "(it makes 32 sample-gradients per env step where jaxexo makes one, so it may need fewer steps; "
        "its measured curve is in the JSON).",
    ]
    return "\n".join(lines)


def _load(avg) -> str:
    return ", ".join(f"{x:.1f}" for x in avg)
