"""``jaxexo walk``: a walk over a measured course, its footholds and every swing timed for the
device, written as CSV/JSON, plotted and animated. Method: docs/walking.md."""

from __future__ import annotations

from jaxexo.cli import common


def cmd_walk(args) -> int:
    common.swing_outputs(
        args,
        [("--policy", args.policy), ("--terrain", args.terrain)]
        + [("--update-terrain", t) for t in args.update_terrain or ()],
    )
    common.check_rate(args.rate, "--rate")
    _check_updates(args)
    fallback_method = common.fallback(args)
    from jaxexo.course.ground import check_double_support, check_number

    # The course's own checks, before any policy or terrain is read, naming the options as typed.
    check_number("--start-y", args.start_y)
    check_number("--goal-y", args.goal_y)
    check_number("--steps", args.steps, 1, integer=True)
    check_double_support("--double-support", args.double_support)
    gen = common.generator(args)
    common.check_clearance(args.clearance, gen.config)
    from jaxexo.course import CourseError, plan_course
    from jaxexo.storage.terrain_file import read_terrain

    terrain = read_terrain(args.terrain)
    _check_size(args, gen.config, terrain)
    kw = common.option_values(
        args, "start_y", "goal_y", "steps", "rate", "clearance", "double_support"
    )
    kw["updates"] = _updates(args)
    kw.update(common.method_options(gen, fallback=fallback_method))
    try:  # an infeasible course is refused here: nothing written
        course = plan_course(gen, terrain, **kw)
    except CourseError as e:
        raise CourseError(_as_typed_update(str(e), args)) from None
    _check_size(args, gen.config, terrain, course)
    from jaxexo.plots.animate import animate_course
    from jaxexo.plots.plot import plot_course

    written = common.write_outputs(
        args,
        course,
        lambda path: plot_course(course, path),
        (lambda path: animate_course(course, path)) if len(course.samples) else None,
    )
    _report_course(course, terrain.source)
    print("wrote " + ", ".join(written))
    return 0 if course.ok else 1


def _check_updates(args) -> None:
    """--update-at and --update-terrain, before any work: given in pairs (the n-th time with the
    n-th terrain file), each time a finite number of s >= 0 on the walk's clock."""
    from jaxexo.course.ground import check_number

    at, files = args.update_at or [], args.update_terrain or []
    if len(at) != len(files):
        short, other = (
            ("--update-terrain", "--update-at")
            if len(at) > len(files)
            else ("--update-at", "--update-terrain")
        )
        raise ValueError(
            f"{short}: give one per {other} (the n-th time with the n-th terrain file), got "
            f"{len(at)} --update-at and {len(files)} --update-terrain"
        )
    for t in at:
        check_number("--update-at", t, 0.0)
    from jaxexo.physics.geometry import as_given

    for i, t in enumerate(at):
        if t in at[:i]:
            raise ValueError(
                f"--update-at: {as_given(t)} s is given twice; give one terrain per instant"
            )


def _as_typed_update(message: str, args) -> str:
    """A refusal naming ``updates[i] (t = ...)`` worded as the command line gave that update."""
    import re

    from jaxexo.physics.geometry import as_given

    def typed(m):
        i = int(m.group(1))
        return (
            f"--update-at {as_given(args.update_at[i])} (--update-terrain {args.update_terrain[i]})"
        )

    return re.sub(r"updates\[(\d+)\](?: \(t = [^)]*\))?", typed, message)


def _updates(args):
    """The terrain updates of --update-at/--update-terrain (each file read and checked)."""
    from jaxexo.course import TerrainUpdate
    from jaxexo.storage.terrain_file import read_terrain

    return [
        TerrainUpdate(t, read_terrain(f))
        for t, f in zip(args.update_at or [], args.update_terrain or [])
    ]


