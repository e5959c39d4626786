"""``jaxexo replay``: one scene's swing (RL, CFFTG or both) replayed in MuJoCo, kinematically and
with ``--driven`` at the [device] limits; the figures and report come from jaxexo.sim.report.
Method: docs/safety.md, "Replayed in a physics engine"."""

from __future__ import annotations

from argparse import ArgumentTypeError

from jaxexo.cli.common import check_paths, check_rate, method_options, option_values, real
from jaxexo.cli.scene import add_scene_args, add_sim_policy, scene_from_args

METHODS = ("rl", "cfftg", "both")  # --method: a registered generator, or both of these two


def _check_drive_options(args) -> None:
    """The driven replay's options only with --driven, and --reference-rate only with a sampled
    --reference: refused as typed, before any work (they used to be ignored)."""
    if not args.driven:
        given = [
            option
            for option, value in (
                ("--reference", args.reference),
                ("--reference-rate", args.reference_rate),
                ("--half-limits", args.half_limits or None),
                ("--controller", args.controller),
            )
            if value is not None
        ]
        if given:
            raise ValueError(
                f"{given[0]}: needs --driven (it sets how the driven replay drives the legs; "
                f"without --driven the swing is only replayed kinematically); add --driven, or "
                f"leave out {', '.join(given)}"
            )
    if args.reference_rate is not None and args.reference in (None, "curve"):
        reference = (
            "--reference was not given (its default, curve,"
            if args.reference is None
            else "--reference is curve (it"
        )
        raise ValueError(
            f"--reference-rate: only for a sampled --reference (quintic, cubic or linear), but "
            f"{reference} follows the curve at every physics step); got --reference-rate "
            f"{args.reference_rate}: add --reference quintic, or leave --reference-rate out"
        )


def _rate_option(text: str | None, option: str) -> float | None:
    """A rate option kept as typed (for messages) and read as a number here."""
    if text is None:
        return None
    try:
        return real(text)  # the one number syntax of every numeric option (no '_')
    except ArgumentTypeError as e:
        raise ValueError(f"{option}: expected a rate in Hz: {e}") from None


def cmd_replay(args) -> int:
    check_paths([("--policy", args.policy)], [("--json", args.json)])
    check_rate(args.rate, "--rate")
    reference_rate = _rate_option(args.reference_rate, "--reference-rate")
    check_rate(reference_rate, "--reference-rate")
    _check_drive_options(args)  # with the options as typed
    args.reference_rate = reference_rate
    from jaxexo.sim.replay import require_mujoco

    require_mujoco()  # a clear error before any work
    from jaxexo.inference import TrajectoryGenerator
    from jaxexo.inference.registry import generator_class
    from jaxexo.sim.report import replay_document, replay_swing

    rl = TrajectoryGenerator.load(args.policy)
    config = rl.config
    scene = scene_from_args(args, config)
    common = dict(
        pivot=scene.pivot_y if args.pivot_y is not None else (args.pivot or None),
        start_y=args.start_y,
        step_length=args.step_length,
    )

    def swing(name):  # the swing alone: no fallback
        cls = generator_class(name)
        gen = rl if cls.needs_policy else cls.from_config(config)
        return gen.with_defaults(**method_options(gen, fallback=None)).generate(
            scene.obstacle, **common
        )

    options = option_values(args, "rate", "driven", "half_limits", "reference_rate")
    if args.driven:
        options.update(controller=args.controller or "pd_ff", reference=args.reference or "curve")
    replays = []
    for name in METHODS[:-1] if args.method == "both" else (args.method,):
        r = replay_swing(name, swing(name), config, **options)
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
        choices=METHODS,
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
        help="with --driven: PD with inverse-dynamics feed-forward (pd_ff, default) or stiff "
        "position servos (servo)",
    )
    x.add_argument(
        "--reference",
        choices=("curve", "quintic", "cubic", "linear"),
        help="with --driven: what the setpoints follow: the timed curve at every physics step "
        "(default), or its samples at --reference-rate interpolated as a drive does (quintic or "
        "cubic Hermite; linear for comparison only)",
    )
    x.add_argument(
        "--reference-rate",
        help="with --driven and a sampled --reference: the samples' rate, Hz (default: --rate)",
    )
    x.add_argument(
        "--half-limits", action="store_true", help="with --driven: also at half the limits"
    )
    x.add_argument("--json", help="write the figures (SI units) to this JSON file")
    x.set_defaults(func=cmd_replay)
