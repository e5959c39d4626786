"""The ``jaxexo`` command line. Subcommands import JAX lazily, after the CPU-device setup."""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

# Shipped inside the package (package data), so the default model is the same however jaxexo is
# installed; the repository's configs/default.toml is a byte-equal copy.
DEFAULT_CONFIG = Path(__file__).resolve().parent / "config" / "default.toml"


def _load(path):
    from jaxexo.config import load_config

    path = DEFAULT_CONFIG if path is None else path
    return load_config(path), str(path)


def _sizes(text: str) -> list[int]:
    try:
        sizes = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--envs: expected comma-separated integers, got {text!r}"
        ) from None
    if not sizes or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"--envs: sizes must be >= 1, got {text!r}")
    return sizes


def cmd_bench_env(args) -> int:
    from jaxexo.train.devices import use_all_cpu_cores

    use_all_cpu_cores()
    cfg, name = _load(args.config)
    from jaxexo.benchmarks.env_bench import run_env_benchmark

    run_env_benchmark(
        cfg, Path(name).stem, args.envs, args.out, name=args.name, mixed=not args.no_mixed
    )
    return 0


def _resume_command(args) -> str:
    """The command line that continues an interrupted ``jaxexo train`` (its options, and --resume)."""
    import shlex

    argv = ["jaxexo", "train"]
    if args.config_given is not None:
        argv.append(str(args.config_given))
    argv += ["--out", str(args.out)]
    if args.seed != 0:
        argv += ["--seed", str(args.seed)]
    if args.population is not None:
        argv += ["--population", str(args.population)]
    return shlex.join([*argv, "--resume"])


def cmd_train(args) -> int:
    from jaxexo.train.devices import use_all_cpu_cores

    use_all_cpu_cores()
    args.config_given = args.config  # as typed: the resume command repeats it
    if args.config is None and args.resume and (Path(args.out) / "config.toml").is_file():
        args.config = Path(args.out) / "config.toml"  # the run's own resolved config
    cfg, name = _load(args.config)
    if args.population is not None:
        from jaxexo.config import with_population

        cfg = with_population(cfg, args.population, "--population")
    from jaxexo.config import check_seed

    check_seed(
        args.seed, "--seed", cfg.train.population
    )  # before JAX starts (run_training checks it too)
    from jaxexo.config.memory import check_memory

    check_memory(cfg)  # before JAX allocates: a run the machine cannot hold is refused here
    from jaxexo.train.devices import use_compilation_cache

    use_compilation_cache()  # a later run of these static settings loads its programs
    from jaxexo.train.driver import run_training

    k = cfg.train.population
    seeds = (
        f"seeds {args.seed}..{args.seed + k - 1}, population of {k}"
        if k > 1
        else f"seed {args.seed}"
    )
    print(f"jaxexo train: {name} -> {args.out} ({seeds}{', resume' if args.resume else ''})")
    try:
        res = run_training(
            cfg, args.out, seed=args.seed, resume=args.resume, progress=not args.quiet
        )
    except KeyboardInterrupt:
        print(
            f"jaxexo: interrupted; {args.out} keeps the chunks trained up to its last checkpoint; "
            f"continue it with: {_resume_command(args)}",
            file=sys.stderr,
        )
        # Out at once: an interpreter shutdown with XLA's threads mid-computation can crash
        # (seen: SIGSEGV after this message); every file is already written atomically.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)
    held = res.get("held_out") or {}
    print(
        f"trained {res['episodes']} episodes, {res['env_steps']:,} env steps in {res['train_seconds']:.1f} s"
    )
    print(
        f"greedy eval on {sum(v['n'] for v in res['by_obstacle'].values())} test layouts: "
        f"success_raw {res['success_raw']:.3f}, accuracy {res['accuracy']:.3f}"
        + (f"; held-out triangle/half-circle success_raw {held['success_raw']:.3f}" if held else "")
    )
    if "members" in res:
        ok = [m for m in res["members"] if m["diverged_chunk"] is None]
        print(
            f"exported member {res['exported_member']} (seed {res['seed']}, chunk {res['selected_chunk']}, "
            f"validation {res['validation_success_raw']:.3f}); {len(ok)} of {k} members finite, test success_raw "
            + ", ".join(
                f"{m['test']['success_raw']:.2f}" if m["test"] else "-" for m in res["members"]
            )
        )
    print(f"wrote {args.out}/policy.npz, eval.json, metrics.jsonl, training_curve.png")
    return 0


GENERAL_SHAPES = (
    "rectangle",
    "half_ellipse",
)  # --obstacle kinds of any size besides the thesis's five
DEFAULT_SIZE = (0.20, 0.15)  # m, width and height of a general shape


def _profile_obstacle(path):
    """--profile's obstacle: the file read by the terrain rules, then held to the one outline rule
    of every command (jaxexo.sim.pieces.check_simple, as replay and the MJCF scene hold it: a closed
    outline of one obstacle); an error names the option and the file."""
    from jaxexo.physics.geometry import GeometryError, Obstacle
    from jaxexo.sim.pieces import check_simple
    from jaxexo.storage.terrain_file import read_terrain

    t = read_terrain(path)
    try:
        obstacle = Obstacle.profile(t.points)
        check_simple(obstacle.outline_array(len(obstacle.unit_vertices)))
    except GeometryError as e:
        raise ValueError(f"--profile: {path}: {e}") from None
    return obstacle


