"""jaxexo.config: the default TOML file, and errors that name the bad field."""

from __future__ import annotations

import copy
import math

import pytest

from jaxexo.config import (
    Config,
    ConfigError,
    config_from_dict,
    load_config,
    validate,
)
from jaxexo.physics.kinematics import PIVOT_CONDITIONS

from conftest import MIXED_KINDS, PROFILE_POINTS, ROOT, legacy_raw


def test_default_toml_loads():
    import tomllib

    path = ROOT / "configs" / "default.toml"
    cfg = load_config(path)
    assert isinstance(cfg, Config)
    assert cfg == config_from_dict(tomllib.loads(path.read_text()))
    # Thesis facts the default file fixes: 0.5 m thigh and shin, the common exoskeleton joint
    # limits, Base 1-3 in the training mixture, every pivot condition.
    assert (cfg.kinematics.thigh, cfg.kinematics.shin) == (0.5, 0.5)
    assert cfg.kinematics.hip_limits == pytest.approx(
        (math.radians(-30), math.radians(115)), abs=1e-4
    )
    assert cfg.kinematics.knee_limits == pytest.approx((math.radians(-100), 0.0), abs=1e-4)
    kinds = [o.kind for o in cfg.layout.obstacles]
    assert {"base1", "base2", "base3"} <= set(kinds)
    b1 = cfg.layout.obstacles[kinds.index("base1")]
    assert b1.width == (0.2, 0.2) and b1.height == (0.1, 0.1) and b1.shape == "rectangle"
    assert cfg.layout.pivot == (1.0, 1.0, 1.0)
    assert cfg.env.obs_mode in ("thesis", "conditioned")
    assert cfg.outline_vertices >= 4


def test_empty_config_is_the_defaults():
    # One default: an empty config, Config() and the packaged default are the same model.
    cfg = config_from_dict({})
    assert cfg == Config() == load_config(ROOT / "configs" / "default.toml")
    assert [o.kind for o in cfg.layout.obstacles] == [
        "base1",
        "base2",
        "base3",
        "rectangle",
        "rectangle",
    ]
    validate(Config())


def test_mixed_config(mixed_config):
    assert tuple(o.kind for o in mixed_config.layout.obstacles) == MIXED_KINDS
    shapes = [o.shape for o in mixed_config.layout.obstacles]
    assert shapes == ["rectangle"] * 3 + [
        "triangle",
        "half_ellipse",
        "rectangle",
        "half_ellipse",
        "profile",
    ]
    assert mixed_config.outline_vertices == 16
    prof = mixed_config.layout.obstacles[-1]
    assert prof.width == pytest.approx((0.16, 0.16)) and prof.height == pytest.approx((0.12, 0.12))
    assert [list(map(float, p)) for p in prof.points] == PROFILE_POINTS
    assert len(prof.unit_vertices()) == len(PROFILE_POINTS)
    assert mixed_config.layout.obstacles[4].width == (0.2, 0.2)  # half_circle, Table 3.1
    assert mixed_config.layout.obstacles[4].height == (0.25, 0.25)


def test_pivot_forms():
    assert config_from_dict(legacy_raw({"layout": {"pivot": "agent"}})).layout.pivot == (
        1.0,
        0.0,
        0.0,
    )
    assert config_from_dict(
        legacy_raw({"layout": {"pivot": ["obstacle", "between"]}})
    ).layout.pivot == (0.0, 1.0, 1.0)
    assert config_from_dict(legacy_raw({"layout": {"pivot": {"between": 2.0}}})).layout.pivot == (
        0.0,
        0.0,
        2.0,
    )
    assert PIVOT_CONDITIONS == ("agent", "obstacle", "between")


def test_max_vertices_explicit():
    cfg = config_from_dict(legacy_raw({"env": {"max_vertices": 20}}))
    assert cfg.outline_vertices == 20


def test_scalar_range_and_weights():
    cfg = config_from_dict(
        legacy_raw(
            {
                "layout": {
                    "obstacles": [
                        {"kind": "rectangle", "width": 0.1, "height": 0.1, "weight": 2.0},
                        {"kind": "base1", "weight": 0.5},
                    ]
                }
            }
        )
    )
    assert cfg.layout.obstacles[0].width == (0.1, 0.1)
    assert cfg.layout.obstacles[0].weight == 2.0 and cfg.layout.obstacles[1].weight == 0.5


