"""Cross-field validation: a config whose fields are each valid but cannot work together (an obstacle
a step could jump through, one that does not fit between the toe and the goal, one the leg cannot
clear, a budget no scan can count) is refused here, naming the field to change. A shielded config
may step further than its thinnest obstacle: the shield checks each move's whole sweep.
"""

from __future__ import annotations

import itertools

import numpy as np

from jaxexo.config.checks import ConfigError
from jaxexo.config.sections import INT32_MAX, Config, num_updates
from jaxexo.physics import kinematics, terrain
from jaxexo.physics.kinematics import PIVOT_CONDITIONS


def validate(cfg: Config) -> None:
    env, kin, rew, lay, tr = cfg.env, cfg.kinematics, cfg.reward, cfg.layout, cfg.train
    if tr.budget_episodes == 0 and tr.budget_env_steps == 0:
        raise ConfigError(
            "train.budget_episodes: set a budget (budget_episodes and/or budget_env_steps > 0)"
        )
    if tr.num_envs % tr.num_minibatches:
        raise ConfigError(
            f"train.num_minibatches: {tr.num_minibatches} does not divide train.num_envs = "
            f"{tr.num_envs} (minibatches are blocks of environments)"
        )
    if num_updates(cfg) > INT32_MAX:
        which = "budget_env_steps" if tr.budget_env_steps else "budget_episodes"
        raise ConfigError(
            f"train.{which}: needs {num_updates(cfg)} updates of train.num_envs x "
            f"train.rollout_steps env steps, more than a scan can count ({INT32_MAX})"
        )
    if tr.eps_end > tr.eps_start:
        raise ConfigError("train.eps_end: must not exceed train.eps_start")
    if sum(rew.traj_weights) <= 0:
        raise ConfigError(
            "reward.traj_weights: at least one weight must be > 0 (eq 2.38 divides by the sum)"
        )
    if sum(rew.exo_weights) <= 0:
        raise ConfigError(
            "reward.exo_weights: at least one weight must be > 0 (eq 2.52 divides by the sum)"
        )
    if sum(lay.pivot) <= 0:
        raise ConfigError("layout.pivot: at least one pivot condition needs a weight > 0")
    if sum(o.weight for o in lay.obstacles) <= 0:
        raise ConfigError("layout.obstacles: at least one obstacle needs a weight > 0")
    if kin.hip_limits[0] >= kin.hip_limits[1]:
        raise ConfigError("kinematics.hip_limits: lower limit must be below the upper one")
    if kin.knee_limits[0] >= kin.knee_limits[1]:
        raise ConfigError("kinematics.knee_limits: lower limit must be below the upper one")
    key = (env, kin, lay)
    if key not in _SCENES_OK:
        _check_scene(cfg)
        if len(_SCENES_OK) >= 4096:
            _SCENES_OK.clear()
        _SCENES_OK.add(key)
    if env.shield and env.shield_clearance < env.min_clearance:
        raise ConfigError(
            f"env.shield_clearance: {env.shield_clearance} m is below env.min_clearance = "
            f"{env.min_clearance} m; the shield must keep at least the margin that a safe swing needs"
        )
    if env.shield and env.floor_clearance >= env.step_size:
        raise ConfigError(
            f"env.floor_clearance: {env.floor_clearance} m is not below env.step_size = "
            f"{env.step_size} m; the first move off the floor could not clear it"
        )
    if rew.safety_distance < env.min_clearance:
        raise ConfigError(
            f"reward.safety_distance: {rew.safety_distance} m is below env.min_clearance = "
            f"{env.min_clearance} m; the safety term (eq 2.35) must pay the policy to keep the "
            "margin that a safe swing needs, not only to avoid contact"
        )
    change = env.obstacle_change
    if change is not None and change.steps[1] >= env.max_steps:
        raise ConfigError(
            f"env.obstacle_change.steps: a change at step {change.steps[1]} is not before "
            f"env.max_steps = {env.max_steps}, the episode's last step"
        )
    if env.max_steps < rew.step_threshold:
        raise ConfigError(
            f"env.max_steps: {env.max_steps} is below reward.step_threshold = {rew.step_threshold}"
        )


# (env, kinematics, layout) sections that passed _check_scene: its costly reach and room checks
# depend on these alone, so a sweep's configurations that share them are checked once.
_SCENES_OK: set = set()


