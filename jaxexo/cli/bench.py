"""``jaxexo bench-env`` (environment steps per second) and ``jaxexo bench`` (every benchmark into
benchmarks/results with a summary table): both run the benchmark suite of a source checkout
(benchmarks/benchlib beside the package), which an installed jaxexo does not carry. What they
measure: docs/benchmarks.md."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from jaxexo.cli.common import check_count, load, real, whole

# The checkout's benchmarks/ folder, whose benchlib package holds the suite.
SUITE = Path(__file__).resolve().parents[2] / "benchmarks"


def _use_suite(command: str) -> None:
    """Puts the checkout's benchmarks/ on the import path; outside a checkout, an error naming the
    folder it lacks."""
    if not (SUITE / "benchlib").is_dir():
        raise FileNotFoundError(
            f"{command} runs the benchmark suite of a source checkout: there is no {SUITE}/benchlib "
            "beside this jaxexo (clone the repository, pip install -e . and run it there)"
        )
    if str(SUITE) not in sys.path:
        sys.path.insert(0, str(SUITE))


def _sizes(text: str) -> list[int]:
    try:
        sizes = [whole(x) for x in text.split(",") if x.strip()]
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"--envs: expected comma-separated integers, got {text!r}"
        ) from None
    if not sizes or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"--envs: sizes must be >= 1, got {text!r}")
    return sizes


def cmd_bench_env(args) -> int:
    from jaxexo.train.devices import use_all_cpu_cores

    _use_suite("jaxexo bench-env")
    use_all_cpu_cores()
    cfg, name = load(args.config)
    from benchlib.env_bench import run_env_benchmark

    run_env_benchmark(
        cfg, Path(name).stem, args.envs, args.out, name=args.name, mixed=not args.no_mixed
    )
    return 0


def cmd_bench(args) -> int:
    from jaxexo.physics.geometry import as_given
    from jaxexo.train.devices import use_all_cpu_cores

    if not (math.isfinite(args.baseline_seconds) and args.baseline_seconds > 0):
        raise ValueError(
            f"--baseline-seconds: a time budget must be a finite number of seconds > 0, "
            f"got {as_given(args.baseline_seconds)}"
        )
    check_count(args.courses, "--courses")
    _use_suite("jaxexo bench")
    use_all_cpu_cores()
    from benchlib.run_all import run_all

    run_all(
        args.out,
        policy=args.policy,
        baseline_seconds=args.baseline_seconds,
        skip=args.skip,
        courses=args.courses,
    )
    return 0


def _add_results_out(p) -> None:
    """bench-env's and bench's --out: where benchmark results go."""
    p.add_argument(
        "--out", default="benchmarks/results", help="folder for the JSON and Markdown results"
    )


def add_env_options(b) -> None:
    """The `jaxexo bench-env` options."""
    b.add_argument(
        "--config", help="TOML config (default: the packaged default, configs/default.toml)"
    )
    b.add_argument(
        "--envs", type=_sizes, default=[1, 256, 4096, 16384], help="batch sizes, e.g. 1,256,4096"
    )
    _add_results_out(b)
    b.add_argument(
        "--name", default="env", help="result files' name: NAME_<date>_<machine>.json and .md"
    )
    b.add_argument(
        "--no-mixed", action="store_true", help="skip the all-obstacle-kinds comparison rows"
    )
    b.set_defaults(func=cmd_bench_env)


def add_options(bb) -> None:
    """The `jaxexo bench` options."""
    _add_results_out(bb)
    bb.add_argument(
        "--policy",
        help="policy.npz for the generator benchmarks (default: train configs/default.toml)",
    )
    bb.add_argument(
        "--baseline-seconds",
        type=real,
        default=600.0,
        help="time budget of the thesis-style baseline's training run",
    )
    bb.add_argument(
        "--skip",
        default="",
        help="comma-separated parts to skip: env,train,generate,compare,baseline,course",
    )
    bb.add_argument(
        "--courses",
        type=whole,
        default=200,
        help="courses drawn for the course part (walks, RL alone against CFFTG)",
    )
    bb.set_defaults(func=cmd_bench)