def obstacle_from_args(args):
    """An Obstacle from --obstacle/--width/--height/--center-y (metres); thesis shapes keep their
    Table 3.1 size unless --width/--height are given. Sizes within the one obstacle-size bound
    (jaxexo.physics.geometry.MAX_OBSTACLE_WIDTH, _HEIGHT); errors name the option."""
    from jaxexo.physics.geometry import THESIS_OBSTACLES, GeometryError, Obstacle

    if getattr(args, "profile", None) is not None:
        given = [
            o
            for o, v in (
                ("--width", args.width),
                ("--height", args.height),
                ("--center-y", args.center_y),
            )
            if v is not None
        ]
        if given:
            raise ValueError(
                f"{given[0]}: not with --profile (the profile file gives the obstacle's shape and place)"
            )
        return _profile_obstacle(args.profile)
    if args.obstacle is None:
        raise ValueError(
            "--obstacle or --profile: give the obstacle (a named shape, or a profile file)"
        )
    kind = args.obstacle
    center = 0.45 if args.center_y is None else args.center_y
    try:
        if kind in THESIS_OBSTACLES and args.width is None and args.height is None:
            return Obstacle.named(kind, center_y=center)
        shape, default_w, default_h = (
            THESIS_OBSTACLES[kind] if kind in THESIS_OBSTACLES else (kind, *DEFAULT_SIZE)
        )
        w = default_w if args.width is None else args.width
        h = default_h if args.height is None else args.height
        return getattr(Obstacle, shape)(w, h, center_y=center)
    except GeometryError as e:
        option = {"width": "--width", "height": "--height", "center_y": "--center-y"}.get(
            str(e).split()[0], "--obstacle"
        )
        raise ValueError(f"{option}: {e}") from None


# A file name to suggest for each output of jaxexo generate (its kind's suffix).
OUTPUT_EXAMPLES = {
    "--out": "trajectory.csv",
    "--json": "trajectory.json",
    "--plot": "swing.png",
    "--animate": "swing.gif",
}


def _check_output_file(option: str, value) -> None:
    """An output path must name a file in an existing folder: refused before any work (and before any
    temporary file is made next to it)."""
    if value is None:
        return
    text = str(value)
    if not text:
        raise ValueError(
            f"{option}: the option is empty; give a file name (e.g. {OUTPUT_EXAMPLES[option]})"
        )
    p = Path(value)
    if text.endswith(("/", "\\")) or p.is_dir():
        raise ValueError(
            f"{option}: {text} is a directory; give a file name (e.g. {p / OUTPUT_EXAMPLES[option]})"
        )
    if option == "--animate":
        _check_animation_name(text)
    if not p.parent.is_dir():
        _check_folder_part(option, p.parent, text)
        raise ValueError(f"{option}: the folder {p.parent} does not exist (for {text})")


def _check_animation_name(text: str) -> None:
    """--animate writes a GIF (Pillow's writer): its file is named .gif, or is a special output
    (``-``, a device, a FIFO) that takes the bytes as they are."""
    from jaxexo.storage.atomic import direct_output

    if Path(text).suffix.lower() != ".gif" and not direct_output(text):
        raise ValueError(
            f"--animate: {text} would hold GIF data (the animation is written as a GIF); "
            f"name it .gif (e.g. {Path(text).with_suffix('.gif')})"
        )


def _check_folder_part(option: str, folder: Path, text: str) -> None:
    """Refuse a path whose nearest existing ancestor is a file (``afile/t.csv``), saying so."""
    from jaxexo.storage.rundir import blocking_file

    q = blocking_file(folder)
    if q is not None:
        raise ValueError(f"{option}: {q} is a file, not a folder (for {text})")


def _same_file(a, b) -> bool:
    """Whether two paths name one file: the same path after symbolic links, or the same inode."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _check_outputs(inputs, outputs) -> None:
    """Outputs never replace an input, and no two outputs share a path: refused before any work.
    ``inputs``, ``outputs``: (option, path or None) pairs."""
    outs = [(o, v) for o, v in outputs if v is not None]
    for i, (option, value) in enumerate(outs):
        for other, v in outs[:i]:
            if _same_file(value, v):
                raise ValueError(
                    f"{option}: {value} is also the {other} output; give each output its own path"
                )
        for other, v in inputs:
            if v is not None and _same_file(value, v):
                raise ValueError(
                    f"{option}: {value} is the {other} input; an output never replaces an input, "
                    "pick another path"
                )


def _check_clearance(clearance, config) -> None:
    """--clearance against the model's env.min_clearance, before any work (names the option)."""
    from jaxexo.physics.scene import check_clearance

    try:
        check_clearance(clearance, config.env.min_clearance)
    except (TypeError, ValueError) as e:
        raise ValueError(f"--{e}") from None


