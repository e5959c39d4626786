"""What group-size independence costs in throughput: the same agents trained by one
vmapped batch per device (``over_agents``, what sweeps ran before) and by fixed blocks of LANES
(``over_lanes``, what sweeps and populations run now), in one process, medians of repeated compiled
calls after a compiling one (jaxexo.benchmarks.sweep_bench.agents_throughput).

Rows: the sweep benchmark's static settings (configs/sweeps/benchmark.toml: thesis network, 256
environments, T = 16) with 16 agents, and thesis (b) learns (64 environments, T = 8) with 8 agents,
every CPU core a JAX device. Writes benchmarks/results/lanes_<date>_<machine>.{json,md}.

Run: python benchmarks/bench_lanes.py
"""

from __future__ import annotations

import os
from pathlib import Path

from jaxexo.train.devices import use_all_cpu_cores

use_all_cpu_cores()

import jax  # noqa: E402

from jaxexo.benchmarks.sweep_bench import agents_throughput  # noqa: E402
from jaxexo.config import load_config, packaged_config  # noqa: E402
from jaxexo.evaluation.machine import write_result  # noqa: E402
from jaxexo.train.lanes import LANES, over_agents, over_lanes  # noqa: E402
from jaxexo.sweep.spec import load_sweep  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    devices = jax.local_devices()
    cases = [("sweep benchmark (256 envs, T 16)", load_sweep(ROOT / "configs" / "sweeps" / "benchmark.toml").members[0].config,
              16, 10),
             ("thesis (b) learns (64 envs, T 8)", load_config(Path(packaged_config("default")).parent / "thesis" /
                                                              "b-learns.toml"), 8, 100)]
    load_before = os.getloadavg()
    rows = []
    for name, cfg, n, updates in cases:
        for label, wrap in (("one vmap per device", over_agents), (f"blocks of {LANES}", over_lanes)):
            r = agents_throughput(cfg, n, devices, updates, repeats=3, wrap=wrap)
            rows.append({"case": name, "program": label, **r})
            print(name, label, f"{r['env_steps_per_s'] / 1e6:.3f} M env-steps/s", flush=True)
    lines = ["# Fixed vmap blocks against one batch per device", "",
             f"{len(devices)} CPU devices; load average before {tuple(round(x, 2) for x in load_before)}, after "
             f"{tuple(round(x, 2) for x in os.getloadavg())} (a shared machine). Training only (no evaluation); "
             "median of 3 compiled calls.", "",
             "| case | agents | program | M env-steps/s | median s per call | ratio to one vmap per device |",
             "|---|---:|---|---:|---:|---:|"]
    for i, r in enumerate(rows):
        base = rows[i - i % 2]
        lines.append(f"| {r['case']} | {r['agents']} | {r['program']} | {r['env_steps_per_s'] / 1e6:.3f} | "
                     f"{r['median_s']:.2f} | {r['env_steps_per_s'] / base['env_steps_per_s']:.2f} |")
    for p in write_result("lanes", {"rows": rows, "load_before": load_before}, "\n".join(lines), ROOT / "benchmarks" / "results"):
        print(p)


if __name__ == "__main__":
    main()