def _check_scene(cfg: Config) -> None:
    """The obstacles and terrain against the step, the room between the feet, the ceiling and the
    leg's reach (env, kinematics and layout only)."""
    env, lay = cfg.env, cfg.layout
    need = max(len(o.unit_vertices()) for o in lay.obstacles)
    if env.max_vertices and env.max_vertices < need:
        raise ConfigError(
            f"env.max_vertices: {env.max_vertices} is fewer than the {need} outline vertices "
            "of an obstacle in layout.obstacles (0 picks the size automatically)"
        )
    if lay.terrain is not None:
        _check_terrain(cfg)
    j = lay.size_jitter
    for i, ob in enumerate(lay.obstacles):
        p = f"layout.obstacles[{i}]"
        if ob.weight <= 0:
            continue
        w_min, w_max = ob.width[0] * (1 - j), ob.width[1] * (1 + j)
        h_min, h_max = ob.height[0] * (1 - j), ob.height[1] * (1 + j)
        if not env.shield and env.step_size >= min(w_min, h_min):
            field_ = "width" if w_min <= h_min else "height"
            smallest = min(w_min, h_min)
            if j > 0 and env.step_size < min(ob.width[0], ob.height[0]):
                # The obstacle itself is large enough: the jitter shrinks it below a step.
                raise ConfigError(
                    f"layout.size_jitter: {j} shrinks {p}.{field_} to {smallest:.3f} m, not larger than "
                    f"env.step_size = {env.step_size} m: a step could jump through the obstacle"
                )
            raise ConfigError(
                f"env.step_size: {env.step_size} m is not smaller than {p}.{field_} "
                f"(smallest {smallest:.3f} m): a step could jump through the obstacle"
            )
        _check_room(cfg, p, w_max)
        top = h_max
        mid_z = top + env.mid_goal_clearance
        if mid_z + env.mid_goal_half_size[1] >= env.max_z:
            raise ConfigError(
                f"{p}.height: up to {h_max:.3f} m puts the mid-goal above env.max_z = {env.max_z} m"
            )
        if top + env.mid_goal_clearance - env.mid_goal_half_size[1] <= top:
            raise ConfigError(
                "env.mid_goal_half_size: the mid-goal box must lie above the obstacle "
                "(mid_goal_clearance must exceed its half height)"
            )
        _check_clearable(cfg, p, h_max, w_max)
    if env.step_size > 2.0 * env.goal_tolerance[0]:
        # a heel moving along the ground must be able to land inside the goal window (eq 2.32)
        raise ConfigError(
            f"env.step_size: {env.step_size} m is longer than the goal window "
            f"(2 x env.goal_tolerance[0] = {2.0 * env.goal_tolerance[0]:.3f} m): a step could "
            "jump over the goal"
        )
    if env.bounds_y[0] > 0.0:
        raise ConfigError("env.bounds_y: the lower bound must be at or behind the start (y = 0)")
    goal_far = lay.start_shift[1] + lay.step_length[1] + env.goal_tolerance[0]
    if env.bounds_y[1] <= goal_far:
        raise ConfigError(
            f"env.bounds_y: the upper bound must lie beyond the goal region ({goal_far:.3f} m)"
        )


def _check_terrain(cfg: Config) -> None:
    """A terrain spec must fit the env: outlines of terrain.K_MAX vertices, obstacles larger than a
    step, the mid-goal over the tallest below env.max_z, the goal inside env.bounds_y, and every
    family clearable at every placement extreme and pivot (TerrainSpec.check)."""
    env, kin, t = cfg.env, cfg.kinematics, cfg.layout.terrain
    if env.max_vertices and env.max_vertices < terrain.K_MAX:
        raise ConfigError(
            f"env.max_vertices: {env.max_vertices} is fewer than the {terrain.K_MAX} outline vertices "
            "of layout.terrain's families (0 picks the size automatically)"
        )
    if not env.shield and env.step_size >= t.min_size:
        raise ConfigError(
            f"env.step_size: {env.step_size} m is not smaller than the smallest width or height "
            f"of layout.terrain.families ({t.min_size:.3f} m): a step could jump through the obstacle"
        )
    if t.max_height + env.mid_goal_clearance + env.mid_goal_half_size[1] >= env.max_z:
        raise ConfigError(
            f"layout.terrain.families: obstacles up to {t.max_height:.3f} m put the mid-goal above "
            f"env.max_z = {env.max_z} m"
        )
    goal_far = t.start_shift[1] + t.step_length[1] + env.goal_tolerance[0]
    if env.bounds_y[1] <= goal_far:
        raise ConfigError(
            f"env.bounds_y: the upper bound must lie beyond layout.terrain's goal region ({goal_far:.3f} m)"
        )
    try:
        t.check(
            foot_length=kin.foot_length,
            thigh=kin.thigh,
            shin=kin.shin,
            hip_limits=kin.hip_limits,
            knee_limits=kin.knee_limits,
            heel_lift=env.mid_goal_clearance - env.mid_goal_half_size[1],
            goal_tolerance=env.goal_tolerance[0],
        )
    except terrain.TerrainError as e:
        raise ConfigError(str(e)) from None


