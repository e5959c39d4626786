"""Device-timing benchmark: RL and CFFTG swings on the same scenes (the thesis's five obstacles over the
three pivots, and unseen shapes), each timed for the [device] joint limits and sampled at a control
rate; durations side by side, peaks and limit checks by finite differences of the exported samples.
Writes benchmarks/results/timing_<date>_<machine>.json and .md.

Run: python benchmarks/bench_timing.py RUN_DIR/policy.npz
(train one first: jaxexo train --out RUN_DIR)"""

from pathlib import Path

from jaxexo.benchmarks.runner import parser
from jaxexo.benchmarks.timing_bench import run_timing_benchmark

if __name__ == "__main__":
    p = parser(__doc__)
    p.add_argument("--n", type=int, default=1000, help="thesis-obstacle scenes")
    p.add_argument("--unseen", type=int, default=300, help="unseen-shape scenes")
    p.add_argument("--rate", type=float, default=100.0, help="control rate, Hz")
    a = p.parse_args()
    run_timing_benchmark(
        a.policy, Path(__file__).resolve().parent / "results", a.n, a.unseen, a.rate
    )
