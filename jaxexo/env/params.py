"""Environment parameters as a flax.struct pytree, built from a validated Config.

Every field here is a pytree leaf (vmappable: reward weights and constants, kinematic constants, the
layout distribution). Shapes (the number of outline vertices, shape-descriptor points, obstacle
kinds, the observation mode) are fixed by the arrays themselves or by the ExoStepEnv instance.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from flax import struct

from jaxexo import geometry
from jaxexo.config import PIVOT_CONDITIONS, Config
from jaxexo.rewards import normalize_weights


@struct.dataclass
class EnvParams:
    # Episode and motion
    step_size: jnp.ndarray
    max_steps_in_episode: jnp.ndarray          # gymnax name for the step limit
    terminate_on_collision: jnp.ndarray        # bool
    obs_true_profile: jnp.ndarray              # bool: observe the true profile, not the bounding box
    directions: jnp.ndarray                    # (36, 2): unit moves at k * 10 deg (thesis 2.1)
    bounds_y: jnp.ndarray                      # (2,)
    max_z_world: jnp.ndarray
    goal_tolerance: jnp.ndarray                # (2,)
    mid_goal_clearance: jnp.ndarray
    mid_goal_half_size: jnp.ndarray            # (2,)
    max_height_margin: jnp.ndarray
    # Kinematics
    thigh: jnp.ndarray
    shin: jnp.ndarray
    foot_length: jnp.ndarray
    hip_limits: jnp.ndarray                    # (2,) rad
    knee_limits: jnp.ndarray                   # (2,) rad
    # Reward (eq 2.29-2.52)
    traj_weights: jnp.ndarray                  # (8,), normalised to sum 0.5
    exo_weights: jnp.ndarray                   # (4,), normalised to sum 0.5
    step_threshold: jnp.ndarray
    collision_penalty: jnp.ndarray
    backward_penalty: jnp.ndarray
    goal_reward: jnp.ndarray
    mid_goal_penalty: jnp.ndarray
    max_height_penalty: jnp.ndarray
    safety_penalty: jnp.ndarray
    safety_distance: jnp.ndarray
    z_monotone_penalty: jnp.ndarray
    hlc_penalty: jnp.ndarray
    hlc_threshold: jnp.ndarray
    leg_length_penalty: jnp.ndarray
    leg_length_tolerance: jnp.ndarray
    joint_limit_penalty: jnp.ndarray
    hip_height_penalty: jnp.ndarray
    max_hip_z: jnp.ndarray
    progress_shaping: jnp.ndarray
    shaping_discount: jnp.ndarray
    # Layout distribution (sampled in reset)
    kind_outlines: jnp.ndarray                 # (B, K, 2) unit-frame outlines
    kind_shape: jnp.ndarray                    # (B, P) unit-frame shape descriptors
    kind_cdf: jnp.ndarray                      # (B,) cumulative probabilities of the kinds
    kind_width: jnp.ndarray                    # (B, 2) ranges, m
    kind_height: jnp.ndarray                   # (B, 2) ranges, m
    size_jitter: jnp.ndarray
    obstacle_offset: jnp.ndarray               # (2,)
    pivot_cdf: jnp.ndarray                     # (3,) cumulative probabilities of PIVOT_CONDITIONS
    start_shift: jnp.ndarray                   # (2,)
    step_length: jnp.ndarray                   # (2,)

    @classmethod
    def from_config(cls, cfg: Config) -> "EnvParams":
        env, kin, rew, lay = cfg.env, cfg.kinematics, cfg.reward, cfg.layout
        f = lambda x: jnp.asarray(x, dtype=jnp.float32)  # noqa: E731
        k = np.arange(36)
        directions = np.stack([np.cos(np.deg2rad(10.0 * k)), np.sin(np.deg2rad(10.0 * k))], axis=-1)
        # Exact zeros for the axis-aligned moves: cos(270 deg) = -1.8e-16 would count as "backward".
        directions = np.where(np.abs(directions) < 1e-12, 0.0, directions)
        outlines = np.stack([geometry.pad_outline(o.unit_vertices(), cfg.outline_vertices) for o in lay.obstacles])
        shapes = np.stack([geometry.shape_descriptor(u, env.shape_points) for u in outlines])
        weights = np.array([o.weight for o in lay.obstacles], dtype=np.float64)
        pivot = np.asarray(lay.pivot, dtype=np.float64)
        assert len(PIVOT_CONDITIONS) == len(pivot)
        return cls(
            step_size=f(env.step_size),
            max_steps_in_episode=jnp.asarray(env.max_steps, dtype=jnp.int32),
            terminate_on_collision=jnp.asarray(env.collision == "terminate"),
            obs_true_profile=jnp.asarray(env.obs_profile == "shape"),
            directions=f(directions),
            bounds_y=f(env.bounds_y),
            max_z_world=f(env.max_z),
            goal_tolerance=f(env.goal_tolerance),
            mid_goal_clearance=f(env.mid_goal_clearance),
            mid_goal_half_size=f(env.mid_goal_half_size),
            max_height_margin=f(env.max_height_margin),
            thigh=f(kin.thigh),
            shin=f(kin.shin),
            foot_length=f(kin.foot_length),
            hip_limits=f(kin.hip_limits),
            knee_limits=f(kin.knee_limits),
            traj_weights=f(normalize_weights(rew.traj_weights)),
            exo_weights=f(normalize_weights(rew.exo_weights)),
            step_threshold=f(rew.step_threshold),
            collision_penalty=f(rew.collision_penalty),
            backward_penalty=f(rew.backward_penalty),
            goal_reward=f(rew.goal_reward),
            mid_goal_penalty=f(rew.mid_goal_penalty),
            max_height_penalty=f(rew.max_height_penalty),
            safety_penalty=f(rew.safety_penalty),
            safety_distance=f(rew.safety_distance),
            z_monotone_penalty=f(rew.z_monotone_penalty),
            hlc_penalty=f(rew.hlc_penalty),
            hlc_threshold=f(rew.hlc_threshold),
            leg_length_penalty=f(rew.leg_length_penalty),
            leg_length_tolerance=f(rew.leg_length_tolerance),
            joint_limit_penalty=f(rew.joint_limit_penalty),
            hip_height_penalty=f(rew.hip_height_penalty),
            max_hip_z=f(rew.max_hip_z),
            progress_shaping=f(rew.progress_shaping),
            shaping_discount=f(rew.shaping_discount),
            kind_outlines=f(outlines),
            kind_shape=f(shapes),
            kind_cdf=f(_cdf(weights)),
            kind_width=f([o.width for o in lay.obstacles]),
            kind_height=f([o.height for o in lay.obstacles]),
            size_jitter=f(lay.size_jitter),
            obstacle_offset=f(lay.obstacle_offset),
            pivot_cdf=f(_cdf(pivot)),
            start_shift=f(lay.start_shift),
            step_length=f(lay.step_length),
        )


def _cdf(weights) -> np.ndarray:
    w = np.asarray(weights, dtype=np.float64)
    c = np.cumsum(w / w.sum())
    c[-1] = 1.0
    return c
