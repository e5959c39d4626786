"""Trainer benchmarks: env-steps/s of the thesis network at 4096 environments (forward and backward
view), and wall time and greedy success of `jaxexo train` on configs/default.toml and a thesis
config and the seven thesis configs. Writes benchmarks/results/train_<date>_<machine>.json and .md.

Run: python benchmarks/bench_train.py"""

import sys
from pathlib import Path

from jaxexo.train.devices import use_all_cpu_cores

use_all_cpu_cores()

from jaxexo.benchmarks.train_bench import run_train_benchmark  # noqa: E402

if __name__ == "__main__":
    root = Path(__file__).resolve().parent.parent
    thesis = [str(root / "configs" / "thesis" / f"{n}.toml") for n in ("a", "b", "c", "1", "2", "3", "final")]
    run_train_benchmark(root / "benchmarks" / "results", str(root / "configs" / "default.toml"), thesis)
    sys.exit(0)
