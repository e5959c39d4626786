"""Scenario sets for evaluating and timing generators in NumPy (no JAX).

The test set follows the training environment's evaluation (jaxexo.train.evaluate): the five
thesis obstacles (Table 3.1; Base 1-3 seen in training, triangle and half-circle held out) crossed
with the three pivot conditions, cycling evenly, and jittered like the config's training layouts
(size jitter, obstacle offset, start shift, step length), from a fixed seed. The training set
draws the config's own obstacle mixture and pivot conditions the same way.
"""

from __future__ import annotations

import numpy as np

from jaxexo.config import PIVOT_CONDITIONS, Config, named_spec
from jaxexo.physics.geometry import Obstacle

TEST_KINDS = ("base1", "base2", "base3", "triangle", "half_circle")
HELD_OUT = ("triangle", "half_circle")


def sample_scenarios(config: Config, n: int, seed: int = 12345, kinds=TEST_KINDS) -> list[dict]:
    """n scenarios as keyword arguments of ``TrajectoryGenerator.generate`` plus ``kind``: kind i % len(kinds),
    pivot (i // len(kinds)) % 3, the rest drawn from the config's layout distribution."""
    return _sample(config, n, seed, [named_spec(k) for k in kinds], PIVOT_CONDITIONS)


def training_scenarios(config: Config, n: int, seed: int = 54321) -> list[dict]:
    """n scenarios of the config's own training distribution: its obstacle mixture (every entry in
    turn, sizes drawn from its ranges) and the pivot conditions it trains on (in turn)."""
    pivots = [p for p, w in zip(PIVOT_CONDITIONS, config.layout.pivot) if w > 0]
    return _sample(config, n, seed, [o for o in config.layout.obstacles if o.weight > 0], pivots)


def _sample(config: Config, n: int, seed: int, specs, pivots) -> list[dict]:
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    lay, foot = config.layout, config.kinematics.foot_length
    rng = np.random.default_rng(seed)
    u = rng.uniform(size=(n, 5))
    u_size = rng.uniform(size=(n, 2))     # drawn after u: sizes within a spec's ranges
    lerp = lambda x, r: r[0] + (r[1] - r[0]) * x  # noqa: E731
    out = []
    for i in range(n):
        spec = specs[i % len(specs)]
        jitter = (2.0 * u[i, :2] - 1.0) * lay.size_jitter
        w = lerp(u_size[i, 0], spec.width) * (1 + jitter[0])
        h = lerp(u_size[i, 1], spec.height) * (1 + jitter[1])
        step_length = lerp(u[i, 2], lay.step_length)
        center = lay.default_center(foot, step_length) + lerp(u[i, 3], lay.obstacle_offset)
        if spec.shape == "profile":
            ob = Obstacle("profile", "profile", center, w, h, spec.unit_vertices())
        else:
            ob = getattr(Obstacle, spec.shape)(w, h, center_y=center)
        out.append({"kind": spec.kind, "obstacle": ob, "pivot": pivots[(i // len(specs)) % len(pivots)],
                    "start_y": lerp(u[i, 4], lay.start_shift), "step_length": step_length})
    return out
