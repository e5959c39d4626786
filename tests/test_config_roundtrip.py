"""Config round trips through the writer (jaxexo.config.toml_io): load -> write -> load is the
identity for drawn configs (every obstacle kind and thesis name) and for every config file shipped
(configs/ and the package's copies, which must be byte-equal); the package data is in the wheel."""

from __future__ import annotations

import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import jaxexo.config
from jaxexo.config import (
    CONTROLS,
    OBS_MODES,
    OBS_PROFILES,
    TARGETS,
    TRACE_KINDS,
    TRACE_VIEWS,
    Config,
    ConfigError,
    config_from_dict,
    load_config,
)
from jaxexo.config.toml_io import config_to_toml
from jaxexo.physics.geometry import THESIS_OBSTACLES
from jaxexo.physics.kinematics import PIVOT_CONDITIONS

from conftest import ROOT, legacy_raw

PACKAGE = Path(jaxexo.config.__file__).resolve().parent


def roundtrip(cfg: Config, tmp_path: Path | None = None) -> Config:
    """Write cfg with the run directory's writer and read it back with load_config."""
    text = config_to_toml(cfg)
    if tmp_path is None:
        again = config_from_dict(tomllib.loads(text))
    else:
        (tmp_path / "config.toml").write_text(text)
        again = load_config(tmp_path / "config.toml")
    assert config_to_toml(again) == text  # the text is a fixed point too
    return again


# --------------------------------------------------------------------------------------------
# Drawn configs
# --------------------------------------------------------------------------------------------


def _lohi(lo, hi):
    return st.tuples(st.floats(lo, hi), st.floats(lo, hi)).map(lambda t: [min(t), max(t)])


PROFILE = st.lists(st.floats(0.02, 0.12), min_size=1, max_size=6).map(
    lambda zs: (
        [[-0.07, 0.0]]
        + [[-0.07 + 0.14 * (i + 1) / (len(zs) + 1), z] for i, z in enumerate(zs)]
        + [[0.07, 0.0]]
    )
)

OBSTACLE = st.one_of(
    st.sampled_from(sorted(THESIS_OBSTACLES)),
    st.builds(
        lambda k, w: {"kind": k, "weight": w},
        st.sampled_from(sorted(THESIS_OBSTACLES)),
        st.floats(0.1, 3.0),
    ),
    st.builds(
        lambda k, w, h, wt: {"kind": k, "width": w, "height": h, "weight": wt},
        st.sampled_from(["rectangle", "triangle", "half_ellipse"]),
        _lohi(0.05, 0.2),
        _lohi(0.05, 0.25),
        st.floats(0.0, 2.0),
    ),
    st.builds(
        lambda pts, w: {"kind": "profile", "points": pts, **w},
        PROFILE,
        st.one_of(
            st.just({}),
            st.builds(lambda w, h: {"width": w, "height": h}, _lohi(0.05, 0.2), _lohi(0.05, 0.25)),
        ),
    ),
)

TERRAIN = st.one_of(
    st.just(False),
    st.builds(
        lambda fams, w, s, L, piv: {
            "families": fams,
            "weights": w[: len(fams)],
            "start_shift": s,
            "step_length": L,
            "pivot": piv,
        },
        st.lists(
            st.sampled_from(["rectangle", "trapezoid", "wedge", "step", "bump", "polyline"]),
            min_size=1,
            max_size=6,
            unique=True,
        ),
        st.lists(st.floats(0.1, 3.0), min_size=6, max_size=6),
        _lohi(0.0, 0.12),
        st.tuples(st.floats(0.55, 0.70), st.floats(0.75, 0.85)).map(list),
        st.lists(st.floats(0.1, 2.0), min_size=3, max_size=3),
    ),
)

