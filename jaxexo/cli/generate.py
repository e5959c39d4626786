"""``jaxexo generate``: one checked swing from the trained policy or CFFTG, optionally timed for the
device, written as CSV/JSON/ROS 2, plotted and animated. Method: docs/generation.md."""

from __future__ import annotations

import sys

from jaxexo.cli.common import (
    add_fallback,
    add_method,
    add_policy,
    check_clearance,
    check_rate,
    fallback,
    generator,
    method_options,
    option_values,
    real,
    refuse_unused,
    swing_outputs,
    whole,
    write_outputs,
)
from jaxexo.cli.replan import add_replan_args, replan_request, replanned, report_replan
from jaxexo.cli.scene import add_scene_args, obstacle_from_args


def cmd_generate(args) -> int:
    outputs = swing_outputs(
        args,
        [
            ("--policy", args.policy),
            ("--profile", args.profile),
            ("--replan-profile", args.replan_profile),
        ],
    )
    if args.obstacle is not None and args.profile is not None:
        raise ValueError(
            "--obstacle, --profile: give one of them (a named shape, or a profile file)"
        )
    refuse_unused(args, "smoothing")
    fallback_method = fallback(args)
    from jaxexo.storage.atomic import writes_to_stdout
    from jaxexo.swing.options import check_duration, check_points

    # The generators' own checks, before any policy is read (the message names the option).
    check_rate(args.rate, "--rate")
    if args.ros and args.rate is None:
        raise ValueError("--ros: a ROS 2 JointTrajectory is a timed swing; give --rate too")
    joint_names = _joint_names(args)
    check_points(args.points, "--points")
    check_duration(args.duration, "--duration")
    obstacle = obstacle_from_args(args)
    request = replan_request(args)
    # An output on standard output (-, /dev/stdout) keeps it for the data: messages go to stderr.
    report = sys.stderr if any(writes_to_stdout(v) for _, v in outputs) else sys.stdout
    common = option_values(
        args,
        "pivot",
        "pivot_y",
        "start_y",
        "step_length",
        "duration",
        "clearance",
        n_points="points",
    )
    gen = generator(args)
    check_clearance(args.clearance, gen.config)
    own = method_options(gen, smoothing=args.smoothing, fallback=fallback_method)
    traj = gen.generate(obstacle, **own, **common)
    timed = _timed_swing(args, traj, gen.config, request is not None)
    # The swing as planned (``old``) is kept beside the replanned one for the figure and the GIF.
    old, timed = (timed, replanned(gen, timed, request, args, own)) if request else (None, timed)
    written = write_outputs(args, timed or traj, *_drawings(traj, old, timed))
    if args.ros:
        timed.to_joint_trajectory(args.ros, joint_names=joint_names)
        written.append(args.ros)
    ok = _report_swing(gen, traj, old or timed, report)
    if old is not None:
        ok = report_replan(old, timed, report)
    print("wrote " + ", ".join(written), file=report)
    return 0 if ok else 1


def _drawings(traj, old, timed):
    """--plot's and --animate's writers: of the swing, or of the swing replanned (old beside new)."""
    from jaxexo.plots.animate import animate_replan, animate_swing
    from jaxexo.plots.plot import plot_replan, plot_trajectory

    if old is None:
        return (lambda path: plot_trajectory(traj, path)), (lambda path: animate_swing(timed, path))
    return (lambda path: plot_replan(old, timed, path)), (
        lambda path: animate_replan(old, timed, path)
    )


def _joint_names(args):
    """--joint-names (comma-separated, for --ros) checked before any work; None: not given."""
    if args.joint_names is None:
        return None
    if not args.ros:
        raise ValueError("--joint-names: names the joints of the --ros output; give --ros too")
    from jaxexo.swing.export import check_joint_names

    names = [n.strip() for n in args.joint_names.split(",")]
    return check_joint_names(names, "--joint-names", repr(args.joint_names))


