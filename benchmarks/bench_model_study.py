"""The model study's measurements (benchlib.model_study_bench): every agent of a finished
model-study sweep (exported with ``jaxexo sweep configs/sweeps/model_study.toml --out DIR --export-all``)
screened (one swing timed against CFFTG, RL alone safe on the screen's scenes) and, where the screen
passes, measured beside CFFTG on the swing-quality benchmark's three sets.

Writes benchmarks/results/model_study_<date>_<machine>.{json,md,png}; the figure plots each agent's
generation time against its timed-swing p95 and its lift (the default's configuration marked).

Run: python benchmarks/bench_model_study.py SWEEP_DIR [--n 120] [--time-n 80] [--configs 0,3,...]
"""

from pathlib import Path

from benchlib.model_study_bench import rerender, run_model_study
from benchlib.runner import parser

if __name__ == "__main__":
    ap = parser(__doc__.split("\n\n")[0], policy=False)
    ap.add_argument("sweep_dir")
    ap.add_argument("--n", type=int, default=120, help="scenes per set")
    ap.add_argument(
        "--time-n", type=int, default=80, help="scenes per set for the one-swing timing"
    )
    ap.add_argument("--configs", default="", help="comma-separated config ids (default: all)")
    ap.add_argument("--tag", default="")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    ap.add_argument(
        "--from-json",
        help="re-render the tables and figure of an earlier run's JSON (no measuring)",
    )
    a = ap.parse_args()
    if a.from_json:
        rerender(a.from_json)
    else:
        run_model_study(
            a.sweep_dir,
            a.out,
            a.n,
            a.time_n,
            {int(c) for c in a.configs.split(",") if c} or None,
            a.tag,
        )
