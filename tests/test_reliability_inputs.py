"""Nothing lost, round two (issue 22): no file outside the run touched, no input overwritten by an
output, no setting that silently means something else, every bad input refused before any work with
one line naming the field, option or file (no traceback, no kill for memory).

Fast: no training (the one CLI run that reaches training stops at its lock); subprocesses only where
the exit code and stderr are what is checked. The README's "Reliability" table lists these cases.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from jaxexo.config import ConfigError, config_from_dict
from jaxexo.storage.atomic import SymlinkRefused, append_line
from jaxexo.storage.rundir import LOCK_NAME, RunDirError, run_lock

from conftest import ROOT


def cli(*args):
    return [sys.executable, "-m", "jaxexo.cli", *map(str, args)]


def run_cli(*args, timeout=300):
    return subprocess.run(cli(*args), capture_output=True, text=True, cwd=ROOT, timeout=timeout)


def assert_clean_refusal(r: subprocess.CompletedProcess, *needles: str, code: int = 2):
    """Non-zero exit, one line ``jaxexo: error`` naming what is wrong, and no traceback."""
    assert r.returncode == code, (r.returncode, r.stderr[-2000:])
    assert "Traceback" not in r.stderr and "jaxexo: error:" in r.stderr, r.stderr[-2000:]
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr[-2000:]
    for n in needles:
        assert n in r.stderr, (n, r.stderr[-2000:])


# --------------------------------------------------------------------------------------------
# No file outside the run reached through a symbolic link
# --------------------------------------------------------------------------------------------

def test_a_symlinked_lock_file_is_refused_and_its_target_untouched(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    run = tmp_path / "run"
    run.mkdir()
    (run / LOCK_NAME).symlink_to(victim)
    with pytest.raises(RunDirError, match="symbolic link"):
        with run_lock(run, "train"):
            pass
    assert victim.read_text() == "precious\n"
    cfg = tmp_path / "tiny.toml"
    cfg.write_text('[train]\nbudget_env_steps = 1024\nnum_envs = 64\n')
    r = run_cli("train", cfg, "--out", run, "--quiet")
    assert_clean_refusal(r, "--out", LOCK_NAME, "symbolic link")
    assert victim.read_text() == "precious\n"


def test_an_append_only_log_replaced_by_a_symlink_is_refused(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    log = tmp_path / "metrics.jsonl"
    log.symlink_to(victim)
    with pytest.raises(SymlinkRefused, match="metrics.jsonl is a symbolic link"):
        append_line(log, "{}\n")
    assert victim.read_text() == "precious\n"