RAW = st.fixed_dictionaries(
    {
        "env": st.fixed_dictionaries(
            {},
            optional={
                "step_size": st.floats(0.01, 0.04),
                "max_steps": st.integers(30, 300),
                "obs_mode": st.sampled_from(OBS_MODES),
                "obs_profile": st.sampled_from(OBS_PROFILES),
                "collision": st.sampled_from(["penalty", "terminate"]),
                "shape_points": st.integers(1, 32),
                "max_vertices": st.sampled_from([0, 64]),
                "goal_tolerance": st.tuples(st.floats(0.01, 0.04), st.floats(0.01, 0.04)).map(list),
                "max_height_margin": st.floats(0.0, 0.5),
            },
        ),
        "kinematics": st.fixed_dictionaries({}, optional={"foot_length": st.floats(0.15, 0.22)}),
        "reward": st.fixed_dictionaries(
            {},
            optional={
                "traj_weights": st.lists(st.floats(0.0, 5.0), min_size=8, max_size=8).map(
                    lambda w: [1.0] + w[1:]
                ),
                "exo_weights": st.lists(st.floats(0.1, 5.0), min_size=4, max_size=4),
                "goal_reward": st.floats(0.0, 50.0),
                "hlc_threshold": st.floats(0.5, 1.0),
                "progress_shaping": st.floats(0.0, 10.0),
                "shaping_discount": st.floats(0.5, 1.0),
            },
        ),
        "layout": st.fixed_dictionaries(
            {
                "obstacles": st.lists(OBSTACLE, min_size=1, max_size=6).map(
                    lambda obs: obs + ["base1"]
                )
            },
            optional={
                "pivot": st.one_of(
                    st.lists(st.sampled_from(PIVOT_CONDITIONS), min_size=1, unique=True),
                    st.lists(st.floats(0.1, 2.0), min_size=3, max_size=3),
                ),
                "size_jitter": st.floats(0.0, 0.2),
                "start_shift": _lohi(0.0, 0.03),
                "obstacle_offset": _lohi(-0.02, 0.02),
                "step_length": _lohi(0.7, 0.8),
                "terrain": TERRAIN,
            },
        ),
        "train": st.fixed_dictionaries(
            {},
            optional={
                "num_envs": st.sampled_from([1, 8, 64, 1024]),
                "rollout_steps": st.integers(1, 64),
                "hidden": st.lists(st.integers(1, 256), min_size=1, max_size=4),
                "layer_norm": st.booleans(),
                "trace": st.sampled_from(TRACE_VIEWS),
                "trace_kind": st.sampled_from(TRACE_KINDS),
                "control": st.sampled_from(CONTROLS),
                "target": st.sampled_from(TARGETS),
                "budget_episodes": st.integers(0, 10**6),
                "budget_env_steps": st.integers(1, 10**9),
                "lr": st.floats(1e-6, 1.0),
                "gamma": st.floats(0.0, 1.0),
                "lam": st.floats(0.0, 1.0),
                "target_period": st.integers(1, 2**31 - 1),
                "target_tau": st.floats(1e-3, 1.0),
                "eps_end": st.floats(0.0, 0.5),
                "chunk_updates": st.integers(0, 1000),
            },
        ),
    }
)


@settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(raw=RAW)
def test_drawn_configs_roundtrip_through_the_writer(raw):
    raw["train"]["num_minibatches"] = 1
    try:
        cfg = config_from_dict(legacy_raw(raw))
    except ConfigError:
        assume(
            False
        )  # a drawn combination that validation refuses (e.g. a jittered obstacle too wide)
    assert roundtrip(cfg) == cfg


def test_drawn_configs_cover_every_kind():
    """The strategy above can draw each thesis name, each shape with sizes, and a profile."""
    kinds = set()

    @settings(max_examples=200, deadline=None, database=None)
    @given(OBSTACLE)
    def collect(o):
        kinds.add(o if isinstance(o, str) else (o["kind"], "width" in o or "points" in o))

    collect()
    for name in THESIS_OBSTACLES:
        assert name in kinds or (name, False) in kinds
    for shape in ("rectangle", "triangle", "half_ellipse", "profile"):
        assert (shape, True) in kinds


