"""What group-size independence costs in throughput (benchlib.sweep_bench.run_lanes_benchmark):
the same agents trained by one vmapped batch per device (``over_agents``, what sweeps ran before) and by
fixed blocks of LANES (``over_lanes``, what sweeps and populations run now), in one process, medians of
repeated compiled calls after a compiling one.

Rows: the sweep benchmark's static settings (configs/sweeps/benchmark.toml: thesis network, 256
environments, T = 16) with 16 agents, and thesis (b) learns (64 environments, T = 8) with 8 agents,
every CPU core a JAX device. Writes benchmarks/results/lanes_<date>_<machine>.{json,md}.

Run: python benchmarks/bench_lanes.py
"""

from pathlib import Path

from jaxexo.train.devices import use_all_cpu_cores

use_all_cpu_cores()

from benchlib.runner import parser  # noqa: E402
from benchlib.sweep_bench import run_lanes_benchmark  # noqa: E402

if __name__ == "__main__":
    parser(__doc__, policy=False).parse_args()
    root = Path(__file__).resolve().parent.parent
    run_lanes_benchmark(
        root / "benchmarks" / "results", root / "configs" / "sweeps" / "benchmark.toml"
    )