def cmd_generate(args) -> int:
    outputs = _checked_outputs(args, [("--policy", args.policy), ("--profile", args.profile)])
    if args.obstacle is not None and args.profile is not None:
        raise ValueError(
            "--obstacle, --profile: give one of them (a named shape, or a profile file)"
        )
    if args.method == "cfftg" and args.smoothing is not None:
        raise ValueError(
            "--smoothing: applies to --method rl only (CFFTG's polynomial path is not smoothed)"
        )
    fallback = _fallback(args)
    from jaxexo.storage.atomic import writes_to_stdout
    from jaxexo.swing.options import check_duration, check_points
    from jaxexo.swing.timing import check_rate

    # The generators' own checks, before any policy is read (the message names the option).
    if args.rate is not None:
        check_rate(args.rate, "--rate")
    if args.ros and args.rate is None:
        raise ValueError("--ros: a ROS 2 JointTrajectory is a timed swing; give --rate too")
    check_points(args.points, "--points")
    check_duration(args.duration, "--duration")
    obstacle = obstacle_from_args(args)
    # An output on standard output (-, /dev/stdout) keeps it for the data: messages go to stderr.
    report = sys.stderr if any(writes_to_stdout(v) for _, v in outputs) else sys.stdout
    common = _options(
        args,
        "pivot",
        "pivot_y",
        "start_y",
        "step_length",
        "duration",
        "clearance",
        n_points="points",
    )
    gen = _generator(args)
    _check_clearance(args.clearance, gen.config)
    if args.method == "cfftg":
        traj = gen.generate(obstacle, **common)
    else:
        traj = gen.generate(
            obstacle,
            smoothing=args.smoothing,
            fallback=fallback,
            **common,
        )
    timed = _timed_swing(args, traj, gen.config)
    from jaxexo.plots.animate import animate_swing
    from jaxexo.plots.plot import plot_trajectory

    written = _write_outputs(
        args,
        timed or traj,
        lambda path: plot_trajectory(traj, path),
        lambda path: animate_swing(timed, path),
    )
    if args.ros:
        timed.to_joint_trajectory(args.ros)
        written.append(args.ros)
    ok = _report_swing(traj, timed, report)
    print("wrote " + ", ".join(written), file=report)
    return 0 if ok else 1


def _options(args, *names, **renamed) -> dict:
    """Keyword arguments from the parsed options: ``name=args.name`` for each of ``names`` and
    ``key=args.<option>`` for each ``key=option`` of ``renamed``."""
    return {
        **{n: getattr(args, n) for n in names},
        **{k: getattr(args, v) for k, v in renamed.items()},
    }


def _checked_outputs(args, inputs):
    """generate's and walk's output files (--out, --json, --plot, --animate) as (option, path),
    each checked, and none the same file as an input or another output."""
    outputs = (
        ("--out", args.out),
        ("--json", args.json),
        ("--plot", args.plot),
        ("--animate", args.animate),
        ("--ros", getattr(args, "ros", None)),
    )
    for option, value in outputs:
        _check_output_file(option, value)
    _check_outputs(inputs, outputs)
    return outputs


def _generator(args):
    """The generator --method names: CFFTG (with the kinematics and joint limits of --policy's
    config when one is given) or the trained policy."""
    if args.method == "cfftg":
        from jaxexo.baselines import CFFTG

        return CFFTG.from_policy(args.policy) if args.policy else CFFTG(_load(None)[0])
    if not args.policy:
        raise ValueError("--policy: required with --method rl (the trained policy.npz)")
    from jaxexo.inference import TrajectoryGenerator

    return TrajectoryGenerator.load(args.policy)


def _write_outputs(args, data, draw, animate) -> list[str]:
    """``data`` (a swing or a course) as --out's CSV and --json's JSON, --plot drawn by
    ``draw(path)`` and --animate by ``animate(path)`` (None: no GIF); the files written, in order."""
    data.to_csv(args.out)
    written = [args.out]
    for path, write in ((args.json, data.to_json), (args.plot, draw), (args.animate, animate)):
        if path and write is not None:
            write(path)
            written.append(path)
    return written


def _report_swing(traj, timed, report) -> bool:
    """``jaxexo generate``'s summary of a swing (and its device timing) on ``report``; whether it is ok."""
    import numpy as np

    c = traj.checks
    moves = (
        f"{len(traj.raw) - 1} agent moves"
        if traj.method == "rl"
        else (
            "polynomial path (CFFTG fallback: the RL swing was not safe)"
            if traj.method == "cfftg-fallback"
            else "polynomial path (CFFTG)"
        )
    )
    print(
        f"{traj.scene.obstacle.kind} {traj.scene.width * 100:.1f} x {traj.scene.height * 100:.1f} cm, pivot "
        f"{traj.scene.pivot}: {moves}, min clearance (between samples, guaranteed) {c.min_clearance * 100:.1f} cm, "
        f"{'ok' if c.ok else 'FAILED'}",
        file=report,
    )
    for r in c.reasons + traj.notes:
        print(f"  {r}", file=report)
    if timed is not None:
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
        ok = c.ok and timed.ok
    else:
        ok = c.ok
    return ok


def cmd_walk(args) -> int:
    _checked_outputs(args, [("--policy", args.policy), ("--terrain", args.terrain)])
    from jaxexo.config import MAX_CONTROL_RATE

    if args.rate is not None and not (
        math.isfinite(args.rate) and 0 < args.rate <= MAX_CONTROL_RATE
    ):
        raise ValueError(
            f"--rate: control rate must be > 0 and <= {MAX_CONTROL_RATE:g} Hz, got {args.rate:g}"
        )
    fallback = _fallback(args)
    from jaxexo.course.ground import check_number

    # The course's own checks, before any policy or terrain is read, naming the options as typed.
    check_number("--start-y", args.start_y)
    check_number("--goal-y", args.goal_y)
    check_number("--steps", args.steps, 1, integer=True)
    check_number("--double-support", args.double_support, 0.0)
    gen = _generator(args)
    _check_clearance(args.clearance, gen.config)
    from jaxexo.course import plan_course
    from jaxexo.storage.terrain_file import read_terrain

    terrain = read_terrain(args.terrain)
    kw = _options(args, "start_y", "goal_y", "steps", "rate", "clearance", "double_support")
    if args.method == "rl":
        kw["fallback"] = fallback
    course = plan_course(
        gen, terrain, **kw
    )  # an infeasible course is refused here: nothing written
    from jaxexo.plots.animate import animate_course
    from jaxexo.plots.plot import plot_course

    written = _write_outputs(
        args,
        course,
        lambda path: plot_course(course, path),
        (lambda path: animate_course(course, path)) if len(course.samples) else None,
    )
    fb = sum(s.method == "cfftg-fallback" for s in course.steps)
    print(
        f"{terrain.source}: {len(course.footholds)} swings from y = {course.footholds.start_y:.2f} m to "
        f"{course.footholds.landings[-1]:.2f} m ({course.method}"
        + (f", {fb} CFFTG fallback{'s' * (fb != 1)}" if fb else "")
        + f"), {course.duration:.2f} s at "
        f"{course.rate:g} Hz, {'ok' if course.ok else 'FAILED'}"
    )
    for st in course.steps:
        print(
            f"  step {st.index + 1:2d} {st.leg:5s} {st.start_y:6.2f} -> {st.landing_y:6.2f} m (pivot {st.pivot_y:.2f} m)"
            f" {st.method:14s} {st.end_s - st.start_s:5.2f} s{'' if st.ok else '  FAILED'}"
        )
    for r in course.reasons:
        print(f"  {r}")
    print("wrote " + ", ".join(written))
    return 0 if course.ok else 1


