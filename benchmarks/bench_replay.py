"""MuJoCo replay benchmark (benchlib.replay_bench): every swing of the safety sets (the thesis
five shifted, unseen shapes, the held-out families), RL alone and CFFTG, timed for the device and
replayed in MuJoCo (jaxexo.sim.replay): kinematically (MuJoCo's distance against jaxexo's, swings
flagged ok that come within the margin) and, for the swings flagged ok, driven at the [device] limits
by PD with inverse-dynamics feed-forward and by stiff position servos (tracking error, contacts,
saturation).

Writes benchmarks/results/replay_<date>_<machine>.{json,md}.
Run: python benchmarks/bench_replay.py RUN_DIR/policy.npz [--n 1000] [--rate 100]
"""

from pathlib import Path

from benchlib.replay_bench import run_replay_benchmark
from benchlib.runner import parser

if __name__ == "__main__":
    p = parser(__doc__)
    p.add_argument(
        "--n",
        type=int,
        default=1000,
        help="scenes per set (the held-out families round up to whole cells)",
    )
    p.add_argument(
        "--rate", type=float, default=None, help="control rate, Hz (default: the config's)"
    )
    p.add_argument("--no-driven", action="store_true", help="kinematic replay only")
    p.add_argument("--name", default="replay")
    a = p.parse_args()
    run_replay_benchmark(
        a.policy, Path(__file__).resolve().parent / "results", a.n, a.rate, not a.no_driven, a.name
    )