def _check_room(cfg: Config, p: str, w_max: float) -> None:
    """The obstacle must lie between the toe at the start and the goal for every start shift, step
    length and offset that reset can draw. The error names the field at fault: the step length when
    the obstacle does not fit even without a shift or offset, else the shift or the offset."""
    env, kin, lay = cfg.env, cfg.kinematics, cfg.layout
    s_lo, s_hi = lay.start_shift
    o_lo, o_hi = lay.obstacle_offset
    fl, tol = kin.foot_length, env.goal_tolerance[0]

    def near_ok(L, shift, off):  # the obstacle's near edge lies ahead of the toe at the start
        return lay.default_center(fl, L) + off - 0.5 * w_max > shift + fl

    def far_ok(L, shift, off):  # the goal lies beyond the obstacle's far edge
        return lay.default_center(fl, L) + off + 0.5 * w_max < shift + L - tol

    for L in lay.step_length:
        if not near_ok(L, 0.0, 0.0):
            raise ConfigError(
                f"layout.step_length: {L} m is too short for {p} (up to {w_max:.3f} m wide): centred in the gap, "
                f"it reaches back to the toe at the start ({fl:.3f} m); the step must be longer than the foot "
                "length plus the obstacle's width; use a longer step or a narrower obstacle"
            )
        if not far_ok(L, 0.0, 0.0):
            raise ConfigError(
                f"layout.step_length: the goal at {L:.3f} m is not beyond {p} (its far edge reaches "
                f"{lay.default_center(fl, L) + 0.5 * w_max:.3f} m); the goal must lie ahead of the obstacle"
            )
        if not near_ok(L, 0.0, o_lo) or not far_ok(L, 0.0, o_hi):
            side = o_lo if not near_ok(L, 0.0, o_lo) else o_hi
            raise ConfigError(
                f"layout.obstacle_offset: {side} m moves {p} (up to {w_max:.3f} m wide, step length {L} m) "
                "onto the foot at the start or past the goal; reduce the offset or the width"
            )
        if not near_ok(L, s_hi, o_lo):
            raise ConfigError(
                f"layout.start_shift: with {p} up to {w_max:.3f} m wide, step length {L} m and "
                f"offset {o_lo} m, the obstacle reaches back to the toe at the "
                f"start (y = {s_hi + fl:.3f} m); reduce start_shift, obstacle_offset or the width"
            )
        if not far_ok(L, s_lo, o_hi):
            goal = s_lo + L
            raise ConfigError(
                f"layout.step_length: the goal at {goal:.3f} m is not beyond {p} (its far edge "
                f"reaches {lay.default_center(fl, L) + o_hi + 0.5 * w_max:.3f} m); the goal must lie ahead of the obstacle"
            )


def _check_clearable(cfg: Config, path: str, h_max: float, w_max: float) -> None:
    """Refuse an obstacle that the leg cannot clear: with the heel at the bottom of the mid-goal box
    over the obstacle (the lowest point the reward asks the foot to pass), every pivot condition the
    layout can draw must give a reachable leg within the joint limits, at every extreme of the
    start shift, step length and obstacle offset that reset can draw."""
    env, kin, lay = cfg.env, cfg.kinematics, cfg.layout
    heel_z = h_max + env.mid_goal_clearance - env.mid_goal_half_size[1]
    for start, L, off in itertools.product(lay.start_shift, lay.step_length, lay.obstacle_offset):
        center = lay.default_center(kin.foot_length, L) + off
        pivots = {
            name: float(kinematics.pivot_position(np, i, start, center))
            for i, name in enumerate(PIVOT_CONDITIONS)
        }
        heel = np.array([center, heel_z])
        for name, weight in zip(PIVOT_CONDITIONS, lay.pivot):
            if weight <= 0:
                continue
            if kinematics.swing_heel_unreachable(
                np, pivots[name], heel, kin.thigh, kin.shin, kin.hip_limits, kin.knee_limits
            ):
                raise ConfigError(
                    f"{path}.height: an obstacle {h_max:.3f} m high cannot be cleared with pivot {name!r} "
                    f"(start {start:.3f} m, step length {L:.3f} m): the heel over it at {heel_z:.3f} m is "
                    "out of the leg's reach or joint limits"
                )
