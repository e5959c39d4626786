"""Sweep benchmarks (benchlib.sweep_bench): 64 vmapped configurations against one large run,
one CPU device against all, agents trained per minute for 1, 8, 64 and 256 configurations, and the
64 x 4 seeds x 256 envs x 2 M env-steps run of configs/sweeps/benchmark.toml timed against 10 minutes.
Writes benchmarks/results/sweep_<date>_<machine>.json and .md. Takes about 20 minutes on 2 cores; run it on
an otherwise idle machine.

Run: python benchmarks/bench_sweep.py [--no-target]

The learning sweep (agents that learn: configs/sweeps/learning_benchmark.toml, a few minutes) alone:
python benchmarks/bench_sweep.py --learning [SWEEP_FILE]; writes sweep-learning_<date>_<machine>.*"""

from pathlib import Path

from jaxexo.train.devices import use_all_cpu_cores

use_all_cpu_cores()

from benchlib.runner import parser  # noqa: E402
from benchlib.sweep_bench import run_learning_benchmark, run_sweep_benchmark  # noqa: E402

if __name__ == "__main__":
    root = Path(__file__).resolve().parent.parent
    p = parser(__doc__, policy=False)
    p.add_argument(
        "--learning",
        nargs="?",
        const=root / "configs" / "sweeps" / "learning_benchmark.toml",
        metavar="SWEEP_FILE",
        help="only the learning sweep",
    )
    p.add_argument("--no-target", action="store_true", help="without the 10-minute target run")
    a = p.parse_args()
    if a.learning:
        run_learning_benchmark(root / "benchmarks" / "results", a.learning)
    else:
        run_sweep_benchmark(
            root / "benchmarks" / "results",
            root / "configs" / "sweeps" / "benchmark.toml",
            target=not a.no_target,
        )
