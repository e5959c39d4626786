"""Nothing lost, round four: the training extra declares what the compilation cache needs,
outputs follow the umask, every count and size is bounded before any work, files are parsed as their
format says, records check their fields when made, one rule per option across commands, and messages
name the option as typed and the bound. docs/reliability.md lists these cases.
"""

from __future__ import annotations

import os
import re
import stat
import tomllib

import pytest

from conftest import ROOT, run_cli
from test_reliability_inputs import assert_clean_refusal

# --------------------------------------------------------------------------------------------
# The README's first command: the train extra brings what JAX's persistent cache needs
# --------------------------------------------------------------------------------------------


def _requirement_names(reqs: list[str]) -> set[str]:
    return {re.split(r"[<>=!~;\[ ]", r, maxsplit=1)[0].strip().lower() for r in reqs}


def test_the_train_extra_declares_what_the_compilation_cache_imports():
    """JAX's size-bounded persistent cache (which use_compilation_cache turns on) imports filelock;
    without it every `jaxexo train` warns and compiles from scratch. The test extra brings filelock
    through other packages, so only the declaration proves the train-only venv has it."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    train = _requirement_names(project["optional-dependencies"]["train"])
    assert "filelock" in train
    import filelock  # noqa: F401 - the declared package is importable here
    from jax._src import lru_cache

    assert lru_cache.filelock is not None  # what JAX itself found at import


# --------------------------------------------------------------------------------------------
# Outputs follow the umask; a file replaced keeps its mode
# --------------------------------------------------------------------------------------------


@pytest.fixture
def umask():
    """Sets the process's umask for the test (returns the setter), restoring it after."""
    before = os.umask(0o022)
    os.umask(before)
    yield os.umask
    os.umask(before)


@pytest.mark.parametrize("mask, mode", [(0o002, 0o664), (0o022, 0o644), (0o077, 0o600)])
def test_new_outputs_are_created_with_the_umasks_mode(tmp_path, umask, mask, mode):
    from jaxexo.storage.atomic import append_line, atomic_write

    umask(mask)
    atomic_write(tmp_path / "policy.npz", b"x")
    append_line(tmp_path / "metrics.jsonl", "{}\n")
    assert oct(stat.S_IMODE(os.stat(tmp_path / "policy.npz").st_mode)) == oct(mode)
    assert oct(stat.S_IMODE(os.stat(tmp_path / "metrics.jsonl").st_mode)) == oct(mode)


def test_an_existing_file_keeps_its_mode_when_replaced(tmp_path, umask):
    from jaxexo.storage.atomic import atomic_write

    umask(0o077)
    shared = tmp_path / "shared.csv"
    shared.write_text("old\n")
    os.chmod(shared, 0o664)
    atomic_write(shared, "new\n")
    assert shared.read_text() == "new\n"
    assert oct(stat.S_IMODE(os.stat(shared).st_mode)) == oct(0o664)


# --------------------------------------------------------------------------------------------
# Every count and size bounded before any work, naming the option and the bound
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "option, value, bound",
    [("--n", "100000000", "100,000"), ("--batch", "1000000000", "100,000"), ("--n", "0", "1")],
)
def test_eval_bounds_its_counts_before_any_work(tmp_path, option, value, bound):
    # No policy at all: the bound is checked before the policy is read.
    r = run_cli("eval", "--policy", tmp_path / "none.npz", option, value, "--out", tmp_path / "rep")
    assert_clean_refusal(r, f"{option}: ", bound, value)
    assert not (tmp_path / "rep").exists()


def test_reproduce_bounds_its_scenario_count():
    from jaxexo.evaluation.reproduce import check_reproduce_options

    with pytest.raises(ValueError, match="--n: .* from 1 to 100,000, got 100000000"):
        check_reproduce_options("/tmp/unused-reproduce", 100_000_000)


# --------------------------------------------------------------------------------------------
# Terrain files parsed as their format says: JSON depth and digits, CSV numbers, byte-order marks
# --------------------------------------------------------------------------------------------


def _terrain(tmp_path, name: str, data: bytes):
    from jaxexo.storage.terrain_file import read_terrain

    path = tmp_path / name
    path.write_bytes(data)
    return path, lambda: read_terrain(path)


@pytest.mark.parametrize(
    "name, data, message",
    [
        ("deep.json", b"[" * 100_000 + b"]" * 100_000, "nested deeper"),
        ("digits.json", b"[[0, 0], [1, " + b"9" * 5000 + b"]]", "more than 4300 digits"),
        ("huge.json", b"[[0, 0], [1, " + b"9" * 4000 + b"]]", "too large for metres"),
        ("under.csv", b"y,z\n0,0\n1_0,0\n", "line 3: y is not a number: '1_0'"),
        ("arabic.csv", "y,z\n0,0\n\u0661,0\n".encode(), "line 3: y is not a number"),
    ],
)
def test_terrain_files_are_refused_naming_the_file(tmp_path, name, data, message):
    from jaxexo.storage.terrain_file import TerrainFileError

    path, read = _terrain(tmp_path, name, data)
    with pytest.raises(TerrainFileError) as e:
        read()
    assert str(path) in str(e.value) and message in str(e.value), str(e.value)


