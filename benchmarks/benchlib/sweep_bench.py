"""Sweep benchmarks: vmapped agents against one large run, devices, agents per minute, the 10-minute
target run and the lanes. Run by benchmarks/bench_sweep.py; method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import copy
import dataclasses
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

from jaxexo.config import Config
from jaxexo.summary import Summary, table
from jaxexo.sweep.spec import load_sweep, sweep_from_dict
from jaxexo.train.lanes import LANES, over_agents, over_lanes
from jaxexo.train.trainer import Hyperparams, Trainer

from benchlib.runner import Record, timed_calls
from benchlib.train_bench import throughput

TARGET_S = 600.0


def _m(r) -> str:
    """A row's env-steps/s in millions, as the tables show it."""
    return f"{r['env_steps_per_s'] / 1e6:.3f}"


@dataclasses.dataclass(frozen=True)
class AgentsThroughput(Record):
    """Training env-steps/s of a batch of agents (the median call's figures)."""

    agents: int
    devices: int
    env_steps_per_call: int
    median_s: float
    env_steps_per_s: float
    compile_s: float
    repeats: int


def agents_throughput(
    cfg: Config, n_agents: int, devices, updates: int, repeats: int = 3, wrap=over_agents
) -> AgentsThroughput:
    """Training env-steps/s of ``n_agents`` agents (learning rates spread over a decade, one seed
    each) vmapped and split over ``devices``: the sweep's training program without its evaluation.
    ``wrap``: over_agents (one vmapped batch per device) or over_lanes (fixed blocks, what sweeps and
    populations run)."""
    tr = Trainer(cfg)
    h = Hyperparams.from_config(cfg)
    hyper = jax.tree.map(
        lambda x: np.broadcast_to(np.asarray(x), (n_agents,) + np.shape(x)).copy(), h
    )
    hyper = hyper.replace(
        lr=np.asarray(cfg.train.lr * np.logspace(-0.5, 0.5, n_agents), np.float32)
    )
    keys = np.stack([np.asarray(jax.random.PRNGKey(s)) for s in range(n_agents)])
    ts = wrap(tr.init, devices, 2)(keys, hyper)
    run = wrap(lambda t, hh: tr.run(t, hh, updates), devices, 2)
    compile_s, times = timed_calls(lambda s: run(s, hyper)[0], ts, repeats)
    steps = n_agents * updates * cfg.train.num_envs * cfg.train.rollout_steps
    med = Summary.of(times).median
    return AgentsThroughput(
        agents=n_agents,
        devices=len(devices),
        env_steps_per_call=steps,
        median_s=med,
        env_steps_per_s=steps / med,
        compile_s=compile_s,
        repeats=repeats,
    )


def _timed_sweep(sweep, progress: bool = False) -> tuple[dict, float, list[dict]]:
    """``run_sweep`` of ``sweep`` in a temporary folder: its result, its wall seconds (everything
    included) and the rows of its results.csv."""
    import csv

    from jaxexo.sweep.runner import run_sweep

    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        res = run_sweep(sweep, Path(d) / "sweep", progress=progress)
        wall = time.perf_counter() - t0
        with open(Path(d) / "sweep" / "results.csv") as f:
            return res, wall, list(csv.DictReader(f))


def agents_per_minute(
    base_raw: dict, n_configs: int, budget_env_steps: int, progress=print
) -> dict:
    """A whole sweep of ``n_configs`` learning rates x 1 seed at ``budget_env_steps`` each."""
    raw = copy.deepcopy(base_raw)
    raw["train"]["budget_env_steps"] = budget_env_steps
    lrs = [float(x) for x in np.logspace(-4, -2, n_configs)]
    raw["sweep"] = {"seeds": 1, "grid": {"train.lr": lrs}}
    sweep = sweep_from_dict(raw)
    res, wall, _ = _timed_sweep(sweep)
    row = {
        "configs": n_configs,
        "agents": sweep.num_agents,
        "env_steps": res["env_steps"],
        "wall_s": wall,
        "agents_per_min": sweep.num_agents / wall * 60.0,
        "env_steps_per_s": res["env_steps"] / wall,
        "best_success": res["ranking"][0]["success_mean"],
    }
    progress(
        f"  {n_configs:4d} configurations: {wall:7.1f} s, {row['agents_per_min']:7.1f} agents/min, "
        f"{_m(row)} M env-steps/s (all included)"
    )
    return row


def vmap_throughputs(cfg: Config, devices, progress=print, updates: int = 10) -> dict:
    """Training env-steps/s of 64 agents vmapped over ``devices`` and over one device, and of one
    run of 64 times the environments, data parallel over ``devices``: the payload's three entries."""
    tc = cfg.train
    sweep64 = agents_throughput(cfg, 64, devices, updates).to_dict()
    progress(f"64 agents x {tc.num_envs} envs, {len(devices)} devices: {_m(sweep64)} M env-steps/s")
    one_dev = agents_throughput(cfg, 64, devices[:1], updates).to_dict()
    progress(f"64 agents x {tc.num_envs} envs, 1 device: {_m(one_dev)} M env-steps/s")
    big = dataclasses.replace(cfg, train=dataclasses.replace(tc, num_envs=64 * tc.num_envs))
    single = throughput(big, updates, repeats=3, devices=devices).to_dict()
    progress(
        f"one run of {big.train.num_envs} envs, {single['devices']} devices: "
        f"{_m(single)} M env-steps/s"
    )
    return {"sweep_64": sweep64, "sweep_64_one_device": one_dev, "single_run": single}


