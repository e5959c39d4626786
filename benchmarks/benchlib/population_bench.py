"""Population benchmarks: what a population costs against one agent, and whether a member's arithmetic
depends on the number of CPU devices. Run by benchmarks/bench_population.py and
benchmarks/population_devices_check.py; method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from jaxexo.config import load_config, num_updates, packaged_config, with_population
from jaxexo.evaluation.machine import write_result
from jaxexo.summary import Summary, table

THESIS_B_LEARNS = Path(packaged_config("default")).parent / "thesis" / "b-learns.toml"


COST_HEADER = (
    *(
        "K",
        "devices",
        "train s",
        "ratio to K = 1",
        "target",
        "met",
        "steady chunk s",
        "steady ratio",
    ),
    *("exported seed", "members' test strict success"),
)


def _cost_cells(r: dict) -> tuple:
    """One population size's row of the cost table."""
    return (
        *(r["k"], r["devices"], f"{r['train_seconds']:.1f}"),
        *(f"{r[k]:.2f}" for k in ("ratio", "target")),
        "yes" if r["meets_target"] else "no",
        *(f"{r[k]:.2f}" for k in ("steady_chunk_s", "steady_ratio")),
        r["exported_seed"],
        ", ".join("-" if s is None else f"{s:.2f}" for s in r["test_success_raw"]),
    )


def target(k: int) -> float:
    return 1.5 + (k - 1) * 0.25


def population_row(base, k: int, work: Path) -> dict:
    """Population ``k`` of config ``base`` trained into ``work``/k<k>: its times and members' outcomes."""
    from jaxexo.train.driver import run_training

    ev = run_training(with_population(base, k), work / f"k{k}", seed=0, progress=False)
    chunks = [json.loads(x) for x in (work / f"k{k}" / "metrics.jsonl").read_text().splitlines()]
    walls = [c["wall_s"] for c in chunks]
    steady = [b - a for a, b in zip(walls[:-1], walls[1:])][1:] or [walls[-1]]
    members = ev["members"]
    return {
        "k": k,
        "train_seconds": ev["train_seconds"],
        "chunks": len(chunks),
        "steady_chunk_s": Summary.of(steady).median,
        "devices": ev["devices"],
        "exported_seed": ev["seed"],
        "validation_success_raw": ev["validation_success_raw"],
        "test_success_raw": [m["test"]["success_raw"] if m.get("test") else None for m in members],
        "reached_goal": [m["test"]["reached_goal"] if m.get("test") else None for m in members],
    }


def run_population_benchmark(
    out_dir, config: str | None = None, ks=(1, 4, 8), name: str = "population"
) -> dict:
    """Populations of each K in ``ks`` (default config: thesis (b) learns), printed and written as
    <name>_<date>_<machine>.{json,md}."""
    path = config or str(THESIS_B_LEARNS)
    base = load_config(path)
    rows = []
    load_before = os.getloadavg()
    work = Path(tempfile.mkdtemp(prefix="bench_population_"))
    try:
        for k in ks:
            rows.append(population_row(base, k, work))
            print(
                f"K={k}: {rows[-1]['train_seconds']:.1f} s, steady chunk {rows[-1]['steady_chunk_s']:.2f} s",
                flush=True,
            )
    finally:
        shutil.rmtree(work, ignore_errors=True)
    load_after = os.getloadavg()
    one = rows[0]
    for r in rows:
        r["ratio"] = r["train_seconds"] / one["train_seconds"]
        r["steady_ratio"] = r["steady_chunk_s"] / one["steady_chunk_s"]
        r["target"] = target(r["k"])
        r["meets_target"] = r["ratio"] <= r["target"]
    lines = [
        "# Population cost",
        "",
        f"Config `{Path(path).name}`; seeds 0..K-1; `jaxexo train`'s driver in one process, the CPU cores as JAX "
        "devices. K = 1 is one agent (data parallel over the devices); K > 1 a population "
        "(jaxexo.train.population: members in fixed blocks of 2 lanes per device). Wall time: eval.json's "
        "train_seconds (compilation and per-chunk validation included). Load average (1, 5, 15 min) before "
        f"{tuple(round(x, 2) for x in load_before)}, after {tuple(round(x, 2) for x in load_after)}.",
        "",
        *table(COST_HEADER, map(_cost_cells, rows), "rrrrrlrrrl"),
    ]
    payload = {
        "config": Path(path).name,
        "rows": rows,
        "load_before": load_before,
        "load_after": load_after,
    }
    for p in write_result(name, payload, "\n".join(lines), out_dir):
        print(p)
    return payload


