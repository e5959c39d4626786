"""The environment's transition, observation and scene rules, written once for every array module.

The JAX environment (jaxexo.env), the NumPy trajectory generator (jaxexo.inference) and the NumPy
environment used by the thesis-style baseline all step the heel, test the mid-goal and the goal,
and build observations with these functions. Each takes the array module ``xp`` first: ``numpy``,
``jax.numpy``, or ``jaxexo.physics.dynamics.scalar`` (plain Python floats, for the generator's fast
single-trajectory loop). Heel coordinates are passed as separate y and z components so that the
same code serves a scalar, a batch (B,) and a traced JAX value.

``p`` is any object with the parameter attributes of ``jaxexo.config.param_values`` (``EnvParams``
in JAX, a ``SimpleNamespace`` of NumPy arrays or Python floats elsewhere); ``layout`` any object with the
``Scene``/``Layout`` fields (outline, shape, center_y, width, height, pivot_y, start_y, goal_y).

Also here, because it is NumPy-only: ``make_scene``, the one place where a fixed scene (an Obstacle,
a pivot condition or pivot y, a start and a step length) is validated and laid out.
"""

from __future__ import annotations

import math
import types
from dataclasses import dataclass

import numpy as np

from jaxexo.physics import geometry, kinematics, rewards, swept
from jaxexo.physics.kinematics import PIVOT_CONDITIONS

NUM_ACTIONS = 36  # thesis 2.1: 36 moves, 10 degrees apart
# Observation entries besides the obstacle profile (``observation``, conditioned mode): heel (2),
# scene relative to the heel (10), progress and mid-goal flag (2).
OBS_SCENE_ENTRIES = 14
# Lengths in observations are divided by this (m), so that they are of order 1.
LENGTH_SCALE = 0.5
# Thesis-mode observation centre (m): the middle of a default step, a little above the ground.
THESIS_OBS_CENTER = (0.35, 0.10)

# A scalar "array module" for the generator's per-step loop on Python floats: the few functions the
# transition rules below use, with numpy's meaning.
scalar = types.SimpleNamespace(
    minimum=min,
    maximum=max,
    abs=abs,
    sqrt=math.sqrt,
    clip=lambda x, lo, hi: min(max(x, lo), hi),
    where=lambda c, a, b: a if c else b,
)


def action_angles(n: int = NUM_ACTIONS) -> np.ndarray:
    """(n,) move directions (rad): k * 2 pi / n, k = 0..n-1 (thesis 2.1: 36 moves, 10 degrees apart)."""
    return np.deg2rad(360.0 / n * np.arange(n))


def action_directions(n: int = NUM_ACTIONS) -> np.ndarray:
    """(n, 2) unit moves along ``action_angles``.

    Axis-aligned moves get exact zeros: cos(270 deg) = -1.8e-16 would count as "backward" (eq 2.31)."""
    a = action_angles(n)
    d = np.stack([np.cos(a), np.sin(a)], axis=-1)
    return np.where(np.abs(d) < 1e-12, 0.0, d)


def obs_dim(obs_mode: str, shape_points: int) -> int:
    """Length of ``observation``'s output: the heel (2) in ``thesis`` mode, else the scene entries and
    the obstacle profile's ``shape_points`` heights."""
    return 2 if obs_mode == "thesis" else OBS_SCENE_ENTRIES + shape_points


# m: the largest clearance a caller may ask of a swing (``generate(..., clearance=C)``). The obstacles
# jaxexo trains on reach 0.28 m, and a heel lifted 10 cm above such a top is near the hip and knee
# limits of the default leg; beyond that the clearance is a different task (stepping onto it).
MAX_CLEARANCE = 0.10


def check_clearance(clearance, min_clearance: float) -> float | None:
    """The clearance (m) a caller asks of a swing, validated: None (the config's env.min_clearance), or
    a number in [min_clearance, MAX_CLEARANCE]. Raises ValueError naming ``clearance``."""
    if clearance is None:
        return None
    if isinstance(clearance, bool) or not isinstance(
        clearance, (int, float, np.integer, np.floating)
    ):
        raise TypeError(f"clearance: expected a number of metres, got {type(clearance).__name__}")
    c = float(clearance)
    if not math.isfinite(c) or c < float(min_clearance) - 1e-12 or c > MAX_CLEARANCE:
        raise ValueError(
            f"clearance must be between env.min_clearance = {float(min_clearance):g} m and "
            f"{MAX_CLEARANCE:g} m, got {clearance!r}"
        )
    return c


