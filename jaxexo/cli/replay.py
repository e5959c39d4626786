"""``jaxexo replay``: one scene's swing (RL, CFFTG or both) replayed in MuJoCo, kinematically and
with ``--driven`` at the [device] limits; the figures and report come from jaxexo.sim.report.
Method: docs/safety.md, "Replayed in a physics engine"."""

from __future__ import annotations

from jaxexo.cli.common import check_paths, check_rate, option_values, real
from jaxexo.cli.scene import add_scene_args, add_sim_policy, scene_from_args


def cmd_replay(args) -> int:
    check_paths([("--policy", args.policy)], [("--json", args.json)])
    check_rate(args.rate, "--rate")
    check_rate(args.reference_rate, "--reference-rate")
    from jaxexo.sim.replay import require_mujoco

    require_mujoco()  # a clear error before any work
    from jaxexo.baselines import CFFTG
    from jaxexo.inference import TrajectoryGenerator
    from jaxexo.sim.report import replay_document, replay_swing

    rl = TrajectoryGenerator.load(args.policy)
    config = rl.config
    scene = scene_from_args(args, config)
    common = dict(
        pivot=scene.pivot_y if args.pivot_y is not None else (args.pivot or None),
        start_y=args.start_y,
        step_length=args.step_length,
    )
    gens = {
        "rl": lambda: rl.generate(scene.obstacle, fallback=None, **common),
        "cfftg": lambda: CFFTG(config).generate(scene.obstacle, **common),
    }
    options = option_values(
        args, "rate", "driven", "half_limits", "controller", "reference", "reference_rate"
    )
    replays = []
    for name in ("rl", "cfftg") if args.method == "both" else (args.method,):
        r = replay_swing(name, gens[name](), config, **options)
        print("\n".join(r.lines()))
        replays.append(r)
    if args.json:
        from jaxexo.swing.export import write_json

        write_json(replay_document(scene, replays), args.json)
        print(f"wrote {args.json}")
    return 0 if all(r.ok for r in replays) else 1


def add_options(x) -> None:
    """The `jaxexo replay` options."""
    add_sim_policy(x, required=True)
    add_scene_args(x)
    x.add_argument(
        "--method",
        choices=("rl", "cfftg", "both"),
        default="rl",
        help="the RL swing alone (no fallback), CFFTG's, or both",
    )
    x.add_argument(
        "--rate", type=real, help="control rate, Hz (default: the config's control_rate)"
    )
    x.add_argument(
        "--driven",
        action="store_true",
        help="also drive the legs within the [device] limits",
    )
    x.add_argument(
        "--controller",
        choices=("pd_ff", "servo"),
        default="pd_ff",
        help="with --driven: PD with inverse-dynamics feed-forward (pd_ff, default) or stiff "
        "position servos (servo)",
    )
    x.add_argument(
        "--reference",
        choices=("curve", "quintic", "cubic", "linear"),
        default="curve",
        help="with --driven: what the setpoints follow: the timed curve at every physics step "
        "(default), or its samples at --reference-rate interpolated as a drive does (quintic or "
        "cubic Hermite; linear for comparison only)",
    )
    x.add_argument(
        "--reference-rate",
        type=real,
        help="with --driven and a sampled --reference: the samples' rate, Hz (default: --rate)",
    )
    x.add_argument(
        "--half-limits", action="store_true", help="with --driven: also at half the limits"
    )
    x.add_argument("--json", help="write the figures (SI units) to this JSON file")
    x.set_defaults(func=cmd_replay)