def test_a_deep_terrain_json_is_a_clean_refusal_at_the_cli(tmp_path):
    path, _ = _terrain(tmp_path, "deep.json", b"[" * 100_000 + b"]" * 100_000)
    r = run_cli("walk", "--method", "cfftg", "--terrain", path, "--out", tmp_path / "walk.csv")
    assert_clean_refusal(r, str(path), "nested deeper")


@pytest.mark.parametrize(
    "name, data",
    [
        ("bom.csv", b"\xef\xbb\xbfy,z\n0,0\n1,0.5e-1\n"),
        ("bom.json", b'\xef\xbb\xbf{"points": [[0, 0], [1, 0.05]]}'),
        ("brackets.json", b'{"note": "[[[[", "points": [[0, 0], [1, 0.05]]}'),
    ],
)
def test_byte_order_marks_and_csv_numbers_are_read(tmp_path, name, data):
    _, read = _terrain(tmp_path, name, data)
    assert read().points.tolist() == [[0.0, 0.0], [1.0, 0.05]]


# --------------------------------------------------------------------------------------------
# metrics.jsonl is JSON: a diverged chunk's NaN is written as null and read back as NaN
# --------------------------------------------------------------------------------------------


def test_a_diverged_rows_non_finite_numbers_are_written_as_null_and_read_back(tmp_path):
    pytest.importorskip("flax")
    import json
    import math

    from jaxexo.train import metrics_log

    def strict(constant):
        raise AssertionError(f"{constant} is not JSON")

    row = {"chunk": 1, "loss": float("nan"), "q_mean": float("inf"), "accuracy": 0.5, "label": "x"}
    row["members"] = [{"loss": float("-inf"), "validation_success_raw": None}]
    line = metrics_log.metrics_line(row)
    parsed = json.loads(line, parse_constant=strict)
    assert parsed["loss"] is None and parsed["members"][0]["loss"] is None
    (tmp_path / "metrics.jsonl").write_text(line)
    back = metrics_log.read_metrics_rows(tmp_path / "metrics.jsonl", 1)[0]
    assert math.isnan(back["loss"]) and math.isnan(back["q_mean"]) and back["accuracy"] == 0.5
    assert back["members"][0]["validation_success_raw"] is None  # a null that means "none"


# --------------------------------------------------------------------------------------------
# Records check their fields when made, naming the field
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "fields, message",
    [
        ({"pivot": "x"}, "pivot must be one of"),
        ({"pivot": ["agent", "x"]}, r"pivot\[1\] must be one of"),
        ({"pivot_y": float("nan")}, "pivot_y must be finite"),
        ({"clearance": float("nan")}, "clearance must be a finite number"),
        ({"clearance": 5.0}, "clearance must be a finite number of metres in"),
        ({"start_y": float("inf")}, "start_y must be finite"),
        ({"start_y": [0.0, float("inf")]}, r"start_y\[1\] must be finite"),
        ({"step_length": -0.7}, "step_length must be > 0"),
    ],
)
def test_generate_options_check_the_scene_and_clearance_when_made(fields, message):
    from jaxexo.inference import GenerateOptions, SwingOptions

    for record in (GenerateOptions, SwingOptions):
        with pytest.raises(ValueError, match=message):
            record(**fields)


def test_generate_options_still_take_per_obstacle_columns_and_a_pivot_y():
    from jaxexo.inference import GenerateOptions

    o = GenerateOptions(pivot=["agent", None], pivot_y=[None, 0.3], start_y=(0.0, 0.05))
    assert o.start_y == (0.0, 0.05)
    assert GenerateOptions(clearance=0.05, pivot=0.3).clearance == 0.05


# --------------------------------------------------------------------------------------------
# Outputs: --animate is a GIF, an empty option says so
# --------------------------------------------------------------------------------------------

GEN = ("generate", "--method", "cfftg")
GEN_BASE1 = (*GEN, "--obstacle", "base1")


