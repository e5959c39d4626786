"""Typed, validated configuration: TOML files under configs/ become frozen dataclasses.

Everything here is NumPy-only (``import jaxexo`` must not import JAX). Every value is checked when
the config is built, and an error names the bad field (``ConfigError: layout.obstacles[1].height:
...``), so an impossible layout never shows up as a NaN inside a jitted run.

Units: metres, radians, steps. Sections: [env], [kinematics], [reward], [layout]; later issues add
their own sections (e.g. [train]) through ``EXTRA_SECTIONS``.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from jaxexo.physics import geometry, kinematics
from jaxexo.physics.geometry import THESIS_OBSTACLES

PIVOT_CONDITIONS = ("agent", "obstacle", "between")  # thesis 3.1: (b)/(2), (a)/(1), (c)/(3)
OBS_MODES = ("thesis", "conditioned")
OBS_PROFILES = ("bbox", "shape")
COLLISION_MODES = ("penalty", "terminate")


class ConfigError(ValueError):
    """A config value that is invalid or impossible; the message starts with the field's path."""


def _deg(d: float) -> float:
    return math.radians(d)


# --------------------------------------------------------------------------------------------
# Sections
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class EnvConfig:
    step_size: float = 0.03            # m per action; about 30 steps for a 0.70 m step over 0.2 m
    max_steps: int = 100               # step limit -> truncated
    collision: str = "penalty"         # "penalty" (thesis: pay r1 and continue) or "terminate"
    obs_mode: str = "conditioned"      # "thesis" (heel y, z) or "conditioned"
    # How the conditioned observation shows the obstacle's profile: "bbox" (its bounding rectangle:
    # a policy trained on rectangles treats any unseen shape conservatively) or "shape" (the true
    # profile, for policies trained on varied shapes). Collisions always use the true outline.
    obs_profile: str = "bbox"
    max_vertices: int = 0              # outline size K; 0: the largest count among the layout's kinds
    shape_points: int = geometry.DEFAULT_SHAPE_POINTS
    goal_tolerance: tuple[float, float] = (0.04, 0.02)   # goal box: |heel_y - goal_y| <= [0], heel_z <= [1]
    mid_goal_clearance: float = 0.08   # mid-goal centre height above the obstacle top, m
    mid_goal_half_size: tuple[float, float] = (0.06, 0.04)  # half extents (y, z) of the mid-goal box, m
    max_height_margin: float = 0.20    # max_z of eq 2.34 = obstacle top + this, m
    bounds_y: tuple[float, float] = (-0.30, 1.30)  # the heel is kept inside these (m)
    max_z: float = 0.80                # ceiling for the heel (m); the ground is z = 0
    # The safe-swing definition (issue 11, jaxexo.physics.swept): the foot's motion between samples
    # never comes closer than min_clearance to the obstacle, and the heel never moves backward by
    # more than backward_tolerance. The environment's success flag and the generators' ``ok`` use both.
    min_clearance: float = 0.02        # m
    backward_tolerance: float = 0.005  # m


@dataclass(frozen=True)
class KinematicsConfig:
    thigh: float = 0.50
    shin: float = 0.50
    foot_length: float = 0.20          # heel-to-toe, m
    hip_limits: tuple[float, float] = (_deg(-30.0), _deg(115.0))   # rad
    knee_limits: tuple[float, float] = (_deg(-100.0), 0.0)         # rad


@dataclass(frozen=True)
class RewardConfig:
    # Weights alpha (eq 2.38) over TRAJECTORY_TERMS and beta (eq 2.52) over EXO_TERMS, normalised.
    traj_weights: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    exo_weights: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0)
    step_threshold: float = 30.0       # n of eq 2.29, steps
    collision_penalty: float = 10.0    # c, eq 2.30
    backward_penalty: float = 1.0      # y, eq 2.31
    goal_reward: float = 10.0          # g, eq 2.32
    mid_goal_penalty: float = 1.0      # m, eq 2.33
    max_height_penalty: float = 1.0    # z, eq 2.34
    safety_penalty: float = 2.0        # f, eq 2.35
    safety_distance: float = 0.03      # min_dt, eq 2.35, m
    z_monotone_penalty: float = 0.5    # k, eq 2.36
    hlc_penalty: float = 1.0           # o, eq 2.43
    hlc_threshold: float = 0.90        # hlc, eq 2.43 (fraction of the leg length)
    leg_length_penalty: float = 1.0    # l, eq 2.45
    leg_length_tolerance: float = 0.0  # n, eq 2.45, m
    joint_limit_penalty: float = 1.0   # j, eq 2.50
    hip_height_penalty: float = 1.0    # n, eq 2.51
    max_hip_z: float = 1.0             # max_hz, eq 2.51, m (the hip model never exceeds thigh+shin)
    # Potential-based progress shaping per metre (not in the thesis; 0 = thesis reward), see
    # jaxexo.physics.rewards.shaping_reward for the choice of its discount.
    progress_shaping: float = 0.0
    shaping_discount: float = 1.0


