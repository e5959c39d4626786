"""Values that make a result nonsense are refused at the boundary, naming the option or field: swing
durations, control rates and path samples below a swing's physical scale, obstacles beyond the one
size bound (config, generator API and CLI alike), joint limits beyond a turn, seeds beyond
PRNGKey's range, empty or duplicated choices, non-boolean flags; sweep grids beyond their stated
limit, counted before they are built; refusals that leave no half-made run folder; resume messages
that name the field. docs/reliability.md lists these cases.

No training: the CLI runs stop at their checks (or at a checkpoint that cannot be read).
"""

from __future__ import annotations

import copy
import time

import pytest

from jaxexo.config import ConfigError, config_from_dict, load_config
from jaxexo.physics.geometry import MAX_OBSTACLE_HEIGHT, MAX_OBSTACLE_WIDTH, GeometryError, Obstacle

from conftest import ROOT
from test_reliability_inputs import assert_clean_refusal, make_policy, run_cli


def cli_error(capsys, *argv) -> str:
    """Run the CLI in this process; assert it refused (exit 2) and return its one error line."""
    from jaxexo.cli import main

    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("jaxexo: error:") and len(err.splitlines()) == 1, err
    return err


GEN = ("generate", "--method", "cfftg", "--obstacle")


@pytest.fixture(scope="module")
def generator(tmp_path_factory):
    from jaxexo.inference import TrajectoryGenerator

    return TrajectoryGenerator.load(make_policy(tmp_path_factory.mktemp("policy") / "policy.npz"))


# --------------------------------------------------------------------------------------------
# jaxexo generate and the generator API
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "extra, needles",
    [
        (["--duration", "1e-300"], ["--duration must be >= 0.01 s"]),
        (["--rate", "1e-9"], ["--rate: control rate must be between 10 and 10000 Hz"]),
        (["--points", "2"], ["--points must be an integer in [20, 100000]"]),
    ],
)
def test_generate_refuses_values_below_a_swings_scale(tmp_path, capsys, extra, needles):
    err = cli_error(capsys, *GEN, "base1", "--out", tmp_path / "t.csv", *extra)
    for n in needles:
        assert n in err, err
    assert list(tmp_path.iterdir()) == []


RATE_REFUSAL = "--rate: control rate must be between 10 and 10000 Hz, got 5"


def test_walk_refuses_a_rate_below_the_bound_naming_the_option(tmp_path, capsys):
    """The one rate check (the timing's), at the boundary: before the terrain is read."""
    terrain = tmp_path / "none.csv"  # never read: the refusal comes first
    err = cli_error(
        capsys, "walk", "--method", "cfftg", "--terrain", terrain, "--out", tmp_path / "w.csv",
        "--rate", "5",
    )  # fmt: skip
    assert RATE_REFUSAL in err, err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("option", ["--rate", "--reference-rate"])
def test_replay_refuses_a_rate_below_the_bound_naming_the_option(tmp_path, capsys, option):
    """replay's rates by the same check, before MuJoCo or the policy is needed."""
    err = cli_error(
        capsys, "replay", "--policy", tmp_path / "none.npz", "--obstacle", "base1", option, "5"
    )
    assert RATE_REFUSAL.replace("--rate", option) in err, err
    assert list(tmp_path.iterdir()) == []


def test_the_api_refuses_the_same_values(generator):
    from jaxexo.baselines import CFFTG
    from jaxexo.swing.timing import time_swing

    ob = Obstacle.named("base1")
    with pytest.raises(ValueError, match="duration must be >= 0.01 s"):
        generator.generate(ob, duration=1e-300)
    with pytest.raises(ValueError, match=r"n_points must be an integer in \[20, "):
        generator.generate(ob, n_points=2)
    with pytest.raises(ValueError, match=r"n_points must be an integer in \[20, "):
        CFFTG(None).generate(ob, n_points=2)
    traj = CFFTG(generator.config).generate(ob)
    with pytest.raises(ValueError, match="rate: control rate must be between 10 and"):
        time_swing(traj, generator.config, rate=1e-9)
    with pytest.raises(ConfigError, match=r"device.control_rate: must be >= 10"):
        config_from_dict({"device": {"control_rate": 1e-9}})