@pytest.mark.parametrize(
    "args, needles",
    [
        (["--out", "t.csv", "--animate", "x.png"], ["--animate", "x.png", "GIF", ".gif"]),
        (["--out", "t.csv", "--animate", "x"], ["--animate", "GIF", ".gif"]),
        (["--out", ""], ["--out: the option is empty"]),
        (["--out", "t.csv", "--json", ""], ["--json: the option is empty"]),
        (["--out", "t.csv", "--fallback", "none"], ["--fallback", "--method rl only"]),
        (["--out", "t.csv", "--fallback", "cfftg"], ["--fallback", "--method rl only"]),
    ],
)
def test_generate_refuses_outputs_and_options_it_cannot_honour(tmp_path, args, needles):
    args = [str(tmp_path / a) if a and a != "none" and "." in a or a == "x" else a for a in args]
    r = run_cli(*GEN_BASE1, *args)
    assert_clean_refusal(r, *needles)
    assert list(tmp_path.iterdir()) == []


def test_an_animation_named_gif_is_accepted_in_any_case(tmp_path):
    from jaxexo.cli.common import check_output_file

    check_output_file("--animate", tmp_path / "walk.GIF")
    check_output_file("--animate", "-")  # standard output takes the bytes as they are


def test_walk_and_generate_share_one_fallback_rule(tmp_path):
    terrain = tmp_path / "t.csv"
    terrain.write_text("0,0\n3,0\n")
    for fallback in ("none", "cfftg"):
        r = run_cli(
            "walk", "--method", "cfftg", "--fallback", fallback, "--terrain", terrain, "--out",
            tmp_path / "w.csv",
        )  # fmt: skip
        assert_clean_refusal(r, "--fallback", "--method rl only")


# --------------------------------------------------------------------------------------------
# jaxexo mjcf: --config is used (or refused with --policy), the pose exists
# --------------------------------------------------------------------------------------------


def test_mjcf_uses_its_config_and_refuses_one_beside_a_policy(tmp_path):
    from test_reliability_inputs import make_policy

    cfg = tmp_path / "long.toml"
    cfg.write_text("[kinematics]\nthigh = 0.55\nshin = 0.55\n")
    r = run_cli("mjcf", "--config", cfg, "--obstacle", "base1", "--out", tmp_path / "a.xml")
    assert r.returncode == 0, r.stderr
    r2 = run_cli("mjcf", "--obstacle", "base1", "--out", tmp_path / "b.xml")
    assert r2.returncode == 0, r2.stderr
    assert (tmp_path / "a.xml").read_text() != (tmp_path / "b.xml").read_text()
    policy = make_policy(tmp_path / "p.npz")
    r = run_cli(
        "mjcf", "--policy", policy, "--config", cfg, "--obstacle", "base1", "--out",
        tmp_path / "c.xml",
    )  # fmt: skip
    assert_clean_refusal(r, "--policy, --config", "give one of them")
    assert not (tmp_path / "c.xml").exists()


@pytest.mark.parametrize("pivot_y", ["50", "-3"])
def test_mjcf_refuses_a_pivot_no_pose_reaches(tmp_path, pivot_y):
    r = run_cli("mjcf", "--obstacle", "base1", "--pivot-y", pivot_y, "--out", tmp_path / "a.xml")
    assert_clean_refusal(r, "--pivot-y", "reach", "thigh + shin")
    assert not (tmp_path / "a.xml").exists()


# --------------------------------------------------------------------------------------------
# Sweeps: the base is one model's config; the memory budget is bounded
# --------------------------------------------------------------------------------------------

SWEEP_AXES = '[sweep]\nseeds = [0]\n[sweep.grid]\n"train.lr" = [0.001, 0.002]\n'


def test_a_sweep_whose_base_is_itself_or_another_sweep_is_refused(tmp_path):
    from jaxexo.config import ConfigError
    from jaxexo.sweep.spec import load_sweep

    own = tmp_path / "own.toml"
    own.write_text(SWEEP_AXES.replace("[sweep]\n", '[sweep]\nbase = "own.toml"\n'))
    with pytest.raises(ConfigError, match=r"own.toml: sweep.base: 'own.toml' is this sweep file"):
        load_sweep(own)
    other = tmp_path / "other.toml"
    other.write_text(SWEEP_AXES.replace("[sweep]\n", '[sweep]\nbase = "plain.toml"\n'))
    (tmp_path / "plain.toml").write_text("[train]\nlr = 0.003\n")
    assert load_sweep(other).members  # a plain config is a base
    on_sweep = tmp_path / "on_sweep.toml"
    on_sweep.write_text(SWEEP_AXES.replace("[sweep]\n", '[sweep]\nbase = "other.toml"\n'))
    with pytest.raises(ConfigError, match="other.toml is a sweep file"):
        load_sweep(on_sweep)
    r = run_cli("sweep", on_sweep, "--out", tmp_path / "run")
    assert_clean_refusal(r, "on_sweep.toml", "sweep.base", "is a sweep file")
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("budget", ["1KiB", "1000", "63MiB"])
def test_a_memory_budget_below_one_agent_is_refused_naming_the_bound(tmp_path, budget):
    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP_AXES)
    r = run_cli("sweep", sweep, "--out", tmp_path / "run", "--memory-budget", budget)
    assert_clean_refusal(r, "--memory-budget", "at least 64 MiB", budget)
    assert not (tmp_path / "run").exists()
    from jaxexo.config import ConfigError
    from jaxexo.sweep.spec import load_sweep

    sweep.write_text(SWEEP_AXES.replace("[sweep]\n", f'[sweep]\nmemory_budget = "{budget}"\n'))
    with pytest.raises(ConfigError, match="sweep.memory_budget: must be at least 64 MiB"):
        load_sweep(sweep)


