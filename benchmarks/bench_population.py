"""The population cost target: a population of K costs at most 1.5 + (K - 1) x 0.25 times the wall time of
one agent of the same config (``jaxexo train`` with population 1, data parallel over the cores).

For each K, ``jaxexo train``'s driver (jaxexo.train.driver.run_training, as the CLI runs it: every
CPU core a JAX device) trains the config into a fresh directory, in this one process, one K after
the other. Reported per K: the training wall time (eval.json's train_seconds: first compilation and
every chunk's validation included, the final test evaluation not), the steady chunk time (median over
the chunks after the first, which compiles), their ratios to K = 1 and the target, and the members'
outcomes. The machine's load average is recorded before and after: it is shared, and timings on a
loaded core are slower.

Writes benchmarks/results/population_<date>_<machine>.{json,md}.

Run: python benchmarks/bench_population.py [CONFIG] [K,K,...] [NAME]   (default: the thesis (b) learns
config, 1,4,8, results named ``population``)
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import sys
import tempfile
from pathlib import Path

from jaxexo.train.devices import use_all_cpu_cores

use_all_cpu_cores()

from jaxexo.config import load_config, packaged_config, with_population  # noqa: E402
from jaxexo.evaluation.machine import write_result  # noqa: E402

ROOT = Path(__file__).resolve().parent


def target(k: int) -> float:
    return 1.5 + (k - 1) * 0.25


def main(config: str | None = None, ks=(1, 4, 8), name: str = "population") -> None:
    from jaxexo.train.driver import run_training

    path = config or str(Path(packaged_config("default")).parent / "thesis" / "b-learns.toml")
    base = load_config(path)
    rows = []
    load_before = os.getloadavg()
    work = Path(tempfile.mkdtemp(prefix="bench_population_"))
    try:
        for k in ks:
            cfg = with_population(base, k)
            ev = run_training(cfg, work / f"k{k}", seed=0, progress=False)
            chunks = [json.loads(x) for x in (work / f"k{k}" / "metrics.jsonl").read_text().splitlines()]
            walls = [c["wall_s"] for c in chunks]
            steady = [b - a for a, b in zip(walls[:-1], walls[1:])][1:] or [walls[-1]]
            members = ev.get("members") or [{"seed": ev["seed"], "test": {"success_raw": ev["success_raw"],
                                                                          "reached_goal": ev["reached_goal"]}}]
            rows.append({"k": k, "train_seconds": ev["train_seconds"], "chunks": len(chunks),
                         "steady_chunk_s": statistics.median(steady), "devices": ev["devices"],
                         "exported_seed": ev["seed"], "validation_success_raw": ev["validation_success_raw"],
                         "test_success_raw": [m["test"]["success_raw"] if m.get("test") else None for m in members],
                         "reached_goal": [m["test"]["reached_goal"] if m.get("test") else None for m in members]})
            print(f"K={k}: {ev['train_seconds']:.1f} s, steady chunk {rows[-1]['steady_chunk_s']:.2f} s", flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    load_after = os.getloadavg()
    one = rows[0]
    for r in rows:
        r["ratio"] = r["train_seconds"] / one["train_seconds"]
        r["steady_ratio"] = r["steady_chunk_s"] / one["steady_chunk_s"]
        r["target"] = target(r["k"])
        r["meets_target"] = r["ratio"] <= r["target"]
    lines = ["# Population cost", "",
             f"Config `{Path(path).name}`; seeds 0..K-1; `jaxexo train`'s driver in one process, the CPU cores as JAX "
             "devices. K = 1 is one agent (data parallel over the devices); K > 1 a population "
             "(jaxexo.train.population: members in fixed blocks of 2 lanes per device). Wall time: eval.json's "
             "train_seconds (compilation and per-chunk validation included). Load average (1, 5, 15 min) before "
             f"{tuple(round(x, 2) for x in load_before)}, after {tuple(round(x, 2) for x in load_after)}.", "",
             "| K | devices | train s | ratio to K = 1 | target | met | steady chunk s | steady ratio | exported seed | "
             "members' test strict success |", "|---:|---:|---:|---:|---:|---|---:|---:|---:|---|"]
    for r in rows:
        lines.append(f"| {r['k']} | {r['devices']} | {r['train_seconds']:.1f} | {r['ratio']:.2f} | {r['target']:.2f} | "
                     f"{'yes' if r['meets_target'] else 'no'} | {r['steady_chunk_s']:.2f} | {r['steady_ratio']:.2f} | "
                     f"{r['exported_seed']} | "
                     + ", ".join("-" if s is None else f"{s:.2f}" for s in r["test_success_raw"]) + " |")
    payload = {"config": Path(path).name, "rows": rows, "load_before": load_before, "load_after": load_after}
    for p in write_result(name, payload, "\n".join(lines), ROOT / "results"):
        print(p)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None,
         tuple(int(x) for x in sys.argv[2].split(",")) if len(sys.argv) > 2 else (1, 4, 8),
         sys.argv[3] if len(sys.argv) > 3 else "population")
