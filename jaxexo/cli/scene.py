"""The scene's options of generate, mjcf and replay (the obstacle by name, size or profile file; the
pivot; the start and step length), read into a checked scene with errors naming the option."""

from __future__ import annotations

from jaxexo.cli.common import real

GENERAL_SHAPES = (
    "rectangle",
    "half_ellipse",
)  # --obstacle kinds of any size besides the thesis's five
DEFAULT_SIZE = (0.20, 0.15)  # m, width and height of a general shape


def _profile_obstacle(path, option: str = "--profile"):
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
        raise ValueError(f"{option}: {path}: {e}") from None
    return obstacle


def obstacle_from_args(args, prefix: str = ""):
    """An Obstacle from --obstacle/--width/--height/--center-y (metres); thesis shapes keep their
    Table 3.1 size unless --width/--height are given. Sizes within the one obstacle-size bound
    (jaxexo.physics.geometry.MAX_OBSTACLE_WIDTH, _HEIGHT); errors name the option. ``prefix``
    ("replan_"): the same options of another obstacle (--replan-obstacle, --replan-width, ...)."""
    from jaxexo.physics.geometry import THESIS_OBSTACLES, GeometryError, Obstacle

    def value(name):
        return getattr(args, prefix + name, None)

    def option(name):
        return "--" + (prefix + name).replace("_", "-")

    sizes = ("width", "height", "center_y")
    if value("profile") is not None:
        given = [option(n) for n in sizes if value(n) is not None]
        if given:
            raise ValueError(
                f"{given[0]}: not with {option('profile')} (the profile file gives the obstacle's "
                "shape and place)"
            )
        return _profile_obstacle(value("profile"), option("profile"))
    if value("obstacle") is None:
        raise ValueError(
            f"{option('obstacle')} or {option('profile')}: give the "
            f"{'new ' if prefix else ''}obstacle (a named shape, or a profile file)"
        )
    kind, width, height = value("obstacle"), value("width"), value("height")
    center = 0.45 if value("center_y") is None else value("center_y")
    try:
        if kind in THESIS_OBSTACLES and width is None and height is None:
            return Obstacle.named(kind, center_y=center)
        shape, default_w, default_h = (
            THESIS_OBSTACLES[kind] if kind in THESIS_OBSTACLES else (kind, *DEFAULT_SIZE)
        )
        w = default_w if width is None else width
        h = default_h if height is None else height
        return getattr(Obstacle, shape)(w, h, center_y=center)
    except GeometryError as e:
        field = str(e).split()[0]
        raise ValueError(f"{option(field if field in sizes else 'obstacle')}: {e}") from None


def scene_from_args(args, config):
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


def add_scene_args(g) -> None:
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
    g.add_argument("--width", type=real, help="obstacle width, m")
    g.add_argument("--height", type=real, help="obstacle height, m")
    g.add_argument(
        "--center-y", type=real, help="obstacle centre, m ahead of the start (default 0.45)"
    )
    pv = g.add_mutually_exclusive_group()
    pv.add_argument(
        "--pivot",
        choices=("agent", "obstacle", "between"),
        help=f"stance-foot condition (thesis 3.1; default: {DEFAULT_PIVOT})",
    )
    pv.add_argument("--pivot-y", type=real, help="stance heel y, m")
    g.add_argument("--start-y", type=real, default=DEFAULT_START_Y, help="swing heel start y, m")
    g.add_argument(
        "--step-length", type=real, default=DEFAULT_STEP_LENGTH, help="goal = start + this, m"
    )


def add_sim_policy(x, required: bool) -> None:
    """mjcf's and replay's --policy: the model whose config gives the legs."""
    x.add_argument(
        "--policy", required=required, help="policy.npz (its config: legs, limits, margin)"
    )
