"""Tracking-room study (benchlib.tracking_bench): the [device] tracking headroom and jerk
limit against duration, setpoint clipping and tracking error under the feed-forward controller.

Run: python benchmarks/bench_tracking.py RUN_DIR/policy.npz [--n 100] [--rate 100]"""

from pathlib import Path

from benchlib.runner import parser
from benchlib.tracking_bench import run_tracking_benchmark

if __name__ == "__main__":
    p = parser(__doc__)
    p.add_argument("--n", type=int, default=100, help="unseen-shape scenes")
    p.add_argument("--rate", type=float, default=100.0, help="control rate, Hz")
    a = p.parse_args()
    run_tracking_benchmark(a.policy, Path(__file__).resolve().parent / "results", a.n, a.rate)
