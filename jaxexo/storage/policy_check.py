"""Reading an exported policy for generation: policy.npz (no pickle) checked against the observation
and action set that this jaxexo builds, so that a network is never driven with inputs it was not
trained on. Used by the RL generator and by CFFTG.from_policy (its kinematics)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from jaxexo.config.sections import LEG_FIELDS
from jaxexo.physics import actions
from jaxexo.storage.policy_file import PolicyFileError, QPolicy, load_policy, policy_config


def check_policy_legs(policy: QPolicy, config, source: str) -> None:
    """``config`` given beside an exported ``policy`` (read from ``source``) must have the legs of
    the config it was trained with (its metadata.config_toml); ValueError naming each differing
    kinematics field with both values. A policy without a stored config is not checked."""
    meta = getattr(policy, "metadata", None)
    if not isinstance(meta, dict) or "config_toml" not in meta:
        return
    trained = policy_config(meta, source).kinematics
    config.kinematics.check_legs(
        {f: getattr(trained, f) for f in LEG_FIELDS},
        f"the policy {source} was trained with",
        "a policy drives only the legs it was trained for: use its own config "
        "(TrajectoryGenerator.load), or train one for these legs",
    )


def load_checked(path: str | Path) -> tuple[QPolicy, object]:
    """(policy, its complete training Config) from ``path``; PolicyFileError naming the field that
    disagrees (observation size, action angles, observation scale)."""
    policy = load_policy(path)
    meta = policy.metadata
    config = policy_config(meta, path)  # complete, and agreeing with the metadata
    obs_dim = actions.obs_dim(config.env.obs_mode, config.env.shape_points)
    if policy.obs_dim != obs_dim or meta.get("obs_dim") != obs_dim:
        raise PolicyFileError(
            f"{path}: the network takes {policy.obs_dim} inputs (metadata.obs_dim "
            f"{meta.get('obs_dim')!r}) but its config's {config.env.obs_mode!r} observation "
            f"has {obs_dim}"
        )
    angles = meta.get("action_angles_rad")
    expected = actions.action_angles()
    if (
        not isinstance(angles, list)
        or len(angles) != len(expected)
        or not np.allclose(
            np.mod(np.asarray(angles, float) - expected + np.pi, 2 * np.pi) - np.pi, 0, atol=1e-9
        )
    ):
        raise PolicyFileError(
            f"{path}: metadata.action_angles_rad does not match the "
            f"{actions.NUM_ACTIONS} moves of jaxexo.physics.actions.action_angles"
        )
    for key, value in (
        ("length_scale", actions.LENGTH_SCALE),
        ("thesis_obs_center", list(actions.THESIS_OBS_CENTER)),
    ):
        if meta.get(key) != value:
            raise PolicyFileError(
                f"{path}: metadata.{key} is {meta.get(key)!r}; this jaxexo builds "
                f"observations with {value!r}"
            )
    return policy, config
