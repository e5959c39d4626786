"""Typed, validated configuration: TOML files under configs/ become frozen dataclasses.

Everything here is NumPy-only (``import jaxexo`` must not import JAX). Each field is declared once,
with ``declare(default, check, unit=..., role=...)``: its type (the dataclass annotation), its check
(which parses and validates the raw TOML value), its unit, and its role in the compiled program:

- ``"leaf"``: a pytree leaf, vmappable (sweeps): an ``EnvParams`` field (env, kinematics, reward,
  layout) or a ``Hyperparams`` field (train); ``param``/``to_param`` say how it becomes one;
- ``"static"``: fixes the compiled program's shapes or structure (``static_settings``);
- ``"static+leaf"``: both (``env.max_steps``: the step limit is a leaf, but the scan length over
  episodes depends on it);
- ``"setting"``: read by the Python driver only (``train.chunk_updates``) or resolved into a
  derived static setting (``env.max_vertices`` -> ``Config.outline_vertices``).

Parsing and its messages (``config_from_dict``), the TOML writer (``jaxexo.config.toml_io``),
``HYPER_FIELDS``, ``EnvParams`` (``jaxexo.config.views.param_values``), ``Hyperparams`` and
``static_settings`` all iterate these declarations. Every value is checked when the config is
built, and an error names the bad field (``ConfigError: layout.obstacles[1].height: ...``), so an
impossible layout never shows up as a NaN inside a jitted run.

Units: metres, radians, steps. Sections: [env], [kinematics], [reward], [layout], [train], [device]. A sweep
file's [sweep] table is read by ``jaxexo sweep`` (jaxexo.sweep.spec), which removes it before the
rest reaches ``config_from_dict``; a train config refuses it.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Callable

import numpy as np

from jaxexo.physics import geometry, kinematics, outcome, rewards, terrain
from jaxexo.physics.geometry import THESIS_OBSTACLES
from jaxexo.physics.kinematics import PIVOT_CONDITIONS

OBS_MODES = ("thesis", "conditioned")
OBS_PROFILES = ("bbox", "shape")
COLLISION_MODES = ("penalty", "terminate")
TRACE_VIEWS = ("forward", "backward")
TRACE_KINDS = ("accumulating", "replacing")
CONTROLS = ("off_policy", "on_policy")
TARGETS = ("hard", "polyak")

INT32_MAX = 2**31 - 1   # integers that reach JAX as int32 (or index a scan) stay below this
MAX_CONTROL_RATE = 10_000.0   # Hz: a timed export's rate ([device] control_rate, jaxexo generate --rate)
MAX_SWING_DURATION = 60.0     # s: one swing (about 1 s on today's exoskeletons), not a walk
SECTIONS = ("env", "kinematics", "reward", "layout", "train", "device")
# Sections that other commands read; a train config refuses them, saying where they belong.
OTHER_COMMANDS = {"sweep": "it is read by jaxexo sweep (a sweep file, see configs/sweeps/*.toml)",
                  "eval": "no command reads it: jaxexo eval takes its settings as options (--n, --scenarios, "
                          "--against), and training's greedy evaluation size is train.eval_episodes"}


class ConfigError(ValueError):
    """A config value that is invalid or impossible; the message starts with the field's path."""


def _deg(d: float) -> float:
    return math.radians(d)


# --------------------------------------------------------------------------------------------
# Checks: each parses one raw TOML value, ``check(path, raw) -> value``, raising ConfigError that
# starts with ``path``.
# --------------------------------------------------------------------------------------------


def _number(path: str, v: Any, *, positive=False, nonneg=False, integer=False, lo=None, hi=None) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ConfigError(f"{path}: expected a number, got {v!r}")
    if integer and not (isinstance(v, int) or float(v).is_integer()):
        raise ConfigError(f"{path}: expected an integer, got {v!r}")
    if not isinstance(v, int) and not math.isfinite(v):
        raise ConfigError(f"{path}: must be finite, got {v!r}")
    if positive and v <= 0:
        raise ConfigError(f"{path}: must be > 0, got {v!r}")
    if nonneg and v < 0:
        raise ConfigError(f"{path}: must be >= 0, got {v!r}")
    if lo is not None and v < lo:
        raise ConfigError(f"{path}: must be >= {lo}, got {v!r}")
    if hi is not None and v > hi:
        raise ConfigError(f"{path}: must be <= {hi}, got {v!r}")
    return int(v) if integer else float(v)


def number(*, positive=False, nonneg=False, integer=False, lo=None, hi=None) -> Callable:
    if integer and hi is None:
        raise TypeError("an integer field needs an upper bound (hi)")
    return lambda path, v: _number(path, v, positive=positive, nonneg=nonneg, integer=integer, lo=lo, hi=hi)


def fraction(positive: bool = False) -> Callable:
    """A number in [0, 1] ((0, 1] if ``positive``)."""
    def check(path, v):
        x = _number(path, v, positive=positive, nonneg=True)
        if x > 1:
            raise ConfigError(f"{path}: a fraction, must be in {'(0' if positive else '[0'}, 1], got {x}")
        return x
    return check


def below_one(path: str, v: Any) -> float:
    x = _number(path, v, nonneg=True)
    if x >= 1:
        raise ConfigError(f"{path}: relative jitter must be < 1, got {x}")
    return x


def _vector(path: str, v: Any, n: int | None = None, **kw) -> tuple:
    if not isinstance(v, (list, tuple)):
        raise ConfigError(f"{path}: expected a list of numbers, got {v!r}")
    if n is not None and len(v) != n:
        raise ConfigError(f"{path}: expected {n} numbers, got {len(v)}")
    return tuple(_number(f"{path}[{i}]", x, **kw) for i, x in enumerate(v))


def vector(n: int | None = None, *, max_len: int | None = None, **kw) -> Callable:
    def check(path, v):
        out = _vector(path, v, n, **kw)
        if max_len is not None and len(out) > max_len:
            raise ConfigError(f"{path}: at most {max_len} numbers, got {len(out)}")
        return out
    return check