@dataclass(frozen=True)
class ObstacleSpec:
    """One entry of the layout's obstacle mixture.

    ``kind`` is a thesis obstacle (base1, base2, base3, triangle, half_circle: fixed size) or a shape
    (rectangle, triangle, half_ellipse, profile) with ``width`` and ``height`` ranges [lo, hi] in m.
    A ``profile`` takes ``points`` (y, z), y relative to the obstacle centre, and is scaled to
    ``width`` and ``height`` ranges in metres (default: its own extents, as drawn)."""

    kind: str
    width: tuple[float, float]
    height: tuple[float, float]
    weight: float = 1.0
    shape: str = "rectangle"
    points: tuple[tuple[float, float], ...] = ()

    def unit_vertices(self) -> np.ndarray:
        if self.shape == "profile":
            return geometry.Obstacle.profile(self.points).unit_vertices
        return geometry.unit_profile(self.shape)


@dataclass(frozen=True)
class LayoutConfig:
    obstacles: tuple[ObstacleSpec, ...] = ()
    size_jitter: float = 0.0           # relative +- jitter of every width and height
    obstacle_offset: tuple[float, float] = (0.0, 0.0)  # m, added to the default centre
    pivot: tuple[float, float, float] = (1.0, 1.0, 1.0)  # weights of PIVOT_CONDITIONS
    start_shift: tuple[float, float] = (0.0, 0.0)   # m, agent start moved towards the obstacle
    step_length: tuple[float, float] = (0.70, 0.70)  # m; the goal is start + step length

    def default_center(self, foot_length: float, step_length: float) -> float:
        """Default obstacle centre: the middle of the free gap between the toe at the (unshifted)
        start and the heel at the goal."""
        return 0.5 * (foot_length + step_length)


TRACE_VIEWS = ("forward", "backward")
TRACE_KINDS = ("accumulating", "replacing")
CONTROLS = ("off_policy", "on_policy")
TARGETS = ("hard", "polyak")


@dataclass(frozen=True)
class TrainConfig:
    """[train]: the TD(lambda) agent (thesis 2.3-2.4).

    Static settings fix the compiled program's shapes and structure; the hyperparameters below
    ``lr`` are pytree leaves of ``jaxexo.train.Hyperparams`` and can be vmapped (sweeps)."""

    # --- static ---
    num_envs: int = 1024
    rollout_steps: int = 16            # T: steps per environment between updates
    num_minibatches: int = 4           # forward view: gradient steps per epoch over the T x N batch
    num_epochs: int = 1
    hidden: tuple[int, ...] = (64, 32, 32, 32)   # the thesis network (Fig. 2.2)
    layer_norm: bool = False
    trace: str = "forward"             # "forward": lambda-returns; "backward": eligibility traces
    trace_kind: str = "accumulating"   # backward view: "accumulating" or "replacing"
    control: str = "off_policy"        # "off_policy": Watkins Q(lambda) (eq 2.13, 2.28);
                                       # "on_policy": SARSA(lambda) (eq 2.14, 2.27)
    target: str = "hard"               # "hard": copy every target_period updates; "polyak": tau
    budget_episodes: int = 0           # stop after this many finished episodes (0: no limit)
    budget_env_steps: int = 20_000_000 # stop after this many env steps (0: no limit)
    chunk_updates: int = 0             # updates per compiled chunk (progress, checkpoint); 0: auto
    eval_episodes: int = 1000
    # --- vmappable hyperparameters ---
    lr: float = 1e-3
    lr_end_fraction: float = 1.0       # linear decay of the learning rate to lr * this at the budget's end
    gamma: float = 0.99
    lam: float = 0.8
    eps_start: float = 1.0
    eps_end: float = 0.02
    eps_decay_fraction: float = 0.5    # of the budget, linear
    target_period: int = 10            # updates, "hard"
    target_tau: float = 0.05           # "polyak"
    max_grad_norm: float = 10.0


