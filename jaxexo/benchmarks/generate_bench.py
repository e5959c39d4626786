"""Generator benchmark (issue 12): the RL generator against CFFTG, side by side in one process, on the
same scenes: time per trajectory (rollout, smoothing, every safe-swing check, kinematics, joint
angles; a CFFTG fallback at its real cost), per batch of 1000 scenarios with the default BLAS threads
and with single-threaded BLAS, and the cold import of jaxexo.inference, all in NumPy (no JAX in the
timed code). The plain reference implementation (``fast=False``) is timed too, so that each speed-up
shows. ``generate_batch`` runs its BLAS on one thread (jaxexo.inference.blas); the batch with the
process's own BLAS threads (``batch_blas_threads = None``) is timed too.

The scenarios are the test set (jaxexo.inference.scenarios: the five thesis obstacles x three pivot
conditions, jittered like training). Figures are medians over repeated runs; the single-trajectory
figures alternate the generators per scene (jaxexo.evaluation.compare.run_generators)."""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

import numpy as np

from jaxexo.inference import TrajectoryGenerator
from jaxexo.inference.scenarios import TEST_KINDS, sample_scenarios
from jaxexo.evaluation.timing import time_batch
from jaxexo.inference.blas import blas_threads

THESIS_MS = {"rl_single": 3.0, "cfftg_single": 2.0, "rl_batch_1000": 1764.0}   # Table 3.11, §3.4
TARGETS = {"rl_single_ms": 0.5, "rl_batch_1000_ms": 50.0, "import_s": 0.3}     # issue 12


def time_import(repeats: int = 7) -> list[float]:
    """Seconds to import jaxexo.inference in a fresh interpreter (one process per repeat); fails if
    the import pulled in JAX or SciPy."""
    code = ("import sys, time; t = time.perf_counter(); import jaxexo.inference; dt = time.perf_counter() - t; "
            "bad = [m for m in ('jax', 'scipy') if m in sys.modules]; print(dt if not bad else 'imported ' + str(bad))")
    out = []
    for _ in range(repeats):
        text = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
        if text.startswith("imported"):
            raise RuntimeError(f"import jaxexo.inference {text.strip()}")
        out.append(float(text))
    return out


_BATCH_CODE = """
import json, sys
from jaxexo.benchmarks.generate_bench import _batch_ms
print(json.dumps(_batch_ms(sys.argv[1], int(sys.argv[2]))))
"""


def _batch_ms(policy, n: int) -> dict:
    """Median ms per generate_batch of n scenes (fast and reference) and per CFFTG batch, this process.
    ``rl_process_blas``: the fast batch with ``batch_blas_threads = None``, i.e. on the process's own
    BLAS threads instead of generate_batch's one (jaxexo.inference.blas)."""
    import copy

    from jaxexo.baselines.cfftg import CFFTG

    gen = TrajectoryGenerator.load(policy)
    free = copy.copy(gen)
    free.batch_blas_threads = None
    sc = sample_scenarios(gen.config, n)
    cf = CFFTG(gen.config)
    out = {}
    for name, g, kw in (("rl", gen, {}), ("rl_process_blas", free, {}), ("rl_reference", gen, {"fast": False}),
                        ("cfftg", cf, {})):
        g.generate_batch([s["obstacle"] for s in sc[:20]], **kw)       # warm-up
        out[name] = statistics.median(time_batch(g, sc, 5, **kw)[0]) * 1e3
    return out