def _range(path: str, v: Any, **kw) -> tuple[float, float]:
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        v = [v, v]
    lo, hi = _vector(path, v, 2, **kw)
    if lo > hi:
        raise ConfigError(f"{path}: range [lo, hi] needs lo <= hi, got [{lo}, {hi}]")
    return lo, hi


def range_(**kw) -> Callable:
    """A range [lo, hi] (a single number x means [x, x])."""
    return lambda path, v: _range(path, v, **kw)


def _choice(path: str, v: Any, options) -> str:
    if v not in options:
        raise ConfigError(f"{path}: must be one of {list(options)}, got {v!r}")
    return v


def choice(options) -> Callable:
    return lambda path, v: _choice(path, v, options)


def boolean(path: str, v: Any) -> bool:
    if not isinstance(v, bool):
        raise ConfigError(f"{path}: expected true or false, got {v!r}")
    return v


def pivot_weights(path: str, v: Any) -> tuple[float, float, float]:
    """Names from PIVOT_CONDITIONS (weight 1 each), three weights in that order, or a table."""
    if isinstance(v, str):
        v = [v]
    if isinstance(v, list) and v and all(isinstance(x, str) for x in v):
        for x in v:
            _choice(path, x, PIVOT_CONDITIONS)
        return tuple(1.0 if c in v else 0.0 for c in PIVOT_CONDITIONS)
    if isinstance(v, (list, tuple)) and len(v) == len(PIVOT_CONDITIONS) and not any(isinstance(x, str) for x in v):
        return _vector(path, v, len(PIVOT_CONDITIONS), nonneg=True)
    if isinstance(v, dict):
        for x in v:
            _choice(f"{path}.{x}", x, PIVOT_CONDITIONS)
        return tuple(_number(f"{path}.{c}", v.get(c, 0.0), nonneg=True) for c in PIVOT_CONDITIONS)
    raise ConfigError(f"{path}: expected a list of names from {list(PIVOT_CONDITIONS)}, three weights "
                      "in that order, or a table of weights")


# --------------------------------------------------------------------------------------------
# The declaration of a field
# --------------------------------------------------------------------------------------------

ROLES = ("leaf", "static", "static+leaf", "setting")


@dataclass(frozen=True)
class FieldSpec:
    """How one config field is parsed, what unit it has and what it becomes (see module doc)."""

    check: Callable[[str, Any], Any]
    unit: str = ""
    role: str = "leaf"
    param: str | None = None        # EnvParams name when it differs from the field name
    # value -> {EnvParams name: NumPy value}; ``cfg`` is passed for values that need other fields.
    to_param: Callable[[Any, Any], dict] | None = None
    dtype: str = "float32"          # of the pytree leaf
    write: Callable[[Any], Any] | None = None   # value -> TOML-writable value (default: as is)

    @property
    def leaf(self) -> bool:
        return self.role in ("leaf", "static+leaf")

    @property
    def static(self) -> bool:
        return self.role in ("static", "static+leaf")

    def params(self, name: str, value, cfg) -> dict[str, np.ndarray]:
        if self.to_param is not None:
            return self.to_param(value, cfg)
        return {self.param or name: np.asarray(value, dtype=self.dtype)}


def declare(default=dataclasses.MISSING, check=None, *, default_factory=dataclasses.MISSING, **kw):
    """A dataclass field with its FieldSpec (in ``field.metadata["spec"]``)."""
    if check is None:
        raise TypeError("declare: every field needs a check")
    if kw.get("role", "leaf") not in ROLES:
        raise TypeError(f"declare: role must be one of {ROLES}")
    return field(default=default, default_factory=default_factory, metadata={"spec": FieldSpec(check, **kw)})


def spec_of(f: dataclasses.Field) -> FieldSpec:
    return f.metadata["spec"]


def declared_fields(section_cls) -> list[tuple[str, FieldSpec]]:
    return [(f.name, spec_of(f)) for f in fields(section_cls)]


def _normalized(name):
    # eq 2.38 / 2.52: the weights enter the reward normalised to sum 0.5
    return lambda v, cfg: {name: np.asarray(rewards.normalize_weights(v), dtype=np.float32)}


def _cdf(weights) -> np.ndarray:
    w = np.asarray(weights, dtype=np.float64)
    c = np.cumsum(w / w.sum())
    c[-1] = 1.0
    return c.astype(np.float32)


