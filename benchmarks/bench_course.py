"""Walks over courses: RL alone against CFFTG on the same footholds (benchlib.course_bench,
also ``jaxexo bench``'s ``course`` part). Writes benchmarks/results/course_<date>_<machine>.{json,md}.

Run: python benchmarks/bench_course.py RUN_DIR/policy.npz [--n 200] [--seed 0] [--log FILE] [--pivots | --swings]
     (``--log`` keeps each course's row as it is done; ``--summarize FILE`` writes the results of
     an interrupted run from its log)
"""

from __future__ import annotations

from pathlib import Path

from benchlib.course_bench import (
    markdown,
    run_course_benchmark,
    run_pivot_benchmark,
    run_swing_breakdown,
    summarize_log,
)
from benchlib.runner import parser

OUT = Path(__file__).resolve().parent / "results"


def main() -> None:
    p = parser(__doc__, policy=False)
    p.add_argument("policy", nargs="?")
    p.add_argument("--n", type=int, default=200, help="courses drawn")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--log", help="JSON-lines file receiving each course's row")
    p.add_argument("--summarize", help="write the results of the courses logged in this file")
    p.add_argument(
        "--pivots",
        action="store_true",
        help="only the pivots a course produces (RL alone, per family)",
    )
    p.add_argument(
        "--swings",
        action="store_true",
        help="only where a walk's time goes, swing by swing (--n courses)",
    )
    p.add_argument("--out", default=str(OUT))
    a = p.parse_args()
    if a.swings:
        print(run_swing_breakdown(a.policy, a.out, n=a.n, seed=a.seed))
        return
    if a.pivots:
        print(run_pivot_benchmark(a.policy, a.out, seed=a.seed)["total"])
        return
    if a.summarize:
        from jaxexo.evaluation.machine import write_result

        res = summarize_log(a.summarize, a.seed)
        write_result("course", res, markdown(res), a.out)
        print(markdown(res))
        return
    if not a.policy:
        p.error("policy: the policy.npz to benchmark")
    res = run_course_benchmark(a.policy, a.out, a.n, a.seed, log=a.log)
    print(markdown(res))


if __name__ == "__main__":
    main()
