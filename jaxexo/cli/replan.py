"""``jaxexo generate --replan-at T``: the swing replanned in flight at T over a new obstacle
(jaxexo.swing.replan), its options checked before any work and its refusals named as typed.
Method: docs/replanning.md."""

from __future__ import annotations

import math
from dataclasses import dataclass

from jaxexo.cli.common import option_values, real

# The options that describe the new obstacle (option, attribute), in --help's order.
SHAPE_OPTIONS = (
    ("--replan-obstacle", "replan_obstacle"),
    ("--replan-profile", "replan_profile"),
    ("--replan-width", "replan_width"),
    ("--replan-height", "replan_height"),
    ("--replan-center-y", "replan_center_y"),
)


@dataclass(frozen=True)
class ReplanRequest:
    """What --replan-at and the --replan-* options ask for: the switch time (s), the new obstacle
    and the option that gave it (for a refusal that names it)."""

    at: float
    obstacle: object  # jaxexo.physics.geometry.Obstacle
    option: str


def replan_request(args) -> ReplanRequest | None:
    """The replan asked for (None: no --replan-at), checked before any work: every --replan-*
    option needs --replan-at, --replan-at needs one new obstacle (a named shape with its sizes, as
    --obstacle, or a profile file, as --profile) and a time after lift-off within the longest swing."""
    from jaxexo.config import MAX_SWING_DURATION
    from jaxexo.physics.geometry import as_given

    given = [o for o, a in SHAPE_OPTIONS if getattr(args, a) is not None]
    at = args.replan_at
    if at is None:
        if given:
            raise ValueError(
                f"{given[0]}: needs --replan-at (the time, s after lift-off, from which the new "
                f"obstacle is known); add --replan-at, or leave out {given[0]}"
            )
        return None
    if not (math.isfinite(at) and 0.0 < at < MAX_SWING_DURATION):
        raise ValueError(
            f"--replan-at: expected a time in s after lift-off (0 < t < {MAX_SWING_DURATION:g}, "
            f"the longest swing), got {as_given(at)}"
        )
    if args.replan_obstacle is None and args.replan_profile is None:
        raise ValueError(
            "--replan-at: give the new obstacle too (--replan-obstacle with --replan-width, "
            "--replan-height, --replan-center-y as for --obstacle, or --replan-profile FILE)"
        )
    if args.replan_obstacle is not None and args.replan_profile is not None:
        raise ValueError(
            "--replan-obstacle, --replan-profile: give one of them (a named shape, or a profile file)"
        )
    from jaxexo.cli.scene import obstacle_from_args

    option = "--replan-profile" if args.replan_profile is not None else "--replan-obstacle"
    return ReplanRequest(float(at), obstacle_from_args(args, "replan_"), option)


def replanned(gen, swing, request: ReplanRequest, args, own: dict):
    """``swing`` (a TimedSwing) replanned by ``gen`` at request.at over request.obstacle with
    generate's options (--clearance, --points, and ``own``: those of --smoothing and --fallback its
    generator takes); a refusal of the library names the option as typed (at: --replan-at,
    obstacle: the option that gave it)."""
    kw = {**option_values(args, "clearance", n_points="points"), **own}
    try:
        return gen.replan(swing, request.obstacle, at=request.at, **kw)
    except ValueError as e:
        text = str(e)
        for field, option in (("at:", "--replan-at:"), ("obstacle:", request.option + ":")):
            if text.startswith(field):
                text = option + text[len(field) :]
        raise ValueError(text) from None


def report_replan(old, new, report) -> bool:
    """Where the swing switched and the replanned swing's verdict on ``report``; whether it is ok."""
    import numpy as np

    sc, c = new.scene, new.checks
    print(
        f"replanned at t = {new.switch_times[-1]:.4f} s (of a {old.duration:.2f} s swing) over "
        f"{sc.obstacle.kind} {sc.width * 100:.1f} x {sc.height * 100:.1f} cm: {new.method} "
        f"continuation, min clearance {c.min_clearance * 100:.1f} cm, {new.duration:.2f} s swing, "
        f"peak joint velocity {np.degrees(new.peak_velocity.max()):.0f} deg/s, "
        f"{'within' if new.within_limits else 'OUTSIDE'} the limits, "
        f"{'ok' if new.ok else 'FAILED'}",
        file=report,
    )
    for r in new.reasons + tuple(n for n in new.notes if n not in old.notes):
        print(f"  {r}", file=report)
    return new.ok


def add_replan_args(g) -> None:
    """generate's --replan-* options: the time of the update and the new obstacle, written as
    generate's own obstacle options are."""
    from jaxexo.cli.scene import GENERAL_SHAPES
    from jaxexo.physics.geometry import THESIS_OBSTACLES

    g.add_argument(
        "--replan-at",
        type=real,
        help="replan the timed swing in flight at this time (s after lift-off) over the new "
        "obstacle (--replan-obstacle or --replan-profile): the same swing before it, a "
        "continuation joined with continuous joint acceleration after it; every output is the "
        "replanned swing (timed at --rate, default the config's control rate)",
    )
    g.add_argument(
        "--replan-obstacle",
        choices=(*THESIS_OBSTACLES, *GENERAL_SHAPES),
        help="the new obstacle, named as --obstacle (or --replan-profile)",
    )
    g.add_argument(
        "--replan-profile", help="the new obstacle as a height profile file, as --profile takes"
    )
    g.add_argument("--replan-width", type=real, help="new obstacle width, m")
    g.add_argument("--replan-height", type=real, help="new obstacle height, m")
    g.add_argument(
        "--replan-center-y",
        type=real,
        help="new obstacle centre, m ahead of the start (default 0.45)",
    )
