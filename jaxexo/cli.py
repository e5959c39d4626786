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


def cmd_sweep(args) -> int:
    from jaxexo.sweep.spec import load_sweep, parse_bytes

    budget = parse_bytes(args.memory_budget) if args.memory_budget else None
    sweep = load_sweep(args.sweep)      # validated (NumPy only) before JAX starts
    if args.backend == "local":
        from jaxexo.devices import use_all_cpu_cores

        use_all_cpu_cores()
    from jaxexo.sweep.runner import run_sweep

    print(f"jaxexo sweep: {args.sweep} -> {args.out}: {len(sweep.members)} configurations x {len(sweep.seeds)} "
          f"seeds = {sweep.num_agents} agents in {len(sweep.groups)} group(s) ({args.backend} backend"
          f"{', resume' if args.resume else ''})")
    heatmap = tuple(args.heatmap.split(",")) if args.heatmap else None
    res = run_sweep(sweep, args.out, resume=args.resume, backend=args.backend, address=args.address,
                    memory_budget=budget, task_cpus=args.task_cpus, progress=not args.quiet,
                    export_best=args.export_best, heatmap=heatmap)
    for i, e in enumerate(res["ranking"][:5], 1):
        print(f"  #{i} config {e['config_id']} ({e['label']}): success {e['success_mean']:.3f} "
              f"± {e['success_std']:.3f} over {e['seeds']} seeds, held-out {e['held_out_success']:.3f}"
              + (f", {e['diverged']} diverged" if e["diverged"] else ""))
    if res["wall_s_this_run"] > 0 and res["env_steps_this_run"]:
        print(f"{res['env_steps_this_run']:,.0f} env steps in {res['wall_s_this_run']:.1f} s "
              f"({res['env_steps_this_run'] / res['wall_s_this_run'] / 1e6:.3f} M env-steps/s)")
    print(f"wrote {args.out}/results.csv, summary.md, " + ", ".join(res["figures"])
          + (", best/policy.npz, best/config.toml" if "exported" in res else ""))
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
    s = sub.add_parser("sweep", help="train a grid of configurations x seeds as compiled, vmapped programs")
    s.add_argument("sweep", help="sweep file (a config with a [sweep] table; see configs/sweeps/)")
    s.add_argument("--out", required=True, help="sweep directory (results.csv, summary.md, figures)")
    s.add_argument("--resume", action="store_true", help="run only the chunks of --out without results")
    s.add_argument("--export-best", action="store_true", help="write best/policy.npz and best/config.toml")
    s.add_argument("--backend", choices=["local", "ray"], default="local",
                   help="local: chunks over this machine's CPU cores; ray: chunks as tasks on a Ray cluster")
    s.add_argument("--address", help="Ray cluster address (default: start a local Ray instance)")
    s.add_argument("--task-cpus", type=int, help="ray: CPUs (JAX devices) per chunk task (default: this machine's cores)")
    s.add_argument("--memory-budget", help="memory for one chunk, e.g. 4GiB (default: half the available memory)")
    s.add_argument("--heatmap", help="two axes for heatmap.png, e.g. train.lr,train.lam (default: sweep.heatmap)")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=cmd_sweep)
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
