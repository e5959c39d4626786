"""Swing-quality benchmark (benchlib.swing_quality_bench): what a wearer feels of the RL swing
beside CFFTG's (safe %, lift, timed duration, jerk) on the held-out terrain families, the thesis five
shifted and unseen shapes, RL alone (``fallback=None``) and CFFTG on the same scenes.

``--clearance C`` asks both generators for clearance C (m). ``--perception-error E`` (m) plans over a
wrong obstacle estimate (its outline lowered by E and shifted by E along y, alternating sign) while
the judge sees the true obstacle; the swing's clearance is asked as ``C`` (default 2 cm + E), and the
report counts contact with the true obstacle, and swings within 1 cm of it.

Writes benchmarks/results/swing_quality[_tag]_<date>_<machine>.{json,md,png} (the figure: the
distributions of lift and timed swing, RL beside CFFTG, per set).

Run: python benchmarks/bench_swing_quality.py RUN_DIR/policy.npz [--n 600] [--clearance C]
     [--perception-error E] [--tag NAME]
"""

from pathlib import Path

from benchlib.runner import parser
from benchlib.swing_quality_bench import run_swing_quality_benchmark

if __name__ == "__main__":
    ap = parser(__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=600, help="scenes per set")
    ap.add_argument(
        "--clearance", type=float, default=None, help="m; default env.min_clearance (+ the error)"
    )
    ap.add_argument("--perception-error", type=float, default=0.0, help="m")
    ap.add_argument(
        "--smoothing",
        type=float,
        default=None,
        help="m^2, the RL spline's (default: the generator's)",
    )
    ap.add_argument("--tag", default="")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    a = ap.parse_args()
    run_swing_quality_benchmark(
        a.policy, a.out, a.n, a.clearance, a.perception_error, a.smoothing, a.tag
    )
