"""The config's [train] section: errors name the field, TOML round trip."""

from __future__ import annotations

import pytest

from jaxexo.config import ConfigError, config_from_dict, load_config
from jaxexo.config.toml_io import config_to_toml

from conftest import legacy_raw

jax = pytest.importorskip("jax")

from train_helpers import *  # noqa: F401,F403 (the shared tiny config, helpers and fixtures)

# --------------------------------------------------------------------------------------------
# Config errors and the driver's refusals
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "train, field, text",
    [
        ({"trace": "sideways"}, "train.trace", "forward"),
        ({"trace_kind": "dutch"}, "train.trace_kind", "replacing"),
        ({"control": "sarsa"}, "train.control", "on_policy"),
        ({"target": "soft"}, "train.target", "polyak"),
        ({"num_envs": 64, "num_minibatches": 3}, "train.num_minibatches", "64"),
        ({"gamma": 1.5}, "train.gamma", "[0, 1]"),
        ({"lam": -0.1}, "train.lam", ">= 0"),
        ({"budget_env_steps": 0, "budget_episodes": 0}, "train.budget", "budget"),
        ({"budget_env_steps": -5}, "train.budget_env_steps", ">= 0"),
        ({"learning_rate": 1e-3}, "train.learning_rate", "unknown field"),
        ({"eps_start": 0.1, "eps_end": 0.5}, "train.eps_end", "eps_start"),
        ({"hidden": [64, 0]}, r"train.hidden\[1\]", "> 0"),
        ({"hidden": [64.5]}, r"train.hidden\[0\]", "integer"),
        ({"hidden": "64"}, "train.hidden", "list"),
        ({"num_envs": 0}, "train.num_envs", "> 0"),
        ({"lr": 0.0}, "train.lr", "> 0"),
        ({"layer_norm": "yes"}, "train.layer_norm", "true or false"),
        ({"eps_decay_fraction": 0.0}, "train.eps_decay_fraction", "> 0"),
        ({"target_period": 2.5}, "train.target_period", "integer"),
    ],
)
def test_train_config_errors_name_the_field(train, field, text):
    raw = tiny_raw()
    raw["train"].update(train)
    with pytest.raises(ConfigError, match=field) as info:
        config_from_dict(legacy_raw(raw))
    assert str(info.value).startswith(field.replace("\\", "").split("[")[0])
    assert text in str(info.value)


def test_train_config_round_trips_through_toml(tmp_path):
    cfg = tiny_config(
        trace="backward",
        trace_kind="replacing",
        control="on_policy",
        target="polyak",
        hidden=[7, 5],
        budget_episodes=100,
    )
    path = tmp_path / "c.toml"
    path.write_text(config_to_toml(cfg))
    assert load_config(path) == cfg
    assert cfg.train.hidden == (7, 5) and cfg.train.trace_kind == "replacing"
