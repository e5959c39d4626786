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