# --------------------------------------------------------------------------------------------
# Sections
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class EnvConfig:
    # m per action; about 30 steps for a 0.70 m step over 0.2 m
    step_size: float = declare(0.03, number(positive=True), unit="m")
    # step limit -> truncated; a leaf (EnvParams.max_steps_in_episode) and a static (episode budgets)
    max_steps: int = declare(100, number(positive=True, integer=True, hi=100_000), unit="steps",
                             role="static+leaf", param="max_steps_in_episode", dtype="int32")
    # "penalty" (thesis: pay r1 and continue) or "terminate"
    collision: str = declare("penalty", choice(COLLISION_MODES), to_param=lambda v, cfg: {
        "terminate_on_collision": np.asarray(v == "terminate")})
    # "thesis" (heel y, z) or "conditioned"
    obs_mode: str = declare("conditioned", choice(OBS_MODES), role="static")
    # How the conditioned observation shows the obstacle's profile: "bbox" (its bounding rectangle:
    # a policy trained on rectangles treats any unseen shape conservatively) or "shape" (the true
    # profile, for policies trained on varied shapes). Collisions always use the true outline.
    obs_profile: str = declare("shape", choice(OBS_PROFILES), to_param=lambda v, cfg: {
        "obs_true_profile": np.asarray(v == "shape")})
    # outline size K; 0: the largest count among the layout's kinds (resolved: Config.outline_vertices)
    max_vertices: int = declare(0, number(nonneg=True, integer=True, hi=geometry.MAX_PROFILE_VERTICES),
                                unit="vertices", role="setting")
    shape_points: int = declare(geometry.DEFAULT_SHAPE_POINTS, number(positive=True, integer=True, hi=1024),
                                unit="points", role="static")
    # goal box: |heel_y - goal_y| <= [0], heel_z <= [1]
    goal_tolerance: tuple[float, float] = declare((0.04, 0.02), vector(2, positive=True), unit="m")
    # mid-goal centre height above the obstacle top
    mid_goal_clearance: float = declare(0.045, number(nonneg=True), unit="m")
    # half extents (y, z) of the mid-goal box
    mid_goal_half_size: tuple[float, float] = declare((0.06, 0.02), vector(2, positive=True), unit="m")
    # max_z of eq 2.34 = obstacle top + this
    max_height_margin: float = declare(0.20, number(nonneg=True), unit="m")
    bounds_y: tuple[float, float] = declare((-0.30, 1.30), range_(), unit="m")  # the heel is kept inside
    # ceiling for the heel; the ground is z = 0
    max_z: float = declare(0.80, number(positive=True), unit="m", param="max_z_world")
    # The safe-swing definition (issue 11, jaxexo.physics.swept): the foot's motion between samples
    # never comes closer than min_clearance to the obstacle, and the heel never moves backward by
    # more than backward_tolerance. The environment's success flag and the generators' ``ok`` use both.
    min_clearance: float = declare(outcome.DEFAULT_MIN_CLEARANCE, number(nonneg=True), unit="m")
    # At most 10 m: any value beyond env.bounds_y's span turns the check off, and the thesis configs
    # write 10 m for that.
    backward_tolerance: float = declare(outcome.DEFAULT_BACKWARD_TOLERANCE, number(nonneg=True, hi=10.0), unit="m")
    # The shield (issue 11; not in the thesis): the agent chooses only among admissible moves
    # (jaxexo.physics.dynamics.admissible_moves): no backward component, the exact clearance of the
    # whole move at least shield_clearance, joint limits and reach respected at its end. The same
    # mask in training, evaluation and the NumPy generator; off reproduces the thesis's free choice.
    shield: bool = declare(True, boolean, role="static+leaf", dtype="bool")
    # m: the clearance a shielded move keeps; above min_clearance so that the smoothed curve, which
    # cuts corners, still keeps min_clearance without falling back to the raw polyline. With the shield
    # on it must be at least min_clearance (validate); at most 10 cm, above that no step over an
    # obstacle remains admissible.
    shield_clearance: float = declare(0.025, number(nonneg=True, hi=0.10), unit="m")


@dataclass(frozen=True)
class KinematicsConfig:
    # Human segments (an adult's thigh or shin is about 0.4-0.55 m, a foot 0.2-0.3 m): at most 1 m each,
    # a foot at most 0.5 m.
    thigh: float = declare(0.50, number(positive=True, hi=1.0), unit="m")
    shin: float = declare(0.50, number(positive=True, hi=1.0), unit="m")
    foot_length: float = declare(0.20, number(positive=True, hi=0.5), unit="m")   # heel-to-toe
    hip_limits: tuple[float, float] = declare((-0.5236, 2.0071), range_(), unit="rad")     # -30 .. 115 deg
    knee_limits: tuple[float, float] = declare((-1.7453, 0.0), range_(), unit="rad")       # -100 .. 0 deg


@dataclass(frozen=True)
class DeviceConfig:
    """[device]: the exoskeleton's joint drives, for timing swings (jaxexo.inference.swing_timing).

    Limits are per joint kind (hip, knee) and apply to both legs, in rad/s and rad/s^2. The defaults
    are conservative, order-of-magnitude figures, not one device's data sheet: lower-limb
    exoskeletons for paraplegic gait (ReWalk, Ekso, Indego, TWIICE) walk at about 0.2-0.5 m/s with
    swings near one second, far slower than able-bodied gait, whose swing knee peaks at the order of
    6 rad/s (~350 deg/s) and 50-100 rad/s^2 (Winter, Biomechanics and Motor Control of Human Movement,
    4th ed., 2009, ch. 4); their drives (brushless motor + harmonic drive, ratio of the order of 100)
    reach the order of 3-5 rad/s at the joint. We take the order's lower end: hip 3 rad/s (172 deg/s),
    knee 4 rad/s (229 deg/s), both under 300 deg/s, and 15 / 20 rad/s^2. Set your device's own.

    Read by the NumPy timing code only: every field is a Python-side setting, never a pytree leaf."""

    # Bounds: a drive slower than 0.1 rad/s (6 deg/s) or 0.1 rad/s^2 cannot swing a leg within a
    # minute; 50 rad/s and 1000 rad/s^2 are beyond any joint drive.
    joint_velocity: tuple[float, float] = declare((3.0, 4.0), vector(2, positive=True, lo=0.1, hi=50.0),
                                                  unit="rad/s", role="setting")          # (hip, knee)
    joint_acceleration: tuple[float, float] = declare((15.0, 20.0), vector(2, positive=True, lo=0.1, hi=1000.0),
                                                      unit="rad/s^2", role="setting")      # (hip, knee)
    # a swing never takes less (0: as fast as the limits allow); at most MAX_SWING_DURATION
    min_swing_duration: float = declare(0.0, number(nonneg=True, hi=MAX_SWING_DURATION), unit="s", role="setting")
    # default rate of timed exports (jaxexo generate --rate); at most MAX_CONTROL_RATE
    control_rate: float = declare(100.0, number(positive=True, hi=MAX_CONTROL_RATE), unit="Hz", role="setting")


def _penalty(default):
    """A penalty or reward magnitude of eq 2.29-2.52 (>= 0)."""
    return declare(default, number(nonneg=True))


