"""Trainer benchmarks: env-steps/s of the thesis network at 4096 environments (forward and backward
view), and wall time and greedy success of `jaxexo train` on configs/default.toml and a thesis
config and the seven thesis configs. Writes benchmarks/results/train_<date>_<machine>.json and .md.

Run: python benchmarks/bench_train.py

Steady rate of given configs through the real driver (issue 24): compilations of the chunk program,
the rate of each chunk (chunk 1 includes compilation), the steady rate (median of chunks 3 on):
  python benchmarks/bench_train.py --steady configs/quick.toml configs/default.toml [--budget 4000000]
      [--label NAME]
writes benchmarks/results/train-steady[-NAME]_<date>_<machine>.json and .md. This part only uses
jaxexo's public driver, so it can measure an older checkout too (run it from outside the repository
with PYTHONPATH pointing at that checkout)."""

import sys
from pathlib import Path

from jaxexo.train.devices import use_all_cpu_cores

use_all_cpu_cores()


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
               "validation_success_raw": res["validation_success_raw"], "success_raw": res["success_raw"]}
        rows.append(row)
        print(json.dumps(row), flush=True)
    lines = [f"# Trainer steady rate through `jaxexo train` ({label}, jaxexo at {commit})", "",
             "| config | env steps | chunks | compilations of the chunk program | chunk 1 (incl. compile) | chunk 2 | "
             "steady (median of chunks 3+) | train s |", "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        c = r["chunk_env_steps_per_s"]
        lines.append(f"| {r['config']} | {r['budget_env_steps']:,} | {r['chunks']} | {r['compilations_run']} | "
                     f"{c[0] / 1e3:.0f}k | {c[1] / 1e3 if len(c) > 1 else float('nan'):.0f}k | "
                     f"{(r['steady_env_steps_per_s'] or float('nan')) / 1e3:.0f}k | {r['train_seconds']:.1f} |")
    lines += ["", "Env-steps/s per chunk as metrics.jsonl reports them. Shared machine: other jobs ran at the same "
              "time, so rates are noisy; compare rows measured back to back."]
    md = "\n".join(lines)
    name = "train-steady" + (f"-{label}" if label else "")
    write_result(name, {"rows": rows, "commit": commit, "label": label}, md, out_dir)
    print(md)
    return {"rows": rows}


if __name__ == "__main__":
    root = Path(__file__).resolve().parent.parent
    args = sys.argv[1:]
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
