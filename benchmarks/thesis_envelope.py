"""Why the heel-only thesis models need a wider safety margin to clear the test obstacles
(benchlib.thesis_reports.run_envelope): on a dense grid of flat-foot positions, whether every
position that keeps min_dt from Base 1-3 (or from Base 3 alone) is also clear of the test triangle and
half-circle. Writes benchmarks/results/thesis-learning-envelope_<date>_<machine>.{json,md}.

Run: python benchmarks/thesis_envelope.py"""

from pathlib import Path

from benchlib.runner import parser
from benchlib.thesis_reports import run_envelope

if __name__ == "__main__":
    parser(__doc__, policy=False).parse_args()
    run_envelope(Path(__file__).resolve().parent / "results")