def _timed_swing(args, traj, config):
    """The swing timed for the device ([device] limits of the config) at --rate (default: the
    config's control_rate) when --rate or --animate is asked for; else None (uniform time stamps)."""
    if args.rate is None and not args.animate:
        return None
    from jaxexo.swing.timing import time_swing

    return time_swing(traj, config, rate=args.rate)


def _scene_args(args, config):
    """The scene of --obstacle/--width/--height/--center-y, --pivot/--pivot-y, --start-y, --step-length."""
    from jaxexo.physics.scene import DEFAULT_PIVOT, make_scene

    pivot = args.pivot_y if args.pivot_y is not None else (args.pivot or DEFAULT_PIVOT)
    return make_scene(
        obstacle_from_args(args),
        pivot,
        args.start_y,
        args.step_length,
        foot_length=config.kinematics.foot_length,
    )


def _check_start_pose(scene, config) -> None:
    """The keyframe's pose must exist: the swing heel's start within the swing leg's reach (thigh +
    shin) and joint limits from a stance heel at the pivot; else refused naming the option."""
    import numpy as np

    from jaxexo.physics.kinematics import swing_heel_unreachable

    k = config.kinematics
    heel = np.array([scene.start_y, 0.0])
    if swing_heel_unreachable(
        np, scene.pivot_y, heel, k.thigh, k.shin, k.hip_limits, k.knee_limits
    ):
        option = "--pivot-y" if scene.pivot_kind < 0 else "--start-y"
        raise ValueError(
            f"{option}: with the stance heel at {scene.pivot_y:g} m, the swing heel's start "
            f"({scene.start_y:g} m) is out of the leg's reach (thigh + shin = "
            f"{k.thigh + k.shin:g} m) or joint limits; no pose has both feet there"
        )


def cmd_mjcf(args) -> int:
    _check_output_file("--out", args.out)
    _check_outputs([("--policy", args.policy), ("--config", args.config)], [("--out", args.out)])
    if args.policy and args.config:
        raise ValueError(
            "--policy, --config: give one of them (a policy's legs are its own config's)"
        )
    if args.policy:
        from jaxexo.storage.policy_check import load_checked

        config = load_checked(args.policy)[1]
    else:
        config = _load(args.config)[0]
    from jaxexo.sim.mjcf import scene_mjcf
    from jaxexo.storage.atomic import atomic_write

    scene = _scene_args(args, config)
    _check_start_pose(scene, config)
    atomic_write(args.out, scene_mjcf(config, scene))
    print(
        f"wrote {args.out} (open it with: python -m mujoco.viewer --mjcf={args.out}; keyframe 'start')"
    )
    return 0