# TrainConfig fields that are leaves of jaxexo.train.Hyperparams (vmappable). The budgets are leaves
# too, but the number of updates they need (num_updates) is static: it is the length of the scan.
HYPER_FIELDS = ("lr", "lr_end_fraction", "gamma", "lam", "eps_start", "eps_end", "eps_decay_fraction",
                "target_period", "target_tau", "max_grad_norm", "budget_episodes", "budget_env_steps")


@dataclass(frozen=True)
class Config:
    """The whole configuration. ``outline_vertices`` is the resolved fixed outline size K."""

    env: EnvConfig = field(default_factory=EnvConfig)
    kinematics: KinematicsConfig = field(default_factory=KinematicsConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    layout: LayoutConfig = field(default_factory=lambda: LayoutConfig(obstacles=default_obstacles()))
    train: TrainConfig = field(default_factory=TrainConfig)
    extra: dict = field(default_factory=dict)  # sections owned by later stages

    @property
    def outline_vertices(self) -> int:
        need = max(len(o.unit_vertices()) for o in self.layout.obstacles)
        return self.env.max_vertices or need


def num_updates(cfg: Config) -> int:
    """Updates that the budget can need: env steps / (N T), or for an episode budget the bound at
    which every environment has run ceil(budget / N) episodes to the step limit. Updates past the
    budget are masked (``Trainer.active``), so the bound may be generous."""
    t = cfg.train
    per = t.num_envs * t.rollout_steps
    bounds = []
    if t.budget_env_steps:
        bounds.append(math.ceil(t.budget_env_steps / per))
    if t.budget_episodes:
        per_env_steps = math.ceil(t.budget_episodes / t.num_envs) * cfg.env.max_steps
        bounds.append(math.ceil(per_env_steps / t.rollout_steps))
    return max(1, min(bounds))


def static_settings(cfg: Config) -> tuple:
    """Everything about a config that fixes the compiled trainer (and its greedy evaluation): shapes,
    structure, the scan length and the learning-rate schedule's length. Configs with equal static
    settings differ only in pytree leaves (jaxexo.train.Hyperparams, EnvParams) and can be vmapped
    together as one program; the rest (every other reward, layout, kinematics and env value, and
    HYPER_FIELDS) are leaves."""
    t, e = cfg.train, cfg.env
    train = tuple((f.name, getattr(t, f.name)) for f in fields(t)
                  if f.name not in HYPER_FIELDS and f.name != "chunk_updates")
    env = (("obs_mode", e.obs_mode), ("shape_points", e.shape_points), ("max_steps", e.max_steps),
           ("outline_vertices", cfg.outline_vertices), ("obstacle_kinds", len(cfg.layout.obstacles)))
    return train + env + (("num_updates", num_updates(cfg)),)


def default_obstacles() -> tuple[ObstacleSpec, ...]:
    """Training mixture of the default config: Base 1-3 and random rectangles (triangle and
    half-circle are held out for testing)."""
    return tuple(named_spec(k) for k in ("base1", "base2", "base3")) + (
        ObstacleSpec("rectangle", (0.05, 0.20), (0.05, 0.20), 1.0, "rectangle"),
    )


def named_spec(kind: str, weight: float = 1.0) -> ObstacleSpec:
    shape, w, h = THESIS_OBSTACLES[kind]
    return ObstacleSpec(kind, (w, w), (h, h), weight, shape)


# --------------------------------------------------------------------------------------------
# Parsing
# --------------------------------------------------------------------------------------------

EXTRA_SECTIONS: set[str] = {"eval", "sweep"}


def _number(path: str, v: Any, *, positive=False, nonneg=False, integer=False) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ConfigError(f"{path}: expected a number, got {v!r}")
    if integer and not float(v).is_integer():
        raise ConfigError(f"{path}: expected an integer, got {v!r}")
    if not math.isfinite(v):
        raise ConfigError(f"{path}: must be finite, got {v!r}")
    if positive and v <= 0:
        raise ConfigError(f"{path}: must be > 0, got {v!r}")
    if nonneg and v < 0:
        raise ConfigError(f"{path}: must be >= 0, got {v!r}")
    return int(v) if integer else float(v)


def _fraction(path: str, v: Any, positive: bool = False) -> float:
    """A number in [0, 1] ((0, 1] if ``positive``)."""
    x = _number(path, v, positive=positive, nonneg=True)
    if x > 1:
        raise ConfigError(f"{path}: a fraction, must be in {'(0' if positive else '[0'}, 1], got {x}")
    return x


def _vector(path: str, v: Any, n: int | None = None, **kw) -> tuple:
    if not isinstance(v, (list, tuple)):
        raise ConfigError(f"{path}: expected a list of numbers, got {v!r}")
    if n is not None and len(v) != n:
        raise ConfigError(f"{path}: expected {n} numbers, got {len(v)}")
    return tuple(_number(f"{path}[{i}]", x, **kw) for i, x in enumerate(v))


def _range(path: str, v: Any, **kw) -> tuple[float, float]:
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        v = [v, v]
    lo, hi = _vector(path, v, 2, **kw)
    if lo > hi:
        raise ConfigError(f"{path}: range [lo, hi] needs lo <= hi, got [{lo}, {hi}]")
    return lo, hi


def _choice(path: str, v: Any, options) -> str:
    if v not in options:
        raise ConfigError(f"{path}: must be one of {list(options)}, got {v!r}")
    return v


def _section(cls, path: str, raw: dict, coerce) -> Any:
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: expected a table, got {raw!r}")
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(raw) - names)
    if unknown:
        raise ConfigError(f"{path}.{unknown[0]}: unknown field (known: {', '.join(sorted(names))})")
    kwargs = {k: coerce(f"{path}.{k}", k, v) for k, v in raw.items()}
    return cls(**kwargs)