def _timed_swing(args, traj, config, replan: bool):
    """The swing timed for the device ([device] limits of the config) at --rate (default: the
    config's control_rate) when --rate, --animate or a replan (of a timed swing) is asked for; else
    None (uniform time stamps)."""
    if args.rate is None and not args.animate and not replan:
        return None
    from jaxexo.swing.timing import time_swing

    return time_swing(traj, config, rate=args.rate)


def _report_swing(gen, traj, timed, report) -> bool:
    """The summary of a swing (and its device timing) on ``report``; whether it is ok."""
    import numpy as np

    c = traj.checks
    moves = gen.describe(traj)
    print(
        f"{traj.scene.obstacle.kind} {traj.scene.width * 100:.1f} x {traj.scene.height * 100:.1f} cm, pivot "
        f"{traj.scene.pivot}: {moves}, min clearance (between samples, guaranteed) {c.min_clearance * 100:.1f} cm, "
        f"{'ok' if c.ok else 'FAILED'}",
        file=report,
    )
    for r in c.reasons + traj.notes:
        print(f"  {r}", file=report)
    if timed is None:
        return c.ok
    print(
        f"device timing: {timed.duration:.2f} s swing at {timed.rate:g} Hz, peak joint velocity "
        f"{np.degrees(timed.peak_velocity.max()):.0f} deg/s, acceleration "
        f"{np.degrees(timed.peak_acceleration.max()):.0f} deg/s^2, "
        f"{'within' if timed.within_limits else 'OUTSIDE'} the limits",
        file=report,
    )
    for r in timed.reasons:
        if r not in c.reasons:
            print(f"  {r}", file=report)
    return c.ok and timed.ok


def add_options(g) -> None:
    """The `jaxexo generate` options."""
    add_policy(g)
    add_method(g, "rl: the trained policy; cfftg: the polynomial baseline (jaxexo.baselines.cfftg)")
    add_scene_args(g)
    g.add_argument("--points", type=whole, default=100, help="samples of the smoothed path")
    add_fallback(
        g, "when the RL swing is not safe, return CFFTG's plan (cfftg) or the RL swing alone (none)"
    )
    g.add_argument(
        "--smoothing",
        type=real,
        help="B-spline smoothing s, m^2 (0: raw polyline; default: the model's, 0.001 for a "
        "shielded model, the thesis's 0.005 otherwise); rl only",
    )
    g.add_argument(
        "--clearance",
        type=real,
        help="m the swing keeps from the obstacle (default: the model's "
        "env.min_clearance; at most 0.10); the verdict judges against it",
    )
    g.add_argument(
        "--duration",
        type=real,
        default=1.0,
        help="swing duration for the time stamps, s (ignored with --rate)",
    )
    g.add_argument(
        "--rate",
        type=real,
        help="device-ready output: the shortest rest-to-rest timing within the "
        "config's [device] joint limits, sampled at this rate (Hz); the CSV "
        "and JSON gain joint velocities and accelerations",
    )
    g.add_argument(
        "--animate",
        help="also write a GIF of both legs stepping over the obstacle in real time at "
        "the device timing (needs matplotlib and Pillow)",
    )
    g.add_argument(
        "--out",
        required=True,
        help="CSV file (time, heel, toe, hip, knees, joint angles; SI units)",
    )
    g.add_argument("--json", help="also write JSON (scene, checks, raw points, samples)")
    g.add_argument(
        "--ros",
        help="also write the timed swing as ROS 2 trajectory_msgs/JointTrajectory JSON "
        "(positions, velocities, accelerations; needs --rate)",
    )
    g.add_argument(
        "--joint-names",
        help="the --ros output's joint names, as the robot's controller names them: four, "
        "comma-separated, for hip_swing,knee_swing,hip_stance,knee_stance in that order "
        "(default: those names)",
    )
    g.add_argument("--plot", help="also draw the legs, the foot path and the joint angles (PNG)")
    add_replan_args(g)
    g.set_defaults(func=cmd_generate)