# --------------------------------------------------------------------------------------------
# Errors name the field
# --------------------------------------------------------------------------------------------

NAN, INF = float("nan"), float("inf")


# The mid-goal constants the height checks depend on, pinned (thesis-like: 10 cm over the top).
MID = {"env": {"mid_goal_clearance": 0.10, "mid_goal_half_size": [0.06, 0.05], "max_z": 0.80}}


def obstacles(*obs):
    return {"layout": {"obstacles": list(obs)}}


@pytest.mark.parametrize(
    "raw, field",
    [
        ({"foo": {}}, r"^foo: unknown section"),
        ({"env": {"foo": 1}}, r"^env\.foo: unknown field"),
        ({"reward": {"alpha": [1]}}, r"^reward\.alpha: unknown field"),
        ({"env": "fast"}, r"^env: expected a table"),
        # negative / zero sizes
        ({"env": {"step_size": -0.03}}, r"^env\.step_size: must be > 0"),
        ({"env": {"step_size": 0}}, r"^env\.step_size: must be > 0"),
        ({"kinematics": {"thigh": 0.0}}, r"^kinematics\.thigh: must be > 0"),
        ({"kinematics": {"foot_length": -0.2}}, r"^kinematics\.foot_length: must be > 0"),
        ({"env": {"max_steps": 0}}, r"^env\.max_steps: must be > 0"),
        ({"env": {"max_steps": 10.5}}, r"^env\.max_steps: expected an integer"),
        (
            obstacles({"kind": "rectangle", "width": [0.0, 0.1], "height": 0.1}),
            r"^layout\.obstacles\[0\]\.width\[0\]: must be > 0",
        ),
        (
            obstacles("base1", {"kind": "rectangle", "width": 0.1, "height": -0.1}),
            r"^layout\.obstacles\[1\]\.height\[0\]: must be > 0",
        ),
        (
            obstacles({"kind": "half_ellipse", "width": 0.1, "height": 0.1, "weight": -1}),
            r"^layout\.obstacles\[0\]\.weight: must be >= 0",
        ),
        # NaN / inf
        ({"env": {"step_size": NAN}}, r"^env\.step_size: must be finite"),
        ({"kinematics": {"shin": INF}}, r"^kinematics\.shin: must be finite"),
        ({"reward": {"goal_reward": NAN}}, r"^reward\.goal_reward: must be finite"),
        (
            {"kinematics": {"hip_limits": [NAN, 1.0]}},
            r"^kinematics\.hip_limits\[0\]: must be finite",
        ),
        (
            obstacles({"kind": "rectangle", "width": [0.1, INF], "height": 0.1}),
            r"^layout\.obstacles\[0\]\.width\[1\]: must be finite",
        ),
        (
            obstacles({"kind": "rectangle", "width": 0.1, "height": NAN}),
            r"^layout\.obstacles\[0\]\.height\[0\]: must be finite",
        ),
        # types and choices
        ({"env": {"step_size": "0.03"}}, r"^env\.step_size: expected a number"),
        ({"env": {"step_size": True}}, r"^env\.step_size: expected a number"),
        ({"env": {"obs_mode": "pixels"}}, r"^env\.obs_mode: must be one of"),
        ({"env": {"collision": "bounce"}}, r"^env\.collision: must be one of"),
        ({"layout": {"pivot": ["agent", "left"]}}, r"^layout\.pivot: must be one of"),
        (
            {"layout": {"pivot": {"agent": 1.0, "left": 1.0}}},
            r"^layout\.pivot\.left: must be one of",
        ),
        ({"layout": {"pivot": 3}}, r"^layout\.pivot: expected a list"),
        ({"layout": {"pivot": {"agent": 0.0}}}, r"^layout\.pivot: at least one"),
        (
            obstacles({"kind": "hexagon", "width": 0.1, "height": 0.1}),
            r"^layout\.obstacles\[0\]\.kind: must be",
        ),
        (obstacles("base1", "pentagon"), r"^layout\.obstacles\[1\]\.kind: must be"),
        (
            obstacles({"kind": "rectangle", "height": 0.1}),
            r"^layout\.obstacles\[0\]\.width: required",
        ),
        (
            obstacles({"kind": "rectangle", "width": 0.1, "height": 0.1, "colour": "red"}),
            r"^layout\.obstacles\[0\]\.colour: unknown field",
        ),
        (
            obstacles({"kind": "base1", "height": 0.3}),
            r"^layout\.obstacles\[0\]\.height: base1 has the fixed size",
        ),
        (obstacles({"kind": "profile"}), r"^layout\.obstacles\[0\]\.points: required"),
        (
            obstacles({"kind": "profile", "points": [[0.1, 0.1], [0.0, 0.1]]}),
            r"^layout\.obstacles\[0\]\.points: .*non-decreasing",
        ),
        (
            obstacles({"kind": "profile", "points": [[0.0, 0.1], [0.1, -0.1]]}),
            r"^layout\.obstacles\[0\]\.points: .*z >= 0",
        ),
        ({"layout": {"obstacles": []}}, r"^layout\.obstacles: expected a non-empty list"),
        (obstacles({"kind": "base1", "weight": 0.0}), r"^layout\.obstacles: at least one"),
        (
            {"layout": {"step_length": [0.75, 0.65]}},
            r"^layout\.step_length: range \[lo, hi\] needs lo <= hi",
        ),
        ({"layout": {"size_jitter": 1.0}}, r"^layout\.size_jitter: relative jitter must be < 1"),
        ({"reward": {"hlc_threshold": 1.5}}, r"^reward\.hlc_threshold: a fraction"),
        ({"reward": {"traj_weights": [1.0] * 7}}, r"^reward\.traj_weights: expected 8 numbers"),
        ({"kinematics": {"knee_limits": [0.5, 0.5]}}, r"^kinematics\.knee_limits: lower limit"),
        # cross-field: impossible layouts
        (
            {"env": {"step_size": 0.06}, **obstacles("base3")},
            r"^env\.step_size: .*layout\.obstacles\[0\]\.width",
        ),
        (
            {
                "env": {"step_size": 0.08},
                **obstacles({"kind": "rectangle", "width": 0.2, "height": 0.07}),
            },
            r"^env\.step_size: .*layout\.obstacles\[0\]\.height",
        ),
        (
            {**MID, **obstacles({"kind": "rectangle", "width": 0.1, "height": 0.6})},
            r"^layout\.obstacles\[0\]\.height: .*cannot be cleared",
        ),
        (
            {
                "env": {**MID["env"], "max_z": 0.6},
                **obstacles("base1", {"kind": "rectangle", "width": 0.1, "height": 0.55}),
            },
            r"^layout\.obstacles\[1\]\.height: .*above env\.max_z",
        ),
        (
            {"layout": {"step_length": [0.45, 0.7]}},
            r"^layout\.step_length: the goal .* not beyond layout\.obstacles\[0\]",
        ),
        (
            {"layout": {"start_shift": [0.0, 0.3]}},
            r"^layout\.start_shift: with layout\.obstacles\[0\]",
        ),
        ({"env": {"max_vertices": 3}}, r"^env\.max_vertices: 3 is fewer than the 4"),
        (
            {
                "env": {"max_vertices": 8},
                **obstacles({"kind": "half_ellipse", "width": 0.1, "height": 0.1}),
            },
            r"^env\.max_vertices: 8 is fewer than the 16",
        ),
        ({"reward": {"traj_weights": [0] * 8}}, r"^reward\.traj_weights: at least one weight"),
        ({"reward": {"exo_weights": [0, 0, 0, 0]}}, r"^reward\.exo_weights: at least one weight"),
        ({"env": {"max_steps": 20}}, r"^env\.max_steps: 20 is below reward\.step_threshold"),
        ({"env": {"bounds_y": [0.1, 1.3]}}, r"^env\.bounds_y: the lower bound"),
        ({"env": {"bounds_y": [-0.3, 0.7]}}, r"^env\.bounds_y: the upper bound"),
        (
            {"env": {"mid_goal_clearance": 0.04, "mid_goal_half_size": [0.06, 0.05]}},
            r"^env\.mid_goal_half_size: the mid-goal box must lie above",
        ),
    ],
)
def test_config_errors_name_the_field(raw, field):
    with pytest.raises(ConfigError, match=field):
        config_from_dict(legacy_raw(raw))