def _coerce_env(path, k, v):
    if k == "max_vertices":
        return _number(path, v, nonneg=True, integer=True)
    if k in ("max_steps", "shape_points"):
        return _number(path, v, positive=True, integer=True)
    if k == "collision":
        return _choice(path, v, COLLISION_MODES)
    if k == "obs_mode":
        return _choice(path, v, OBS_MODES)
    if k == "obs_profile":
        return _choice(path, v, OBS_PROFILES)
    if k in ("goal_tolerance", "mid_goal_half_size"):
        return _vector(path, v, 2, positive=True)
    if k == "bounds_y":
        return _range(path, v)
    if k in ("max_height_margin", "mid_goal_clearance", "min_clearance", "backward_tolerance"):
        return _number(path, v, nonneg=True)
    return _number(path, v, positive=True)


def _coerce_kin(path, k, v):
    if k in ("hip_limits", "knee_limits"):
        return _range(path, v)
    return _number(path, v, positive=True)


def _coerce_reward(path, k, v):
    if k == "traj_weights":
        return _vector(path, v, 8, nonneg=True)
    if k == "exo_weights":
        return _vector(path, v, 4, nonneg=True)
    if k == "step_threshold":
        return _number(path, v, positive=True)
    if k in ("hlc_threshold", "shaping_discount"):
        return _fraction(path, v, positive=True)
    if k in ("max_hip_z", "safety_distance"):
        return _number(path, v, positive=True)
    return _number(path, v, nonneg=True)


def _coerce_train(path, k, v):
    choices = {"trace": TRACE_VIEWS, "trace_kind": TRACE_KINDS, "control": CONTROLS, "target": TARGETS}
    if k in choices:
        return _choice(path, v, choices[k])
    if k == "layer_norm":
        if not isinstance(v, bool):
            raise ConfigError(f"{path}: expected true or false, got {v!r}")
        return v
    if k == "hidden":
        return tuple(int(x) for x in _vector(path, v, None, positive=True, integer=True))
    if k in ("num_envs", "rollout_steps", "num_minibatches", "num_epochs", "eval_episodes", "target_period"):
        return _number(path, v, positive=True, integer=True)
    if k in ("budget_episodes", "budget_env_steps", "chunk_updates"):
        return _number(path, v, nonneg=True, integer=True)
    if k in ("gamma", "lam", "eps_start", "eps_end", "lr_end_fraction"):
        return _fraction(path, v)
    if k in ("eps_decay_fraction", "target_tau"):
        return _fraction(path, v, positive=True)
    return _number(path, v, positive=True)