# The devices check's config: tests/test_population.py's tiny config, written out (the test checks).
DEVICES_CHECK = Path(__file__).with_name("population_devices.toml")
SEED = 3  # the member compared, alone and as the fourth of five


def member_digest(seeds, i: int) -> str:
    """sha256 of member ``i``'s final parameters and per-update metrics [chunks, U, metrics] (in
    METRICS order) after a Population of ``seeds`` trained on every device of this process."""
    import hashlib

    import jax

    from jaxexo.train.population import Population
    from jaxexo.train.trainer import METRICS

    cfg = load_config(DEVICES_CHECK)
    pop = Population(cfg, seeds, devices=jax.local_devices())
    ts, metrics = pop.init(), []
    for _ in range(num_updates(cfg) // cfg.train.chunk_updates):
        ts, m, _, _ = pop.chunk(ts)
        metrics.append(np.stack([np.asarray(getattr(m, k)) for k in METRICS], axis=-1)[i])
    params = jax.tree.map(lambda x: x[i], pop.real(ts.params))
    leaves = [np.ascontiguousarray(np.asarray(x)).tobytes() for x in jax.tree.leaves(params)]
    return hashlib.sha256(b"".join(leaves) + np.stack(metrics).tobytes()).hexdigest()


def print_member_digests() -> None:
    """The child process's work: the member alone and as the fourth of five, as one RESULT line."""
    import jax

    five, one = member_digest([0, 1, 2, SEED, 4], 3), member_digest([SEED], 0)
    result = {"devices": len(jax.local_devices()), "alone": one, "fourth_of_five": five}
    print("RESULT " + json.dumps(result), flush=True)


def member_digests(devices: int) -> dict:
    """The child's digests in a fresh process with ``devices`` CPU devices."""
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={devices}"
    child = "from benchlib.population_bench import print_member_digests; print_member_digests()"
    out = subprocess.run(
        [sys.executable, "-c", child],
        cwd=Path(__file__).resolve().parents[1],  # benchmarks/, where benchlib is
        env=env,
        capture_output=True,
        text=True,
        timeout=1800,
    )
    if out.returncode:
        raise RuntimeError(out.stderr[-3000:])
    return json.loads(next(x for x in out.stdout.splitlines() if x.startswith("RESULT "))[7:])


def run_population_devices_check(out_dir) -> dict:
    """Digests on 1, 2 and 4 devices, written as population-devices_<date>_<machine>.{json,md}."""
    rows = [member_digests(d) for d in (1, 2, 4)]
    lines = [
        "# Population members across device counts",
        "",
        "The tiny config of tests/test_population.py, seed 3, trained alone and as the fourth member of a "
        "population of 5, in a fresh process with 1, 2 and 4 CPU devices (the population spread over all of "
        "them); sha256 of the final parameters and per-update metrics.",
        "",
        *table(
            ("devices", "alone", "fourth of five", "equal"),
            [
                (r["devices"], r["alone"][:16], r["fourth_of_five"][:16])
                + ("yes" if r["alone"] == r["fourth_of_five"] else "no",)
                for r in rows
            ],
            "rlll",
        ),
    ]
    same = {
        f"{a['devices']} vs {b['devices']}": a["alone"] == b["alone"]
        for a in rows
        for b in rows
        if a["devices"] < b["devices"]
    }
    lines += [
        "",
        "Across device counts (alone): "
        + ", ".join(f"{k}: {'equal' if v else 'differ'}" for k, v in same.items()),
    ]
    payload = {"rows": rows, "across": same}
    for p in write_result("population-devices", payload, "\n".join(lines), out_dir):
        print(p)
    return payload
