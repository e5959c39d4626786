"""The config's sections as frozen dataclasses, each field declared once
(jaxexo.config.declarations), and the whole ``Config`` with the values derived from it. The
fields: docs/configuration.md. Units: metres, radians, steps. NumPy-only (``import jaxexo`` must not
import JAX).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from jaxexo.config.changes import ChangeSpec, change_params, parse_change, write_change
from jaxexo.config.checks import (
    ConfigError,
    below_one,
    boolean,
    choice,
    fraction,
    number,
    pivot_weights,
    range_,
    vector,
)
from jaxexo.config.declarations import declare, declared_fields, spec_of
from jaxexo.config.obstacles import (
    DEFAULT_TERRAIN,
    MAX_SHIFT,
    MAX_STEP_LENGTH,
    ObstacleSpec,
    cdf,
    default_obstacles,
    obstacle_params,
    parse_obstacles,
    parse_terrain,
    terrain_params,
    write_terrain,
)
from jaxexo.physics import geometry, outcome, rewards, terrain
from jaxexo.physics.scene import MAX_CLEARANCE

OBS_MODES = ("thesis", "conditioned")
OBS_PROFILES = ("bbox", "shape")
COLLISION_MODES = ("penalty", "terminate")
TRACE_VIEWS = ("forward", "backward")
TRACE_KINDS = ("accumulating", "replacing")
CONTROLS = ("off_policy", "on_policy")
TARGETS = ("hard", "polyak")

INT32_MAX = 2**31 - 1  # integers that reach JAX as int32 (or index a scan) stay below this
MAX_CONTROL_RATE = (
    10_000.0  # Hz: a timed export's rate ([device] control_rate, jaxexo generate --rate)
)
MAX_TRACKING_HEADROOM = (
    0.5  # a reference using less than half of each limit is a slower device, not headroom
)
MAX_SWING_DURATION = 60.0  # s: one swing (about 1 s on today's exoskeletons), not a walk
# Hz: the slowest rate of a timed export; a swing sampled more coarsely is not a control signal.
MIN_CONTROL_RATE = 10.0
# Every physical field has a physical bound (docs/reliability.md). Lengths: two segments of at most
# 1 m make a leg of at most MAX_LEG; heights, ceilings and hip heights stay within it.
MAX_LEG = 2.0
# Reward magnitudes and weights (dimensionless): far beyond any useful scale, below float32's reach.
MAX_REWARD_SCALE = 1e6
SECTIONS = ("env", "kinematics", "reward", "layout", "train", "device")


def _normalized(name):
    # eq 2.38 / 2.52: the weights enter the reward normalised to sum 0.5
    return lambda v, cfg: {name: np.asarray(rewards.normalize_weights(v), dtype=np.float32)}


@dataclass(frozen=True)
class EnvConfig:
    # m per action; about 30 steps for a 0.70 m step over 0.2 m
    step_size: float = declare(0.03, number(positive=True, hi=0.1), unit="m")
    # step limit -> truncated; a leaf (EnvParams.max_steps_in_episode) and a static (episode budgets)
    max_steps: int = declare(
        100,
        number(positive=True, integer=True, hi=100_000),
        unit="steps",
        role="static+leaf",
        param="max_steps_in_episode",
        dtype="int32",
    )
    # "penalty" (thesis: pay r1 and continue) or "terminate"
    collision: str = declare(
        "penalty",
        choice(COLLISION_MODES),
        to_param=lambda v, cfg: {"terminate_on_collision": np.asarray(v == "terminate")},
    )
    # "thesis" (heel y, z) or "conditioned"
    obs_mode: str = declare("conditioned", choice(OBS_MODES), role="static")
    # How the conditioned observation shows the obstacle's profile: "bbox" (its bounding rectangle:
    # a policy trained on rectangles treats any unseen shape conservatively) or "shape" (the true
    # profile, for policies trained on varied shapes). Collisions always use the true outline.
    obs_profile: str = declare(
        "shape",
        choice(OBS_PROFILES),
        to_param=lambda v, cfg: {"obs_true_profile": np.asarray(v == "shape")},
    )
    # outline size K; 0: the largest count among the layout's kinds (resolved: Config.outline_vertices)
    max_vertices: int = declare(
        0,
        number(nonneg=True, integer=True, hi=geometry.MAX_PROFILE_VERTICES),
        unit="vertices",
        role="setting",
    )
    shape_points: int = declare(
        geometry.DEFAULT_SHAPE_POINTS,
        number(positive=True, integer=True, hi=1024),
        unit="points",
        role="static",
    )
    # goal box: |heel_y - goal_y| <= [0], heel_z <= [1] (a few mm: the swing ends with the heel on
    # the floor; the thesis's 2 cm ended it in the air)
    goal_tolerance: tuple[float, float] = declare(
        (0.04, 0.005), vector(2, positive=True, hi=0.5), unit="m"
    )
    # mid-goal centre height above the obstacle top
    mid_goal_clearance: float = declare(0.045, number(nonneg=True, hi=0.5), unit="m")
    # half extents (y, z) of the mid-goal box
    mid_goal_half_size: tuple[float, float] = declare(
        (0.06, 0.02), vector(2, positive=True, hi=0.5), unit="m"
    )
    # max_z of eq 2.34 = obstacle top + this
    max_height_margin: float = declare(0.20, number(nonneg=True, hi=MAX_LEG), unit="m")
    bounds_y: tuple[float, float] = declare(
        (-0.30, 1.30), range_(lo=-10.0, hi=10.0), unit="m"
    )  # the heel is kept inside
    # ceiling for the heel; the ground is z = 0
    max_z: float = declare(0.80, number(positive=True, hi=MAX_LEG), unit="m", param="max_z_world")
    # The safe-swing rule's two parameters (docs/safety.md#a-safe-swing-the-trajectory-checks);
    # at most MAX_CLEARANCE, the most a generator may be asked to keep.
    min_clearance: float = declare(
        outcome.DEFAULT_MIN_CLEARANCE, number(nonneg=True, hi=MAX_CLEARANCE), unit="m"
    )
    # At most 10 m: beyond env.bounds_y's span the check is off (the thesis configs write 10 m).
    backward_tolerance: float = declare(
        outcome.DEFAULT_BACKWARD_TOLERANCE, number(nonneg=True, hi=10.0), unit="m"
    )
    # The shield (not in the thesis; off is the thesis's free choice): the agent chooses only among
    # admissible moves (docs/safety.md#the-shield-the-policy-chooses-only-among-safe-moves).
    shield: bool = declare(True, boolean, role="static+leaf", dtype="bool")
    # m: the clearance a shielded move keeps; above min_clearance so that the smoothed curve, which
    # cuts corners, still keeps it (validated); above 10 cm no step over an obstacle is admissible.
    shield_clearance: float = declare(0.025, number(nonneg=True, hi=0.10), unit="m")
    # m: with the shield, a move may end lower than this above the floor only inside the goal box's
    # column, so the heel never skims the floor before the goal (0: off); below env.step_size
    # (validated), so that the first move off the floor can clear it.
    floor_clearance: float = declare(0.02, number(nonneg=True, hi=0.10), unit="m")
    # Training episodes whose obstacle changes at a random step (jaxexo.config.changes): None (0 in a
    # file, off) or a ChangeSpec. Static (on or off is a different program) and leaves (its ranges);
    # left out of a written config when off, so every config written before it reads the same.
    obstacle_change: ChangeSpec | None = declare(
        None,
        parse_change,
        role="static+leaf",
        to_param=change_params,
        write=write_change,
        params_from=(("change_max_height", "layout.terrain"),),
        omit_default=True,
    )


@dataclass(frozen=True)
class KinematicsConfig:
    # Human segments (an adult's thigh or shin is about 0.4-0.55 m, a foot 0.2-0.3 m): at most 1 m each,
    # a foot at most 0.5 m.
    thigh: float = declare(0.50, number(positive=True, hi=1.0), unit="m")
    shin: float = declare(0.50, number(positive=True, hi=1.0), unit="m")
    foot_length: float = declare(0.20, number(positive=True, hi=0.5), unit="m")  # heel-to-toe
    # Joint limits within one turn, [-pi, pi] rad: a hinge has no more.
    hip_limits: tuple[float, float] = declare(
        (-0.5236, 2.0071), range_(lo=-math.pi, hi=math.pi), unit="rad"
    )  # -30 .. 115 deg
    knee_limits: tuple[float, float] = declare(
        (-1.7453, 0.0), range_(lo=-math.pi, hi=math.pi), unit="rad"
    )  # -100 .. 0 deg

    def differing_legs(self, legs: dict) -> list[tuple[str, float, float]]:
        """(field, this value, the value in ``legs``) of each LEG_FIELDS length that differs from
        ``legs`` (field: metres) by more than a micrometre (a file's rounding): a policy's moves, a
        swing's joint angles and its foot's clearance hold only for the legs they were made for."""
        out = [(f, float(getattr(self, f)), float(legs[f])) for f in LEG_FIELDS]
        return [(f, a, b) for f, a, b in out if not abs(a - b) <= 1e-6]

    def check_legs(self, legs: dict, made_for: str, advice: str) -> None:
        """ValueError naming each ``differing_legs`` field with both values: "config: kinematics.thigh
        = 0.45 m, but ``made_for`` kinematics.thigh = 0.5 m; ``advice``"."""
        bad = self.differing_legs(legs)
        if bad:
            raise ValueError(
                "config: "
                + ", ".join(f"kinematics.{f} = {a:g} m" for f, a, _ in bad)
                + f", but {made_for} "
                + ", ".join(f"kinematics.{f} = {b:.6g} m" for f, _, b in bad)
                + f"; {advice}"
            )


# The legs' lengths in [kinematics] (KinematicsConfig.differing_legs).
LEG_FIELDS = ("thigh", "shin", "foot_length")


# The thesis's joint limits to the last bit (the declared defaults above are rounded to 0.1 mrad) as a
# [kinematics] table states them: what the thesis configs hold, for configs stated in full.
THESIS_JOINT_LIMITS = {
    "hip_limits": [math.radians(-30), math.radians(115)],
    "knee_limits": [math.radians(-100), 0.0],
}


@dataclass(frozen=True)
class DeviceConfig:
    """[device]: the exoskeleton's joint drives, for timing swings (jaxexo.swing.timing).

    Limits are per joint kind (hip, knee) and apply to both legs; a swing is timed within
    (1 - tracking_headroom) of each. The defaults are conservative order-of-magnitude figures
    (sources: docs/device-timing.md#limits). Read by the NumPy timing code only: every field is a
    Python-side setting, never a pytree leaf."""

    # Bounds: a drive slower than 0.1 rad/s (6 deg/s) or 0.1 rad/s^2 cannot swing a leg within a
    # minute; 50 rad/s and 1000 rad/s^2 are beyond any joint drive.
    joint_velocity: tuple[float, float] = declare(
        (3.0, 4.0), vector(2, positive=True, lo=0.1, hi=50.0), unit="rad/s", role="setting"
    )  # (hip, knee)
    joint_acceleration: tuple[float, float] = declare(
        (15.0, 20.0), vector(2, positive=True, lo=0.1, hi=1000.0), unit="rad/s^2", role="setting"
    )  # (hip, knee)
    # Jerk bounds how fast the drives' torque may change: at the defaults the full acceleration is
    # reached in 10 ms (docs/device-timing.md#limits); 10 rad/s^3 to 1e5 rad/s^3.
    joint_jerk: tuple[float, float] = declare(
        (1500.0, 2000.0), vector(2, positive=True, lo=10.0, hi=1e5), unit="rad/s^3", role="setting"
    )  # (hip, knee)
    # Fraction of each limit the timed reference leaves to the feedback controller, so that a drive
    # correcting a tracking error is not already at its limit (docs/device-timing.md#limits).
    tracking_headroom: float = declare(
        0.05, number(nonneg=True, hi=MAX_TRACKING_HEADROOM), role="setting"
    )
    # a swing never takes less (0: as fast as the limits allow); at most MAX_SWING_DURATION
    min_swing_duration: float = declare(
        0.0, number(nonneg=True, hi=MAX_SWING_DURATION), unit="s", role="setting"
    )
    # default rate of timed exports (jaxexo generate --rate); at most MAX_CONTROL_RATE
    control_rate: float = declare(
        100.0,
        number(positive=True, lo=MIN_CONTROL_RATE, hi=MAX_CONTROL_RATE),
        unit="Hz",
        role="setting",
    )


def _penalty(default):
    """A penalty or reward magnitude of eq 2.29-2.52 (>= 0, at most MAX_REWARD_SCALE)."""
    return declare(default, number(nonneg=True, hi=MAX_REWARD_SCALE))


# Every term of eq 2.38 and of eq 2.52 weighted alike, as a [reward] table states it.
EQUAL_WEIGHTS = {"traj_weights": [1.0] * 8, "exo_weights": [1.0] * 4}


@dataclass(frozen=True)
class RewardConfig:
    # Weights alpha (eq 2.38) over TRAJECTORY_TERMS and beta (eq 2.52) over EXO_TERMS, normalised.
    traj_weights: tuple[float, ...] = declare(
        (0.0, 2.0, 0.5, 4.0, 0.5, 0.5, 1.0, 0.5),
        vector(8, nonneg=True, hi=MAX_REWARD_SCALE),
        to_param=_normalized("traj_weights"),
    )
    exo_weights: tuple[float, ...] = declare(
        (1.0, 1.0, 2.0, 1.0),
        vector(4, nonneg=True, hi=MAX_REWARD_SCALE),
        to_param=_normalized("exo_weights"),
    )
    step_threshold: float = declare(
        30.0, number(positive=True, hi=100_000), unit="steps"
    )  # n of eq 2.29
    collision_penalty: float = _penalty(10.0)  # c, eq 2.30
    backward_penalty: float = _penalty(1.0)  # y, eq 2.31
    goal_reward: float = _penalty(20.0)  # g, eq 2.32
    mid_goal_penalty: float = _penalty(1.0)  # m, eq 2.33
    max_height_penalty: float = _penalty(1.0)  # z, eq 2.34
    safety_penalty: float = _penalty(2.0)  # f, eq 2.35
    safety_distance: float = declare(
        0.03, number(positive=True, hi=0.5), unit="m"
    )  # min_dt, eq 2.35
    z_monotone_penalty: float = _penalty(0.5)  # k, eq 2.36
    hlc_penalty: float = _penalty(1.0)  # o, eq 2.43
    # hlc, eq 2.43 (fraction of the leg length)
    hlc_threshold: float = declare(0.90, fraction(positive=True))
    leg_length_penalty: float = _penalty(1.0)  # l, eq 2.45
    leg_length_tolerance: float = declare(
        0.0, number(nonneg=True, hi=MAX_LEG), unit="m"
    )  # n, eq 2.45
    joint_limit_penalty: float = _penalty(4.0)  # j, eq 2.50
    hip_height_penalty: float = _penalty(1.0)  # n, eq 2.51
    # max_hz, eq 2.51 (the hip model never exceeds thigh+shin)
    max_hip_z: float = declare(1.0, number(positive=True, hi=MAX_LEG), unit="m")
    # Potential-based progress shaping per metre (not in the thesis; 0 = thesis reward), see
    # jaxexo.physics.rewards.shaping_reward for the choice of its discount.
    progress_shaping: float = declare(5.0, number(nonneg=True, hi=1e3), unit="1/m")
    shaping_discount: float = declare(1.0, fraction(positive=True))
    # The wearer's costs (not in the thesis; 0 = thesis reward; docs/configuration.md#reward); the
    # [device] joint velocities enter the environment as ``joint_speed`` (hip, knee, hip, knee).
    lift_cost: float = declare(10.0, number(nonneg=True, hi=1e3), unit="1/m")
    time_cost: float = declare(
        2.0,
        number(nonneg=True, hi=1e3),
        unit="1/s",
        to_param=lambda v, cfg: {
            "time_cost": np.asarray(v, dtype=np.float32),
            "joint_speed": np.asarray(tuple(cfg.device.joint_velocity) * 2, dtype=np.float32),
        },
        params_from=(("joint_speed", "device.joint_velocity"),),
    )
    # per unit of a move's change of direction, 1 - cos of its angle to the last move (a path without
    # corners: quicker at the device, and smoothed without cutting towards the obstacle; 0 = thesis)
    turn_cost: float = declare(2.0, number(nonneg=True, hi=1e3))


@dataclass(frozen=True)
class LayoutConfig:
    # The obstacle mixture; an empty tuple (the dataclass default) means default_obstacles().
    obstacles: tuple[ObstacleSpec, ...] = declare(
        (), parse_obstacles, to_param=obstacle_params, write=lambda obs: [o.to_toml() for o in obs]
    )
    size_jitter: float = declare(0.0, below_one)  # relative +- jitter of every width and height
    obstacle_offset: tuple[float, float] = declare(
        (-0.03, 0.03), range_(lo=-MAX_SHIFT, hi=MAX_SHIFT), unit="m"
    )  # added to the default centre
    # weights of PIVOT_CONDITIONS
    pivot: tuple[float, float, float] = declare(
        (1.0, 1.0, 1.0), pivot_weights, to_param=lambda v, cfg: {"pivot_cdf": cdf(v)}
    )
    start_shift: tuple[float, float] = declare(
        (0.0, 0.05), range_(lo=-MAX_SHIFT, hi=MAX_SHIFT), unit="m"
    )  # agent start moved towards the obstacle
    step_length: tuple[float, float] = declare(
        (0.65, 0.75), range_(positive=True, hi=MAX_STEP_LENGTH), unit="m"
    )  # goal = start + this
    # Procedural obstacle families (jaxexo.physics.terrain): false, or a table (parse_terrain) that
    # replaces the obstacle mixture, start_shift, step_length, obstacle_offset and pivot in reset.
    terrain: Any = declare(
        check=parse_terrain,
        to_param=terrain_params,
        write=write_terrain,
        default_factory=lambda: parse_terrain("layout.terrain", DEFAULT_TERRAIN),
    )

    def default_center(self, foot_length: float, step_length: float) -> float:
        """Default obstacle centre (jaxexo.physics.geometry.default_center, the one definition)."""
        return geometry.default_center(foot_length, step_length)


@dataclass(frozen=True)
class TrainConfig:
    """[train]: the TD(lambda) agent (thesis 2.3-2.4).

    Static settings fix the compiled program's shapes and structure; the leaves are the vmappable
    fields of ``jaxexo.train.Hyperparams`` (sweeps). The budgets are leaves too, but the number of
    updates they need (num_updates) is static: it is the length of the scan."""

    num_envs: int = declare(
        512, number(positive=True, integer=True, hi=2**24), unit="envs", role="static"
    )
    # T: steps per environment between updates
    rollout_steps: int = declare(
        16, number(positive=True, integer=True, hi=100_000), unit="steps", role="static"
    )
    # forward view: gradient steps per epoch over the T x N batch
    num_minibatches: int = declare(4, number(positive=True, integer=True, hi=2**24), role="static")
    num_epochs: int = declare(1, number(positive=True, integer=True, hi=10_000), role="static")
    # the thesis network (Fig. 2.2)
    hidden: tuple[int, ...] = declare(
        (128, 128),
        vector(positive=True, integer=True, hi=65_536, max_len=64),
        unit="units",
        role="static",
    )
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
    budget_episodes: int = declare(
        0, number(nonneg=True, integer=True, hi=INT32_MAX), unit="episodes"
    )
    # stop after this many env steps (0: no limit)
    budget_env_steps: int = declare(
        1_500_000, number(nonneg=True, integer=True, hi=2**40), unit="steps"
    )
    # updates per compiled chunk (progress, checkpoint); 0: auto
    chunk_updates: int = declare(
        0, number(nonneg=True, integer=True, hi=INT32_MAX), unit="updates", role="setting"
    )
    # Agents trained together as one program, seeds seed .. seed + K - 1, the best exported (1: one
    # agent; docs/training.md); bounded loosely here, the memory estimate is the real limit.
    population: int = declare(
        2, number(positive=True, integer=True, hi=4096), unit="agents", role="setting"
    )
    eval_episodes: int = declare(
        1000, number(positive=True, integer=True, hi=10_000_000), unit="episodes", role="static"
    )
    lr: float = declare(1e-3, number(positive=True))
    # linear decay of the learning rate to lr * this at the budget's end
    lr_end_fraction: float = declare(0.1, fraction())
    gamma: float = declare(0.98, fraction())
    lam: float = declare(0.9, fraction())
    eps_start: float = declare(1.0, fraction())
    eps_end: float = declare(0.02, fraction())
    eps_decay_fraction: float = declare(0.5, fraction(positive=True))  # of the budget, linear
    # "hard" target copies every this many updates (int32 in the program)
    target_period: int = declare(
        10, number(positive=True, integer=True, hi=INT32_MAX), unit="updates", dtype="int32"
    )
    target_tau: float = declare(0.05, fraction(positive=True))  # "polyak"
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
    layout: LayoutConfig = field(
        default_factory=lambda: LayoutConfig(obstacles=default_obstacles())
    )
    train: TrainConfig = field(default_factory=TrainConfig)
    device: DeviceConfig = field(default_factory=DeviceConfig)

    @property
    def outline_vertices(self) -> int:
        return self.env.max_vertices or _vertices_needed(self.layout)


def _vertices_needed(lay: LayoutConfig) -> int:
    need = max(len(o.unit_vertices()) for o in lay.obstacles)
    return max(need, terrain.K_MAX) if lay.terrain is not None else need


SECTION_CLASSES = {
    "env": EnvConfig,
    "kinematics": KinematicsConfig,
    "reward": RewardConfig,
    "layout": LayoutConfig,
    "train": TrainConfig,
    "device": DeviceConfig,
}


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
    return dataclasses.replace(
        cfg, train=dataclasses.replace(cfg.train, population=check(where, k))
    )


# Seeds reach jax.random.PRNGKey (a population's members take seed .. seed + K - 1).
MAX_SEED = INT32_MAX


def check_seed(seed, where: str = "--seed", count: int = 1) -> int:
    """``seed`` when it and the ``count - 1`` seeds after it lie in [0, MAX_SEED]; ConfigError naming
    ``where`` otherwise."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ConfigError(f"{where}: expected an integer seed, got {seed!r}")
    hi = MAX_SEED - (count - 1)
    if not 0 <= seed <= hi:
        more = f" (with {count - 1} more seeds after it)" if count > 1 else ""
        raise ConfigError(f"{where}: a seed must be in [0, {hi}]{more}, got {seed}")
    return int(seed)


# (section, field) of every field declared static, in declaration order (read once: a sweep asks
# for the static settings of each of its configurations).
_STATIC_FIELDS = tuple(
    (section, name)
    for section in SECTIONS
    for name, s in declared_fields(SECTION_CLASSES[section])
    if s.static
)


def static_settings(cfg: Config) -> tuple:
    """Everything about a config that fixes the compiled trainer (and its greedy evaluation): the
    fields declared static, the resolved outline size, the number of obstacle kinds and the scan
    length. Configs with equal static settings differ only in pytree leaves (jaxexo.train.Hyperparams,
    EnvParams) and can be vmapped together as one program."""
    out = tuple(
        (f"{section}.{name}", getattr(getattr(cfg, section), name))
        for section, name in _STATIC_FIELDS
    )
    return out + (
        ("outline_vertices", cfg.outline_vertices),
        ("obstacle_kinds", len(cfg.layout.obstacles)),
        ("terrain_families", () if cfg.layout.terrain is None else cfg.layout.terrain.families),
        ("num_updates", num_updates(cfg)),
    )


def to_toml_values(section_obj) -> list[tuple[str, Any]]:
    """(name, TOML-writable value) for every field of a section, by its declaration (a field declared
    ``omit_default`` is left out at its default)."""
    out = []
    for f in fields(section_obj):
        s, v = spec_of(f), getattr(section_obj, f.name)
        if s.omit_default and v == f.default:
            continue
        out.append((f.name, s.write(v) if s.write else v))
    return out
