"""Replanning benchmark (benchlib.replan_bench): swings planned over an estimate of the
obstacle, replanned mid-swing over the true one by the RL generator (alone, and with the CFFTG
fallback) and by CFFTG side by side, each replanned swing judged by an independent dense check;
latency, duration over a swing planned from the start, lift.

Run: python benchmarks/bench_replan.py RUN_DIR/policy.npz [--n 300] [--seed 5917] [--rate 100]"""

from pathlib import Path

from benchlib.replan_bench import OPTIONS, run_replan_benchmark
from benchlib.runner import run_script

if __name__ == "__main__":
    results = Path(__file__).resolve().parent / "results"
    run_script(__doc__, run_replan_benchmark, OPTIONS, results)
