"""Landing benchmark (benchlib.landing_bench): where the RL swing ends and what a complete
swing costs beside CFFTG's, on the safety scene sets (the thesis five shifted, shapes never trained
on, the held-out families), RL alone (``fallback=None``) and CFFTG on the same scenes: safe and goal
%, final heel height, lift, timed duration (and with a vertical touch-down appended), the landing's
approach, RL swings retried or on the raw polyline.

Writes benchmarks/results/landing[_tag]_<date>_<machine>.{json,md}.

Run: python benchmarks/bench_landing.py RUN_DIR/policy.npz [--n 300] [--tag NAME] [--note TEXT]
"""

from pathlib import Path

from benchlib.landing_bench import run_landing_benchmark
from benchlib.runner import parser

if __name__ == "__main__":
    p = parser(__doc__)
    p.add_argument("--n", type=int, default=300)
    p.add_argument("--tag", default="")
    p.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    p.add_argument("--note", default="", help="a line for the report (where the policy came from)")
    a = p.parse_args()
    run_landing_benchmark(a.policy, a.out, a.n, a.tag, a.note)
