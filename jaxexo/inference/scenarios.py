"""Scenario sets for evaluating and timing generators in NumPy: the scenes of
jaxexo.physics.scenarios as ``TrajectoryGenerator.generate`` arguments. ``sample_scenarios`` is the
test set eval.json and sweeps score on (bit for bit), ``training_scenarios`` the config's own draw.
"""

from __future__ import annotations

import numpy as np

from jaxexo.config import Config, numpy_params, test_config
from jaxexo.physics import scenarios
from jaxexo.physics.scenarios import Scenario


def sample_scenarios(config: Config, n: int, seed: int = 12345) -> list[Scenario]:
    """n test scenarios: kind i % 5, pivot (i // 5) % 3, the rest drawn from the config's layouts."""
    tcfg = test_config(config)
    return _kwargs(tcfg, scenarios.scenario_layouts(np, numpy_params(tcfg), seed, n, cycle=True))


def training_scenarios(config: Config, n: int, seed: int = 54321) -> list[Scenario]:
    """n scenarios of the config's own training distribution: its obstacle mixture (every entry of
    positive weight in turn, sizes drawn from its ranges) and the pivot conditions it trains on (in
    turn), the rest drawn as the environment's reset draws it."""
    t = config.layout.terrain
    if t is not None:  # procedural terrain: its families (indices into t.families) and pivots
        kinds = [i for i, w in enumerate(t.weights) if w > 0]
        pivots = [i for i, w in enumerate(t.pivot) if w > 0]
    else:
        kinds = [i for i, o in enumerate(config.layout.obstacles) if o.weight > 0]
        pivots = [i for i, w in enumerate(config.layout.pivot) if w > 0]
    return _kwargs(
        config,
        scenarios.scenario_layouts(
            np, numpy_params(config), seed, n, cycle=True, kinds=kinds, pivots=pivots
        ),
    )


def safety_scenarios(
    config: Config, n: int, seed: int = 2024, unseen: bool = False
) -> list[Scenario]:
    """jaxexo.physics.scenarios.safety_scenes for the config's foot length and step lengths."""
    return scenarios.safety_scenes(
        config.kinematics.foot_length, config.layout.step_length, n, seed, unseen
    )


def _kwargs(cfg: Config, lay) -> list[Scenario]:
    return scenarios.as_scenarios(lay, cfg.layout.obstacles if cfg.layout.terrain is None else None)
