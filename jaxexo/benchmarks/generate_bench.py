"""Generator benchmark: time per trajectory (rollout, smoothing and every check included), per batch
of 1000 scenarios, and the cold import of jaxexo.inference, all in NumPy (no JAX in the timed code).

The scenarios are the test set (jaxexo.inference.scenarios: the five thesis obstacles x three pivot
conditions, jittered like training). Figures are medians over repeated runs in one process."""

from __future__ import annotations

import statistics
import subprocess
import sys
from pathlib import Path

import numpy as np

from jaxexo.inference import TrajectoryGenerator
from jaxexo.inference.scenarios import TEST_KINDS, sample_scenarios
from jaxexo.evaluation.timing import time_batch, time_single

THESIS_MS = {"rl_single": 3.0, "cfftg_single": 2.0, "rl_batch_1000": 1764.0}   # Table 3.11, §3.4


def time_import(repeats: int = 7) -> list[float]:
    """Seconds to import jaxexo.inference in a fresh interpreter (one process per repeat)."""
    code = "import time; t = time.perf_counter(); import jaxexo.inference; print(time.perf_counter() - t)"
    return [float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout)
            for _ in range(repeats)]


def run_generate_benchmark(policy: str | Path, out_dir, n: int = 1000, progress=print) -> dict:
    from jaxexo.evaluation.machine import write_result

    gen = TrajectoryGenerator.load(policy)
    scenarios = sample_scenarios(gen.config, n)
    gen.generate(scenarios[0]["obstacle"])      # warm-up (first-call allocations)
    single = time_single(gen, scenarios)
    batch, last = time_batch(gen, scenarios)
    imports = time_import()
    ok = last.ok
    kinds = np.array([s["kind"] for s in scenarios])
    res = {
        "policy": str(policy), "n": n,
        "single_ms": {"median": float(np.median(single) * 1e3), "mean": float(single.mean() * 1e3),
                      "p95": float(np.percentile(single, 95) * 1e3)},
        "single_ms_by_kind": {k: float(np.median(single[kinds == k]) * 1e3) for k in TEST_KINDS},
        "batch_1000_ms": {"median": statistics.median(batch) * 1e3 * 1000 / n, "runs": [b * 1e3 for b in batch]},
        "import_s": {"median": statistics.median(imports), "runs": imports},
        "success": float(ok.mean()),
        "thesis_ms": THESIS_MS,
    }
    s, b, i = res["single_ms"], res["batch_1000_ms"]["median"], res["import_s"]["median"]
    lines = [
        "# Generator benchmark (NumPy only)", "",
        f"Policy `{Path(policy).name}` on {n} test scenarios (5 thesis obstacles x 3 pivot conditions); "
        f"strict success {res['success']:.3f}.", "",
        "| figure | jaxexo | target | thesis |", "|---|---:|---:|---:|",
        f"| one trajectory, median (rollout + smoothing + checks) | {s['median']:.3f} ms | <= 0.5 ms | ~3 ms (RL), ~2 ms (CFFTG) |",
        f"| one trajectory, mean / p95 | {s['mean']:.3f} / {s['p95']:.3f} ms | | 2.31 ms mean |",
        f"| batch of 1000 scenarios | {b:.1f} ms | <= 20 ms | 1764 ms |",
        f"| `import jaxexo.inference`, cold process | {i:.3f} s | <= 0.3 s | |", "",
        "| obstacle | median ms per trajectory |", "|---|---:|",
    ] + [f"| {k} | {v:.3f} |" for k, v in res["single_ms_by_kind"].items()]
    jpath, _ = write_result("generate", res, "\n".join(lines), out_dir)
    progress("\n".join(lines))
    progress(f"wrote {jpath}")
    return res