def cmd_replay(args) -> int:
    outputs = [("--json", args.json)]
    for option, value in outputs:
        _check_output_file(option, value)
    _check_outputs([("--policy", args.policy)], outputs)
    from jaxexo.config import MAX_CONTROL_RATE

    if args.rate is not None and not (
        math.isfinite(args.rate) and 0 < args.rate <= MAX_CONTROL_RATE
    ):
        raise ValueError(
            f"--rate: control rate must be > 0 and <= {MAX_CONTROL_RATE:g} Hz, got {args.rate:g}"
        )
    from jaxexo.sim.replay import require_mujoco

    require_mujoco()  # a clear error before any work
    from jaxexo.baselines import CFFTG
    from jaxexo.inference import TrajectoryGenerator
    from jaxexo.sim.replay import Legs, driven_replay, kinematic_replay
    from jaxexo.swing.timing import DeviceLimits, time_swing

    rl = TrajectoryGenerator.load(args.policy)
    config = rl.config
    scene = _scene_args(args, config)
    common = dict(
        pivot=scene.pivot_y if args.pivot_y is not None else (args.pivot or None),
        start_y=args.start_y,
        step_length=args.step_length,
    )
    gens = {
        "rl": lambda: rl.generate(scene.obstacle, fallback=None, **common),
        "cfftg": lambda: CFFTG(config).generate(scene.obstacle, **common),
    }
    methods = ("rl", "cfftg") if args.method == "both" else (args.method,)
    report, ok = {}, True
    for name in methods:
        timed = time_swing(gens[name](), config, rate=args.rate)
        legs = Legs(config, timed.scene)
        r = {
            "flagged_ok": bool(timed.ok),
            "duration_s": timed.duration,
            "rate_hz": timed.rate,
            "kinematic": kinematic_replay(timed, config, legs=legs),
        }
        k = r["kinematic"]
        print(
            f"{name}: {timed.duration:.2f} s swing at {timed.rate:g} Hz, jaxexo {'ok' if timed.ok else 'FAILED'} "
            f"(guaranteed clearance {100 * timed.checks.min_clearance:.2f} cm); MuJoCo kinematic replay: smallest "
            f"distance {100 * k['mujoco_min_distance_m']:.2f} cm over {k['poses']} poses, largest difference from "
            f"jaxexo at the samples {1e6 * k['max_disagreement_m']:.3f} um, {1e3 * k['seconds']:.1f} ms"
        )
        ok &= not k["flagged_ok_but_within_margin"]
        if args.driven:
            for label, scale in (("driven", 1.0), ("driven_half_limits", 0.5))[
                : 2 if args.half_limits else 1
            ]:
                lim = DeviceLimits.from_config(config).scaled(scale, scale)
                d = r[label] = driven_replay(
                    timed,
                    config,
                    limits=lim,
                    legs=legs,
                    controller=args.controller,
                    reference=args.reference,
                    reference_rate=args.reference_rate,
                )
                print(
                    f"  {label.replace('_', ' ')}: heel error max {100 * d['heel_error_max_m']:.2f} cm, toe "
                    f"{100 * d['toe_error_max_m']:.2f} cm; smallest distance {100 * d['mujoco_min_distance_m']:.2f} "
                    f"cm; {'CONTACT' if d['contact'] else 'no contact'}; "
                    f"{'a limit saturates' if d['saturated'] else 'no limit saturates'}; {1e3 * d['seconds']:.0f} ms"
                )
                ok &= not (timed.ok and d["contact"]) or scale != 1.0
        report[name] = r
    if args.json:
        from jaxexo.swing.export import write_json

        write_json(
            {
                "units": {"length": "m", "angle": "rad", "time": "s"},
                "scene": {
                    "obstacle": scene.obstacle.kind,
                    "pivot_y": scene.pivot_y,
                    "start_y": scene.start_y,
                    "goal_y": scene.goal_y,
                },
                "replays": report,
            },
            args.json,
        )
        print(f"wrote {args.json}")
    return 0 if ok else 1


def cmd_sweep(args) -> int:
    from jaxexo.sweep.spec import load_sweep, memory_budget

    if args.task_cpus is not None and args.task_cpus < 1:
        raise ValueError(f"--task-cpus: must be >= 1, got {args.task_cpus}")
    budget = None if args.memory_budget is None else memory_budget(args.memory_budget)
    sweep = load_sweep(args.sweep)  # validated (NumPy only) before JAX starts
    if args.backend == "local":
        from jaxexo.train.devices import use_all_cpu_cores, use_compilation_cache

        use_all_cpu_cores()
        use_compilation_cache()
    from jaxexo.sweep.runner import run_sweep

    print(
        f"jaxexo sweep: {args.sweep} -> {args.out}: {len(sweep.members)} configurations x {len(sweep.seeds)} "
        f"seeds = {sweep.num_agents} agents in {len(sweep.groups)} group(s) ({args.backend} backend"
        f"{', resume' if args.resume else ''})"
    )
    heatmap = tuple(args.heatmap.split(",")) if args.heatmap else None
    res = run_sweep(
        sweep,
        args.out,
        resume=args.resume,
        backend=args.backend,
        address=args.address,
        memory_budget=budget,
        task_cpus=args.task_cpus,
        progress=not args.quiet,
        export_best=args.export_best,
        export_all=args.export_all,
        heatmap=heatmap,
    )
    for i, e in enumerate(res["ranking"][:5], 1):
        print(
            f"  #{i} config {e['config_id']} ({e['label']}): success {e['success_mean']:.3f} "
            f"± {e['success_std']:.3f} over {e['seeds']} seeds, held-out {e['held_out_success']:.3f}"
            + (f", {e['diverged']} diverged" if e["diverged"] else "")
        )
    if res["wall_s_this_run"] > 0 and res["env_steps_this_run"]:
        print(
            f"{res['env_steps_this_run']:,.0f} env steps in {res['wall_s_this_run']:.1f} s "
            f"({res['env_steps_this_run'] / res['wall_s_this_run'] / 1e6:.3f} M env-steps/s)"
        )
    print(
        f"wrote {args.out}/results.csv, summary.md, "
        + ", ".join(res["figures"])
        + (", best/policy.npz, best/config.toml" if "exported" in res else "")
    )
    return 0


def cmd_eval(args) -> int:
    from jaxexo.evaluation.compare import check_eval_counts, check_report_folder, run_eval

    check_eval_counts(args.n, args.batch)
    check_report_folder(args.out, args.policy, force=args.force)
    report = run_eval(
        args.policy,
        args.out,
        against=args.against,
        scenarios=args.scenarios,
        n=args.n,
        figures=not args.no_figures,
        batch_size=args.batch,
        force=args.force,
        replay=args.replay,
    )
    for name, r in report.items():
        print(
            f"{name}: accuracy {r['accuracy']:.3f}, success {r['success']:.3f}, median {r['time_ms_median']:.3f} ms "
            f"per trajectory, {r['batch_1000_ms']:.1f} ms per batch of 1000"
        )
    print(
        f"wrote {args.out}/report.md, report.json"
        + ("" if args.no_figures else ", trajectories.png, joint_angles.png")
    )
    return 0