# --------------------------------------------------------------------------------------------
# Ctrl-C during jaxexo train: one line saying how to resume, exit 130
# --------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_ctrl_c_during_train_says_how_to_resume(tmp_path):
    import shlex
    import signal
    import subprocess
    import time

    from jaxexo.config.toml_io import config_to_toml

    from conftest import SEED, TINY_N, TINY_T, cli_cmd, tiny_config, without_compilation_cache

    cfg_path = tmp_path / "tiny.toml"
    # A budget the run cannot finish before the signal comes, however fast the machine: the tiny
    # default's few updates could end between the config's write and the Ctrl-C.
    cfg_path.write_text(config_to_toml(tiny_config(budget_env_steps=TINY_N * TINY_T * 20_000)))
    run = tmp_path / "run"
    p = subprocess.Popen(
        cli_cmd("train", cfg_path, "--out", run, "--quiet", "--seed", SEED),
        cwd=ROOT,
        env=without_compilation_cache(dict(os.environ)),  # may die mid-write of an entry
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        # As from a terminal: a pytest-xdist worker ignores SIGINT, and a child inherits that, so
        # Python would never raise KeyboardInterrupt there (the run then trains to its end).
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    t0 = time.monotonic()
    # Training under way (its first checkpoint written), not starting up: the signal then always
    # lands in the chunk loop.
    while not (run / "checkpoint.msgpack").exists():
        assert p.poll() is None, p.stderr.read()[-3000:]
        assert time.monotonic() - t0 < 300
        time.sleep(0.01)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=300)
    assert p.returncode == 130, err[-3000:]
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err[-3000:]
    assert "interrupted" in err
    command = err.strip().split("continue it with: ", 1)[1]
    assert shlex.split(command) == [
        "jaxexo", "train", str(cfg_path), "--out", str(run), "--seed", str(SEED), "--resume",
    ]  # fmt: skip


# --------------------------------------------------------------------------------------------
# Messages name the option or argument: walk's numbers, an empty or NUL path
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "option, value, message",
    [
        ("--start-y", "nan", "--start-y: must be a finite number, got nan"),
        ("--goal-y", "nan", "--goal-y: must be a finite number, got nan"),
        ("--steps", "0", "--steps: must be a finite number >= 1, got 0"),
    ],
)
def test_walk_names_its_options_and_bounds(tmp_path, option, value, message):
    terrain = tmp_path / "t.csv"
    terrain.write_text("0,0\n3,0\n")
    r = run_cli("walk", "--method", "cfftg", "--terrain", terrain, "--out", tmp_path / "w.csv",
                option, value)  # fmt: skip
    assert_clean_refusal(r, message)
    assert "None" not in r.stderr


@pytest.mark.parametrize("path, message", [("", "the path is empty"), ("a\0b", "NUL byte")])
def test_an_empty_or_nul_path_names_the_argument(path, message):
    from jaxexo.config import ConfigError, load_config
    from jaxexo.inference import TrajectoryGenerator

    with pytest.raises(ConfigError, match=f"^path: .*{message}"):
        TrajectoryGenerator.load(path)
    with pytest.raises(ConfigError, match=f"^config: .*{message}"):
        load_config(path)


def test_cfftgs_backward_figure_at_few_points_is_worded_as_a_bound(tmp_path):
    r = run_cli(*GEN_BASE1, "--points", "20", "--out", tmp_path / "t.csv")
    assert "may move backward by up to" in r.stdout and "a bound" in r.stdout, r.stdout
    assert "the heel moves backward by" not in r.stdout


def test_a_profile_of_two_obstacles_is_refused_by_generate_naming_the_file(tmp_path):
    profile = tmp_path / "two.csv"
    profile.write_text("0.3,0\n0.35,0.05\n0.4,0\n0.45,0.05\n0.5,0\n")
    r = run_cli(*GEN, "--profile", profile, "--out", tmp_path / "t.csv")
    assert_clean_refusal(r, "--profile", str(profile), "interior vertex 2 touches the ground")
    assert not (tmp_path / "t.csv").exists()