def target_run(sweep, progress=print) -> dict:
    """The whole sweep through ``run_sweep`` (compilation, evaluation and the report included),
    its wall time against TARGET_S."""
    res, wall, _ = _timed_sweep(sweep, progress=True)
    full = {
        "agents": sweep.num_agents,
        "env_steps": res["env_steps"],
        "wall_s": wall,
        "env_steps_per_s": res["env_steps"] / wall,
        "target_s": TARGET_S,
        "best": {
            k: res["ranking"][0][k]
            for k in ("label", "success_mean", "success_std", "held_out_success")
        },
        "diverged_agents": sum(e["diverged"] for e in res["ranking"]),
    }
    progress(
        f"target run: {sweep.num_agents} agents, {res['env_steps']:,.0f} env steps in {wall:.1f} s "
        f"({'within' if wall <= TARGET_S else 'over'} the {TARGET_S:.0f} s target)"
    )
    return full


def sweep_markdown(cfg: Config, payload: dict, per_minute_budget: int) -> str:
    """The sweep benchmarks' Markdown, from their figures (``run_sweep_benchmark``'s payload)."""
    tc = cfg.train
    sweep64, one_dev = payload["sweep_64"], payload["sweep_64_one_device"]
    single, full = payload["single_run"], payload["target_run"]
    n, per_min = tc.num_envs, payload["agents_per_minute"]
    vm = f"64 agents × {n} envs (vmapped)"
    lines = [
        "# Sweep benchmarks",
        "",
        f"Static settings (configs/sweeps/benchmark.toml): network 2-{'-'.join(map(str, tc.hidden))}-36, "
        f"observation `{cfg.env.obs_mode}`, {tc.num_envs} environments per agent, T = {tc.rollout_steps}, "
        f"{tc.num_minibatches} minibatch(es) per update, forward view, {tc.control}.",
        "",
        *table(
            ("what", "M env-steps/s"),
            [
                (f"{vm}, {sweep64['devices']} CPU devices", _m(sweep64)),
                (f"{vm}, 1 CPU device", _m(one_dev)),
                (
                    f"one run of {64 * n} envs, {single['devices']} CPU devices (data parallel)",
                    _m(single),
                ),
            ],
        ),
        "",
        *table(
            f"configurations (1 seed, {per_minute_budget:,} env steps each)|wall s (all included)|"
            "agents per minute|M env-steps/s".split("|"),
            [
                (r["configs"], f"{r['wall_s']:.1f}", f"{r['agents_per_min']:.1f}", _m(r))
                for r in per_min
            ],
            "rrrr",
        ),
    ]
    if full:
        lines += [
            "",
            f"Target run (64 configurations × 4 seeds × {tc.num_envs} envs × {tc.budget_env_steps:,} env "
            f"steps): {full['env_steps']:,.0f} env steps in **{full['wall_s']:.1f} s** "
            f"(target ≤ {TARGET_S:.0f} s), {_m(full)} M env-steps/s including "
            f"compilation, evaluation and the report; best: {full['best']['label']} "
            f"(success {full['best']['success_mean']:.3f} ± {full['best']['success_std']:.3f}).",
        ]
    return "\n".join(lines)


def run_sweep_benchmark(
    out_dir,
    sweep_file: str | Path,
    target: bool = True,
    per_minute_budget: int = 500_000,
    progress=print,
) -> dict:
    from jaxexo.evaluation.machine import write_result

    sweep = load_sweep(sweep_file)
    cfg = sweep.members[0].config
    tc = cfg.train
    devices = jax.local_devices()
    progress(
        f"static settings: hidden {list(tc.hidden)}, obs {cfg.env.obs_mode}, {tc.num_envs} envs/agent, "
        f"T = {tc.rollout_steps}, {tc.num_minibatches} minibatch(es); {len(devices)} CPU device(s)"
    )
    vmapped = vmap_throughputs(cfg, devices, progress)
    progress(
        f"agents trained per minute ({per_minute_budget:,} env steps each, one seed, everything included):"
    )
    base_raw = {k: v for k, v in sweep.to_dict().items() if k != "sweep"}
    per_minute = [
        agents_per_minute(base_raw, n, per_minute_budget, progress) for n in (1, 8, 64, 256)
    ]
    full = target_run(sweep, progress) if target else None
    payload = {
        "settings": {
            "hidden": list(tc.hidden),
            "obs_mode": cfg.env.obs_mode,
            "num_envs": tc.num_envs,
            "rollout_steps": tc.rollout_steps,
            "num_minibatches": tc.num_minibatches,
        },
        **vmapped,
        "agents_per_minute": per_minute,
        "target_run": full,
    }
    md = sweep_markdown(cfg, payload, per_minute_budget)
    write_result("sweep", payload, md, out_dir)
    progress(md)
    return payload


