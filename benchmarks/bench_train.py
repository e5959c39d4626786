"""Trainer benchmarks: env-steps/s of the thesis network at 4096 environments (forward and backward
view), and wall time and greedy success of `jaxexo train` on configs/default.toml and a thesis
config and the seven thesis configs. Writes benchmarks/results/train_<date>_<machine>.json and .md.

Run: python benchmarks/bench_train.py

Steady rate of given configs through the real driver: compilations of the chunk program,
the rate of each chunk (chunk 1 includes compilation), the steady rate (median of chunks 3 on):
  python benchmarks/bench_train.py --steady configs/quick.toml configs/default.toml [--budget 4000000]
      [--label NAME]
writes benchmarks/results/train-steady[-NAME]_<date>_<machine>.json and .md. This part only uses
jaxexo's public driver, so it can measure an older checkout too (run it from outside the repository
with PYTHONPATH pointing at that checkout).

The shield's mask inside the trainer, plain rule against the batched one, alternated in one process:
  python benchmarks/bench_train.py --mask-ab configs/default.toml [--updates 30] [--rounds 2]
writes benchmarks/results/train-mask-ab_<date>_<machine>.json and .md.

Where an update's time goes (rollout, environment, network passes, optimizer), per config:
  python benchmarks/bench_train.py --breakdown configs/quick.toml configs/default.toml [--label NAME]
writes benchmarks/results/train-breakdown[-NAME]_<date>_<machine>.json and .md.

The code: benchlib.train_bench and train_steady_bench."""

import argparse
import importlib.util
from pathlib import Path

from jaxexo.train.devices import use_all_cpu_cores

use_all_cpu_cores()

ROOT = Path(__file__).resolve().parent.parent


def steady_module():
    """This checkout's train_steady_bench, loaded by path: the jaxexo it measures may be another's."""
    spec = importlib.util.spec_from_file_location(
        "train_steady_bench", ROOT / "jaxexo" / "benchmarks" / "train_steady_bench.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


if __name__ == "__main__":
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    mode = ap.add_mutually_exclusive_group()
    mode.add_argument("--steady", nargs="+", metavar="CONFIG")
    mode.add_argument("--mask-ab", metavar="CONFIG")
    mode.add_argument("--breakdown", nargs="+", metavar="CONFIG")
    ap.add_argument("--budget", type=int, default=4_000_000, help="--steady: env steps per config")
    ap.add_argument("--updates", type=int, default=30, help="--mask-ab: updates per call")
    ap.add_argument("--rounds", type=int, default=2, help="--mask-ab: alternated calls of each")
    ap.add_argument("--label", default="")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results"))
    a = ap.parse_args()
    if a.steady:
        steady_module().run_train_steady(a.steady, a.budget, a.label, Path(a.out))
    elif a.mask_ab:
        from benchlib.train_bench import run_mask_ab_benchmark

        run_mask_ab_benchmark(a.mask_ab, a.updates, a.rounds, Path(a.out))
    elif a.breakdown:
        from benchlib.train_bench import run_breakdown_benchmark

        run_breakdown_benchmark(a.breakdown, a.label, Path(a.out))
    else:
        from benchlib.train_bench import run_train_benchmark

        thesis = [
            str(ROOT / "configs" / "thesis" / f"{n}.toml")
            for n in ("a", "b", "c", "1", "2", "3", "final")
        ]
        run_train_benchmark(Path(a.out), str(ROOT / "configs" / "default.toml"), thesis)
