"""Environment parameters as a flax.struct pytree, built from a validated Config.

Every field here is a pytree leaf (vmappable: reward weights and constants, kinematic constants, the
layout distribution). Shapes (the number of outline vertices, shape-descriptor points, obstacle
kinds, the observation mode) are fixed by the arrays themselves or by the ExoStepEnv instance.
"""

from __future__ import annotations

import jax.numpy as jnp
from flax import struct

from jaxexo.config import Config
from jaxexo.physics.dynamics import param_values


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
    min_clearance: jnp.ndarray
    backward_tolerance: jnp.ndarray
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
        # One list of values (jaxexo.physics.dynamics.param_values) for the JAX and the NumPy side.
        return cls(**{k: jnp.asarray(v) for k, v in param_values(cfg).items()})