def _check_size(args, config, terrain, course=None) -> None:
    """The walk's samples and outputs (the CSV, and --json's lists and text) refused where they
    would not fit in half the memory this process may use, naming --rate and the course: before
    any work by an estimate (jaxexo.course.ground.walk_size, a lower bound), and once the course
    is planned by its rows, before anything is written."""
    from jaxexo.course.ground import (
        JSON_ROW_BYTES,
        ROW_BYTES,
        FootholdRules,
        WalkSize,
        check_walk_size,
        walk_size,
    )
    from jaxexo.course.record import WALK_COLUMNS
    from jaxexo.swing.timing import DeviceLimits

    names = {
        "rate": "--rate",
        "course": "--goal-y, --steps",
        "outputs": " with the --json document" if args.json else " with the CSV",
    }
    if course is None:
        size = walk_size(
            terrain,
            config,
            FootholdRules.of(config, args.clearance),
            limits=DeviceLimits.from_config(config),
            rate=args.rate,
            start_y=args.start_y,
            goal_y=args.goal_y,
            steps=args.steps,
            dwell=args.double_support,
        )
    else:
        landings = course.footholds.landings
        size = WalkSize(
            course.footholds.start_y,
            landings[-1] if landings else course.footholds.start_y,
            len(course.steps),
            course.duration,
            len(course.samples),
            course.rate,
        )
    row = JSON_ROW_BYTES if args.json else ROW_BYTES
    check_walk_size(
        size, columns=len(WALK_COLUMNS), row_bytes=row, names=names, known=course is not None
    )


def _report_course(course, source) -> None:
    """The walk's summary: its swings, their methods and times, and what failed."""
    fb = sum(s.method == "cfftg-fallback" for s in course.steps)
    print(
        f"{source}: {len(course.footholds)} swings from y = {course.footholds.start_y:.2f} m to "
        f"{course.footholds.landings[-1]:.2f} m ({course.method}"
        + (f", {fb} CFFTG fallback{'s' * (fb != 1)}" if fb else "")
        + f"), {course.duration:.2f} s at "
        f"{course.rate:g} Hz, {'ok' if course.ok else 'FAILED'}"
    )
    for st in course.steps:
        switched = st.timed.switch_times if st.replanned_from is not None else ()
        print(
            f"  step {st.index + 1:2d} {st.leg:5s} {st.start_y:6.2f} -> {st.landing_y:6.2f} m (pivot {st.pivot_y:.2f} m)"
            f" {st.method:14s} {st.end_s - st.start_s:5.2f} s{'' if st.ok else '  FAILED'}"
            + "".join(f", replanned at {st.start_s + t:.3f} s" for t in switched)
        )
    for r in course.reasons:
        print(f"  {r}")


def add_options(w) -> None:
    """The `jaxexo walk` options."""
    common.add_policy(w)
    w.add_argument(
        "--terrain",
        required=True,
        help="the ground profile: a CSV (y,z per line) or JSON "
        '({"points": [[y, z], ...]}) file, m, y increasing, z >= 0',
    )
    common.add_method(
        w, "rl: the trained policy's swings; cfftg: CFFTG's swings on the same footholds"
    )
    common.add_fallback(
        w, "when an RL swing is not safe, use CFFTG's (cfftg, reported per step) or stop (none)"
    )
    w.add_argument(
        "--start-y",
        type=common.real,
        help="where both feet stand at first, m (default: the terrain's first point)",
    )
    end = w.add_mutually_exclusive_group()
    end.add_argument(
        "--goal-y",
        type=common.real,
        help="where both feet stand at the end, m (default: the furthest foothold on the terrain)",
    )
    end.add_argument("--steps", type=common.whole, help="walk exactly this many swings instead")
    w.add_argument(
        "--rate",
        type=common.real,
        help="control rate, Hz (default: the config's [device] control_rate)",
    )
    w.add_argument(
        "--clearance",
        type=common.real,
        help="m every swing keeps from the terrain (default: the model's env.min_clearance)",
    )
    w.add_argument(
        "--double-support",
        type=common.real,
        default=0.0,
        help="s both feet stand still at each landing (default 0: the swings meet at rest)",
    )
    w.add_argument(
        "--out",
        required=True,
        help="CSV file: both legs' heels, toes, hip, knees, joint angles, "
        "velocities and accelerations at the control rate (SI units)",
    )
    w.add_argument(
        "--json",
        help="also write JSON (footholds, ok, and each step's samples, landing and method)",
    )
    w.add_argument(
        "--update-at",
        type=common.real,
        action="append",
        help="s on the walk's clock (0: the first lift-off) from which the terrain is "
        "--update-terrain's: the swing in flight is replanned over it, later swings planned on "
        "it, the footholds kept; repeat both for several updates",
    )
    w.add_argument(
        "--update-terrain",
        action="append",
        help="the terrain known from --update-at on (a file as --terrain takes)",
    )
    w.add_argument("--plot", help="also draw the footholds and the swings over the terrain (PNG)")
    w.add_argument(
        "--animate",
        help="also write a GIF of the whole walk in real time (needs matplotlib and Pillow)",
    )
    w.set_defaults(func=cmd_walk)