@dataclass(frozen=True)
class RewardConfig:
    # Weights alpha (eq 2.38) over TRAJECTORY_TERMS and beta (eq 2.52) over EXO_TERMS, normalised.
    traj_weights: tuple[float, ...] = declare((0.0, 2.0, 0.5, 4.0, 0.5, 0.5, 1.0, 0.5), vector(8, nonneg=True),
                                              to_param=_normalized("traj_weights"))
    exo_weights: tuple[float, ...] = declare((1.0, 1.0, 2.0, 1.0), vector(4, nonneg=True),
                                             to_param=_normalized("exo_weights"))
    step_threshold: float = declare(30.0, number(positive=True), unit="steps")   # n of eq 2.29
    collision_penalty: float = _penalty(10.0)      # c, eq 2.30
    backward_penalty: float = _penalty(1.0)        # y, eq 2.31
    goal_reward: float = _penalty(20.0)            # g, eq 2.32
    mid_goal_penalty: float = _penalty(1.0)        # m, eq 2.33
    max_height_penalty: float = _penalty(1.0)      # z, eq 2.34
    safety_penalty: float = _penalty(2.0)          # f, eq 2.35
    safety_distance: float = declare(0.03, number(positive=True), unit="m")     # min_dt, eq 2.35
    z_monotone_penalty: float = _penalty(0.5)      # k, eq 2.36
    hlc_penalty: float = _penalty(1.0)             # o, eq 2.43
    # hlc, eq 2.43 (fraction of the leg length)
    hlc_threshold: float = declare(0.90, fraction(positive=True))
    leg_length_penalty: float = _penalty(1.0)      # l, eq 2.45
    leg_length_tolerance: float = declare(0.0, number(nonneg=True), unit="m")   # n, eq 2.45
    joint_limit_penalty: float = _penalty(4.0)     # j, eq 2.50
    hip_height_penalty: float = _penalty(1.0)      # n, eq 2.51
    # max_hz, eq 2.51 (the hip model never exceeds thigh+shin)
    max_hip_z: float = declare(1.0, number(positive=True), unit="m")
    # Potential-based progress shaping per metre (not in the thesis; 0 = thesis reward), see
    # jaxexo.physics.rewards.shaping_reward for the choice of its discount.
    progress_shaping: float = declare(5.0, number(nonneg=True), unit="1/m")
    shaping_discount: float = declare(1.0, fraction(positive=True))
    # The wearer's costs (not in the thesis, jaxexo.physics.rewards.wearer_terms; 0 = thesis reward):
    # per metre of heel height above the obstacle's top plus env.shield_clearance, per step (a low
    # swing), and per second the joint drives need for each move at [device] joint_velocity (a quick,
    # straight swing). The velocities enter the environment as ``joint_speed`` (hip, knee, hip, knee).
    lift_cost: float = declare(10.0, number(nonneg=True, hi=1e3), unit="1/m")
    time_cost: float = declare(2.0, number(nonneg=True, hi=1e3), unit="1/s", to_param=lambda v, cfg: {
        "time_cost": np.asarray(v, dtype=np.float32),
        "joint_speed": np.asarray(tuple(cfg.device.joint_velocity) * 2, dtype=np.float32)})
    # per unit of a move's change of direction, 1 - cos of its angle to the last move (a path without
    # corners: quicker at the device, and smoothed without cutting towards the obstacle; 0 = thesis)
    turn_cost: float = declare(2.0, number(nonneg=True, hi=1e3))


@dataclass(frozen=True)
class ObstacleSpec:
    """One entry of the layout's obstacle mixture.

    ``kind`` is a thesis obstacle (base1, base2, base3, triangle, half_circle: the fixed size of thesis
    Table 3.1) or a shape (rectangle, triangle, half_ellipse, profile) with ``width`` and ``height``
    ranges [lo, hi] in m. The name "triangle" is both: without a size it is the thesis triangle, with
    ``width`` and ``height`` the shape (the thesis triangle is the shape at 0.20 x 0.20 m, so both
    readings of an equal spec agree). A ``profile`` takes ``points`` (y, z), y relative to the
    obstacle centre, and is scaled to ``width`` and ``height`` ranges in metres (default: its own
    extents, as drawn)."""

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

    @property
    def is_thesis(self) -> bool:
        """Exactly a thesis obstacle of Table 3.1 (written as its name alone)."""
        return self.kind in THESIS_OBSTACLES and self == named_spec(self.kind, self.weight)

    def to_toml(self) -> dict:
        """The TOML table that ``parse_obstacle`` reads back to this spec."""
        if self.is_thesis:
            return {"kind": self.kind, "weight": self.weight}
        d = {"kind": self.kind, "weight": self.weight, "width": list(self.width), "height": list(self.height)}
        if self.kind == "profile":
            d["points"] = [list(p) for p in self.points]
        return d


def named_spec(kind: str, weight: float = 1.0) -> ObstacleSpec:
    shape, w, h = THESIS_OBSTACLES[kind]
    return ObstacleSpec(kind, (w, w), (h, h), weight, shape)


def parse_obstacle(path: str, raw: Any) -> ObstacleSpec:
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
    sized = any(k in raw for k in ("width", "height", "points"))
    if kind in THESIS_OBSTACLES and not sized:
        return named_spec(kind, weight)
    shapes = geometry.SHAPES
    if kind in THESIS_OBSTACLES and kind not in shapes:
        k = next(k for k in ("width", "height", "points") if k in raw)
        raise ConfigError(f"{path}.{k}: {kind} has the fixed size of thesis Table 3.1; "
                          f"use kind = \"{THESIS_OBSTACLES[kind][0]}\" for other sizes")
    if kind not in shapes:
        raise ConfigError(f"{path}.kind: must be a thesis obstacle {sorted(THESIS_OBSTACLES)} "
                          f"or a shape {list(shapes)}, got {kind!r}")
    if kind != "profile":
        if "points" in raw:
            raise ConfigError(f"{path}.points: only kind = \"profile\" takes points")
        for k in ("width", "height"):
            if k not in raw:
                raise ConfigError(f"{path}.{k}: required for kind = \"{kind}\" (a range [lo, hi] in m)")
        width = _range(f"{path}.width", raw["width"], positive=True)
        height = _range(f"{path}.height", raw["height"], positive=True)
        return ObstacleSpec(kind, width, height, weight, kind)
    if "points" not in raw:
        raise ConfigError(f"{path}.points: required for kind = \"profile\"")
    pts = raw["points"]
    if not isinstance(pts, (list, tuple)) or not all(isinstance(p, (list, tuple)) for p in pts):
        raise ConfigError(f"{path}.points: expected a list of [y, z] pairs in m, got {pts!r}")
    points = tuple(_vector(f"{path}.points[{i}]", p, 2) for i, p in enumerate(pts))
    try:
        ob = geometry.Obstacle.profile(points)
    except geometry.GeometryError as e:
        raise ConfigError(f"{path}.points: {e}") from None
    width = _range(f"{path}.width", raw.get("width", [ob.width, ob.width]), positive=True)
    height = _range(f"{path}.height", raw.get("height", [ob.height, ob.height]), positive=True)
    return ObstacleSpec(kind, width, height, weight, kind, points)


