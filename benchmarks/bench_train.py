"""Trainer benchmarks: env-steps/s of the thesis network at 4096 environments (forward and backward
view), and wall time and greedy success of `jaxexo train` on configs/default.toml and a thesis
config and the seven thesis configs. Writes benchmarks/results/train_<date>_<machine>.json and .md.

Run: python benchmarks/bench_train.py

Steady rate of given configs through the real driver: compilations of the chunk program,
the rate of each chunk (chunk 1 includes compilation), the steady rate (median of chunks 3 on):
  python benchmarks/bench_train.py --steady configs/quick.toml configs/default.toml [--budget 4000000]
      [--label NAME]
writes benchmarks/results/train-steady[-NAME]_<date>_<machine>.json and .md. This part only uses
jaxexo's public driver, so it can measure an older checkout too (run it from outside the repository
with PYTHONPATH pointing at that checkout).

The shield's mask inside the trainer, plain rule against the batched one, alternated in one process:
  python benchmarks/bench_train.py --mask-ab configs/default.toml [--updates 30] [--rounds 2]
writes benchmarks/results/train-mask-ab_<date>_<machine>.json and .md.

Where an update's time goes (rollout, environment, network passes, optimizer), per config:
  python benchmarks/bench_train.py --breakdown configs/quick.toml configs/default.toml [--label NAME]
writes benchmarks/results/train-breakdown[-NAME]_<date>_<machine>.json and .md."""

import sys
from pathlib import Path

from jaxexo.train.devices import use_all_cpu_cores

use_all_cpu_cores()


def matmul_roofline(rows: int = 1024, width: int = 128, length: int = 200, repeats: int = 5) -> float:
    """The machine's float32 matmul rate (FLOP/s): (rows, width) x (width, width) products in a jitted
    loop on every host device at once (one block of rows each), median of ``repeats`` timed calls.
    A 128-wide MLP layer is this product, so it bounds what the trainer's network work can reach."""
    import time

    import jax
    import jax.numpy as jnp
    import numpy as np
    from jax.sharding import Mesh, PartitionSpec as P

    devs = jax.local_devices()

    def loop(x, w):
        return jax.lax.scan(lambda c, _: ((c @ w) * 0.01, None), x, None, length=length)[0]

    f = jax.jit(jax.shard_map(loop, mesh=Mesh(np.array(devs), ("d",)), in_specs=(P("d"), P()), out_specs=P("d")))
    x, w = jnp.ones((rows * len(devs), width)), jnp.full((width, width), 0.01)
    f(x, w).block_until_ready()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        f(x, w).block_until_ready()
        times.append(time.perf_counter() - t0)
    return 2.0 * rows * len(devs) * width * width * length / float(np.median(times))


def network_flops_per_step(cfg) -> float:
    """Matmul FLOPs of the trainer's network per env step: the acting pass and the target network's
    bootstrap pass (one forward each), and the gradient passes (forward and backward: three forwards'
    worth), num_epochs of them in the forward view, one per step in the backward view (each
    environment's gradient of Q(s, a) for its traces). LayerNorm, biases and activations are not
    counted."""
    from jaxexo.env import ExoStepEnv

    env = ExoStepEnv(cfg)
    widths = [env.obs_dim, *cfg.train.hidden, env.num_actions]
    forward = sum(2.0 * a * b for a, b in zip(widths[:-1], widths[1:]))
    gradient_passes = cfg.train.num_epochs if cfg.train.trace == "forward" else 1
    return forward * (2 + 3 * gradient_passes)