def test_mixed_config_errors_point_at_the_right_obstacle(mixed_raw):
    raw = copy.deepcopy(mixed_raw)
    raw["layout"]["obstacles"][6]["height"] = [0.05, 0.6]
    with pytest.raises(ConfigError, match=r"^layout\.obstacles\[6\]\.height"):
        config_from_dict(legacy_raw(raw))
    raw = copy.deepcopy(mixed_raw)
    raw["layout"]["obstacles"][7]["points"] = [[0.0, 0.1]]
    with pytest.raises(ConfigError, match=r"^layout\.obstacles\[7\]\.points"):
        config_from_dict(legacy_raw(raw))


def test_zero_weight_obstacle_is_not_checked():
    # An impossible obstacle with weight 0 is never drawn, so it is not refused.
    cfg = config_from_dict(
        legacy_raw(
            obstacles("base1", {"kind": "rectangle", "width": 0.1, "height": 0.6, "weight": 0.0})
        )
    )
    assert cfg.layout.obstacles[1].weight == 0.0


# --------------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------------


def test_load_config_missing_file(tmp_path):
    path = tmp_path / "nope.toml"
    with pytest.raises(ConfigError, match="cannot read config"):
        load_config(path)


def test_load_config_invalid_toml(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[env\nstep_size = 0.03\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(path)


@pytest.mark.parametrize(
    "text, field",
    [
        ("[env]\nstep_size = nan\n", r"env\.step_size: must be finite"),
        ("[env]\nstep_size = inf\n", r"env\.step_size: must be finite"),
        ("[kinematics]\nthigh = -inf\n", r"kinematics\.thigh: must be finite"),
        (
            '[layout]\nobstacles = [{ kind = "rectangle", width = [0.1, nan], height = 0.1 }]\n',
            r"layout\.obstacles\[0\]\.width\[1\]: must be finite",
        ),
        (
            '[layout]\nobstacles = ["base1", { kind = "rectangle", width = 0.1, height = 0.6 }]\n',
            r"layout\.obstacles\[1\]\.height",
        ),
    ],
)
def test_load_config_toml_values(tmp_path, text, field):
    path = tmp_path / "c.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=field) as e:
        load_config(path)
    assert str(path) in str(e.value)  # the file is named too


def test_load_config_roundtrip(tmp_path):
    path = tmp_path / "ok.toml"
    path.write_text(
        '[env]\nobs_mode = "thesis"\nmax_steps = 50\n[layout]\nobstacles = ["triangle"]\n'
        'pivot = ["between"]\nterrain = false\n'
    )
    cfg = load_config(path)
    assert cfg.env.obs_mode == "thesis" and cfg.env.max_steps == 50
    assert (
        cfg.layout.obstacles[0].kind == "triangle" and cfg.layout.obstacles[0].shape == "triangle"
    )
    assert cfg.layout.pivot == (0.0, 0.0, 1.0)
    assert cfg.outline_vertices == 3


# --------------------------------------------------------------------------------------------
# Bugs
# --------------------------------------------------------------------------------------------

# One rectangle 5 cm wide and 32 cm high, pivot aligned with the agent, starts shifted up to 20 cm.
UNCLEARABLE = {
    **MID,
    "layout": {
        "obstacles": [{"kind": "rectangle", "width": 0.05, "height": 0.32}],
        "pivot": ["agent"],
        "start_shift": [0.0, 0.2],
        "obstacle_offset": [0.0, 0.0],
        "step_length": [0.7, 0.7],
    },
}


def _mid_goal_box_reachable(pivot_y, center, height):
    """Whether any heel in the mid-goal box over the obstacle is reachable within the joint limits."""
    import numpy as np

    from jaxexo.physics import kinematics

    lim = (math.radians(-30), math.radians(115), math.radians(-100), 0.0)
    ys = np.linspace(center - 0.06, center + 0.06, 61)
    zs = np.linspace(height + 0.05, height + 0.15, 51)
    Y, Z = np.meshgrid(ys, zs, indexing="ij")
    ks = kinematics.leg_state(np, pivot_y, np.stack([Y, Z], -1), 0.5, 0.5)
    ok = (ks.leg_swing <= 1.0 + 1e-9) & ~kinematics.joint_limit_violation(
        np, ks.hip_swing, ks.knee_swing_angle, *lim
    )
    return bool(ok.any())


def test_unclearable_layout_premise():
    # The premise of the bug test below: at the unshifted start the mid-goal box is reachable (so
    # the one layout validate() checks passes), at the 20 cm shifted start - which reset() draws -
    # no heel in the whole box is.
    assert _mid_goal_box_reachable(0.0, 0.45, 0.32)
    assert not _mid_goal_box_reachable(0.2, 0.45, 0.32)


def test_unclearable_obstacle_at_shifted_start_is_refused():
    with pytest.raises(ConfigError, match=r"layout\.obstacles\[0\]\.height"):
        config_from_dict(legacy_raw(copy.deepcopy(UNCLEARABLE)))


def test_profile_size_defaults_to_drawn_extents_and_ranges_are_metres():
    cfg = config_from_dict(
        legacy_raw({"layout": {"obstacles": [{"kind": "profile", "points": PROFILE_POINTS}]}})
    )
    ob = cfg.layout.obstacles[0]
    assert ob.width[0] == ob.width[1] == pytest.approx(0.16)
    assert ob.height[0] == ob.height[1] == pytest.approx(0.12)
    # Ranges are metres: a 1 m wide profile cannot fit between the start and the goal.
    with pytest.raises(ConfigError, match=r"layout\.(start_shift|step_length)"):
        config_from_dict(
            legacy_raw(
                {
                    "layout": {
                        "obstacles": [
                            {
                                "kind": "profile",
                                "points": PROFILE_POINTS,
                                "width": [1, 1],
                                "height": [0.5, 0.5],
                            }
                        ]
                    }
                }
            )
        )


# --------------------------------------------------------------------------------------------
# Errors at the boundary, naming the field or file
# --------------------------------------------------------------------------------------------


def test_non_utf8_config_names_the_file(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes("[env]\n# m\xe8tres\nstep_size = 0.03\n".encode("latin-1"))
    with pytest.raises(ConfigError, match=r"latin1\.toml: not UTF-8"):
        load_config(path)


@pytest.mark.parametrize(
    "raw, field",
    [
        (
            {"train": {"target_period": 10_000_000_000}},
            r"^train\.target_period: must be <= 2147483647",
        ),
        ({"train": {"num_envs": 100_000_000_000}}, r"^train\.num_envs: must be <= 16777216"),
        ({"train": {"hidden": [64, 10**9]}}, r"^train\.hidden\[1\]: must be <= 65536"),
        ({"env": {"max_steps": 10**12}}, r"^env\.max_steps: must be <= 100000"),
        ({"train": {"budget_env_steps": 10**15}}, r"^train\.budget_env_steps: must be <="),
        (
            {
                "train": {
                    "num_envs": 1,
                    "rollout_steps": 1,
                    "num_minibatches": 1,
                    "budget_env_steps": 2**40,
                }
            },
            r"^train\.budget_env_steps: needs 1099511627776 updates",
        ),
    ],
)
def test_integers_are_bounded(raw, field):
    with pytest.raises(ConfigError, match=field):
        config_from_dict(legacy_raw(raw))


def test_every_integer_field_declares_a_bound():
    """An int field without an upper bound could overflow int32 inside JAX."""
    from jaxexo.config import SECTION_CLASSES, declared_fields

    for section, cls in SECTION_CLASSES.items():
        for name, spec in declared_fields(cls):
            default = getattr(cls(), name) if section != "layout" else None
            if isinstance(default, int) and not isinstance(default, bool):
                with pytest.raises(ConfigError, match=rf"^{section}\.{name}: must be <="):
                    spec.check(f"{section}.{name}", 2**63)


@pytest.mark.parametrize(
    "raw, field",
    [
        # The step is too short for the obstacle: the fault is the step length, not the start shift.
        (
            {"layout": {"obstacles": ["base1"], "step_length": [0.35, 0.7]}},
            r"^layout\.step_length: 0\.35 m is too short",
        ),
        # A jitter that shrinks an obstacle below one step: the jitter, not the step size.
        (
            {"layout": {"size_jitter": 0.99}},
            r"^layout\.size_jitter: 0\.99 shrinks layout\.obstacles\[0\]",
        ),
        # A start shift onto an obstacle that fits without it still blames the shift.
        (
            {"layout": {"start_shift": [0.0, 0.3]}},
            r"^layout\.start_shift: with layout\.obstacles\[0\]",
        ),
        (
            {"layout": {"obstacles": ["base1"], "obstacle_offset": [-0.2, 0.0]}},
            r"^layout\.obstacle_offset: -0\.2 m",
        ),
        # No jitter: the step size itself is too large.
        ({"env": {"step_size": 0.06}, "layout": {"obstacles": ["base3"]}}, r"^env\.step_size: "),
    ],
)
def test_validation_blames_the_field_at_fault(raw, field):
    with pytest.raises(ConfigError, match=field):
        config_from_dict(legacy_raw(raw))


@pytest.mark.parametrize("section, command", [("sweep", "jaxexo sweep"), ("eval", "jaxexo eval")])
def test_sections_of_other_commands_are_refused(tmp_path, section, command):
    path = tmp_path / "c.toml"
    path.write_text(f"[{section}]\nseeds = 2\n")
    with pytest.raises(
        ConfigError,
        match=rf"c\.toml: {section}: a \[{section}\] section does not belong in a "
        rf"train config; .*{command}",
    ):
        load_config(path)


@pytest.mark.parametrize(
    "make",
    [
        lambda O: O.rectangle(True, 0.1),
        lambda O: O.triangle(0.1, True),
        lambda O: O.half_ellipse(0.1, 0.1, False),
        lambda O: O.named("base1", True),
        lambda O: O.profile([[0.0, 0.1], [True, 0.1]]),
    ],
)
def test_obstacles_refuse_booleans(make):
    from jaxexo.physics.geometry import GeometryError, Obstacle

    with pytest.raises(
        GeometryError, match=r"(width|height|center_y|points) must be .*(boolean|booleans)"
    ):
        make(Obstacle)


# --------------------------------------------------------------------------------------------
# One declaration per field
# --------------------------------------------------------------------------------------------


def test_env_params_and_hyperparams_come_from_the_declarations(mixed_config):
    from jaxexo.config import (
        ENV_SECTIONS,
        HYPER_FIELDS,
        SECTION_CLASSES,
        TrainConfig,
        declared_fields,
        param_values,
    )

    values = param_values(mixed_config)
    leaves = [
        (s, n, spec)
        for s in ENV_SECTIONS
        for n, spec in declared_fields(SECTION_CLASSES[s])
        if spec.leaf
    ]
    names = {"directions"}
    for s, n, spec in leaves:
        out = spec.params(n, getattr(getattr(mixed_config, s), n), mixed_config)
        names |= set(out)
    assert set(values) == names
    # Independent spot checks of the conversions (thesis eq 2.38: weights normalised to sum 0.5).
    assert values["traj_weights"].sum() == pytest.approx(0.5) and values[
        "max_z_world"
    ] == pytest.approx(0.8)
    assert (
        values["max_steps_in_episode"].dtype.name == "int32"
        and values["terminate_on_collision"].dtype == bool
    )
    assert values["kind_outlines"].shape == (len(MIXED_KINDS), mixed_config.outline_vertices, 2)
    assert values["pivot_cdf"][-1] == 1.0 and values["kind_cdf"][-1] == 1.0
    assert HYPER_FIELDS == tuple(n for n, s in declared_fields(TrainConfig) if s.leaf)
    assert (
        "num_envs" not in HYPER_FIELDS
        and "chunk_updates" not in HYPER_FIELDS
        and "lr" in HYPER_FIELDS
    )


def test_static_settings_follow_the_declarations():
    from jaxexo.config import static_settings

    base = config_from_dict(legacy_raw({}))
    names = dict(static_settings(base))
    assert (
        names["train.num_envs"] == base.train.num_envs
        and names["env.obs_mode"] == base.env.obs_mode
    )
    # Leaves do not change the static settings; statics do.
    assert static_settings(
        config_from_dict(legacy_raw({"train": {"lr": 0.5}, "reward": {"goal_reward": 3.0}}))
    ) == static_settings(base)
    assert static_settings(
        config_from_dict(legacy_raw({"train": {"hidden": [8]}}))
    ) != static_settings(base)
    assert static_settings(
        config_from_dict(legacy_raw({"train": {"chunk_updates": 7}}))
    ) == static_settings(base)


# --------------------------------------------------------------------------------------------
# Memory estimate (jaxexo.config.memory)
# --------------------------------------------------------------------------------------------


def test_memory_estimate_refuses_what_does_not_fit():
    from jaxexo.config.memory import check_memory, estimate_memory_bytes, machine_memory_bytes

    small = config_from_dict(legacy_raw({}))
    need = estimate_memory_bytes(small)
    assert 0 < need < 2**30 and check_memory(small, available=2**34) == need
    big = config_from_dict(legacy_raw({"train": {"num_envs": 2**24, "rollout_steps": 64}}))
    assert estimate_memory_bytes(big) > 2**36
    with pytest.raises(
        ConfigError,
        match=r"^train\.num_envs: the run needs at least .* GiB .* but this machine has "
        r"1\.00 GiB of memory",
    ):
        check_memory(big, available=2**30)
    # Linear in the number of environments (every part but the network and eval scale with N).
    a, b = (
        estimate_memory_bytes(config_from_dict(legacy_raw({"train": {"num_envs": n}})))
        for n in (1024, 2048)
    )
    assert 1.8 * a < b < 2 * a
    assert machine_memory_bytes() is None or machine_memory_bytes() > 2**26


@pytest.mark.parametrize(
    "raw",
    [
        {},
        {"env": {"obs_mode": "thesis"}, "train": {"hidden": [64, 32, 32, 32]}},
        {"env": {"shape_points": 5}, "train": {"layer_norm": True, "hidden": [16, 8]}},
    ],
)
def test_memory_estimate_sizes_match_the_real_network_and_env(raw):
    """Independent reference: the network JAX builds and the environment's observation size."""
    jax = pytest.importorskip("jax")
    from jaxexo.config.memory import NUM_ACTIONS, network_size, observation_size
    from jaxexo.env import ExoStepEnv
    from jaxexo.physics.actions import NUM_ACTIONS as ENV_ACTIONS
    from jaxexo.train.network import QNetwork

    cfg = config_from_dict(legacy_raw(raw))
    d = ExoStepEnv(cfg).obs_dim
    assert observation_size(cfg) == d and NUM_ACTIONS == ENV_ACTIONS
    net = QNetwork(hidden=cfg.train.hidden, layer_norm=cfg.train.layer_norm)
    params = net.init(jax.random.PRNGKey(0), jax.numpy.zeros((1, d)))
    assert network_size(cfg) == sum(x.size for x in jax.tree_util.tree_leaves(params))


def test_cmd_sweep_returns_an_exit_status(monkeypatch, tmp_path):
    import argparse

    import jaxexo.sweep.runner as runner
    from jaxexo import cli

    monkeypatch.setattr(
        runner,
        "run_sweep",
        lambda *a, **k: {
            "ranking": [],
            "wall_s_this_run": 0.0,
            "env_steps_this_run": 0,
            "figures": [],
        },
    )
    args = argparse.Namespace(
        memory_budget=None,
        sweep=str(ROOT / "configs" / "sweeps" / "smoke.toml"),
        backend="ray",
        out=str(tmp_path),
        resume=False,
        heatmap=None,
        address=None,
        task_cpus=None,
        quiet=True,
        export_best=False,
        export_all=False,
    )
    assert cli.cmd_sweep(args) == 0


def test_shielded_steps_may_exceed_the_smallest_obstacle_but_not_the_goal_window():
    """The shield checks each move's exact swept clearance, so a shielded model may step 6 cm over 5 cm
    obstacles (the same step unshielded is refused: test_validation_blames_the_field_at_fault); no
    model may step past the goal window (2 x env.goal_tolerance[0])."""
    raw = {"env": {"step_size": 0.06, "shield": True}, "layout": {"obstacles": ["base3"]}}
    assert config_from_dict(legacy_raw(raw)).env.step_size == 0.06
    assert (
        config_from_dict({"env": {"step_size": 0.06}}).env.step_size == 0.06
    )  # the default's terrain
    for shield in (True, False):
        bad = {
            "env": {"step_size": 0.09, "shield": shield, "goal_tolerance": [0.04, 0.02]},
            "layout": {"obstacles": [{"kind": "rectangle", "width": 0.2, "height": 0.2}]},
        }
        with pytest.raises(
            ConfigError,
            match=r"^env\.step_size: 0\.09 m is longer than the goal window \(.*0\.080 m\)",
        ):
            config_from_dict(legacy_raw(bad))