def parse_obstacles(path: str, v: Any) -> tuple[ObstacleSpec, ...]:
    if not isinstance(v, (list, tuple)) or not v:
        raise ConfigError(f"{path}: expected a non-empty list of obstacles")
    return tuple(o if isinstance(o, ObstacleSpec) else parse_obstacle(f"{path}[{i}]", o) for i, o in enumerate(v))


def obstacle_params(obstacles: tuple[ObstacleSpec, ...], cfg) -> dict[str, np.ndarray]:
    """The layout's obstacle mixture as EnvParams leaves: padded unit outlines (B, K, 2), shape
    descriptors (B, P), the kinds' cumulative probabilities and their size ranges (m)."""
    outlines = np.stack([geometry.pad_outline(o.unit_vertices(), cfg.outline_vertices) for o in obstacles])
    shapes = np.stack([geometry.shape_descriptor(u, cfg.env.shape_points) for u in outlines])
    f = lambda x: np.asarray(x, dtype=np.float32)  # noqa: E731
    return {"kind_outlines": f(outlines), "kind_shape": f(shapes), "kind_cdf": _cdf([o.weight for o in obstacles]),
            "kind_width": f([o.width for o in obstacles]), "kind_height": f([o.height for o in obstacles])}


def default_obstacles() -> tuple[ObstacleSpec, ...]:
    """Obstacle mixture of the default model (configs/default.toml): Base 1-3 and random rectangles
    up to 22 cm wide and 28 cm high (triangle and half-circle are held out for testing). With the
    default terrain it sets the thesis-five test set only; reset draws the terrain families."""
    return tuple(named_spec(k) for k in ("base1", "base2", "base3")) + (
        ObstacleSpec("rectangle", (0.05, 0.22), (0.05, 0.28), 1.0, "rectangle"),
        ObstacleSpec("rectangle", (0.15, 0.22), (0.18, 0.28), 1.0, "rectangle"),
    )


# [layout] terrain of the default model (configs/default.toml); the other TerrainSpec fields keep
# jaxexo.physics.terrain's defaults.
DEFAULT_TERRAIN = {"start_shift": [0.0, 0.12], "step_length": [0.55, 0.85]}


TERRAIN_KEYS = ("families", "weights", "start_shift", "step_length", "pivot", "near_margin", "far_margin")


def parse_terrain(path: str, v: Any) -> "terrain.TerrainSpec | None":
    """[layout] terrain: ``false`` (off: reset draws the obstacle mixture) or a table of
    jaxexo.physics.terrain.TerrainSpec fields (families by name, weights, start_shift and step_length
    ranges in m, pivot weights, near/far margins in m): reset then draws a procedural obstacle
    family, its outline and its placement instead of the mixture. Held-out families are refused."""
    if v is None or v is False:
        return None
    if isinstance(v, terrain.TerrainSpec):
        return v
    if v is True:
        v = {}
    if not isinstance(v, dict):
        raise ConfigError(f"{path}: expected false or a table of {', '.join(TERRAIN_KEYS)}, got {v!r}")
    unknown = sorted(set(v) - set(TERRAIN_KEYS))
    if unknown:
        raise ConfigError(f"{path}.{unknown[0]}: unknown field (known: {', '.join(TERRAIN_KEYS)})")
    kw = dict(v)
    if "families" in kw:
        f = kw["families"]
        if isinstance(f, str):
            f = [f]
        if not isinstance(f, (list, tuple)) or not all(isinstance(x, str) for x in f):
            raise ConfigError(f"{path}.families: expected a list of family names, got {f!r}")
        kw["families"] = tuple(f)
    if "weights" in kw:
        kw["weights"] = _vector(f"{path}.weights", kw["weights"], nonneg=True)
    if "pivot" in kw:
        kw["pivot"] = pivot_weights(f"{path}.pivot", kw["pivot"])
    for k in ("start_shift", "step_length"):
        if k in kw:
            kw[k] = _range(f"{path}.{k}", kw[k], nonneg=True)
    for k in ("near_margin", "far_margin"):
        if k in kw:
            kw[k] = _number(f"{path}.{k}", kw[k], positive=True)
    try:
        return terrain.TerrainSpec(**kw, path=path)
    except terrain.TerrainError as e:
        raise ConfigError(str(e)) from None


def write_terrain(spec) -> Any:
    if spec is None:
        return False
    return {"families": list(spec.families), "weights": list(spec.weights), "start_shift": list(spec.start_shift),
            "step_length": list(spec.step_length), "pivot": list(spec.pivot), "near_margin": spec.near_margin,
            "far_margin": spec.far_margin}


def terrain_params(spec, cfg) -> dict[str, np.ndarray]:
    """The terrain description as EnvParams leaves. Off: ``terrain_ids`` has length 0, which
    jaxexo.physics.scenarios reads as a static (shape) switch back to the obstacle mixture."""
    f = lambda x: np.asarray(x, dtype=np.float32)  # noqa: E731
    if spec is None:
        return {"terrain_ids": np.zeros((0,), np.int32), "terrain_cdf": f(np.zeros((0,))),
                "terrain_start_shift": f([0.0, 0.0]), "terrain_step_length": f([0.0, 0.0]),
                "terrain_pivot_cdf": _cdf([1.0, 1.0, 1.0]), "terrain_margins": f([0.0, 0.0])}
    return {"terrain_ids": spec.ids.astype(np.int32), "terrain_cdf": f(spec.cdf),
            "terrain_start_shift": f(spec.start_shift), "terrain_step_length": f(spec.step_length),
            "terrain_pivot_cdf": _cdf(spec.pivot), "terrain_margins": f([spec.near_margin, spec.far_margin])}