def with_clearance(p, clearance: float | None):
    """The parameter view ``p`` (jaxexo.config's ``numpy_params`` or ``scalar_params``) for a swing that must keep
    ``clearance`` (m; None: unchanged): the verdict's margin ``min_clearance`` becomes it, and the shield
    keeps the same excess above it as the config's (``shield_clearance - min_clearance``, the budget
    the smoothed curve may cut)."""
    if clearance is None:
        return p
    extra = clearance - float(p.min_clearance)
    cast = (
        (lambda v: np.asarray(v, dtype=np.asarray(p.min_clearance).dtype))
        if isinstance(p.min_clearance, np.ndarray)
        else float
    )
    return types.SimpleNamespace(
        **{
            **vars(p),
            "min_clearance": cast(clearance),
            "shield_clearance": cast(float(p.shield_clearance) + extra),
        }
    )


# --------------------------------------------------------------------------------------------
# Transition rules (thesis 2.1-2.2)
# --------------------------------------------------------------------------------------------


def move_heel(xp, p, heel_y, heel_z, dir_y, dir_z):
    """One action: the heel moves step_size along its direction, kept inside the world (above the
    ground, below max_z, within bounds_y)."""
    y = xp.clip(heel_y + p.step_size * dir_y, p.bounds_y[0], p.bounds_y[1])
    z = xp.clip(heel_z + p.step_size * dir_z, 0.0, p.max_z_world)
    return y, z


# m: a move shorter than this along both axes does not move the heel. Only a vertical move at the
# ground or a bound is ever that short (any other move keeps >= step_size * sin(10 deg) of its length
# along y), so the threshold decides nothing else; it makes the rule indifferent to a heel a few ulps
# above the ground (float32 and float64 rollouts of one swing agree).
MOVE_EPS = 1e-6


def moves_heel(xp, heel_y, heel_z, ends):
    """(..., F) bool: the forward moves whose end ``ends`` (..., F, 2) is not the heel itself (a move
    into the ground, or past the world's bounds, that ``move_heel``'s clipping cancels)."""
    return (xp.abs(ends[..., 0] - heel_y[..., None]) > MOVE_EPS) | (
        xp.abs(ends[..., 1] - heel_z[..., None]) > MOVE_EPS
    )