def test_the_shortest_accepted_swing_has_distinct_time_stamps():
    from jaxexo.baselines import CFFTG
    from jaxexo.swing.options import MIN_DURATION, MIN_POINTS

    traj = CFFTG(None).generate(Obstacle.named("base1"), n_points=MIN_POINTS, duration=MIN_DURATION)
    times = [float(row.split(",")[0]) for row in traj.to_csv().splitlines()[1:]]
    assert len(set(times)) == MIN_POINTS and times[-1] == pytest.approx(MIN_DURATION)


@pytest.mark.parametrize("flag, value", [("strict", "yes"), ("strict", "no"), ("strict", 1)])
def test_flags_are_booleans_only(generator, flag, value):
    with pytest.raises(TypeError, match=f"{flag}: expected True or False"):
        generator.generate(Obstacle.named("base1"), **{flag: value})
    with pytest.raises(TypeError, match=f"{flag}: expected True or False"):
        generator.generate_batch([Obstacle.named("base1")], **{flag: value})


def test_cfftg_strict_is_a_boolean_only():
    from jaxexo.baselines import CFFTG

    with pytest.raises(TypeError, match="strict: expected True or False"):
        CFFTG(None).generate(Obstacle.named("base1"), strict="yes")


def test_options_are_one_checked_record(generator):
    """GenerateOptions is checked when made (the error names the field) and frozen; ``generate`` takes
    it whole, its keywords replace fields, and a keyword that is no option (``fast``, the reference
    switch that is no longer public) is named; CFFTG takes the fields it has."""
    import dataclasses

    from jaxexo.baselines import CFFTG
    from jaxexo.inference import GenerateOptions, SwingOptions

    with pytest.raises(ValueError, match="^n_points must be an integer"):
        GenerateOptions(n_points=5)
    with pytest.raises(ValueError, match="^smoothing must be >= 0"):
        GenerateOptions(smoothing=-1.0)
    with pytest.raises(ValueError, match="^fallback must be 'cfftg' or None"):
        GenerateOptions(fallback="rl")
    assert GenerateOptions(fallback="none").fallback is None  # as the command line spells it
    o = GenerateOptions(pivot="between", fallback=None, n_points=60)
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.n_points = 70
    ob = Obstacle.named("base1")
    a = generator.generate(ob, o)
    b = generator.generate(ob, pivot="between", fallback=None, n_points=60)
    assert a.heel.shape == (60, 2) and (a.heel == b.heel).all() and a.checks == b.checks
    assert generator.generate(ob, o, n_points=80).heel.shape == (
        80,
        2,
    )  # a keyword replaces a field
    for call in (generator.generate, generator.generate_batch):
        arg = ob if call == generator.generate else [ob]
        with pytest.raises(
            TypeError, match=r"^fast: not an option of generate(_batch)? \(options: pivot, "
        ):
            call(arg, fast=False)
        with pytest.raises(TypeError, match="^options: expected GenerateOptions, got dict"):
            call(arg, {"n_points": 60})
    cf = CFFTG(generator.config)
    with pytest.raises(TypeError, match=r"^fallback: not an option of CFFTG.generate \(options: "):
        cf.generate(ob, fallback=None)
    assert (
        cf.generate(ob, o).heel == cf.generate(ob, SwingOptions(pivot="between", n_points=60)).heel
    ).all()


# --------------------------------------------------------------------------------------------
# One obstacle-size bound: config, API and CLI
# --------------------------------------------------------------------------------------------