def cmd_reproduce(args) -> int:
    from jaxexo.evaluation.reproduce import check_reproduce_options, run_names, run_reproduce
    from jaxexo.train.devices import use_all_cpu_cores, use_compilation_cache

    models = [m.strip() for m in args.models.split(",") if m.strip()]
    if not models:
        raise ValueError(f"--models: name at least one model, got {args.models!r}")
    run_names(models, args.variant)  # checks --models and --variant before anything trains
    check_reproduce_options(args.out, args.n, args.results, args.population, args.seed)
    use_all_cpu_cores()  # after the checks (NumPy only): a refusal starts no JAX
    use_compilation_cache()
    run_reproduce(
        args.out,
        models,
        n=args.n,
        seed=args.seed,
        include_default=args.default,
        results_dir=args.results,
        variant=args.variant,
        population=args.population,
    )
    print(
        f"wrote {args.out}/reproduce.md, reproduce.json and the run directories under {args.out}/runs"
    )
    return 0


def cmd_bench(args) -> int:
    from jaxexo.train.devices import use_all_cpu_cores

    if not (math.isfinite(args.baseline_seconds) and args.baseline_seconds > 0):
        raise ValueError(
            f"--baseline-seconds: a time budget must be a finite number of seconds > 0, "
            f"got {args.baseline_seconds:g}"
        )
    if args.courses < 1:
        raise ValueError(f"--courses: must be >= 1, got {args.courses}")
    use_all_cpu_cores()
    from jaxexo.benchmarks.run_all import run_all

    run_all(
        args.out,
        policy=args.policy,
        baseline_seconds=args.baseline_seconds,
        skip=args.skip,
        courses=args.courses,
    )
    return 0


def _add_scene_args(g) -> None:
    """The scene's options (obstacle, pivot, start, step length) of generate, mjcf and replay."""
    from jaxexo.physics.geometry import THESIS_OBSTACLES
    from jaxexo.physics.scene import DEFAULT_PIVOT, DEFAULT_START_Y, DEFAULT_STEP_LENGTH

    g.add_argument(
        "--obstacle",
        choices=(*THESIS_OBSTACLES, *GENERAL_SHAPES),
        help="a named obstacle (or --profile)",
    )
    g.add_argument(
        "--profile",
        help="the obstacle as a measured height profile: a CSV (y,z per line) or JSON "
        '({"points": [[y, z], ...]}) file, m, y increasing, z >= 0',
    )
    g.add_argument("--width", type=float, help="obstacle width, m")
    g.add_argument("--height", type=float, help="obstacle height, m")
    g.add_argument(
        "--center-y", type=float, help="obstacle centre, m ahead of the start (default 0.45)"
    )
    pv = g.add_mutually_exclusive_group()
    pv.add_argument(
        "--pivot",
        choices=("agent", "obstacle", "between"),
        help=f"stance-foot condition (thesis 3.1; default: {DEFAULT_PIVOT})",
    )
    pv.add_argument("--pivot-y", type=float, help="stance heel y, m")
    g.add_argument("--start-y", type=float, default=DEFAULT_START_Y, help="swing heel start y, m")
    g.add_argument(
        "--step-length", type=float, default=DEFAULT_STEP_LENGTH, help="goal = start + this, m"
    )


def _add_policy(p) -> None:
    """generate's and walk's --policy: the model, or for cfftg only its kinematics."""
    p.add_argument(
        "--policy",
        help="policy.npz written by jaxexo train (required for --method rl; for cfftg it "
        "supplies the kinematics, default: configs/default.toml)",
    )


def _add_method(p, helptext: str) -> None:
    """generate's and walk's --method: the RL generator or CFFTG."""
    p.add_argument("--method", choices=("rl", "cfftg"), default="rl", help=helptext)


def _add_fallback(p, helptext: str) -> None:
    """generate's and walk's --fallback: what stands in for an RL swing that is not safe (not given:
    None, read by ``_fallback``)."""
    p.add_argument("--fallback", choices=("cfftg", "none"), help=helptext + " (default: cfftg)")


def _fallback(args) -> str | None:
    """--fallback's one rule for generate and walk: --method rl only (given with --method cfftg it is
    refused, whatever its value); not given, "cfftg"; "none" is None."""
    if args.method == "cfftg" and args.fallback is not None:
        raise ValueError(
            f"--fallback: applies to --method rl only (CFFTG plans every swing itself), got "
            f"--fallback {args.fallback} with --method cfftg"
        )
    return None if args.fallback == "none" else "cfftg"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="jaxexo", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)
    for name, helptext, add_options in (
        ("bench-env", "environment steps per second (random actions, full reward)", _add_bench_env),
        ("train", "train a policy (TD(lambda)); writes a run directory", _add_train),
        (
            "generate",
            "a smoothed, checked swing trajectory from policy.npz (NumPy only)",
            _add_generate,
        ),
        (
            "mjcf",
            "the legs and the obstacle as a MuJoCo model (MJCF), for MuJoCo's viewer",
            _add_mjcf,
        ),
        (
            "replay",
            "a swing replayed in MuJoCo: its distance to the obstacle, and driven at the "
            "[device] limits with --driven (needs the sim extra)",
            _add_replay,
        ),
        (
            "walk",
            "a walk over a measured course: footholds, every swing and both legs timed "
            "for the device (NumPy only)",
            _add_walk,
        ),
        (
            "sweep",
            "train a grid of configurations x seeds as compiled, vmapped programs",
            _add_sweep,
        ),
        (
            "eval",
            "evaluate the RL generator (and CFFTG) side by side; writes report.md/.json "
            "and figures (NumPy only)",
            _add_eval,
        ),
        (
            "reproduce",
            "train the seven thesis configs and tabulate them beside the thesis's Tables 3.2-3.11",
            _add_reproduce,
        ),
        (
            "bench",
            "every benchmark (environment, trainer, generator, CFFTG, thesis-style "
            "baseline) into benchmarks/results with a summary table",
            _add_bench,
        ),
    ):
        add_options(sub.add_parser(name, help=helptext))
    return p


