"""Does a population member's arithmetic depend on the number of CPU devices?
(benchlib.population_bench.run_population_devices_check)

tests/test_population.py checks group-size independence in one process (one device). This script
trains the test's tiny config in fresh processes with 1, 2 and 4 CPU devices: seed 3 alone and as
the fourth member of a population of 5, each on every device the process has, and compares the
final parameters' bytes within each process and across device counts.

Writes benchmarks/results/population-devices_<date>_<machine>.{json,md}.

Run: python benchmarks/population_devices_check.py
"""

from pathlib import Path

from benchlib.population_bench import run_population_devices_check
from benchlib.runner import parser

if __name__ == "__main__":
    parser(__doc__, policy=False).parse_args()
    root = Path(__file__).resolve().parent.parent
    run_population_devices_check(root / "benchmarks" / "results")