def batch_single_thread(policy, n: int) -> dict:
    """``_batch_ms`` in a fresh process whose BLAS runs on one thread (the thread count is read at
    NumPy's import, so it cannot be changed in this process without threadpoolctl)."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    text = subprocess.run([sys.executable, "-c", _BATCH_CODE, str(policy), str(n)], capture_output=True, text=True,
                          check=True, env=env).stdout
    return json.loads(text.strip().splitlines()[-1])


def _ms(x) -> dict:
    x = np.asarray(x) * 1e3
    return {"median": float(np.median(x)), "mean": float(x.mean()), "p95": float(np.percentile(x, 95))}


def run_generate_benchmark(policy: str | Path, out_dir, n: int = 1000, progress=print) -> dict:
    from jaxexo.baselines.cfftg import CFFTG
    from jaxexo.evaluation.compare import run_generators
    from jaxexo.evaluation.machine import write_result

    gen = TrajectoryGenerator.load(policy)
    cf = CFFTG(gen.config)
    scenarios = sample_scenarios(gen.config, n)

    class _Reference:      # the plain reference path, timed like the others
        def generate(self, obstacle, **kw):
            return gen.generate(obstacle, fast=False, **kw)

    gens = {"rl": gen, "cfftg": cf, "rl_reference": _Reference()}
    passes = [run_generators(gens, scenarios) for _ in range(3)]
    single = {k: np.median([p[k][1] for p in passes], axis=0) for k in gens}
    trajs = passes[-1]["rl"][0]
    kinds = np.array([s["kind"] for s in scenarios])
    fell_back = np.array([t.method == "cfftg-fallback" for t in trajs])
    batch = _batch_ms(policy, n)
    batch_1t = batch_single_thread(policy, n)
    imports = time_import()
    res = {
        "policy": str(policy), "n": n,
        "single_ms": {k: _ms(v) for k, v in single.items()},
        "single_ms_by_kind": {k: {g: float(np.median(single[g][kinds == k]) * 1e3) for g in gens} for k in TEST_KINDS},
        "rl_single_ms_fallback_scenes": _ms(single["rl"][fell_back]) if fell_back.any() else None,
        "rl_over_cfftg_scenes": float(np.mean(single["rl"] > single["cfftg"])),
        "batch_ms": {"default_threads": batch, "single_thread_blas": batch_1t},
        "import_s": {"median": statistics.median(imports), "runs": imports},
        "blas_threads_default": blas_threads(),
        "success": float(np.mean([t.ok for t in trajs])),
        "fallback_rate": float(fell_back.mean()),
        "targets": TARGETS, "thesis_ms": THESIS_MS,
    }
    s, i = res["single_ms"], res["import_s"]["median"]
    b = lambda d, k: d[k] * 1000 / n      # noqa: E731  (scaled to 1000 scenes; exact for n = 1000)
    miss = lambda ok: "met" if ok else "**missed**"    # noqa: E731
    lines = [
        "# Generator benchmark (NumPy only): RL against CFFTG, side by side", "",
        f"Policy `{policy}` on {n} test scenarios (5 thesis obstacles x 3 pivot conditions); RL success "
        f"(CFFTG fallback included) {res['success']:.3f}, fallback rate {res['fallback_rate']:.3f}.", "",
        "| figure | RL (fast) | RL (reference, fast=False) | CFFTG | target | met? |", "|---|---:|---:|---:|---:|---|",
        f"| one trajectory, median | {s['rl']['median']:.3f} ms | {s['rl_reference']['median']:.3f} ms | "
        f"{s['cfftg']['median']:.3f} ms | <= 0.5 ms and <= CFFTG | "
        f"{miss(s['rl']['median'] <= 0.5)} / {miss(s['rl']['median'] <= s['cfftg']['median'])} |",
        f"| one trajectory, mean / p95 | {s['rl']['mean']:.3f} / {s['rl']['p95']:.3f} ms | "
        f"{s['rl_reference']['mean']:.3f} / {s['rl_reference']['p95']:.3f} ms | "
        f"{s['cfftg']['mean']:.3f} / {s['cfftg']['p95']:.3f} ms | | |",
        f"| batch of 1000, default BLAS threads | {b(batch, 'rl'):.1f} ms | {b(batch, 'rl_reference'):.1f} ms | "
        f"{b(batch, 'cfftg'):.1f} ms | <= 50 ms | {miss(b(batch, 'rl') <= 50)} |",
        f"| batch of 1000, single-threaded BLAS | {b(batch_1t, 'rl'):.1f} ms | {b(batch_1t, 'rl_reference'):.1f} ms | "
        f"{b(batch_1t, 'cfftg'):.1f} ms | <= 50 ms | {miss(b(batch_1t, 'rl') <= 50)} |",
        f"| batch of 1000, RL left on the process's BLAS threads (`batch_blas_threads = None`): default threads / "
        f"single-threaded | {b(batch, 'rl_process_blas'):.1f} / {b(batch_1t, 'rl_process_blas'):.1f} ms | | | | |",
        f"| `import jaxexo.inference`, cold process | {i:.3f} s | | | <= 0.3 s | {miss(i <= 0.3)} |", "",
        f"RL slower than CFFTG on {res['rl_over_cfftg_scenes']:.1%} of the scenes (per-scene medians)."
        + (f" Scenes where the RL swing fell back to CFFTG: median {res['rl_single_ms_fallback_scenes']['median']:.3f} ms."
           if fell_back.any() else ""), "",
        "| obstacle | RL ms | RL reference ms | CFFTG ms |", "|---|---:|---:|---:|",
    ] + [f"| {k} | {v['rl']:.3f} | {v['rl_reference']:.3f} | {v['cfftg']:.3f} |" for k, v in res["single_ms_by_kind"].items()]
    jpath, _ = write_result("generate", res, "\n".join(lines), out_dir)
    progress("\n".join(lines))
    progress(f"wrote {jpath}")
    return res
