"""Device-timing benchmark: RL and CFFTG swings on the same scenes (the thesis's five obstacles over the
three pivots, and unseen shapes), each timed for the [device] joint limits and sampled at a control
rate; durations side by side, peaks and limit checks by finite differences of the exported samples.
Writes benchmarks/results/timing_<date>_<machine>.json and .md.

Run: python benchmarks/bench_timing.py RUN_DIR/policy.npz
(train one first: jaxexo train --out RUN_DIR)"""

from pathlib import Path

from benchlib.runner import run_script
from benchlib.timing_bench import OPTIONS, run_timing_benchmark

if __name__ == "__main__":
    results = Path(__file__).resolve().parent / "results"
    run_script(__doc__, run_timing_benchmark, OPTIONS, results)
