"""One compilation of the training program per run.

``jit(run)`` keys its compiled programs on the inputs' shardings. On two CPU devices the state a chunk
returns is split over the device mesh; a state straight from ``init`` (one device) or from a
checkpoint (host arrays) is not, so the second chunk used to compile the whole program again (about
5 s of a 40 s run). These tests count XLA backend compilations (jax.monitoring's
``/jax/core/compile/backend_compile_duration`` event, which names the jitted function and fires on
persistent-cache hits too) in a subprocess that exposes two CPU devices, as ``jaxexo train`` does on
the 2-core machine: a new run of several chunks, a resumed run, and a sweep group of several chunks
must each compile their training program exactly once.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import pytest

from conftest import ROOT

pytestmark = pytest.mark.slow

# Runs in a fresh interpreter so that XLA_FLAGS takes effect before JAX is imported.
SCRIPT = textwrap.dedent(r"""
    import collections, json, pathlib, sys, tempfile
    sys.path.insert(0, sys.argv[1])
    import jax
    from jax import monitoring

    counts = collections.Counter()

    def listen(event, duration, **kw):
        if event == "/jax/core/compile/backend_compile_duration":
            counts[kw.get("fun_name")] += 1

    monitoring.register_event_duration_secs_listener(listen)

    from train_helpers import TINY_N, TINY_T, tiny_config
    from jaxexo.train import checkpoints, driver, run_dir
    from jaxexo.sweep.runner import run_sweep
    from jaxexo.sweep.spec import sweep_from_dict

    out = {"devices": len(jax.local_devices())}
    tmp = pathlib.Path(tempfile.mkdtemp())
    cfg = tiny_config(budget_env_steps=TINY_N * TINY_T * 8)   # 4 chunks of 2 updates

    class Interrupt:   # stop while writing chunk 2's checkpoint (as tests/test_driver.py does)
        def __init__(self):
            self.calls, self.real = 0, checkpoints.checkpoint_write
        def __call__(self, path, data):
            self.calls += 1
            if self.calls == 3:
                raise KeyboardInterrupt
            return self.real(path, data)

    driver.run_training(cfg, tmp / "full", seed=3, progress=False, eval_episodes=20)
    out["new"] = dict(counts)
    out["new_chunks"] = len((tmp / "full" / "metrics.jsonl").read_text().splitlines())
    counts.clear()
    checkpoints.checkpoint_write = Interrupt()
    try:
        driver.run_training(cfg, tmp / "part", seed=3, progress=False, eval_episodes=20)
    except KeyboardInterrupt:
        pass
    checkpoints.checkpoint_write = checkpoints.atomic_write
    counts.clear()
    driver.run_training(cfg, tmp / "part", seed=3, resume=True, progress=False, eval_episodes=20)
    out["resume"] = dict(counts)
    out["resume_same"] = ((tmp / "full" / run_dir.CHECKPOINT).read_bytes()
                          == (tmp / "part" / run_dir.CHECKPOINT).read_bytes())
    counts.clear()
    raw = {"env": {"obs_mode": "thesis"}, "layout": {"obstacles": ["base1"], "pivot": ["obstacle"]},
           "train": {"num_envs": 16, "rollout_steps": 4, "num_minibatches": 2, "hidden": [16],
                     "layer_norm": False, "budget_env_steps": 16 * 4 * 3, "eval_episodes": 10},
           "sweep": {"seeds": 2, "chunk_size": 2, "grid": {"train.lr": [1e-3, 3e-3]}}}
    sweep = sweep_from_dict(raw)
    run_sweep(sweep, tmp / "sweep", progress=False)
    out["sweep"] = dict(counts)
    out["sweep_chunks"] = len(json.loads((tmp / "sweep" / "plan.json").read_text())["chunks"])
    print("RESULT " + json.dumps(out))
""")


@pytest.fixture(scope="module")
def counted():
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env["XLA_FLAGS"] = "--xla_force_host_platform_device_count=2"
    # The session's compilation cache comes with the environment (conftest): the resumed run reads the
    # programs the first run compiled (a cache hit still goes through XLA's compile entry point and is
    # counted, so the counts are the same without it).
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(ROOT / "tests")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    line = next(ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT "))
    return json.loads(line[len("RESULT ") :])


def test_a_run_compiles_its_training_program_once(counted):
    assert counted["devices"] == 2 and counted["new_chunks"] == 4
    # The chunk program and the budget check that runs before each chunk: one compilation each.
    assert counted["new"].get("jit(run)") == 1, counted["new"]
    assert counted["new"].get("jit(active)") == 1, counted["new"]


def test_a_resumed_run_compiles_its_training_program_once(counted):
    assert counted["resume"].get("jit(run)") == 1, counted["resume"]
    assert counted["resume"].get("jit(active)") == 1, counted["resume"]
    assert counted["resume_same"]  # and still ends bit-identical to the uninterrupted run


def test_a_sweep_group_compiles_once(counted):
    # Two chunks of one group (one set of static settings): the chunk program compiles once.
    assert counted["sweep_chunks"] == 2
    agent = {k: v for k, v in counted["sweep"].items() if "agent" in k}
    assert list(agent.values()) == [1], counted["sweep"]