def _obstacle_spec(path: str, raw: Any) -> ObstacleSpec:
    if isinstance(raw, str):
        raw = {"kind": raw}
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: expected a table or a thesis obstacle name, got {raw!r}")
    known = {"kind", "width", "height", "weight", "points"}
    unknown = sorted(set(raw) - known)
    if unknown:
        raise ConfigError(f"{path}.{unknown[0]}: unknown field (known: {', '.join(sorted(known))})")
    kind = raw.get("kind")
    weight = _number(f"{path}.weight", raw.get("weight", 1.0), nonneg=True)
    if kind in THESIS_OBSTACLES:
        for k in ("width", "height", "points"):
            if k in raw:
                raise ConfigError(f"{path}.{k}: {kind} has the fixed size of thesis Table 3.1; "
                                  f"use kind = \"{THESIS_OBSTACLES[kind][0]}\" for other sizes")
        return named_spec(kind, weight)
    shapes = geometry.SHAPES
    if kind not in shapes:
        raise ConfigError(f"{path}.kind: must be a thesis obstacle {sorted(THESIS_OBSTACLES)} "
                          f"or a shape {list(shapes)}, got {kind!r}")
    for k in ("width", "height"):
        if k not in raw:
            if kind == "profile":
                continue
            raise ConfigError(f"{path}.{k}: required for kind = \"{kind}\" (a range [lo, hi] in m)")
    points: tuple = ()
    if kind == "profile":
        if "points" not in raw:
            raise ConfigError(f"{path}.points: required for kind = \"profile\"")
        try:
            ob = geometry.Obstacle.profile(raw["points"])
        except geometry.GeometryError as e:
            raise ConfigError(f"{path}.points: {e}") from None
        points = tuple(map(tuple, np.asarray(raw["points"], dtype=float)))
        width = _range(f"{path}.width", raw.get("width", [ob.width, ob.width]), positive=True)
        height = _range(f"{path}.height", raw.get("height", [ob.height, ob.height]), positive=True)
    else:
        width = _range(f"{path}.width", raw["width"], positive=True)
        height = _range(f"{path}.height", raw["height"], positive=True)
    return ObstacleSpec(kind, width, height, weight, kind, points)


def _coerce_layout(path, k, v):
    if k == "obstacles":
        if not isinstance(v, list) or not v:
            raise ConfigError(f"{path}: expected a non-empty list of obstacles")
        return tuple(_obstacle_spec(f"{path}[{i}]", o) for i, o in enumerate(v))
    if k == "pivot":
        if isinstance(v, str):
            v = [v]
        if isinstance(v, list) and all(isinstance(x, str) for x in v):
            for x in v:
                _choice(path, x, PIVOT_CONDITIONS)
            return tuple(1.0 if c in v else 0.0 for c in PIVOT_CONDITIONS)
        if isinstance(v, list) and len(v) == len(PIVOT_CONDITIONS) and not any(isinstance(x, str) for x in v):
            return _vector(path, v, len(PIVOT_CONDITIONS), nonneg=True)
        if isinstance(v, dict):
            for x in v:
                _choice(f"{path}.{x}", x, PIVOT_CONDITIONS)
            return tuple(_number(f"{path}.{c}", v.get(c, 0.0), nonneg=True) for c in PIVOT_CONDITIONS)
        raise ConfigError(f"{path}: expected a list of names from {list(PIVOT_CONDITIONS)}, three weights "
                          "in that order, or a table of weights")
    if k == "size_jitter":
        x = _number(path, v, nonneg=True)
        if x >= 1:
            raise ConfigError(f"{path}: relative jitter must be < 1, got {x}")
        return x
    if k == "step_length":
        return _range(path, v, positive=True)
    return _range(path, v)