def _add_results_out(p) -> None:
    """bench-env's and bench's --out: where benchmark results go."""
    p.add_argument(
        "--out", default="benchmarks/results", help="folder for the JSON and Markdown results"
    )


def _add_bench_env(b) -> None:
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


def _add_train(t) -> None:
    """The `jaxexo train` options."""
    t.add_argument(
        "config",
        nargs="?",
        help="TOML config (default: the packaged default, configs/default.toml; "
        "with --resume, the run's own config.toml)",
    )
    t.add_argument("--out", required=True, help="run directory")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument(
        "--population",
        type=int,
        help="train K agents (seeds SEED..SEED+K-1) as one program and export the "
        "one a wearer would choose (overrides [train] population; the "
        "default model's: 2)",
    )
    t.add_argument(
        "--resume", action="store_true", help="continue the run in --out from its checkpoint"
    )
    t.add_argument("--quiet", action="store_true", help="no progress bar")
    t.set_defaults(func=cmd_train)


def _add_generate(g) -> None:
    """The `jaxexo generate` options."""
    _add_policy(g)
    _add_method(
        g, "rl: the trained policy; cfftg: the polynomial baseline (jaxexo.baselines.cfftg)"
    )
    _add_scene_args(g)
    g.add_argument("--points", type=int, default=100, help="samples of the smoothed path")
    _add_fallback(
        g, "when the RL swing is not safe, return CFFTG's plan (cfftg) or the RL swing alone (none)"
    )
    g.add_argument(
        "--smoothing",
        type=float,
        help="B-spline smoothing s, m^2 (0: raw polyline; default: the model's, 0.001 for a "
        "shielded model, the thesis's 0.005 otherwise); rl only",
    )
    g.add_argument(
        "--clearance",
        type=float,
        help="m the swing keeps from the obstacle (default: the model's "
        "env.min_clearance; at most 0.10); the verdict judges against it",
    )
    g.add_argument(
        "--duration",
        type=float,
        default=1.0,
        help="swing duration for the time stamps, s (ignored with --rate)",
    )
    g.add_argument(
        "--rate",
        type=float,
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
    g.add_argument("--plot", help="also draw the legs, the foot path and the joint angles (PNG)")
    g.set_defaults(func=cmd_generate)


def _add_sim_policy(x, required: bool) -> None:
    """mjcf's and replay's --policy: the model whose config gives the legs."""
    x.add_argument(
        "--policy", required=required, help="policy.npz (its config: legs, limits, margin)"
    )


def _add_mjcf(x) -> None:
    """The `jaxexo mjcf` options."""
    _add_sim_policy(x, required=False)
    x.add_argument("--config", help="TOML config when no --policy (default: the packaged default)")
    _add_scene_args(x)
    x.add_argument("--out", required=True, help="MJCF file to write (e.g. legs.xml)")
    x.set_defaults(func=cmd_mjcf)


def _add_replay(x) -> None:
    """The `jaxexo replay` options."""
    _add_sim_policy(x, required=True)
    _add_scene_args(x)
    x.add_argument(
        "--method",
        choices=("rl", "cfftg", "both"),
        default="rl",
        help="the RL swing alone (no fallback), CFFTG's, or both",
    )
    x.add_argument(
        "--rate", type=float, help="control rate, Hz (default: the config's control_rate)"
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
        type=float,
        help="with --driven and a sampled --reference: the samples' rate, Hz (default: --rate)",
    )
    x.add_argument(
        "--half-limits", action="store_true", help="with --driven: also at half the limits"
    )
    x.add_argument("--json", help="write the figures (SI units) to this JSON file")
    x.set_defaults(func=cmd_replay)


def _add_walk(w) -> None:
    """The `jaxexo walk` options."""
    _add_policy(w)
    w.add_argument(
        "--terrain",
        required=True,
        help="the ground profile: a CSV (y,z per line) or JSON "
        '({"points": [[y, z], ...]}) file, m, y increasing, z >= 0',
    )
    _add_method(w, "rl: the trained policy's swings; cfftg: CFFTG's swings on the same footholds")
    _add_fallback(
        w, "when an RL swing is not safe, use CFFTG's (cfftg, reported per step) or stop (none)"
    )
    w.add_argument(
        "--start-y",
        type=float,
        help="where both feet stand at first, m (default: the terrain's first point)",
    )
    end = w.add_mutually_exclusive_group()
    end.add_argument(
        "--goal-y",
        type=float,
        help="where both feet stand at the end, m (default: the furthest foothold on the terrain)",
    )
    end.add_argument("--steps", type=int, help="walk exactly this many swings instead")
    w.add_argument(
        "--rate", type=float, help="control rate, Hz (default: the config's [device] control_rate)"
    )
    w.add_argument(
        "--clearance",
        type=float,
        help="m every swing keeps from the terrain (default: the model's env.min_clearance)",
    )
    w.add_argument(
        "--double-support",
        type=float,
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
    w.add_argument("--plot", help="also draw the footholds and the swings over the terrain (PNG)")
    w.add_argument(
        "--animate",
        help="also write a GIF of the whole walk in real time (needs matplotlib and Pillow)",
    )
    w.set_defaults(func=cmd_walk)


def _add_sweep(s) -> None:
    """The `jaxexo sweep` options."""
    s.add_argument("sweep", help="sweep file (a config with a [sweep] table; see configs/sweeps/)")
    s.add_argument(
        "--out", required=True, help="sweep directory (results.csv, summary.md, figures)"
    )
    s.add_argument(
        "--resume", action="store_true", help="run only the chunks of --out without results"
    )
    s.add_argument(
        "--export-best", action="store_true", help="write best/policy.npz and best/config.toml"
    )
    s.add_argument(
        "--export-all",
        action="store_true",
        help="write every agent's policy.npz and config.toml under agents/ (and agents/index.json)",
    )
    s.add_argument(
        "--backend",
        choices=["local", "ray"],
        default="local",
        help="local: chunks over this machine's CPU cores; ray: chunks as tasks on a Ray cluster",
    )
    s.add_argument("--address", help="Ray cluster address (default: start a local Ray instance)")
    s.add_argument(
        "--task-cpus",
        type=int,
        help="ray: CPUs (JAX devices) per chunk task (default: this machine's cores)",
    )
    s.add_argument(
        "--memory-budget",
        help="memory for one chunk, e.g. 4GiB (default: half the available memory)",
    )
    s.add_argument(
        "--heatmap",
        help="two axes for heatmap.png, e.g. train.lr,train.lam (default: sweep.heatmap)",
    )
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=cmd_sweep)


def _add_eval(e) -> None:
    """The `jaxexo eval` options."""
    e.add_argument("--policy", required=True, help="policy.npz written by jaxexo train")
    e.add_argument(
        "--against", choices=("cfftg",), help="also evaluate this baseline on the same scenarios"
    )
    e.add_argument(
        "--scenarios",
        choices=("train", "test", "all", "unseen"),
        default="test",
        help="test: the five thesis obstacles x three pivots; train: the policy's training "
        "distribution; all: both; unseen: the fixed held-out obstacle families "
        "(jaxexo.evaluation.unseen), reported per family",
    )
    e.add_argument("--n", type=int, default=1000, help="scenarios per set")
    e.add_argument(
        "--batch",
        type=int,
        default=1000,
        help="scenarios per timed generate_batch call (reported scaled to a batch of 1000)",
    )
    e.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    e.add_argument("--force", action="store_true", help="replace an earlier report in --out")
    e.add_argument(
        "--replay",
        action="store_true",
        help="also replay every swing in MuJoCo, kinematically and "
        "driven at the [device] limits (needs the sim extra)",
    )
    e.add_argument("--out", required=True, help="report folder")
    e.set_defaults(func=cmd_eval)


def _add_reproduce(r) -> None:
    """The `jaxexo reproduce` options."""
    r.add_argument(
        "--out",
        required=True,
        help="folder for runs/ and reproduce.md/.json (reuses finished runs)",
    )
    r.add_argument("--models", default="a,b,c,1,2,3,final", help="comma-separated thesis models")
    r.add_argument("--n", type=int, default=1000, help="test scenarios per model")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument(
        "--variant",
        default="both",
        choices=("faithful", "learns", "both"),
        help="faithful: configs/thesis/<m>.toml as the thesis wrote it; learns: <m>-learns.toml, with "
        "the named switches that make it learn; both (default): side by side",
    )
    r.add_argument(
        "--default", action="store_true", help="also train and tabulate configs/default.toml"
    )
    r.add_argument(
        "--population",
        type=int,
        help="members per learns model (seeds SEED..SEED+K-1, the best on validation kept; default "
        "4); the faithful configs always train one agent",
    )
    r.add_argument(
        "--results",
        help="also write the tables to this folder as reproduce_<date>_<machine>.json/.md "
        "(e.g. benchmarks/results)",
    )
    r.set_defaults(func=cmd_reproduce)


def _add_bench(bb) -> None:
    """The `jaxexo bench` options."""
    _add_results_out(bb)
    bb.add_argument(
        "--policy",
        help="policy.npz for the generator benchmarks (default: train configs/default.toml)",
    )
    bb.add_argument(
        "--baseline-seconds",
        type=float,
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
        type=int,
        default=200,
        help="courses drawn for the course part (walks, RL alone against CFFTG)",
    )
    bb.set_defaults(func=cmd_bench)


def _warning_line(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as one line ``jaxexo: warning: ...`` (not Python's source-line form)."""
    print(f"jaxexo: warning: {message}", file=sys.stderr if file is None else file)


def main(argv=None) -> int:
    import warnings

    args = build_parser().parse_args(argv)
    from jaxexo.config import ConfigError
    from jaxexo.physics.geometry import GeometryError
    from jaxexo.storage.policy_file import PolicyFileError
    from jaxexo.storage.rundir import TrainingDiverged

    shown, warnings.showwarning = warnings.showwarning, _warning_line
    try:
        return args.func(args)
    except (ConfigError, GeometryError, PolicyFileError, ValueError) as e:
        # Bad input (config, files, options, a checkpoint or run directory that cannot be used).
        print(f"jaxexo: error: {e}", file=sys.stderr)
        return 2
    except TrainingDiverged as e:
        print(f"jaxexo: error: {e}", file=sys.stderr)
        return 3
    except OSError as e:
        # A write that failed (full disk, file-size limit, permissions): what was written before is intact.
        print(f"jaxexo: error: {e}", file=sys.stderr)
        return 1
    finally:
        warnings.showwarning = shown


if __name__ == "__main__":
    sys.exit(main())
