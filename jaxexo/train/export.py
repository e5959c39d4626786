"""The exported greedy policy, policy.npz (jaxexo.storage.policy_file): a run's chosen agent, a
population's candidates (jaxexo.train.selection) and a sweep's agents."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from jaxexo.config import Config
from jaxexo.config.toml_io import config_to_toml
from jaxexo.env.exo_step import LENGTH_SCALE, THESIS_OBS_CENTER
from jaxexo.physics import actions
from jaxexo.storage.policy_file import save_policy
from jaxexo.train.network import dense_layers, norm_layers
from jaxexo.train.trainer import Trainer


def export_policy(path: Path, cfg: Config, trainer: Trainer, params) -> Path:
    env = trainer.env
    dense = [(np.asarray(w), np.asarray(b)) for w, b in dense_layers(params)]
    norms = [(np.asarray(s), np.asarray(b)) for s, b in norm_layers(params)]
    meta = {
        "obs_mode": cfg.env.obs_mode,
        "obs_dim": env.obs_dim,
        "length_scale": LENGTH_SCALE,
        "thesis_obs_center": list(THESIS_OBS_CENTER),
        "num_actions": env.num_actions,
        "action_angles_rad": actions.action_angles(env.num_actions).tolist(),
        "layers": [env.obs_dim, *cfg.train.hidden, env.num_actions],
        "layer_norm": cfg.train.layer_norm,
        "activation": "relu",
        "config_toml": config_to_toml(cfg),
    }
    return save_policy(
        path,
        [w for w, _ in dense],
        [b for _, b in dense],
        [s for s, _ in norms],
        [b for _, b in norms],
        meta,
    )