def undoes(xp, actions, last_action):
    """(..., F) bool: which of ``actions`` ((F,) or (..., F)) undo ``last_action`` (...,; -1: no move
    yet): the move in the opposite direction, NUM_ACTIONS / 2 away."""
    last = xp.asarray(last_action)[..., None]
    return (last >= 0) & (xp.asarray(actions) == (last + NUM_ACTIONS // 2) % NUM_ACTIONS)


def greedy_action(xp, q, mask=None):
    """The greedy move: argmax of Q (..., NUM_ACTIONS) over the admissible moves ``mask`` (None: all),
    for the trainer, the JAX evaluation and the NumPy generator alike."""
    if mask is None:
        return xp.argmax(q, axis=-1)
    return xp.argmax(xp.where(mask, q, -xp.inf), axis=-1)


pivot_position = kinematics.pivot_position  # the three pivot conditions -> pivot y (one definition)


def terminated(xp, p, reached, collided):
    """An episode ends at the goal, or at a collision when collisions terminate (thesis 2.2)."""
    return reached | (collided & p.terminate_on_collision)


def truncated(time, max_steps):
    """The step limit: ``time`` steps taken of at most ``max_steps`` (gymnax's truncation, from the
    step count alone, even on a step that also terminates)."""
    return time >= max_steps


def mid_goal(xp, p, center_y, height):
    """Centre (y, z) of the mid-goal box (thesis 2.2): above the obstacle centre, at a safe height."""
    return center_y, height + p.mid_goal_clearance


def in_mid_goal(xp, p, heel_y, heel_z, mid_y, mid_z):
    return (xp.abs(heel_y - mid_y) <= p.mid_goal_half_size[0]) & (
        xp.abs(heel_z - mid_z) <= p.mid_goal_half_size[1]
    )


def beyond_mid_goal(xp, p, heel_y, mid_y):
    """The heel has passed the mid-goal box's far side (eq 2.33 fires if it never went through)."""
    return heel_y > mid_y + p.mid_goal_half_size[0]


def in_goal_column(xp, p, heel_y, goal_y):
    """The heel is above or in the goal box: |y - goal| <= goal_tolerance[0]."""
    return xp.abs(heel_y - goal_y) <= p.goal_tolerance[0]


def goal_reached(xp, p, heel_y, heel_z, goal_y):
    """The heel is back on the ground at the goal (eq 2.32): in the goal column, z <= goal_tolerance[1]."""
    return in_goal_column(xp, p, heel_y, goal_y) & (heel_z <= p.goal_tolerance[1])


def keeps_off_floor(xp, p, heel_y, heel_z, goal_y):
    """The shield's floor rule: a heel at (y, z) is at least ``p.floor_clearance`` above the floor, or
    in the goal column (where it lands). 0 keeps every heel (the rule off)."""
    return (heel_z >= p.floor_clearance) | in_goal_column(xp, p, heel_y, goal_y)


def observation(xp, p, obs_mode: str, heel_y, heel_z, time, visited_mid, layout):
    """The network's input (..., D).

    ``thesis``: the heel (y, z) only, centred and scaled. ``conditioned``: also the scene relative
    to the heel (start, goal, mid-goal, pivot, obstacle extents and top, the obstacle's profile or
    its bounding box, episode progress and whether the mid-goal was visited). Every entry is affine
    in (heel_y, heel_z, time, visited_mid) for a fixed scene; the generator relies on that."""
    base = [
        (heel_y - THESIS_OBS_CENTER[0]) / LENGTH_SCALE,
        (heel_z - THESIS_OBS_CENTER[1]) / LENGTH_SCALE,
    ]
    if obs_mode == "thesis":
        return xp.stack(base, axis=-1)
    lay = layout
    mid_y, mid_z = mid_goal(xp, p, lay.center_y, lay.height)
    rel = [
        heel_y - lay.start_y,
        heel_z,  # heel relative to its start
        lay.goal_y - heel_y,
        -heel_z,  # goal relative to the heel
        mid_y - heel_y,
        mid_z - heel_z,  # mid-goal relative to the heel
        lay.pivot_y - heel_y,  # pivot heel relative to the heel
        lay.center_y - 0.5 * lay.width - heel_y,  # obstacle near edge
        lay.center_y + 0.5 * lay.width - heel_y,  # obstacle far edge
        lay.height - heel_z,  # obstacle top
    ]
    dtype = heel_y.dtype
    progress = (time / p.max_steps_in_episode).astype(dtype)
    # "bbox": the profile shown as the bounding box's constant height.
    profile = xp.where(p.obs_true_profile, lay.shape, lay.height[..., None]) / LENGTH_SCALE
    return xp.concatenate(
        [
            xp.stack(base + [r / LENGTH_SCALE for r in rel], axis=-1),
            profile,
            xp.stack([progress, visited_mid.astype(dtype)], axis=-1),
        ],
        axis=-1,
    )


def transition(
    xp, p, prev, heel, time, visited_mid, layout, max_y=None, action=None, last_action=None
) -> dict:
    """Everything a step from heel ``prev`` to ``heel`` (..., 2) decides (thesis 2.1-2.5), for the
    JAX environment and the NumPy environment alike: collision, mid-goal, goal, kinematics, the 8 + 4
    reward terms (eq 2.29-2.52), the wearer's costs (rewards.wearer_terms), optional shaping, the
    reward and termination. ``time`` is the step count after the move, ``visited_mid`` whether the
    mid-goal was visited before it, ``max_y`` the heel's largest y so far (None: ``prev``'s y),
    ``action`` the move and ``last_action`` the one before it (-1: none; None: no turn is counted).

    Collision and clearance are those of the whole move (jaxexo.physics.swept: the region the flat
    foot sweeps from ``prev`` to ``heel``), so a move cannot jump through a corner of the obstacle.
    The per-step ``info`` feeds the one safe-swing verdict (jaxexo.physics.outcome.accumulate):
    ``clearance`` of the move, ``backward`` (how far the heel is behind its furthest y), the goal,
    joint-limit and leg-length flags.

    Returns ``{"visited_mid", "reward", "terminated", "info", "max_y"}`` with ``info`` the
    environment's per-step diagnostics (reward terms, clearance, collision, goal, limit and leg-length
    flags, backward, joint angles, heel, hip) and ``max_y`` the running maximum to pass to the next step."""
    lay = layout
    clearance = swept.swept_clearance(xp, prev, heel, p.foot_length, lay.outline)
    collided = geometry.foot_collides(xp, clearance)
    run_max = xp.maximum(prev[..., 0] if max_y is None else max_y, prev[..., 0])
    mid_y, mid_z = mid_goal(xp, p, lay.center_y, lay.height)
    visited = visited_mid | in_mid_goal(xp, p, heel[..., 0], heel[..., 1], mid_y, mid_z)
    missed_mid = beyond_mid_goal(xp, p, heel[..., 0], mid_y) & ~visited
    reached = goal_reached(xp, p, heel[..., 0], heel[..., 1], lay.goal_y)

    kin = kinematics.leg_state(xp, lay.pivot_y, heel, p.thigh, p.shin)
    angles = kinematics.both_legs_angles(xp, kin)
    angles_prev = kinematics.both_legs_angles(
        xp, kinematics.leg_state(xp, lay.pivot_y, prev, p.thigh, p.shin)
    )
    limits_violated = kinematics.legs_outside_limits(xp, angles, p.hip_limits, p.knee_limits)

    traj = rewards.trajectory_terms(
        xp,
        p,
        steps=time,
        prev_heel=prev,
        heel=heel,
        collided=collided,
        clearance=clearance,
        reached_goal=reached,
        missed_mid=missed_mid,
        mid_y=mid_y,
        max_z=lay.height + p.max_height_margin,
    )
    exo = rewards.exo_terms(
        xp,
        p,
        hip_z=kin["hip"][..., 1],
        leg_swing=kin["leg_swing"],
        leg_stance=kin["leg_stance"],
        limits_violated=limits_violated,
    )
    turn = (
        None
        if action is None or last_action is None
        else rewards.turn_of(xp, p.directions, action, last_action)
    )
    wearer = rewards.wearer_terms(
        xp, p, heel=heel, top=lay.height, angles_prev=angles_prev, angles=angles, turn=turn
    )
    done = terminated(xp, p, reached, collided)
    mid = xp.stack([mid_y, mid_z], axis=-1)
    goal = xp.stack([lay.goal_y, 0.0 * lay.goal_y], axis=-1)
    shaping = rewards.shaping_reward(
        xp,
        p,
        rewards.progress_potential(xp, prev, mid, goal, visited_mid),
        rewards.progress_potential(xp, heel, mid, goal, visited),
        done,
    )
    reward = rewards.total_reward(xp, p, traj, exo, wearer) + shaping
    info = {
        "traj_terms": traj,
        "exo_terms": exo,
        "wearer_terms": wearer,
        "shaping": shaping,
        "clearance": clearance,
        "collision": collided,
        "goal_reached": reached,
        "joint_limit_violation": limits_violated,
        "leg_length_violation": exo[..., 1] < 0,
        "joint_angles": angles,
        "heel": heel,
        "hip": kin["hip"],
        # m the heel is behind its furthest y so far (eq 2.31's condition; the safe-swing rule's measure)
        "backward": run_max - heel[..., 0],
    }
    return {
        "visited_mid": visited,
        "reward": reward,
        "terminated": done,
        "info": info,
        "max_y": xp.maximum(run_max, heel[..., 0]),
    }


# --------------------------------------------------------------------------------------------
# Fixed scenes
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Scene:
    """One fixed scenario in world coordinates (metres): the obstacle, where the pivot (stance) heel
    stands, where the swing heel starts and where it must land. Fields match the environment's
    Layout, so the same observation and transition code reads either."""

    obstacle: geometry.Obstacle
    outline: np.ndarray  # (K, 2) world-frame outline, padded to K vertices
    shape: np.ndarray  # (P,) heights at equally spaced fractions of the width
    center_y: float
    width: float
    height: float
    pivot_kind: int  # index into PIVOT_CONDITIONS, -1 for a pivot given as a y
    pivot_y: float
    start_y: float
    goal_y: float

    @property
    def pivot(self) -> str:
        return (
            PIVOT_CONDITIONS[self.pivot_kind] if self.pivot_kind >= 0 else f"y={self.pivot_y:.3f} m"
        )


# A scene's defaults (m): the pivot heel beside the obstacle, the swing heel at the origin, the
# thesis's step (Table 3.1's layouts): make_scene's, and every generator's (jaxexo.inference.options).
DEFAULT_PIVOT = "obstacle"
DEFAULT_START_Y = 0.0
DEFAULT_STEP_LENGTH = 0.70


def make_scene(
    obstacle: geometry.Obstacle,
    pivot: str | float = DEFAULT_PIVOT,
    start_y: float = DEFAULT_START_Y,
    step_length: float = DEFAULT_STEP_LENGTH,
    *,
    foot_length: float,
    max_vertices: int | None = None,
    shape_points: int = geometry.DEFAULT_SHAPE_POINTS,
) -> Scene:
    """Validate and lay out one scene. ``pivot`` is one of PIVOT_CONDITIONS (thesis 3.1) or the pivot
    heel's y in metres. ``max_vertices`` pads the outline to a fixed K (the JAX environment's); None
    keeps the obstacle's own vertex count. Raises ValueError naming the bad argument."""
    if not isinstance(obstacle, geometry.Obstacle):
        raise TypeError(f"obstacle: expected a jaxexo Obstacle, got {type(obstacle).__name__}")
    start_y = geometry.finite("start_y", start_y)
    step_length = geometry.finite_positive("step_length", step_length)
    if isinstance(pivot, str):
        if pivot not in PIVOT_CONDITIONS:
            raise ValueError(
                f"pivot must be one of {PIVOT_CONDITIONS} or a y in metres, got {pivot!r}"
            )
        pk = PIVOT_CONDITIONS.index(pivot)
        py = pivot_position(scalar, pk, start_y, obstacle.center_y)
    else:
        pk, py = -1, geometry.finite("pivot_y", pivot)
    if obstacle.left <= start_y + foot_length:
        raise ValueError(
            f"obstacle: its near edge ({obstacle.left:.4g} m) must lie ahead of the toe at "
            f"the start ({start_y + foot_length:.4g} m)"
        )
    if obstacle.right >= start_y + step_length:
        raise ValueError(
            f"step_length: the goal ({start_y + step_length:.4g} m) must lie beyond the "
            f"obstacle's far edge ({obstacle.right:.4g} m)"
        )
    n_vertices = len(obstacle.unit_vertices)
    max_vertices = n_vertices if max_vertices is None else max_vertices
    if n_vertices > max_vertices:
        raise ValueError(
            f"obstacle: its outline has {n_vertices} vertices, more than this model's "
            f"{max_vertices} (env.max_vertices)"
        )
    shape = obstacle.height * geometry.cached_shape_descriptor(obstacle.unit_vertices, shape_points)
    return Scene(
        obstacle=obstacle,
        outline=obstacle.outline_array(max_vertices),
        shape=shape,
        center_y=obstacle.center_y,
        width=obstacle.width,
        height=obstacle.height,
        pivot_kind=pk,
        pivot_y=float(py),
        start_y=start_y,
        goal_y=start_y + step_length,
    )


def stack_scenes(scenes, dtype=np.float32) -> types.SimpleNamespace:
    """Scenes as arrays with a leading batch axis (outlines padded to the largest vertex count), in
    the Layout field layout that ``observation`` and the checks read."""
    k = max(len(s.outline) for s in scenes)
    f = lambda name: np.asarray([getattr(s, name) for s in scenes], dtype=dtype)  # noqa: E731
    return types.SimpleNamespace(
        outline=np.stack([geometry.pad_outline(s.outline, k) for s in scenes]).astype(dtype),
        shape=np.stack([s.shape for s in scenes]).astype(dtype),
        center_y=f("center_y"),
        width=f("width"),
        height=f("height"),
        pivot_y=f("pivot_y"),
        start_y=f("start_y"),
        goal_y=f("goal_y"),
        pivot_kind=np.asarray([s.pivot_kind for s in scenes], dtype=np.int32),
    )
