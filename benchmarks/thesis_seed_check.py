"""Evidence: the thesis learns configs trained by ``jaxexo train`` (the driver ``jaxexo reproduce``
uses: model selection on validation layouts, the best chunk exported) with several seeds, so that a
target met or missed by ``jaxexo reproduce``'s seed 0 is not read as a property of the config.

Each row (benchlib.thesis_reports.seed_check): one run directory's eval.json (greedy JAX
rollouts of the exported policy on the 1000 test layouts: strict success of the raw moves, eq 3.1
accuracy, goal reached, held-out triangle and half-circle), the chunk selected, the training time.
Writes benchmarks/results/thesis-seeds_<date>_<machine>.{json,md}.

Run: python benchmarks/thesis_seed_check.py NOTE MODEL=RUN_DIR:SEED [MODEL=RUN_DIR:SEED ...]"""

from pathlib import Path

from benchlib.runner import parser
from benchlib.thesis_reports import seed_check

if __name__ == "__main__":
    p = parser(__doc__, policy=False)
    p.add_argument("note")
    p.add_argument("runs", nargs="*", metavar="MODEL=RUN_DIR:SEED")
    a = p.parse_args()
    seed_check(a.note, a.runs, Path(__file__).resolve().parent / "results")