@dataclass(frozen=True)
class LayoutConfig:
    # The obstacle mixture; an empty tuple (the dataclass default) means default_obstacles().
    obstacles: tuple[ObstacleSpec, ...] = declare((), parse_obstacles, to_param=obstacle_params,
                                                 write=lambda obs: [o.to_toml() for o in obs])
    size_jitter: float = declare(0.0, below_one)   # relative +- jitter of every width and height
    obstacle_offset: tuple[float, float] = declare((-0.03, 0.03), range_(), unit="m")  # added to the default centre
    # weights of PIVOT_CONDITIONS
    pivot: tuple[float, float, float] = declare((1.0, 1.0, 1.0), pivot_weights,
                                                to_param=lambda v, cfg: {"pivot_cdf": _cdf(v)})
    start_shift: tuple[float, float] = declare((0.0, 0.05), range_(), unit="m")   # agent start moved towards the obstacle
    step_length: tuple[float, float] = declare((0.65, 0.75), range_(positive=True), unit="m")  # goal = start + this
    # Procedural obstacle families (jaxexo.physics.terrain): false, or a table (parse_terrain) that
    # replaces the obstacle mixture, start_shift, step_length, obstacle_offset and pivot in reset.
    terrain: Any = declare(check=parse_terrain, to_param=terrain_params, write=write_terrain,
                           default_factory=lambda: parse_terrain("layout.terrain", DEFAULT_TERRAIN))

    def default_center(self, foot_length: float, step_length: float) -> float:
        """Default obstacle centre (jaxexo.physics.geometry.default_center, the one definition)."""
        return geometry.default_center(foot_length, step_length)


@dataclass(frozen=True)
class TrainConfig:
    """[train]: the TD(lambda) agent (thesis 2.3-2.4).

    Static settings fix the compiled program's shapes and structure; the leaves are the vmappable
    fields of ``jaxexo.train.Hyperparams`` (sweeps). The budgets are leaves too, but the number of
    updates they need (num_updates) is static: it is the length of the scan."""

    num_envs: int = declare(1024, number(positive=True, integer=True, hi=2**24), unit="envs", role="static")
    # T: steps per environment between updates
    rollout_steps: int = declare(16, number(positive=True, integer=True, hi=100_000), unit="steps", role="static")
    # forward view: gradient steps per epoch over the T x N batch
    num_minibatches: int = declare(4, number(positive=True, integer=True, hi=2**24), role="static")
    num_epochs: int = declare(1, number(positive=True, integer=True, hi=10_000), role="static")
    # the thesis network (Fig. 2.2)
    hidden: tuple[int, ...] = declare((128, 128), vector(positive=True, integer=True, hi=65_536, max_len=64),
                                      unit="units", role="static")
    layer_norm: bool = declare(True, boolean, role="static")
    # "forward": lambda-returns; "backward": eligibility traces
    trace: str = declare("forward", choice(TRACE_VIEWS), role="static")
    # backward view: "accumulating" or "replacing"
    trace_kind: str = declare("accumulating", choice(TRACE_KINDS), role="static")
    # "off_policy": Watkins Q(lambda) (eq 2.13, 2.28); "on_policy": SARSA(lambda) (eq 2.14, 2.27)
    control: str = declare("off_policy", choice(CONTROLS), role="static")
    # "hard": copy every target_period updates; "polyak": tau
    target: str = declare("hard", choice(TARGETS), role="static")
    # stop after this many finished episodes (0: no limit)
    budget_episodes: int = declare(0, number(nonneg=True, integer=True, hi=INT32_MAX), unit="episodes")
    # stop after this many env steps (0: no limit)
    budget_env_steps: int = declare(5_000_000, number(nonneg=True, integer=True, hi=2**40), unit="steps")
    # updates per compiled chunk (progress, checkpoint); 0: auto
    chunk_updates: int = declare(0, number(nonneg=True, integer=True, hi=INT32_MAX), unit="updates", role="setting")
    # Agents of this config trained together as one compiled program (seeds seed .. seed + K - 1), the best
    # on validation exported (jaxexo.train.population); 1: one agent, the data-parallel driver. Bounded
    # here only loosely: the memory estimate (jaxexo.config.memory.check_memory) is the real limit.
    population: int = declare(1, number(positive=True, integer=True, hi=4096), unit="agents", role="setting")
    eval_episodes: int = declare(1000, number(positive=True, integer=True, hi=10_000_000), unit="episodes",
                                 role="static")
    lr: float = declare(3e-4, number(positive=True))
    # linear decay of the learning rate to lr * this at the budget's end
    lr_end_fraction: float = declare(0.1, fraction())
    gamma: float = declare(0.98, fraction())
    lam: float = declare(0.9, fraction())
    eps_start: float = declare(1.0, fraction())
    eps_end: float = declare(0.02, fraction())
    eps_decay_fraction: float = declare(0.5, fraction(positive=True))   # of the budget, linear
    # "hard" target copies every this many updates (int32 in the program)
    target_period: int = declare(10, number(positive=True, integer=True, hi=INT32_MAX), unit="updates", dtype="int32")
    target_tau: float = declare(0.05, fraction(positive=True))          # "polyak"
    max_grad_norm: float = declare(10.0, number(positive=True))


# TrainConfig fields that are leaves of jaxexo.train.Hyperparams (vmappable), in declaration order.
HYPER_FIELDS = tuple(name for name, s in declared_fields(TrainConfig) if s.leaf)
# EnvParams come from the leaves of these sections (jaxexo.config.views.param_values).
ENV_SECTIONS = ("env", "kinematics", "reward", "layout")