def config_from_dict(raw: dict) -> Config:
    """Build and validate a Config from a parsed TOML table."""
    if not isinstance(raw, dict):
        raise ConfigError(f"config: expected a table, got {raw!r}")
    known = {"env", "kinematics", "reward", "layout", "train"} | EXTRA_SECTIONS
    unknown = sorted(set(raw) - known)
    if unknown:
        raise ConfigError(f"{unknown[0]}: unknown section (known: {', '.join(sorted(known))})")
    env = _section(EnvConfig, "env", raw.get("env", {}), _coerce_env)
    kin = _section(KinematicsConfig, "kinematics", raw.get("kinematics", {}), _coerce_kin)
    rew = _section(RewardConfig, "reward", raw.get("reward", {}), _coerce_reward)
    lay_raw = dict(raw.get("layout", {}))
    lay = _section(LayoutConfig, "layout", lay_raw, _coerce_layout)
    if not lay.obstacles:
        lay = dataclasses.replace(lay, obstacles=default_obstacles())
    train = _section(TrainConfig, "train", raw.get("train", {}), _coerce_train)
    extra = {k: raw[k] for k in EXTRA_SECTIONS if k in raw}
    cfg = Config(env, kin, rew, lay, train, extra)
    validate(cfg)
    return cfg


def load_config(path: str | Path) -> Config:
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise ConfigError(f"{path}: cannot read config ({e.strerror})") from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML ({e})") from None
    try:
        return config_from_dict(raw)
    except ConfigError as e:
        raise ConfigError(f"{path}: {e}") from None


# --------------------------------------------------------------------------------------------
# Cross-field validation: impossible layouts are refused here, naming the field to change.
# --------------------------------------------------------------------------------------------


def validate(cfg: Config) -> None:
    env, kin, rew, lay, tr = cfg.env, cfg.kinematics, cfg.reward, cfg.layout, cfg.train
    if tr.budget_episodes == 0 and tr.budget_env_steps == 0:
        raise ConfigError("train.budget_episodes: set a budget (budget_episodes and/or budget_env_steps > 0)")
    if tr.num_envs % tr.num_minibatches:
        raise ConfigError(f"train.num_minibatches: {tr.num_minibatches} does not divide train.num_envs = "
                          f"{tr.num_envs} (minibatches are blocks of environments)")
    if tr.eps_end > tr.eps_start:
        raise ConfigError("train.eps_end: must not exceed train.eps_start")
    if sum(rew.traj_weights) <= 0:
        raise ConfigError("reward.traj_weights: at least one weight must be > 0 (eq 2.38 divides by the sum)")
    if sum(rew.exo_weights) <= 0:
        raise ConfigError("reward.exo_weights: at least one weight must be > 0 (eq 2.52 divides by the sum)")
    if sum(lay.pivot) <= 0:
        raise ConfigError("layout.pivot: at least one pivot condition needs a weight > 0")
    if sum(o.weight for o in lay.obstacles) <= 0:
        raise ConfigError("layout.obstacles: at least one obstacle needs a weight > 0")
    if kin.hip_limits[0] >= kin.hip_limits[1]:
        raise ConfigError("kinematics.hip_limits: lower limit must be below the upper one")
    if kin.knee_limits[0] >= kin.knee_limits[1]:
        raise ConfigError("kinematics.knee_limits: lower limit must be below the upper one")
    need = max(len(o.unit_vertices()) for o in lay.obstacles)
    if env.max_vertices and env.max_vertices < need:
        raise ConfigError(f"env.max_vertices: {env.max_vertices} is fewer than the {need} outline vertices "
                          "of an obstacle in layout.obstacles (0 picks the size automatically)")
    j = lay.size_jitter
    for i, ob in enumerate(lay.obstacles):
        p = f"layout.obstacles[{i}]"
        if ob.weight <= 0:
            continue
        w_min, w_max = ob.width[0] * (1 - j), ob.width[1] * (1 + j)
        h_min, h_max = ob.height[0] * (1 - j), ob.height[1] * (1 + j)
        if env.step_size >= min(w_min, h_min):
            field_ = "width" if w_min <= h_min else "height"
            raise ConfigError(
                f"env.step_size: {env.step_size} m is not smaller than {p}.{field_} "
                f"(smallest {min(w_min, h_min):.3f} m): a step could jump through the obstacle")
        s_lo, s_hi = lay.start_shift
        for L in lay.step_length:
            center_lo = lay.default_center(kin.foot_length, L) + lay.obstacle_offset[0]
            center_hi = lay.default_center(kin.foot_length, L) + lay.obstacle_offset[1]
            toe_start = s_hi + kin.foot_length
            if center_lo - 0.5 * w_max <= toe_start:
                raise ConfigError(
                    f"layout.start_shift: with {p} up to {w_max:.3f} m wide, step length {L} m and "
                    f"offset {lay.obstacle_offset[0]} m, the obstacle reaches back to the toe at the "
                    f"start (y = {toe_start:.3f} m); reduce start_shift, obstacle_offset or the width")
            goal = s_lo + L
            if center_hi + 0.5 * w_max >= goal - env.goal_tolerance[0]:
                raise ConfigError(
                    f"layout.step_length: the goal at {goal:.3f} m is not beyond {p} (its far edge "
                    f"reaches {center_hi + 0.5 * w_max:.3f} m); the goal must lie ahead of the obstacle")
        top = h_max
        mid_z = top + env.mid_goal_clearance
        if mid_z + env.mid_goal_half_size[1] >= env.max_z:
            raise ConfigError(f"{p}.height: up to {h_max:.3f} m puts the mid-goal above env.max_z = {env.max_z} m")
        if top + env.mid_goal_clearance - env.mid_goal_half_size[1] <= top:
            raise ConfigError("env.mid_goal_half_size: the mid-goal box must lie above the obstacle "
                              "(mid_goal_clearance must exceed its half height)")
        _check_clearable(cfg, p, h_max, w_max)
    if env.bounds_y[0] > 0.0:
        raise ConfigError("env.bounds_y: the lower bound must be at or behind the start (y = 0)")
    goal_far = lay.start_shift[1] + lay.step_length[1] + env.goal_tolerance[0]
    if env.bounds_y[1] <= goal_far:
        raise ConfigError(f"env.bounds_y: the upper bound must lie beyond the goal region ({goal_far:.3f} m)")
    if rew.safety_distance < env.min_clearance:
        raise ConfigError(f"reward.safety_distance: {rew.safety_distance} m is below env.min_clearance = "
                          f"{env.min_clearance} m; the safety term (eq 2.35) must pay the policy to keep the "
                          "margin that a safe swing needs, not only to avoid contact")
    if env.max_steps < rew.step_threshold:
        raise ConfigError(f"env.max_steps: {env.max_steps} is below reward.step_threshold = {rew.step_threshold}")


