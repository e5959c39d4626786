"""Device-ready swing benchmark (benchlib.device_ready_bench): generate + time_swing per
swing, RL alone vs CFFTG alternating in one process, and time_swings of a batch of 1000.

Run: python benchmarks/bench_device_ready.py RUN_DIR/policy.npz [--n 300] [--rate 100]"""

from pathlib import Path

from benchlib.device_ready_bench import OPTIONS, run_device_ready_benchmark
from benchlib.runner import run_script

if __name__ == "__main__":
    results = Path(__file__).resolve().parent / "results"
    run_script(__doc__, run_device_ready_benchmark, OPTIONS, results)
