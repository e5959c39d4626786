"""Scenario sets for evaluating and timing generators in NumPy (no JAX): the scenes of
jaxexo.physics.scenarios, the one scenario generator, as ``TrajectoryGenerator.generate`` arguments.

``sample_scenarios(cfg, n, seed)`` is the test set: the five thesis obstacles (Table 3.1; Base 1-3
seen in training, triangle and half-circle held out) crossed with the three pivot conditions, cycling
evenly, jittered like the config's training layouts (size jitter, obstacle offset, start shift, step
length). It is the very set the training run's eval.json and a sweep's ``success_raw`` are scored on
(jaxexo.train.evaluate.test_layouts, same seed): the same scene parameters, bit for bit in float32.
``training_scenarios`` draws the config's own distribution: the scenes ``ExoStepEnv.reset`` draws
for the key words (seed, i), like the training run's validation set (seed 777).
"""

from __future__ import annotations

import numpy as np

from jaxexo.config import Config, numpy_params, test_config
from jaxexo.physics import scenarios, terrain
from jaxexo.physics.geometry import Obstacle
from jaxexo.physics.kinematics import PIVOT_CONDITIONS
from jaxexo.physics.scenarios import HELD_OUT, TEST_KINDS  # noqa: F401 (one definition, re-exported)


def sample_scenarios(config: Config, n: int, seed: int = 12345) -> list[dict]:
    """n test scenarios as keyword arguments of ``TrajectoryGenerator.generate`` plus ``kind``: kind
    i % 5, pivot (i // 5) % 3, the rest drawn from the config's layout distribution."""
    tcfg = test_config(config)
    return _as_kwargs(tcfg, scenarios.scenario_layouts(np, numpy_params(tcfg), seed, n, cycle=True))


def training_scenarios(config: Config, n: int, seed: int = 54321) -> list[dict]:
    """n scenarios of the config's own training distribution: its obstacle mixture (every entry of
    positive weight in turn, sizes drawn from its ranges) and the pivot conditions it trains on (in
    turn), the rest drawn as the environment's reset draws it."""
    t = config.layout.terrain
    if t is not None:   # procedural terrain: its families (indices into t.families) and pivots
        kinds = [i for i, w in enumerate(t.weights) if w > 0]
        pivots = [i for i, w in enumerate(t.pivot) if w > 0]
    else:
        kinds = [i for i, o in enumerate(config.layout.obstacles) if o.weight > 0]
        pivots = [i for i, w in enumerate(config.layout.pivot) if w > 0]
    return _as_kwargs(config, scenarios.scenario_layouts(np, numpy_params(config), seed, n, cycle=True,
                                                         kinds=kinds, pivots=pivots))


def _as_kwargs(cfg: Config, lay: dict) -> list[dict]:
    specs = cfg.layout.obstacles
    out = []
    for i in range(len(lay["start_y"])):
        w, h, center = (float(lay[k][i]) for k in ("width", "height", "center_y"))
        start_y = float(lay["start_y"][i])
        if cfg.layout.terrain is not None:   # kind is the family id; the outline is world-frame
            local = np.asarray(lay["outline"][i], dtype=np.float64) - np.array([center, 0.0])
            out.append({"kind": terrain.FAMILY_NAMES[int(lay["kind"][i])], "obstacle": terrain.to_obstacle(local, center),
                        "pivot": PIVOT_CONDITIONS[int(lay["pivot_kind"][i])], "start_y": start_y,
                        "step_length": float(lay["goal_y"][i]) - start_y})
            continue
        spec = specs[int(lay["kind"][i])]
        if spec.shape == "profile":
            ob = Obstacle("profile", "profile", center, w, h, spec.unit_vertices())
        else:
            ob = getattr(Obstacle, spec.shape)(w, h, center_y=center)
        out.append({"kind": spec.kind, "obstacle": ob, "pivot": PIVOT_CONDITIONS[int(lay["pivot_kind"][i])],
                    "start_y": start_y, "step_length": float(lay["goal_y"][i]) - start_y})
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
    in the gap between the toe at the start and the goal (terrain.NEAR_MARGIN = 2.5 cm from the toe,
    terrain.FAR_MARGIN = 6 cm from the goal: procedural terrain's placement margins), every pivot condition in
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
        # the gap as procedural terrain places obstacles (terrain.place's margins): the foot at the
        # start clears the default 2 cm margin with 5 mm to spare, so every scene admits a safe swing
        lo = start + foot + terrain.NEAR_MARGIN + probe.width / 2
        hi = start + step - terrain.FAR_MARGIN - probe.width / 2
        center = rng.uniform(lo, max(lo, hi))
        ob = Obstacle.profile(probe.outline + [center, 0.0]) if probe.shape == "profile" else (
            getattr(Obstacle, probe.shape)(probe.width, probe.height, center_y=center))
        if not unseen:
            ob = Obstacle.named(kind, center_y=center)
        out.append({"kind": kind, "obstacle": ob, "pivot": PIVOT_CONDITIONS[(i // len(kinds)) % 3],
                    "start_y": float(start), "step_length": float(step)})
    return out
