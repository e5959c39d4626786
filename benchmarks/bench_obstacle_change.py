"""Training with obstacle changes (benchlib.obstacle_change_bench): policies trained without and
with [env] obstacle_change, side by side on the hidden safety sets (RL alone: safe %, lift, timed
duration) and on mid-swing continuation in the environment (the obstacle taller, moved, wider or
doubled at 15-45 % of the swing).

Writes benchmarks/results/obstacle_change[_tag]_<date>_<machine>.{json,md}.

Run: python benchmarks/bench_obstacle_change.py off=RUN_OFF/policy.npz on=RUN_ON/policy.npz
     [name=PATH ...] [--n-safety 600] [--n-change 1000] [--tag NAME]
"""

import argparse
from pathlib import Path

from benchlib.obstacle_change_bench import run_obstacle_change_benchmark

if __name__ == "__main__":
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("policies", nargs="+", help="NAME=policy.npz, the first the baseline")
    ap.add_argument("--n-safety", type=int, default=600, help="scenes per hidden set")
    ap.add_argument("--n-change", type=int, default=1000, help="layouts per change kind")
    ap.add_argument("--tag", default="")
    ap.add_argument("--out", default=str(Path(__file__).resolve().parent / "results"))
    a = ap.parse_args()
    paths = dict(p.split("=", 1) for p in a.policies)
    run_obstacle_change_benchmark(paths, a.out, a.n_safety, a.n_change, a.tag)