def test_one_obstacle_size_bound_for_the_config_the_api_and_the_cli(tmp_path, capsys):
    assert (MAX_OBSTACLE_WIDTH, MAX_OBSTACLE_HEIGHT) == (1.0, 0.6)
    with pytest.raises(GeometryError, match="height must be <= 0.6 metres, got 5"):
        Obstacle.rectangle(0.2, 5.0)
    with pytest.raises(GeometryError, match="width must be <= 1 metres"):
        Obstacle.half_ellipse(1.5, 0.1)
    with pytest.raises(GeometryError, match=r"points \(height\) must be <= 0.6"):
        Obstacle.profile([(0.3, 0.0), (0.4, 0.7), (0.5, 0.0)])
    Obstacle.rectangle(MAX_OBSTACLE_WIDTH, MAX_OBSTACLE_HEIGHT)  # the bound itself is accepted
    with pytest.raises(
        ConfigError, match=r"layout.obstacles\[0\].height\[1\]: must be <= 0.6, got 5"
    ):
        config_from_dict(
            {"layout": {"obstacles": [{"kind": "rectangle", "width": 0.2, "height": [0.1, 5.0]}]}}
        )
    err = cli_error(capsys, *GEN, "rectangle", "--height", "5", "--out", tmp_path / "t.csv")
    assert "--height: height must be <= 0.6 metres, got 5" in err
    err = cli_error(capsys, *GEN, "rectangle", "--width", "1e300", "--out", tmp_path / "t.csv")
    assert "--width: width must be <= 1 metres, got 1e+300" in err and "0000000000" not in err
    err = cli_error(capsys, *GEN, "base1", "--center-y", "1e300", "--out", tmp_path / "t.csv")
    assert "--step-length" in err and "1e+300 m" in err and "0000000000" not in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "option, suggestion",
    [
        ("--animate", "swing.gif"),
        ("--json", "trajectory.json"),
        ("--plot", "swing.png"),
        ("--out", "trajectory.csv"),
    ],
)
def test_a_folder_given_as_an_output_suggests_a_file_of_its_kind(
    tmp_path, capsys, option, suggestion
):
    argv = [*GEN, "base1", "--out", tmp_path / "t.csv"] if option != "--out" else [*GEN, "base1"]
    err = cli_error(capsys, *argv, option, tmp_path)
    assert f"{option}: {tmp_path} is a directory" in err and f"{tmp_path / suggestion}" in err


# --------------------------------------------------------------------------------------------
# Every physical field has its physical bound
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "raw, message",
    [
        (
            {"kinematics": {"hip_limits": [-100.0, 100.0]}},
            r"kinematics.hip_limits\[0\]: must be >= -3.14",
        ),
        (
            {"kinematics": {"knee_limits": [-1.0, 7.0]}},
            r"kinematics.knee_limits\[1\]: must be <= 3.14",
        ),
        ({"env": {"step_size": 5.0}}, r"env.step_size: must be <= 0.1"),
        ({"env": {"max_z": 100.0}}, r"env.max_z: must be <= 2"),
        ({"env": {"min_clearance": 1.0}}, r"env.min_clearance: must be <= 0.1"),
        ({"env": {"bounds_y": [-1e6, 1.3]}}, r"env.bounds_y\[0\]: must be >= -10"),
        ({"env": {"goal_tolerance": [5.0, 0.02]}}, r"env.goal_tolerance\[0\]: must be <= 0.5"),
        ({"reward": {"safety_distance": 3.0}}, r"reward.safety_distance: must be <= 0.5"),
        ({"reward": {"max_hip_z": 50.0}}, r"reward.max_hip_z: must be <= 2"),
        ({"reward": {"goal_reward": 1e30}}, r"reward.goal_reward: must be <= 1000000"),
        (
            {"reward": {"traj_weights": [1e300] * 8}},
            r"reward.traj_weights\[0\]: must be <= 1000000",
        ),
        ({"layout": {"step_length": [0.65, 50.0]}}, r"layout.step_length\[1\]: must be <= 2"),
        ({"layout": {"start_shift": [0.0, 9.0]}}, r"layout.start_shift\[1\]: must be <= 1"),
        (
            {"layout": {"obstacle_offset": [-5.0, 0.0]}},
            r"layout.obstacle_offset\[0\]: must be >= -1",
        ),
        (
            {"layout": {"terrain": {"step_length": [0.55, 30.0]}}},
            r"layout.terrain.step_length\[1\]: must be <= 2",
        ),
    ],
)
def test_every_physical_field_has_its_physical_bound(raw, message):
    with pytest.raises(ConfigError, match=message):
        config_from_dict(raw)


def test_every_shipped_config_is_within_the_bounds():
    for path in sorted((ROOT / "configs").rglob("*.toml")):
        if "sweeps" not in path.parts:
            load_config(path)


