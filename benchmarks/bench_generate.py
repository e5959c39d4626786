"""Generator benchmark: ms per trajectory, per batch of 1000, and the cold import time of
jaxexo.inference. Writes benchmarks/results/generate_<date>_<machine>.json and .md.

Run: python benchmarks/bench_generate.py RUN_DIR/policy.npz
(train one first: jaxexo train --out RUN_DIR)"""

from pathlib import Path

from benchlib.generate_bench import run_generate_benchmark
from benchlib.runner import parser

if __name__ == "__main__":
    p = parser(__doc__)
    p.add_argument("--n", type=int, default=1000)
    a = p.parse_args()
    run_generate_benchmark(a.policy, Path(__file__).resolve().parent / "results", a.n)
