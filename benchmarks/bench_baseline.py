"""jaxexo's trainer against a thesis-style sequential PyTorch trainer, in one process: env-steps/s of
each and the ratio (thesis network), and wall time to the same greedy success (default model).
Needs the bench extra: pip install -e ".[train,bench]". Writes benchmarks/results/baseline_<date>_<machine>.*

Run: python benchmarks/bench_baseline.py [--throughput-seconds 60] [--baseline-seconds 600]"""

import sys
from pathlib import Path

from jaxexo.train.devices import use_all_cpu_cores

use_all_cpu_cores()

from benchlib.baseline_bench import run_baseline_benchmark  # noqa: E402
from benchlib.runner import parser  # noqa: E402

if __name__ == "__main__":
    root = Path(__file__).resolve().parent.parent
    ap = parser(__doc__, policy=False)
    ap.add_argument("--throughput-seconds", type=float, default=60.0)
    ap.add_argument("--baseline-seconds", type=float, default=600.0)
    ap.add_argument("--out", default=str(root / "benchmarks" / "results"))
    a = ap.parse_args()
    run_baseline_benchmark(
        a.out, str(root / "configs" / "default.toml"), a.throughput_seconds, a.baseline_seconds
    )
    sys.exit(0)
