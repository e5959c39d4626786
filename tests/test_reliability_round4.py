"""Nothing lost, round four (issue 52): the training extra declares what the compilation cache needs,
outputs follow the umask, every count and size is bounded before any work, files are parsed as their
format says, records check their fields when made, one rule per option across commands, and messages
name the option as typed and the bound. docs/reliability.md lists these cases.
"""

from __future__ import annotations

import re
import tomllib

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