def test_thesis_triangle_and_triangle_shape_roundtrip(tmp_path):
    """The thesis "triangle" (fixed size) and the "triangle" shape with sizes share a name; a run
    directory's config.toml must load again for both (it failed: 'triangle has the fixed size')."""
    cfg = config_from_dict(
        legacy_raw(
            {
                "layout": {
                    "obstacles": [
                        "triangle",
                        "half_circle",
                        {
                            "kind": "triangle",
                            "width": [0.08, 0.16],
                            "height": [0.1, 0.2],
                            "weight": 2.0,
                        },
                        {"kind": "triangle", "width": 0.2, "height": 0.2},
                    ]
                }
            }
        )
    )
    again = roundtrip(cfg, tmp_path)
    assert again == cfg
    obs = again.layout.obstacles
    assert obs[0].is_thesis and obs[0].width == (0.2, 0.2)
    assert not obs[2].is_thesis and obs[2].width == (0.08, 0.16) and obs[2].weight == 2.0
    assert obs[3] == obs[0]  # the shape at the thesis size is the thesis triangle
    with pytest.raises(
        ConfigError, match=r"^layout\.obstacles\[0\]\.width: base1 has the fixed size"
    ):
        config_from_dict(
            legacy_raw({"layout": {"obstacles": [{"kind": "base1", "width": 0.1, "height": 0.1}]}})
        )


# --------------------------------------------------------------------------------------------
# Shipped files
# --------------------------------------------------------------------------------------------

SHIPPED = sorted(p.relative_to(PACKAGE) for p in PACKAGE.rglob("*.toml"))


def test_package_ships_the_default_and_thesis_configs():
    names = {str(p) for p in SHIPPED}
    assert "default.toml" in names
    assert {f"thesis/{m}.toml" for m in ("a", "b", "c", "1", "2", "3", "final")} <= names


@pytest.mark.parametrize("rel", SHIPPED, ids=str)
def test_repository_copies_are_byte_equal_to_the_packaged_configs(rel):
    """configs/X is a copy of jaxexo/config/X (the package's file is the original): never a second
    version that can drift. To update: cp jaxexo/config/X configs/X."""
    assert (ROOT / "configs" / rel).read_bytes() == (PACKAGE / rel).read_bytes(), (
        f"configs/{rel} differs from jaxexo/config/{rel}: copy the packaged file over it"
    )


def test_every_repository_config_is_shipped():
    repo = {
        p.relative_to(ROOT / "configs")
        for p in (ROOT / "configs").rglob("*.toml")
        if "sweeps" not in p.parts
    }
    assert repo == set(SHIPPED)


CONFIG_FILES = sorted(
    {
        *(ROOT / "configs").glob("*.toml"),
        *(ROOT / "configs" / "thesis").glob("*.toml"),
        *PACKAGE.rglob("*.toml"),
    }
)


@pytest.mark.parametrize("path", CONFIG_FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_config_files_roundtrip(path, tmp_path):
    cfg = load_config(path)
    assert roundtrip(cfg, tmp_path) == cfg


@pytest.mark.parametrize(
    "path", sorted((ROOT / "configs" / "sweeps").glob("*.toml")), ids=lambda p: p.name
)
def test_sweep_member_configs_roundtrip(path):
    from jaxexo.sweep.spec import load_sweep

    sweep = load_sweep(path)
    for m in sweep.members[:: max(1, len(sweep.members) // 4)]:
        assert roundtrip(m.config) == m.config


def test_cli_default_is_the_packaged_file():
    from jaxexo import cli
    from jaxexo.cli.common import load

    assert cli.DEFAULT_CONFIG.resolve() == (PACKAGE / "default.toml").resolve()
    cfg, name = load(None)
    assert cfg == load_config(ROOT / "configs" / "default.toml") and name == str(cli.DEFAULT_CONFIG)
    # One default: the packaged default is Config(), and a missing file is refused
    # (tests/test_config.py), never read as an empty one.
    assert cfg == Config()


@pytest.mark.slow
def test_wheel_contains_the_configs(tmp_path):
    """A non-editable install gets the same default model: the configs are package data."""
    res = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-w", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    if res.returncode != 0 and (
        "No matching distribution" in res.stderr or "Could not find" in res.stderr
    ):
        pytest.skip(
            "pip cannot fetch the build backend (offline): " + res.stderr.strip().splitlines()[-1]
        )
    assert res.returncode == 0, res.stderr
    (wheel,) = tmp_path.glob("jaxexo-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    for rel in SHIPPED:
        assert f"jaxexo/config/{rel}" in names
        assert zipfile.ZipFile(wheel).read(f"jaxexo/config/{rel}") == (PACKAGE / rel).read_bytes()