# Greedy success on the test layouts an agent must reach to count as having learned (the sweep's
# TARGET_SUCCESS, which its training-curve figure episodes_to_90 uses too).
LEARNED_SUCCESS = 0.9


def run_learning_benchmark(out_dir, sweep_file: str | Path, progress=print) -> dict:
    """A whole ``run_sweep`` of agents that learn (configs/sweeps/learning_benchmark.toml): wall time
    (compilation, training, evaluation and the report included), agents per minute, env-steps/s, the
    agents that met LEARNED_SUCCESS, and the compilations of each group's chunk program (one each)."""
    import collections

    from jax import monitoring

    from jaxexo.evaluation.machine import write_result

    counts = collections.Counter()

    def listen(event, duration, **kw):
        if event == "/jax/core/compile/backend_compile_duration":
            counts[kw.get("fun_name")] += 1

    monitoring.register_event_duration_secs_listener(listen)
    sweep = load_sweep(sweep_file)
    res, wall, rows = _timed_sweep(sweep)
    success = np.array([float(r["success"]) for r in rows])
    program = sum(v for k, v in counts.items() if "agent" in k)
    out = {
        "sweep_file": str(Path(sweep_file).name),
        "agents": sweep.num_agents,
        "groups": len(sweep.groups),
        "env_steps": res["env_steps"],
        "wall_s": wall,
        "agents_per_min": sweep.num_agents / wall * 60.0,
        "env_steps_per_s": res["env_steps"] / wall,
        "learned_success": LEARNED_SUCCESS,
        "agents_learned": int(np.sum(success >= LEARNED_SUCCESS)),
        "success": success.tolist(),
        "compilations_per_group": program / max(1, len(sweep.groups)),
        "devices": len(jax.local_devices()),
    }
    head = "agents|groups|env steps|wall s (all included)|agents per minute|M env-steps/s|"
    head += f"agents with greedy success >= {LEARNED_SUCCESS}|compilations per group"
    cells = [out["agents"], out["groups"], f"{out['env_steps']:,.0f}", f"{wall:.1f}"]
    cells += [
        f"{out['agents_per_min']:.1f}",
        _m(out),
        f"{out['agents_learned']} of {out['agents']}",
    ]
    cells.append(f"{out['compilations_per_group']:g}")
    md = "\n".join(
        [
            f"# Learning sweep benchmark ({out['sweep_file']})",
            "",
            *table(head.split("|"), [cells], "r" * 8),
            "",
            "Greedy success per agent (test layouts): "
            + ", ".join(f"{x:.3f}" for x in success)
            + ".",
            "",
            "Shared machine: other jobs ran at the same time, so times are noisy.",
        ]
    )
    write_result("sweep-learning", out, md, out_dir)
    progress(md)
    return out


def run_lanes_benchmark(out_dir, sweep_file: str | Path) -> dict:
    """Both programs on the sweep file's first member (16 agents, 10 updates a call) and on thesis (b)
    learns (8 agents, 100 updates), every CPU core a device; written as lanes_<date>_<machine>.*"""
    import os

    from jaxexo.config import load_config, packaged_config
    from jaxexo.evaluation.machine import write_result

    devices = jax.local_devices()
    thesis_b = load_config(Path(packaged_config("default")).parent / "thesis" / "b-learns.toml")
    cases = [
        ("sweep benchmark (256 envs, T 16)", load_sweep(sweep_file).members[0].config, 16, 10),
        ("thesis (b) learns (64 envs, T 8)", thesis_b, 8, 100),
    ]
    load_before = os.getloadavg()
    rows = []
    for name, cfg, n, updates in cases:
        for label, wrap in (
            ("one vmap per device", over_agents),
            (f"blocks of {LANES}", over_lanes),
        ):
            r = agents_throughput(cfg, n, devices, updates, repeats=3, wrap=wrap).to_dict()
            rows.append({"case": name, "program": label, **r})
            print(name, label, f"{_m(r)} M env-steps/s", flush=True)
    head = "case|agents|program|M env-steps/s|median s per call|ratio to one vmap per device"
    ratios = [r["env_steps_per_s"] / rows[i - i % 2]["env_steps_per_s"] for i, r in enumerate(rows)]
    lines = [
        "# Fixed vmap blocks against one batch per device",
        "",
        f"{len(devices)} CPU devices; load average before {tuple(round(x, 2) for x in load_before)}, after "
        f"{tuple(round(x, 2) for x in os.getloadavg())} (a shared machine). Training only (no evaluation); "
        "median of 3 compiled calls.",
        "",
        *table(
            head.split("|"),
            [
                (r["case"], r["agents"], r["program"], _m(r), f"{r['median_s']:.2f}", f"{q:.2f}")
                for r, q in zip(rows, ratios)
            ],
            "lrlrrr",
        ),
    ]
    payload = {"rows": rows, "load_before": load_before}
    for p in write_result("lanes", payload, "\n".join(lines), out_dir):
        print(p)
    return payload
