"""Merge the per-run evaluations (runs/<name>/reproduce_entry.json, or a reproduce.json) of several
`jaxexo reproduce --out DIR` folders into one benchmarks/results/reproduce_<date>_<machine>.{json,md}, slimmed
to the tabulated figures (< 100 KB). Used when the models were reproduced in parallel processes
(benchlib.thesis_reports.combine_reproduce).

Run: python benchmarks/reproduce_combine.py DIR [DIR ...]"""

from benchlib.runner import parser
from benchlib.thesis_reports import combine_reproduce

if __name__ == "__main__":
    p = parser(__doc__, policy=False)
    p.add_argument("dirs", nargs="*", metavar="DIR")
    combine_reproduce(p.parse_args().dirs)
