"""Device-ready swing benchmark (jaxexo.benchmarks.device_ready_bench): generate + time_swing per
swing, RL alone vs CFFTG alternating in one process, and time_swings of a batch of 1000.

Run: python benchmarks/bench_device_ready.py RUN_DIR/policy.npz [--n 300] [--rate 100]"""

from pathlib import Path

from jaxexo.benchmarks.device_ready_bench import run_device_ready_benchmark
from jaxexo.benchmarks.runner import parser

if __name__ == "__main__":
    p = parser(__doc__)
    p.add_argument("--n", type=int, default=300, help="unseen-shape scenes")
    p.add_argument("--batch", type=int, default=1000, help="swings timed in one time_swings call")
    p.add_argument("--rate", type=float, default=100.0, help="control rate, Hz")
    a = p.parse_args()
    run_device_ready_benchmark(
        a.policy, Path(__file__).resolve().parent / "results", a.n, a.batch, a.rate
    )
