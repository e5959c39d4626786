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


UNSEEN_SHAPES = ("rectangle", "wedge", "pole", "bumps")


def _unseen_obstacle(rng, shape: str, center: float) -> Obstacle:
    """An obstacle of a family the default policy never trained on (issue 11's safety checks)."""
    if shape == "rectangle":
        return Obstacle.rectangle(rng.uniform(0.04, 0.25), rng.uniform(0.04, 0.20), center_y=center)
    if shape == "pole":
        return Obstacle.rectangle(rng.uniform(0.01, 0.04), rng.uniform(0.05, 0.20), center_y=center)
    w, h = rng.uniform(0.08, 0.25), rng.uniform(0.05, 0.20)
    if shape == "wedge":        # a ramp rising (or falling) to a vertical face
        z = [0.0, h] if rng.uniform() < 0.5 else [h, 0.0]
        return Obstacle.profile([[center - w / 2, z[0]], [center + w / 2, z[1]]])
    k = int(rng.integers(2, 4))  # "bumps": k humps of random heights with dips between them
    y = np.linspace(center - w / 2, center + w / 2, 2 * k + 1)
    z = np.zeros(2 * k + 1)
    z[1::2] = h * rng.uniform(0.5, 1.0, k)
    z[2:-1:2] = h * rng.uniform(0.0, 0.4, k - 1)
    return Obstacle.profile(np.column_stack([y, z]))


def safety_scenarios(config: Config, n: int, seed: int = 2024, unseen: bool = False) -> list[dict]:
    """n shifted layouts for the safe-swing checks: the start anywhere in 0-10 cm, the obstacle anywhere
    in the gap between the toe at the start and the goal (1 cm from either), every pivot condition in
    turn; the five thesis obstacles (kind i % 5) or, with ``unseen``, shapes never trained on
    (UNSEEN_SHAPES in turn: random rectangles, wedges, thin poles, profiles with several bumps)."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    rng = np.random.default_rng(seed)
    foot, (l_lo, l_hi) = config.kinematics.foot_length, config.layout.step_length
    kinds = UNSEEN_SHAPES if unseen else TEST_KINDS
    out = []
    for i in range(n):
        kind = kinds[i % len(kinds)]
        start, step = rng.uniform(0.0, 0.10), rng.uniform(l_lo, l_hi)
        probe = _unseen_obstacle(rng, kind, 0.0) if unseen else Obstacle.named(kind, center_y=0.0)
        lo, hi = start + foot + 0.01 + probe.width / 2, start + step - 0.01 - probe.width / 2
        center = rng.uniform(lo, max(lo, hi))
        ob = Obstacle.profile(probe.outline + [center, 0.0]) if probe.shape == "profile" else (
            getattr(Obstacle, probe.shape)(probe.width, probe.height, center_y=center))
        if not unseen:
            ob = Obstacle.named(kind, center_y=center)
        out.append({"kind": kind, "obstacle": ob, "pivot": PIVOT_CONDITIONS[(i // len(kinds)) % 3],
                    "start_y": float(start), "step_length": float(step)})
    return out
