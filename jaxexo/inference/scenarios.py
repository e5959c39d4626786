"""Scenario sets for evaluating and timing generators in NumPy (no JAX).

The test set follows the training environment's evaluation (jaxexo.train.evaluate): the five
thesis obstacles (Table 3.1; Base 1-3 seen in training, triangle and half-circle held out) crossed
with the three pivot conditions, cycling evenly, and jittered like the config's training layouts
(size jitter, obstacle offset, start shift, step length), from a fixed seed.
"""

from __future__ import annotations

import numpy as np

from jaxexo.config import PIVOT_CONDITIONS, Config
from jaxexo.geometry import THESIS_OBSTACLES, Obstacle

TEST_KINDS = ("base1", "base2", "base3", "triangle", "half_circle")
HELD_OUT = ("triangle", "half_circle")


def sample_scenarios(config: Config, n: int, seed: int = 12345, kinds=TEST_KINDS) -> list[dict]:
    """n scenarios as keyword arguments of ``TrajectoryGenerator.generate`` plus ``kind``: kind i % len(kinds),
    pivot (i // len(kinds)) % 3, the rest drawn from the config's layout distribution."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    lay, foot = config.layout, config.kinematics.foot_length
    rng = np.random.default_rng(seed)
    u = rng.uniform(size=(n, 5))
    lerp = lambda x, r: r[0] + (r[1] - r[0]) * x  # noqa: E731
    out = []
    for i in range(n):
        kind = kinds[i % len(kinds)]
        shape, w, h = THESIS_OBSTACLES[kind]
        jitter = (2.0 * u[i, :2] - 1.0) * lay.size_jitter
        step_length = lerp(u[i, 2], lay.step_length)
        center = lay.default_center(foot, step_length) + lerp(u[i, 3], lay.obstacle_offset)
        ob = getattr(Obstacle, shape)(w * (1 + jitter[0]), h * (1 + jitter[1]), center_y=center)
        out.append({"kind": kind, "obstacle": ob, "pivot": PIVOT_CONDITIONS[(i // len(kinds)) % len(PIVOT_CONDITIONS)],
                    "start_y": lerp(u[i, 4], lay.start_shift), "step_length": step_length})
    return out