@dataclass(frozen=True)
class Config:
    """The whole configuration. ``outline_vertices`` is the resolved fixed outline size K."""

    env: EnvConfig = field(default_factory=EnvConfig)
    kinematics: KinematicsConfig = field(default_factory=KinematicsConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    layout: LayoutConfig = field(default_factory=lambda: LayoutConfig(obstacles=default_obstacles()))
    train: TrainConfig = field(default_factory=TrainConfig)
    device: DeviceConfig = field(default_factory=DeviceConfig)

    @property
    def outline_vertices(self) -> int:
        return self.env.max_vertices or _vertices_needed(self.layout)


def _vertices_needed(lay: LayoutConfig) -> int:
    need = max(len(o.unit_vertices()) for o in lay.obstacles)
    return max(need, terrain.K_MAX) if lay.terrain is not None else need


SECTION_CLASSES = {"env": EnvConfig, "kinematics": KinematicsConfig, "reward": RewardConfig,
                   "layout": LayoutConfig, "train": TrainConfig, "device": DeviceConfig}


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


def with_population(cfg: Config, k, where: str = "train.population") -> Config:
    """``cfg`` with ``[train] population = k``, checked by the field's declaration (the error names
    ``where``, e.g. the command-line option that gave it)."""
    check = dict(declared_fields(TrainConfig))["population"].check
    return dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, population=check(where, k)))


def static_settings(cfg: Config) -> tuple:
    """Everything about a config that fixes the compiled trainer (and its greedy evaluation): the
    fields declared static, the resolved outline size, the number of obstacle kinds and the scan
    length. Configs with equal static settings differ only in pytree leaves (jaxexo.train.Hyperparams,
    EnvParams) and can be vmapped together as one program."""
    out = []
    for section in SECTIONS:
        for name, s in declared_fields(SECTION_CLASSES[section]):
            if s.static:
                out.append((f"{section}.{name}", getattr(getattr(cfg, section), name)))
    return tuple(out) + (("outline_vertices", cfg.outline_vertices), ("obstacle_kinds", len(cfg.layout.obstacles)),
                         ("terrain_families", () if cfg.layout.terrain is None else cfg.layout.terrain.families),
                         ("num_updates", num_updates(cfg)))


def to_toml_values(section_obj) -> list[tuple[str, Any]]:
    """(name, TOML-writable value) for every field of a section, by its declaration."""
    out = []
    for f in fields(section_obj):
        s, v = spec_of(f), getattr(section_obj, f.name)
        out.append((f.name, s.write(v) if s.write else v))
    return out


# --------------------------------------------------------------------------------------------
# Parsing
# --------------------------------------------------------------------------------------------


def _section(cls, path: str, raw: Any) -> Any:
    if not isinstance(raw, dict):
        raise ConfigError(f"{path}: expected a table, got {raw!r}")
    specs = dict(declared_fields(cls))
    unknown = sorted(set(raw) - set(specs))
    if unknown:
        raise ConfigError(f"{path}.{unknown[0]}: unknown field (known: {', '.join(sorted(specs))})")
    return cls(**{k: specs[k].check(f"{path}.{k}", v) for k, v in raw.items()})


def config_from_dict(raw: dict) -> Config:
    """Build and validate a Config from a parsed TOML table."""
    if not isinstance(raw, dict):
        raise ConfigError(f"config: expected a table, got {raw!r}")
    for name in raw:
        if name in OTHER_COMMANDS:
            raise ConfigError(f"{name}: a [{name}] section does not belong in a train config; "
                              f"{OTHER_COMMANDS[name]}")
    unknown = sorted(set(raw) - set(SECTIONS))
    if unknown:
        raise ConfigError(f"{unknown[0]}: unknown section (known: {', '.join(sorted(SECTIONS))})")
    parts = {s: _section(SECTION_CLASSES[s], s, raw.get(s, {})) for s in SECTIONS}
    if not parts["layout"].obstacles:
        parts["layout"] = dataclasses.replace(parts["layout"], obstacles=default_obstacles())
    cfg = Config(**parts)
    validate(cfg)
    return cfg


def load_config(path: str | Path) -> Config:
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise ConfigError(f"{path}: cannot read config ({e.strerror})") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ConfigError(f"{path}: not UTF-8 text (byte {e.start}: {data[e.start:e.start + 1]!r}); "
                          "TOML files are UTF-8") from None
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML ({e})") from None
    try:
        return config_from_dict(raw)
    except ConfigError as e:
        raise ConfigError(f"{path}: {e}") from None


def packaged_config(name: str = "default") -> Path:
    """A config shipped inside the package: "default" (jaxexo/config/default.toml) or "thesis/<model>"
    (jaxexo/config/thesis/<model>.toml). The same file however jaxexo is installed; the repository's
    configs/ holds byte-equal copies (tests/test_config_roundtrip.py)."""
    path = Path(__file__).resolve().parent / f"{name}.toml"
    if not path.is_file():
        raise ConfigError(f"{name}: no packaged config {path}")
    return path


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
    if num_updates(cfg) > INT32_MAX:
        which = "budget_env_steps" if tr.budget_env_steps else "budget_episodes"
        raise ConfigError(f"train.{which}: needs {num_updates(cfg)} updates of train.num_envs x "
                          f"train.rollout_steps env steps, more than a scan can count ({INT32_MAX})")
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
    if lay.terrain is not None:
        _check_terrain(cfg)
    j = lay.size_jitter
    for i, ob in enumerate(lay.obstacles):
        p = f"layout.obstacles[{i}]"
        if ob.weight <= 0:
            continue
        w_min, w_max = ob.width[0] * (1 - j), ob.width[1] * (1 + j)
        h_min, h_max = ob.height[0] * (1 - j), ob.height[1] * (1 + j)
        if env.step_size >= min(w_min, h_min):
            field_ = "width" if w_min <= h_min else "height"
            smallest = min(w_min, h_min)
            if j > 0 and env.step_size < min(ob.width[0], ob.height[0]):
                # The obstacle itself is large enough: the jitter shrinks it below a step.
                raise ConfigError(
                    f"layout.size_jitter: {j} shrinks {p}.{field_} to {smallest:.3f} m, not larger than "
                    f"env.step_size = {env.step_size} m: a step could jump through the obstacle")
            raise ConfigError(
                f"env.step_size: {env.step_size} m is not smaller than {p}.{field_} "
                f"(smallest {smallest:.3f} m): a step could jump through the obstacle")
        _check_room(cfg, p, w_max)
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
    if env.shield and env.shield_clearance < env.min_clearance:
        raise ConfigError(f"env.shield_clearance: {env.shield_clearance} m is below env.min_clearance = "
                          f"{env.min_clearance} m; the shield must keep at least the margin that a safe swing needs")
    if rew.safety_distance < env.min_clearance:
        raise ConfigError(f"reward.safety_distance: {rew.safety_distance} m is below env.min_clearance = "
                          f"{env.min_clearance} m; the safety term (eq 2.35) must pay the policy to keep the "
                          "margin that a safe swing needs, not only to avoid contact")
    if env.max_steps < rew.step_threshold:
        raise ConfigError(f"env.max_steps: {env.max_steps} is below reward.step_threshold = {rew.step_threshold}")