def _check_clearable(cfg: Config, path: str, h_max: float, w_max: float) -> None:
    """Refuse an obstacle that the leg cannot clear: with the heel at the bottom of the mid-goal box
    over the obstacle (the lowest point the reward asks the foot to pass), every pivot condition the
    layout can draw must give a reachable leg within the joint limits, at every extreme of the
    start shift, step length and obstacle offset that reset can draw."""
    import itertools

    env, kin, lay = cfg.env, cfg.kinematics, cfg.layout
    heel_z = h_max + env.mid_goal_clearance - env.mid_goal_half_size[1]
    for start, L, off in itertools.product(lay.start_shift, lay.step_length, lay.obstacle_offset):
        center = lay.default_center(kin.foot_length, L) + off
        pivots = {"agent": start, "obstacle": center, "between": 0.5 * (start + center)}
        heel = np.array([center, heel_z])
        for name, weight in zip(PIVOT_CONDITIONS, lay.pivot):
            if weight <= 0:
                continue
            ks = kinematics.leg_state(np, pivots[name], heel, kin.thigh, kin.shin)
            ok = ks["leg_swing"] <= kin.thigh + kin.shin + 1e-9 and not kinematics.joint_limit_violation(
                np, ks["hip_swing"], ks["knee_swing_angle"], *kin.hip_limits, *kin.knee_limits)
            if not ok:
                raise ConfigError(
                    f"{path}.height: an obstacle {h_max:.3f} m high cannot be cleared with pivot {name!r} "
                    f"(start {start:.3f} m, step length {L:.3f} m): the heel over it at {heel_z:.3f} m is "
                    "out of the leg's reach or joint limits")
