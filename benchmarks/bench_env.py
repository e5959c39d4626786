"""Environment throughput: env-steps/s at 1, 256, 4096 and 16384 parallel environments.

Run: python benchmarks/bench_env.py [--config configs/default.toml]  (same as `jaxexo bench-env`).
Writes benchmarks/results/env_<date>_<machine>.json and .md."""

import sys
from pathlib import Path

from jaxexo.cli import main

if __name__ == "__main__":
    out = str(Path(__file__).resolve().parent / "results")
    sys.exit(main(["bench-env", "--out", out, *sys.argv[1:]]))
