"""Nothing lost, round four (issue 52): the training extra declares what the compilation cache needs,
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

from conftest import ROOT

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