def _check_terrain(cfg: Config) -> None:
    """A terrain spec must fit the env: outlines of terrain.K_MAX vertices, obstacles larger than a
    step, the mid-goal over the tallest below env.max_z, the goal inside env.bounds_y, and every
    family clearable at every placement extreme and pivot (TerrainSpec.check)."""
    env, kin, t = cfg.env, cfg.kinematics, cfg.layout.terrain
    if env.max_vertices and env.max_vertices < terrain.K_MAX:
        raise ConfigError(f"env.max_vertices: {env.max_vertices} is fewer than the {terrain.K_MAX} outline vertices "
                          "of layout.terrain's families (0 picks the size automatically)")
    if env.step_size >= t.min_size:
        raise ConfigError(f"env.step_size: {env.step_size} m is not smaller than the smallest width or height "
                          f"of layout.terrain.families ({t.min_size:.3f} m): a step could jump through the obstacle")
    if t.max_height + env.mid_goal_clearance + env.mid_goal_half_size[1] >= env.max_z:
        raise ConfigError(f"layout.terrain.families: obstacles up to {t.max_height:.3f} m put the mid-goal above "
                          f"env.max_z = {env.max_z} m")
    goal_far = t.start_shift[1] + t.step_length[1] + env.goal_tolerance[0]
    if env.bounds_y[1] <= goal_far:
        raise ConfigError(f"env.bounds_y: the upper bound must lie beyond layout.terrain's goal region ({goal_far:.3f} m)")
    try:
        t.check(foot_length=kin.foot_length, thigh=kin.thigh, shin=kin.shin, hip_limits=kin.hip_limits,
                knee_limits=kin.knee_limits, heel_lift=env.mid_goal_clearance - env.mid_goal_half_size[1],
                goal_tolerance=env.goal_tolerance[0])
    except terrain.TerrainError as e:
        raise ConfigError(str(e)) from None


def _check_room(cfg: Config, p: str, w_max: float) -> None:
    """The obstacle must lie between the toe at the start and the goal for every start shift, step
    length and offset that reset can draw. The error names the field at fault: the step length when
    the obstacle does not fit even without a shift or offset, else the shift or the offset."""
    env, kin, lay = cfg.env, cfg.kinematics, cfg.layout
    s_lo, s_hi = lay.start_shift
    o_lo, o_hi = lay.obstacle_offset
    fl, tol = kin.foot_length, env.goal_tolerance[0]

    def near_ok(L, shift, off):   # the obstacle's near edge lies ahead of the toe at the start
        return lay.default_center(fl, L) + off - 0.5 * w_max > shift + fl

    def far_ok(L, shift, off):    # the goal lies beyond the obstacle's far edge
        return lay.default_center(fl, L) + off + 0.5 * w_max < shift + L - tol

    for L in lay.step_length:
        if not near_ok(L, 0.0, 0.0):
            raise ConfigError(
                f"layout.step_length: {L} m is too short for {p} (up to {w_max:.3f} m wide): centred in the gap, "
                f"it reaches back to the toe at the start ({fl:.3f} m); the step must be longer than the foot "
                "length plus the obstacle's width; use a longer step or a narrower obstacle")
        if not far_ok(L, 0.0, 0.0):
            raise ConfigError(
                f"layout.step_length: the goal at {L:.3f} m is not beyond {p} (its far edge reaches "
                f"{lay.default_center(fl, L) + 0.5 * w_max:.3f} m); the goal must lie ahead of the obstacle")
        if not near_ok(L, 0.0, o_lo) or not far_ok(L, 0.0, o_hi):
            side = o_lo if not near_ok(L, 0.0, o_lo) else o_hi
            raise ConfigError(
                f"layout.obstacle_offset: {side} m moves {p} (up to {w_max:.3f} m wide, step length {L} m) "
                "onto the foot at the start or past the goal; reduce the offset or the width")
        if not near_ok(L, s_hi, o_lo):
            raise ConfigError(
                f"layout.start_shift: with {p} up to {w_max:.3f} m wide, step length {L} m and "
                f"offset {o_lo} m, the obstacle reaches back to the toe at the "
                f"start (y = {s_hi + fl:.3f} m); reduce start_shift, obstacle_offset or the width")
        if not far_ok(L, s_lo, o_hi):
            goal = s_lo + L
            raise ConfigError(
                f"layout.step_length: the goal at {goal:.3f} m is not beyond {p} (its far edge "
                f"reaches {lay.default_center(fl, L) + o_hi + 0.5 * w_max:.3f} m); the goal must lie ahead of the obstacle")


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
        pivots = {name: float(kinematics.pivot_position(np, i, start, center)) for i, name in enumerate(PIVOT_CONDITIONS)}
        heel = np.array([center, heel_z])
        for name, weight in zip(PIVOT_CONDITIONS, lay.pivot):
            if weight <= 0:
                continue
            if kinematics.swing_heel_unreachable(np, pivots[name], heel, kin.thigh, kin.shin, kin.hip_limits,
                                                 kin.knee_limits):
                raise ConfigError(
                    f"{path}.height: an obstacle {h_max:.3f} m high cannot be cleared with pivot {name!r} "
                    f"(start {start:.3f} m, step length {L:.3f} m): the heel over it at {heel_z:.3f} m is "
                    "out of the leg's reach or joint limits")