# --------------------------------------------------------------------------------------------
# Seeds, and no half-made run folder on a refusal
# --------------------------------------------------------------------------------------------


def test_a_seed_beyond_the_bound_is_refused_and_leaves_no_run_folder(tmp_path):
    cfg = tmp_path / "tiny.toml"
    cfg.write_text("[train]\nbudget_env_steps = 1024\nnum_envs = 64\npopulation = 1\n")
    out = tmp_path / "new" / "run"
    r = run_cli(
        "train", cfg, "--out", out, "--seed", "1180591620717411303424", "--quiet", timeout=300
    )
    assert_clean_refusal(r, "--seed", "a seed must be in [0, 2147483647]")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tiny.toml"]
    from jaxexo.config import check_seed

    with pytest.raises(
        ConfigError, match=r"--seed: a seed must be in \[0, 2147483644\] \(with 3 more seeds"
    ):
        check_seed(2147483645, "--seed", 4)
    with pytest.raises(ConfigError, match="expected an integer seed"):
        check_seed(True)


def test_a_refusal_inside_a_new_run_folder_removes_what_it_made(tmp_path):
    from jaxexo.storage.rundir import run_lock

    out = tmp_path / "a" / "b"
    with pytest.raises(ConfigError):
        with run_lock(out, "train", scratch=("config.toml",)):
            (out / "config.toml").write_text("x\n")
            raise ConfigError("refused")
    assert list(tmp_path.iterdir()) == []
    # A failed write (a full disk) keeps what was made: that run is resumed from scratch.
    with pytest.raises(OSError):
        with run_lock(out, "train", scratch=("config.toml",)):
            (out / "config.toml").write_text("x\n")
            raise OSError(28, "No space left on device")
    assert (out / "config.toml").exists()
    # A folder that existed before is never removed.
    keep = tmp_path / "keep"
    keep.mkdir()
    with pytest.raises(ConfigError):
        with run_lock(keep, "train", scratch=("config.toml",)):
            raise ConfigError("refused")
    assert keep.is_dir()


def test_reproduce_refuses_no_models_and_a_seed_beyond_the_bound(tmp_path, capsys):
    assert "--models: name at least one model" in cli_error(
        capsys, "reproduce", "--out", tmp_path / "r", "--models", ""
    )
    err = cli_error(
        capsys, "reproduce", "--out", tmp_path / "r", "--models", "a", "--seed", "2147483647"
    )
    assert "--seed: a seed must be in [0, 2147483644] (with 3 more seeds" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("value", ["-1", "nan", "inf", "0"])
def test_bench_refuses_a_baseline_budget_that_is_no_time(tmp_path, capsys, value):
    err = cli_error(capsys, "bench", "--out", tmp_path / "b", f"--baseline-seconds={value}")
    assert "--baseline-seconds: a time budget must be a finite number of seconds > 0" in err
    assert list(tmp_path.iterdir()) == []


def test_sweep_refuses_zero_task_cpus_on_any_backend(tmp_path, capsys):
    err = cli_error(
        capsys,
        "sweep",
        ROOT / "configs" / "sweeps" / "smoke.toml",
        "--out",
        tmp_path / "s",
        "--task-cpus",
        "0",
    )
    assert "--task-cpus: must be >= 1, got 0" in err


# --------------------------------------------------------------------------------------------
# Sweeps: a grid's size before it is built, duplicates, and checks that do not grow with it
# --------------------------------------------------------------------------------------------


def _sweep(grid: dict, **sweep):
    from jaxexo.sweep.spec import sweep_from_dict

    base = load_config(ROOT / "configs" / "quick.toml")
    import tomllib

    from jaxexo.config.toml_io import config_to_toml

    return sweep_from_dict(
        {**tomllib.loads(config_to_toml(base)), "sweep": {"grid": grid, **sweep}}
    )