def steady(paths, budget: int, label: str, out_dir: Path) -> dict:
    import collections
    import dataclasses
    import json
    import subprocess
    import tempfile

    import jax
    import numpy as np
    from jax import monitoring

    import jaxexo
    from jaxexo.config import load_config
    from jaxexo.evaluation.machine import write_result
    from jaxexo.train.driver import run_training

    counts = collections.Counter()

    def listen(event, duration, **kw):
        if event == "/jax/core/compile/backend_compile_duration":
            counts[kw.get("fun_name")] += 1

    monitoring.register_event_duration_secs_listener(listen)
    src = Path(jaxexo.__file__).resolve().parent.parent
    try:
        commit = subprocess.run(["git", "-C", str(src), "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True).stdout.strip() or "?"
    except OSError:
        commit = "?"
    rows = []
    for path in paths:
        cfg = load_config(path)
        cfg = dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, budget_env_steps=budget))
        counts.clear()
        with tempfile.TemporaryDirectory() as d:
            res = run_training(cfg, Path(d) / "run", seed=0, progress=False)
            chunks = [json.loads(x) for x in (Path(d) / "run" / "metrics.jsonl").read_text().splitlines()]
        rates = [c["env_steps_per_s"] for c in chunks]
        row = {"config": Path(path).name, "budget_env_steps": budget, "devices": len(jax.local_devices()),
               "chunks": len(chunks), "chunk_env_steps_per_s": rates,
               "steady_env_steps_per_s": float(np.median(rates[2:])) if len(rates) > 2 else None,
               "compilations_run": counts.get("jit(run)", 0), "train_seconds": res["train_seconds"],
               "validation_success_raw": res["validation_success_raw"], "success_raw": res["success_raw"],
               "network_flops_per_env_step": network_flops_per_step(cfg)}
        rows.append(row)
        print(json.dumps(row), flush=True)
    roof = matmul_roofline()
    for r in rows:
        r["network_flop_per_s"] = (r["steady_env_steps_per_s"] or 0.0) * r["network_flops_per_env_step"]
        r["fraction_of_roofline"] = r["network_flop_per_s"] / roof
    lines = [f"# Trainer steady rate through `jaxexo train` ({label}, jaxexo at {commit})", "",
             "| config | env steps | chunks | compilations of the chunk program | chunk 1 (incl. compile) | chunk 2 | "
             "steady (median of chunks 3+) | network GFLOP/s at the steady rate | of the matmul roofline | train s |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        c = r["chunk_env_steps_per_s"]
        lines.append(f"| {r['config']} | {r['budget_env_steps']:,} | {r['chunks']} | {r['compilations_run']} | "
                     f"{c[0] / 1e3:.0f}k | {c[1] / 1e3 if len(c) > 1 else float('nan'):.0f}k | "
                     f"{(r['steady_env_steps_per_s'] or float('nan')) / 1e3:.0f}k | {r['network_flop_per_s'] / 1e9:.0f} | "
                     f"{100 * r['fraction_of_roofline']:.0f} % | {r['train_seconds']:.1f} |")
    lines += ["", "Env-steps/s per chunk as metrics.jsonl reports them. Network GFLOP/s: the steady rate times the "
              "matmul FLOPs of the acting, bootstrap and update passes per env step (LayerNorm, biases and the "
              "environment not counted). Matmul roofline: (1024, 128) x (128, 128) float32 products in a jitted loop "
              f"on every host device, measured in the same process after the runs: {roof / 1e9:.0f} GFLOP/s. "
              "Shared machine: other jobs may run at the same time, so rates are noisy; compare rows measured back "
              "to back."]
    md = "\n".join(lines)
    name = "train-steady" + (f"-{label}" if label else "")
    write_result(name, {"rows": rows, "commit": commit, "label": label, "matmul_roofline_flop_per_s": roof}, md,
                 out_dir)
    print(md)
    return {"rows": rows}


def mask_ab(path, updates: int, rounds: int, out_dir: Path) -> dict:
    """Steady env-steps/s of the shielded trainer with the plain mask (vmap(env.action_mask)) and with
    the batched one (env.action_masks, the trainer's), compiled once each and alternated A B A B so
    that a shared machine's load hits both alike; the medians of each."""
    import time

    import jax
    import numpy as np

    from jaxexo.config import load_config
    from jaxexo.evaluation.machine import write_result
    from jaxexo.train.trainer import Hyperparams, Trainer

    cfg = load_config(path)
    hyper = Hyperparams.from_config(cfg)
    progs = {}
    for kind in ("plain", "batched"):
        tr = Trainer(cfg, devices=jax.local_devices())
        if kind == "plain":
            tr._mask = lambda st, h, tr=tr: jax.vmap(tr.env.action_mask, in_axes=(0, None))(st, h.env)
        ts = tr.place(jax.jit(tr.init)(jax.random.PRNGKey(0), hyper))
        run = jax.jit(tr.run, static_argnums=2)
        ts, _ = jax.block_until_ready(run(ts, hyper, updates))      # compiles
        progs[kind] = [run, ts, []]
    steps = updates * cfg.train.num_envs * cfg.train.rollout_steps
    for _ in range(rounds):
        for kind, prog in progs.items():
            run, ts, times = prog
            t0 = time.perf_counter()
            prog[1], _ = jax.block_until_ready(run(ts, hyper, updates))
            times.append(time.perf_counter() - t0)
    rates = {k: steps / float(np.median(v[2])) for k, v in progs.items()}
    out = {"config": Path(path).name, "updates_per_call": updates, "rounds": rounds, "env_steps_per_call": steps,
           "devices": len(jax.local_devices()), "env_steps_per_s": rates,
           "times_s": {k: v[2] for k, v in progs.items()}, "ratio": rates["batched"] / rates["plain"]}
    md = "\n".join([
        f"# Shielded trainer, plain mask vs batched mask ({out['config']}, {out['devices']} CPU devices)", "",
        "| mask | steady env-steps/s (median) |", "|---|---:|",
        *(f"| {k} | {v / 1e3:.0f}k |" for k, v in rates.items()), "",
        f"Batched / plain: {out['ratio']:.2f}x; {rounds} alternated calls of {steps:,} env steps each. Shared "
        "machine: other jobs ran at the same time; the alternation exposes both to the same load."])
    write_result("train-mask-ab", out, md, out_dir)
    print(md)
    return out


def breakdown(paths, label: str, out_dir: Path) -> dict:
    """Where an update's time goes (jaxexo.benchmarks.train_bench.update_breakdown), per config."""
    import jax

    from jaxexo.benchmarks.train_bench import update_breakdown
    from jaxexo.config import load_config
    from jaxexo.evaluation.machine import write_result

    rows = []
    for path in paths:
        r = update_breakdown(load_config(path))
        r["config"] = Path(path).name
        rows.append(r)
        print(r, flush=True)
    lines = [f"# Where a training update's time goes ({label or 'one device'})", "",
             "One forward-view update (T steps of N environments, then the learning part) on one CPU device "
             f"(of {len(jax.local_devices())}), each part timed alone on the update's own shapes in a jitted loop; "
             "milliseconds per update and share of the whole update. The parts inside the rollout and the "
             "learning part are measured alone, so they need not add up to their totals exactly.", ""]
    for r in rows:
        parts = r["ms_per_update"]
        lines += [f"## {r['config']} (N = {r['num_envs']}, T = {r['rollout_steps']}, {r['num_minibatches']} "
                  f"minibatches x {r['num_epochs']} epoch(s), hidden {r['hidden']}, shield {r['shield']})", "",
                  "| part | ms per update | share of the update |", "|---|---:|---:|"]
        lines += [f"| {k} | {v:.2f} | {100 * v / parts['update']:.0f} % |" for k, v in parts.items()]
        lines += ["", f"One device: {r['env_steps_per_s_one_device'] / 1e3:.0f}k env-steps/s.", ""]
    md = "\n".join(lines)
    write_result("train-breakdown" + (f"-{label}" if label else ""), {"rows": rows}, md, out_dir)
    print(md)
    return {"rows": rows}


if __name__ == "__main__":
    root = Path(__file__).resolve().parent.parent
    args = sys.argv[1:]
    if args and args[0] == "--breakdown":
        import argparse

        ap = argparse.ArgumentParser()
        ap.add_argument("--breakdown", nargs="+", required=True)
        ap.add_argument("--label", default="")
        ap.add_argument("--out", default=str(root / "benchmarks" / "results"))
        a = ap.parse_args(args)
        breakdown(a.breakdown, a.label, Path(a.out))
        sys.exit(0)
    if args and args[0] == "--mask-ab":
        import argparse

        ap = argparse.ArgumentParser()
        ap.add_argument("--mask-ab", required=True)
        ap.add_argument("--updates", type=int, default=30)
        ap.add_argument("--rounds", type=int, default=2)
        ap.add_argument("--out", default=str(root / "benchmarks" / "results"))
        a = ap.parse_args(args)
        mask_ab(a.mask_ab, a.updates, a.rounds, Path(a.out))
        sys.exit(0)
    if args and args[0] == "--steady":
        import argparse

        ap = argparse.ArgumentParser()
        ap.add_argument("--steady", nargs="+", required=True)
        ap.add_argument("--budget", type=int, default=4_000_000)
        ap.add_argument("--label", default="")
        ap.add_argument("--out", default=str(root / "benchmarks" / "results"))
        a = ap.parse_args(args)
        steady(a.steady, a.budget, a.label, Path(a.out))
        sys.exit(0)
    from jaxexo.benchmarks.train_bench import run_train_benchmark

    thesis = [str(root / "configs" / "thesis" / f"{n}.toml") for n in ("a", "b", "c", "1", "2", "3", "final")]
    run_train_benchmark(root / "benchmarks" / "results", str(root / "configs" / "default.toml"), thesis)
    sys.exit(0)
