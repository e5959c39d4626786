"""``jaxexo mjcf``: the legs and the obstacle as a MuJoCo model (MJCF text) for MuJoCo's viewer; no
MuJoCo needed to write it. The model: docs/safety.md, "Replayed in a physics engine"."""

from __future__ import annotations

from jaxexo.cli.common import check_paths, load
from jaxexo.cli.scene import add_scene_args, add_sim_policy, scene_from_args


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
    check_paths(
        [("--policy", args.policy), ("--config", args.config)],
        [("--out", args.out)],
        {"--out": "legs.xml"},
    )
    if args.policy and args.config:
        raise ValueError(
            "--policy, --config: give one of them (a policy's legs are its own config's)"
        )
    if args.policy:
        from jaxexo.storage.policy_check import load_checked

        config = load_checked(args.policy)[1]
    else:
        config = load(args.config)[0]
    from jaxexo.sim.mjcf import scene_mjcf
    from jaxexo.storage.atomic import atomic_write

    scene = scene_from_args(args, config)
    _check_start_pose(scene, config)
    atomic_write(args.out, scene_mjcf(config, scene))
    print(
        f"wrote {args.out} (open it with: python -m mujoco.viewer --mjcf={args.out}; keyframe 'start')"
    )
    return 0


def add_options(x) -> None:
    """The `jaxexo mjcf` options."""
    add_sim_policy(x, required=False)
    x.add_argument("--config", help="TOML config when no --policy (default: the packaged default)")
    add_scene_args(x)
    x.add_argument("--out", required=True, help="MJCF file to write (e.g. legs.xml)")
    x.set_defaults(func=cmd_mjcf)
