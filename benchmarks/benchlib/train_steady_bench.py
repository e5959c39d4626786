"""Trainer steady rate of given configs through the real driver. benchmarks/bench_train.py --steady
loads this file by its path and it imports only jaxexo's public driver, so that it can measure an
older checkout too. Method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import collections
import dataclasses
import importlib.util
import json
import subprocess
import tempfile
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from jax import monitoring
from jax.sharding import Mesh
from jax.sharding import PartitionSpec as P

from jaxexo.config import load_config
from jaxexo.env import ExoStepEnv
from jaxexo.evaluation.machine import write_result
from jaxexo.summary import Summary, table
from jaxexo.train.driver import run_training


def matmul_roofline(
    rows: int = 1024, width: int = 128, length: int = 200, repeats: int = 5
) -> float:
    """The machine's float32 matmul rate (FLOP/s): (rows, width) x (width, width) products in a jitted
    loop on every host device at once (one block of rows each), median of ``repeats`` timed calls.
    A 128-wide MLP layer is this product, so it bounds what the trainer's network work can reach."""
    devs = jax.local_devices()

    def loop(x, w):
        return jax.lax.scan(lambda c, _: ((c @ w) * 0.01, None), x, None, length=length)[0]

    f = jax.jit(
        jax.shard_map(
            loop, mesh=Mesh(np.array(devs), ("d",)), in_specs=(P("d"), P()), out_specs=P("d")
        )
    )
    x, w = jnp.ones((rows * len(devs), width)), jnp.full((width, width), 0.01)
    f(x, w).block_until_ready()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        f(x, w).block_until_ready()
        times.append(time.perf_counter() - t0)
    return 2.0 * rows * len(devs) * width * width * length / Summary.of(times).median


def network_flops_per_step(cfg) -> float:
    """Matmul FLOPs of the trainer's network per env step: the acting pass and the target network's
    bootstrap pass (one forward each), and the gradient passes (forward and backward: three forwards'
    worth), num_epochs of them in the forward view, one per step in the backward view (each
    environment's gradient of Q(s, a) for its traces). LayerNorm, biases and activations are not
    counted."""
    env = ExoStepEnv(cfg)
    widths = [env.obs_dim, *cfg.train.hidden, env.num_actions]
    forward = sum(2.0 * a * b for a, b in zip(widths[:-1], widths[1:]))
    gradient_passes = cfg.train.num_epochs if cfg.train.trace == "forward" else 1
    return forward * (2 + 3 * gradient_passes)


def _commit() -> str:
    """The short commit of the checkout the imported jaxexo comes from ("?" where git cannot tell)."""
    src = Path(importlib.util.find_spec("jaxexo").origin).resolve().parent.parent
    try:
        return (
            subprocess.run(
                ["git", "-C", str(src), "rev-parse", "--short", "HEAD"],
                capture_output=True,
                text=True,
            ).stdout.strip()
            or "?"
        )
    except OSError:
        return "?"


def run_train_steady(paths, budget: int, label: str, out_dir: Path) -> dict:
    """Each config of ``paths`` trained for ``budget`` env steps (seed 0, a temporary run directory),
    printed and written as train-steady[-label]_<date>_<machine>.{json,md}."""
    counts = collections.Counter()

    def listen(event, duration, **kw):
        if event == "/jax/core/compile/backend_compile_duration":
            counts[kw.get("fun_name")] += 1

    monitoring.register_event_duration_secs_listener(listen)
    commit = _commit()
    rows = []
    for path in paths:
        cfg = load_config(path)
        cfg = dataclasses.replace(
            cfg, train=dataclasses.replace(cfg.train, budget_env_steps=budget)
        )
        counts.clear()
        with tempfile.TemporaryDirectory() as d:
            res = run_training(cfg, Path(d) / "run", seed=0, progress=False)
            chunks = [
                json.loads(x) for x in (Path(d) / "run" / "metrics.jsonl").read_text().splitlines()
            ]
        rates = [c["env_steps_per_s"] for c in chunks]
        row = {
            "config": Path(path).name,
            "budget_env_steps": budget,
            "devices": len(jax.local_devices()),
            "chunks": len(chunks),
            "chunk_env_steps_per_s": rates,
            "steady_env_steps_per_s": Summary.of(rates[2:]).median if len(rates) > 2 else None,
            "compilations_run": counts.get("jit(run)", 0),
            "train_seconds": res["train_seconds"],
            "validation_success_raw": res["validation_success_raw"],
            "success_raw": res["success_raw"],
            "network_flops_per_env_step": network_flops_per_step(cfg),
        }
        rows.append(row)
        print(json.dumps(row), flush=True)
    roof = matmul_roofline()
    for r in rows:
        r["network_flop_per_s"] = (r["steady_env_steps_per_s"] or 0.0) * r[
            "network_flops_per_env_step"
        ]
        r["fraction_of_roofline"] = r["network_flop_per_s"] / roof
    md = steady_markdown(rows, label, commit, roof)
    name = "train-steady" + (f"-{label}" if label else "")
    write_result(
        name,
        {"rows": rows, "commit": commit, "label": label, "matmul_roofline_flop_per_s": roof},
        md,
        out_dir,
    )
    print(md)
    return {"rows": rows}


def _steady_cells(r: dict) -> tuple:
    c, nan = r["chunk_env_steps_per_s"], float("nan")
    return (
        *(r["config"], f"{r['budget_env_steps']:,}", r["chunks"], r["compilations_run"]),
        *(f"{c[0] / 1e3:.0f}k", f"{c[1] / 1e3 if len(c) > 1 else nan:.0f}k"),
        f"{(r['steady_env_steps_per_s'] or nan) / 1e3:.0f}k",
        f"{r['network_flop_per_s'] / 1e9:.0f}",
        f"{100 * r['fraction_of_roofline']:.0f} %",
        f"{r['train_seconds']:.1f}",
    )


def steady_markdown(rows: list[dict], label: str, commit: str, roof: float) -> str:
    head = "config|env steps|chunks|compilations of the chunk program|chunk 1 (incl. compile)|"
    head += "chunk 2|steady (median of chunks 3+)|network GFLOP/s at the steady rate|of the matmul roofline|"
    head += "train s"
    lines = [
        f"# Trainer steady rate through `jaxexo train` ({label}, jaxexo at {commit})",
        "",
        *table(head.split("|"), map(_steady_cells, rows)),
        "",
        "Env-steps/s per chunk as metrics.jsonl reports them. Network GFLOP/s: the steady rate times the "
        "matmul FLOPs of the acting, bootstrap and update passes per env step (LayerNorm, biases and the "
        "environment not counted). Matmul roofline: (1024, 128) x (128, 128) float32 products in a jitted loop "
        f"on every host device, measured in the same process after the runs: {roof / 1e9:.0f} GFLOP/s. "
        "Shared machine: other jobs may run at the same time, so rates are noisy; compare rows measured back "
        "to back.",
    ]
    return "\n".join(lines)