def test_a_grid_beyond_the_limit_is_refused_from_its_axes_at_once():
    from jaxexo.sweep.spec import MAX_CONFIGURATIONS

    t0 = time.perf_counter()
    with pytest.raises(
        ConfigError,
        match=r"sweep.grid: 1,000,000 configurations \(1,000 x 1,000\), more than "
        r"the 10,000 a sweep may have",
    ):
        _sweep(
            {
                "train.lr": [1e-4 * (1 + i) for i in range(1000)],
                "train.lam": [i / 1000 for i in range(1000)],
            }
        )
    assert time.perf_counter() - t0 < 5.0
    assert MAX_CONFIGURATIONS == 10_000


def test_a_value_listed_twice_is_refused_naming_the_axis():
    with pytest.raises(
        ConfigError,
        match=r"sweep.grid.train.lr: the value 0.001 is listed twice \(values 0 and 1\)",
    ):
        _sweep({"train.lr": [1e-3, 0.001]})


def test_a_grids_members_share_one_scene_check_and_equal_the_config_files(monkeypatch):
    from jaxexo.config import consistency

    calls = []
    real = consistency._check_scene
    monkeypatch.setattr(consistency, "_check_scene", lambda cfg: (calls.append(1), real(cfg))[1])
    consistency._SCENES_OK.clear()
    lrs = [1e-4 * (1 + i) for i in range(40)]
    lams = [0.5 + 0.01 * i for i in range(40)]
    t0 = time.perf_counter()
    sweep = _sweep({"train.lr": lrs, "train.lam": lams, "reward.traj_weights[3]": [2.0, 4.0]})
    elapsed = time.perf_counter() - t0
    assert len(sweep.members) == 3200 and len(calls) == 1, len(calls)
    assert elapsed < 20.0, elapsed
    # Independent reference: a config file with the values written in, read the ordinary way.
    base = sweep.raw
    for m in sweep.members[::397]:
        raw = copy.deepcopy(base)
        raw["train"]["lr"], raw["train"]["lam"] = m.values["train.lr"], m.values["train.lam"]
        raw["reward"]["traj_weights"][3] = m.values["reward.traj_weights[3]"]
        assert config_from_dict(raw) == m.config


def test_a_bad_value_in_a_fast_built_grid_is_still_named():
    with pytest.raises(
        ConfigError, match=r"sweep.grid.train.gamma: configuration 1 \(train.gamma=2\).*train.gamma"
    ):
        _sweep({"train.gamma": [0.9, 2.0]})
    with pytest.raises(
        ConfigError, match=r"sweep.grid.layout.step_length: configuration 1 .*layout.step_length"
    ):
        _sweep({"layout.step_length": [[0.65, 0.75], [0.65, 40.0]]})


# --------------------------------------------------------------------------------------------
# Resume: the field that differs, and the run's own config
# --------------------------------------------------------------------------------------------


def test_resume_with_another_config_names_the_field_and_both_values(tmp_path):
    import dataclasses

    from jaxexo.config.toml_io import config_to_toml
    from jaxexo.train.run_dir import prepare_dir

    cfg = load_config(ROOT / "configs" / "quick.toml")
    (tmp_path / "config.toml").write_text(config_to_toml(cfg))
    other = dataclasses.replace(cfg, train=dataclasses.replace(cfg.train, lr=cfg.train.lr * 2))
    with pytest.raises(
        ConfigError,
        match=r"config differs from the run's config .*config.toml in train.lr "
        r"\(given 0.00\d+, the run has 0.00\d+\)",
    ):
        prepare_dir(tmp_path, other, 0, resume=True)


def test_resume_without_a_config_path_uses_the_runs_config(tmp_path, monkeypatch):
    from jaxexo.cli import main
    from jaxexo.config.toml_io import config_to_toml
    from jaxexo.train import driver

    run = tmp_path / "run"
    run.mkdir()
    cfg = load_config(ROOT / "configs" / "quick.toml")
    (run / "config.toml").write_text(config_to_toml(cfg))
    (run / "checkpoint.msgpack").write_bytes(b"not a checkpoint")
    given = []
    monkeypatch.setattr(driver, "run_training", lambda c, *a, **k: (given.append(c), {})[1])
    with pytest.raises(
        KeyError
    ):  # the stand-in returns no results: the config it got is what counts
        main(["train", "--out", str(run), "--resume", "--quiet"])
    assert given == [cfg]
