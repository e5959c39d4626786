"""The action set and the observation: the 36 moves (thesis 2.1), the greedy choice among them, and
the network's input, written once for every array module (``xp``: numpy, jax.numpy).

The JAX environment (jaxexo.env), the trainer and the NumPy generator (jaxexo.inference) all build
observations and pick moves with these functions; ``p`` and ``layout`` are as in
jaxexo.physics.transition.
"""

from __future__ import annotations

import numpy as np

from jaxexo.physics.transition import mid_goal

NUM_ACTIONS = 36  # thesis 2.1: 36 moves, 10 degrees apart
# Observation entries besides the obstacle profile (``observation``, conditioned mode): heel (2),
# scene relative to the heel (10), progress and mid-goal flag (2).
OBS_SCENE_ENTRIES = 14
# Lengths in observations are divided by this (m), so that they are of order 1.
LENGTH_SCALE = 0.5
# Thesis-mode observation centre (m): the middle of a default step, a little above the ground.
THESIS_OBS_CENTER = (0.35, 0.10)


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


def opposite(action):
    """The move in the opposite direction of ``action`` (an int or int array), NUM_ACTIONS / 2 away."""
    return (action + NUM_ACTIONS // 2) % NUM_ACTIONS


def undoes(xp, actions, last_action):
    """(..., F) bool: which of ``actions`` ((F,) or (..., F)) undo ``last_action`` (...,; -1: no move
    yet): its ``opposite``."""
    last = xp.asarray(last_action)[..., None]
    return (last >= 0) & (xp.asarray(actions) == opposite(last))


def greedy_action(xp, q, mask=None):
    """The greedy move: argmax of Q (..., NUM_ACTIONS) over the admissible moves ``mask`` (None: all),
    for the trainer, the JAX evaluation and the NumPy generator alike."""
    if mask is None:
        return xp.argmax(q, axis=-1)
    return xp.argmax(xp.where(mask, q, -xp.inf), axis=-1)


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
