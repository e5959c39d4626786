"""The ``jaxexo`` command line. Subcommands import JAX lazily, after the CPU-device setup."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

DEFAULT_CONFIG = Path(__file__).resolve().parent.parent / "configs" / "default.toml"


def _load(path):
    from jaxexo.config import Config, load_config

    if path is None:
        return (load_config(DEFAULT_CONFIG), str(DEFAULT_CONFIG)) if DEFAULT_CONFIG.exists() else (Config(), "defaults")
    return load_config(path), str(path)


def _sizes(text: str) -> list[int]:
    try:
        sizes = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--envs: expected comma-separated integers, got {text!r}") from None
    if not sizes or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"--envs: sizes must be >= 1, got {text!r}")
    return sizes


def cmd_bench_env(args) -> int:
    from jaxexo.devices import use_all_cpu_cores

    use_all_cpu_cores()
    cfg, name = _load(args.config)
    from jaxexo.benchmarks.env_bench import run_env_benchmark

    run_env_benchmark(cfg, Path(name).stem, args.envs, args.out)
    return 0


def cmd_train(args) -> int:
    from jaxexo.devices import use_all_cpu_cores

    use_all_cpu_cores()
    cfg, name = _load(args.config)
    from jaxexo.train.driver import run_training

    print(f"jaxexo train: {name} -> {args.out} (seed {args.seed}{', resume' if args.resume else ''})")
    res = run_training(cfg, args.out, seed=args.seed, resume=args.resume, progress=not args.quiet)
    held = res.get("held_out") or {}
    print(f"trained {res['episodes']} episodes, {res['env_steps']:,} env steps in {res['train_seconds']:.1f} s")
    print(f"greedy eval on {sum(v['n'] for v in res['by_obstacle'].values())} test layouts: "
          f"success {res['success']:.3f}, accuracy {res['accuracy']:.3f}"
          + (f"; held-out triangle/half-circle success {held['success']:.3f}" if held else ""))
    print(f"wrote {args.out}/policy.npz, eval.json, metrics.jsonl, training_curve.png")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="jaxexo", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    b = sub.add_parser("bench-env", help="environment steps per second (random actions, full reward)")
    b.add_argument("--config", help="TOML config (default: configs/default.toml)")
    b.add_argument("--envs", type=_sizes, default=[1, 256, 4096, 16384], help="batch sizes, e.g. 1,256,4096")
    b.add_argument("--out", default="benchmarks/results", help="folder for the JSON and Markdown results")
    b.set_defaults(func=cmd_bench_env)
    t = sub.add_parser("train", help="train a policy (TD(lambda)); writes a run directory")
    t.add_argument("config", nargs="?", help="TOML config (default: configs/default.toml)")
    t.add_argument("--out", required=True, help="run directory")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--resume", action="store_true", help="continue the run in --out from its checkpoint")
    t.add_argument("--quiet", action="store_true", help="no progress bar")
    t.set_defaults(func=cmd_train)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from jaxexo.config import ConfigError
    from jaxexo.geometry import GeometryError

    try:
        return args.func(args)
    except (ConfigError, GeometryError) as e:
        print(f"jaxexo: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
