"""Safe-swing benchmark (benchlib.safety_bench): how often each generator returns a safe swing
(exact clearance of the moving foot >= env.min_clearance, goal, no backward heel, joint limits, leg
length), and the number of swings flagged safe that a 10x denser look at the same curve contradicts
(must be 0).

Scenes: the thesis's five obstacles with shifted layouts (start 0-10 cm, obstacle anywhere in the gap)
and shapes never trained on (random rectangles, wedges, thin poles, profiles with several bumps), every
pivot condition (jaxexo.inference.scenarios.safety_scenarios). Generators: the RL swing alone
(fallback none), the default combination (CFFTG when the RL swing is not safe), CFFTG alone.
Writes benchmarks/results/safety_<date>_<machine>.{json,md}.

Run: python benchmarks/bench_safety.py RUN_DIR/policy.npz [--n 2000]
(train one first: jaxexo train --out RUN_DIR)"""

from pathlib import Path

from benchlib.runner import parser
from benchlib.safety_bench import run_safety_benchmark

if __name__ == "__main__":
    p = parser(__doc__)
    p.add_argument(
        "--n", type=int, default=2000, help="scenes per set (thesis five; unseen shapes)"
    )
    a = p.parse_args()
    run_safety_benchmark(a.policy, Path(__file__).resolve().parent / "results", a.n)
