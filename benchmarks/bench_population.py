"""The population cost target (benchlib.population_bench): a population of K costs at most
1.5 + (K - 1) x 0.25 times the wall time of one agent of the same config (``jaxexo train`` with
population 1, data parallel over the cores), each K trained by ``jaxexo train``'s driver in this one
process, every CPU core a JAX device; wall and steady chunk times, their ratios to K = 1 and the
members' outcomes, with the machine's load before and after.

Writes benchmarks/results/population_<date>_<machine>.{json,md}.

Run: python benchmarks/bench_population.py [CONFIG] [K,K,...] [NAME]   (default: the thesis (b) learns
config, 1,4,8, results named ``population``)
"""

from pathlib import Path

from jaxexo.train.devices import use_all_cpu_cores

use_all_cpu_cores()

from benchlib.population_bench import run_population_benchmark  # noqa: E402
from benchlib.runner import parser  # noqa: E402

if __name__ == "__main__":
    p = parser(__doc__, policy=False)
    p.add_argument("config", nargs="?", help="config TOML (default: thesis (b) learns)")
    p.add_argument("ks", nargs="?", default="1,4,8", help="population sizes, comma-separated")
    p.add_argument("name", nargs="?", default="population", help="the result files' name")
    a = p.parse_args()
    run_population_benchmark(
        Path(__file__).resolve().parent / "results",
        a.config,
        tuple(int(x) for x in a.ks.split(",")),
        a.name,
    )
