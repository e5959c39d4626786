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


OBSTACLE_KINDS = ("base1", "base2", "base3", "triangle", "half_circle", "rectangle", "half_ellipse")


def obstacle_from_args(args):
    """An Obstacle from --obstacle/--width/--height/--center-y (metres); thesis shapes keep their
    Table 3.1 size unless --width/--height are given."""
    from jaxexo.geometry import THESIS_OBSTACLES, Obstacle

    kind = args.obstacle
    center = 0.45 if args.center_y is None else args.center_y
    if kind in THESIS_OBSTACLES and args.width is None and args.height is None:
        return Obstacle.named(kind, center_y=center)
    shape = {"base1": "rectangle", "base2": "rectangle", "base3": "rectangle", "half_circle": "half_ellipse"}.get(kind, kind)
    default_w, default_h = THESIS_OBSTACLES[kind][1:] if kind in THESIS_OBSTACLES else (0.20, 0.15)
    w = default_w if args.width is None else args.width
    h = default_h if args.height is None else args.height
    return getattr(Obstacle, shape)(w, h, center_y=center)


def cmd_generate(args) -> int:
    from jaxexo.inference import TrajectoryGenerator

    gen = TrajectoryGenerator.load(args.policy)
    traj = gen.generate(obstacle_from_args(args), pivot=args.pivot, pivot_y=args.pivot_y, start_y=args.start_y,
                        step_length=args.step_length, n_points=args.points, smoothing=args.smoothing,
                        duration=args.duration)
    traj.to_csv(args.out)
    written = [args.out]
    if args.json:
        traj.to_json(args.json)
        written.append(args.json)
    if args.plot:
        from jaxexo.inference.plot import plot_trajectory

        plot_trajectory(traj, args.plot)
        written.append(args.plot)
    c = traj.checks
    print(f"{traj.scene.obstacle.kind} {traj.scene.width * 100:.1f} x {traj.scene.height * 100:.1f} cm, pivot "
          f"{traj.scene.pivot}: {len(traj.raw) - 1} agent moves, min clearance {c.min_clearance * 100:.1f} cm, "
          f"{'ok' if c.ok else 'FAILED'}")
    for r in c.reasons + traj.notes:
        print(f"  {r}")
    print("wrote " + ", ".join(written))
    return 0 if c.ok else 1


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
    g = sub.add_parser("generate", help="a smoothed, checked swing trajectory from policy.npz (NumPy only)")
    g.add_argument("--policy", required=True, help="policy.npz written by jaxexo train")
    g.add_argument("--obstacle", required=True, choices=OBSTACLE_KINDS)
    g.add_argument("--width", type=float, help="obstacle width, m")
    g.add_argument("--height", type=float, help="obstacle height, m")
    g.add_argument("--center-y", type=float, help="obstacle centre, m ahead of the start (default 0.45)")
    pv = g.add_mutually_exclusive_group()
    pv.add_argument("--pivot", choices=("agent", "obstacle", "between"), default="obstacle",
                    help="stance-foot condition (thesis 3.1)")
    pv.add_argument("--pivot-y", type=float, help="stance heel y, m")
    g.add_argument("--start-y", type=float, default=0.0, help="swing heel start y, m")
    g.add_argument("--step-length", type=float, default=0.70, help="goal = start + this, m")
    g.add_argument("--points", type=int, default=100, help="samples of the smoothed path")
    g.add_argument("--smoothing", type=float, default=0.005, help="B-spline smoothing s, m^2 (0: raw polyline)")
    g.add_argument("--duration", type=float, default=1.0, help="swing duration for the time stamps, s")
    g.add_argument("--out", required=True, help="CSV file (time, heel, toe, hip, knees, joint angles; SI units)")
    g.add_argument("--json", help="also write JSON (scene, checks, raw points, samples)")
    g.add_argument("--plot", help="also draw the legs, the foot path and the joint angles (PNG)")
    g.set_defaults(func=cmd_generate)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from jaxexo.config import ConfigError
    from jaxexo.geometry import GeometryError
    from jaxexo.policy import PolicyFileError

    try:
        return args.func(args)
    except (ConfigError, GeometryError, PolicyFileError, ValueError) as e:
        print(f"jaxexo: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
