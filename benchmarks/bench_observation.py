"""Observation study: two small models (env.obs_profile "bbox" vs "shape") trained on profile
obstacles drawn from jaxexo.physics.terrain's training families, compared on the held-out benchmark
(jaxexo.evaluation.unseen). Writes benchmarks/results/observation_<date>_<machine>.json and .md.

Run: python benchmarks/bench_observation.py [--budget 8000000] [--repeats 2] [--runs /tmp/obs-runs]"""

import sys
from pathlib import Path

from jaxexo.train.devices import use_all_cpu_cores

use_all_cpu_cores()

from benchlib.observation_bench import run_observation_study  # noqa: E402
from benchlib.runner import parser  # noqa: E402

if __name__ == "__main__":
    root = Path(__file__).resolve().parent.parent
    ap = parser(__doc__, policy=False)
    ap.add_argument("--budget", type=int, default=8_000_000, help="env steps per model")
    ap.add_argument("--repeats", type=int, default=2, help="draws per benchmark cell")
    ap.add_argument("--runs", default="/tmp/jaxexo-observation-runs", help="run directories")
    ap.add_argument("--out", default=str(root / "benchmarks" / "results"))
    a = ap.parse_args()
    run_observation_study(a.out, root / "configs" / "default.toml", a.runs, a.budget, a.repeats)
    sys.exit(0)
