"""Shared fixtures for the jaxexo test suite.

JAX is imported lazily inside the fixtures that need it, so that the NumPy-only tests (geometry,
kinematics, rewards, config) do not pay for it, and so that test_package can check in a subprocess
that ``import jaxexo`` stays free of JAX.
"""

from __future__ import annotations

import copy
import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

from jaxexo.config import EQUAL_WEIGHTS, THESIS_JOINT_LIMITS

ROOT = Path(__file__).resolve().parent.parent

# The CLI keeps compiled programs in ~/.cache/jaxexo/xla (jaxexo.train.devices.use_compilation_cache);
# the CLI runs of the tests (subprocesses inherit this) write nothing there. Tests of that cache set
# the variable themselves.
os.environ["JAXEXO_COMPILATION_CACHE"] = "off"

# JAX compile time dominates the suite, and many tests compile the same programs (the tiny config's
# training, validation and evaluation programs, in process and in CLI subprocesses). One persistent
# compilation cache serves the whole session: made by the controlling process, inherited through the
# environment by the xdist workers and every subprocess, removed when the session ends. A program
# read back is the compiled program itself, so results are bit for bit those of a fresh compile. The
# size bound turns on JAX's file lock, so that two processes never read an entry half written.
SESSION_CACHE_ENV = {
    "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0.5",
    "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES": "0",
    "JAX_COMPILATION_CACHE_MAX_SIZE": str(4 * 2**30),
}
_OWN_SESSION_CACHE: list[str] = []


def pytest_configure(config):
    if os.environ.get("PYTEST_XDIST_WORKER"):
        return  # the controller's cache, inherited
    import tempfile

    folder = tempfile.mkdtemp(prefix="jaxexo-tests-xla-")
    _OWN_SESSION_CACHE.append(folder)
    os.environ.update(SESSION_CACHE_ENV, JAX_COMPILATION_CACHE_DIR=folder)


def pytest_unconfigure(config):
    import shutil

    for folder in _OWN_SESSION_CACHE:
        shutil.rmtree(folder, ignore_errors=True)


def without_compilation_cache(env: dict) -> dict:
    """``env`` without the session's compilation cache: for a subprocess that may die or fail while
    writing files (its half-written entries would stay in the shared cache)."""
    return {k: v for k, v in env.items() if k != "JAX_COMPILATION_CACHE_DIR"}


settings.register_profile(
    "jaxexo",
    deadline=None,
    max_examples=200,
    suppress_health_check=[HealthCheck.too_slow],
    derandomize=False,
)
settings.load_profile("jaxexo")


def metrics_without_clock(path: Path) -> list[dict]:
    """A run's metrics.jsonl rows without the wall-clock fields, the only ones a resumed run may
    change (each row's and each of its members')."""
    import json

    clock = {"wall_s", "env_steps_per_s"}
    return [
        {
            **{k: v for k, v in r.items() if k not in clock},
            "members": [{k: v for k, v in m.items() if k not in clock} for m in r["members"]],
        }
        for r in map(json.loads, path.read_text().splitlines())
    ]


def cli_cmd(*args) -> list[str]:
    """The command line ``python -m jaxexo.cli ARGS`` (each argument as text)."""
    return [sys.executable, "-m", "jaxexo.cli", *map(str, args)]


def run_command(argv, timeout: float = 300, **kw) -> subprocess.CompletedProcess:
    """``argv`` run from the repository root, its output captured as text (``kw``: more of
    subprocess.run's arguments, e.g. env)."""
    return subprocess.run(argv, capture_output=True, text=True, cwd=ROOT, timeout=timeout, **kw)


def run_cli(*args, timeout: float = 300, **kw) -> subprocess.CompletedProcess:
    """``jaxexo ARGS`` in a subprocess from the repository root (run_command)."""
    return run_command(cli_cmd(*args), timeout=timeout, **kw)


def run_python(code: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """``python -c CODE`` in a subprocess from the repository root (run_command)."""
    return run_command([sys.executable, "-c", code], timeout=timeout)


# Every obstacle kind the config accepts: the five thesis obstacles (Table 3.1), a rectangle range,
# a half-ellipse range and a user profile; all three pivot conditions.
PROFILE_POINTS = [[-0.08, 0.0], [-0.08, 0.06], [0.0, 0.12], [0.08, 0.06], [0.08, 0.0]]
MIXED_KINDS = (
    "base1",
    "base2",
    "base3",
    "triangle",
    "half_circle",
    "rectangle",
    "half_ellipse",
    "profile",
)
# Every constant the hand-computed env tests rely on is pinned here, so that changes to the package's
# defaults do not silently change what those tests check.
MIXED_RAW = {
    "env": {
        "obs_mode": "conditioned",
        "step_size": 0.03,
        "max_steps": 100,
        "collision": "penalty",
        "goal_tolerance": [0.04, 0.02],
        "mid_goal_clearance": 0.10,
        "mid_goal_half_size": [0.06, 0.05],
        "max_height_margin": 0.20,
        "bounds_y": [-0.30, 1.30],
        "max_z": 0.80,
        "shape_points": 9,
    },
    "kinematics": {
        "thigh": 0.5,
        "shin": 0.5,
        "foot_length": 0.2,
        **THESIS_JOINT_LIMITS,
    },
    "reward": {
        **EQUAL_WEIGHTS,
        "step_threshold": 30.0,
        "collision_penalty": 10.0,
        "backward_penalty": 1.0,
        "goal_reward": 10.0,
        "mid_goal_penalty": 1.0,
        "max_height_penalty": 1.0,
        "safety_penalty": 2.0,
        "safety_distance": 0.03,
        "z_monotone_penalty": 0.5,
        "hlc_penalty": 1.0,
        "hlc_threshold": 0.90,
        "leg_length_penalty": 1.0,
        "leg_length_tolerance": 0.0,
        "joint_limit_penalty": 1.0,
        "hip_height_penalty": 1.0,
        "max_hip_z": 1.0,
    },
    "layout": {
        "obstacles": [
            "base1",
            "base2",
            "base3",
            "triangle",
            "half_circle",
            {"kind": "rectangle", "width": [0.05, 0.20], "height": [0.05, 0.20]},
            {"kind": "half_ellipse", "width": [0.10, 0.20], "height": [0.05, 0.20]},
            {"kind": "profile", "points": PROFILE_POINTS},
        ],
        "pivot": ["agent", "obstacle", "between"],
        "start_shift": [0.0, 0.05],
        "obstacle_offset": [-0.03, 0.03],
        "step_length": [0.65, 0.75],
    },
}


# The schema's former declared defaults (Config() before they became the default model's),
# resolved from main: tests/data/resolved_configs.json "schema_defaults". The tests' raw configs are
# stated on top of it (legacy_raw), so that each means what it meant when the test was written.
_LEGACY: dict = {}


def legacy_raw(raw: dict | None = None) -> dict:
    """``raw`` (a partial config table) over the former schema defaults, as a fresh table."""
    import json
    import tomllib

    from jaxexo.sweep.spec import deep_merge

    if not _LEGACY:
        snap = json.loads((ROOT / "tests" / "data" / "resolved_configs.json").read_text())
        _LEGACY.update(tomllib.loads(snap["schema_defaults"]))
        from resolved_snapshot import ADDED_SINCE  # fields declared since, at their former meaning

        _LEGACY.update(deep_merge(_LEGACY, ADDED_SINCE))
    return deep_merge(_LEGACY, raw or {})


# A fixed scene: Base 1 at the default place, pivot under the obstacle, no start shift or jitter.
FIXED_LAYOUT = {"obstacles": ["base1"], "pivot": ["obstacle"]}
# configs/default.toml's [reward]
REWARD = {
    "traj_weights": [0.0, 2.0, 0.5, 4.0, 0.5, 0.5, 1.0, 0.5],
    "exo_weights": [1.0, 1.0, 2.0, 1.0],
    "goal_reward": 20.0,
    "joint_limit_penalty": 4.0,
    "progress_shaping": 5.0,
}
# The shared tiny training config (of tests/train_helpers.py's modules, test_reliability and
# tiny_reference below): Watkins Q(lambda) in the backward view (its checkpoint then holds traces,
# the pending action and its greediness too), 6 updates in 3 chunks of 2.
TINY_N, TINY_T, TINY_UPDATES = 64, 8, 6
TINY_TRAIN = {
    "num_envs": TINY_N,
    "rollout_steps": TINY_T,
    "num_minibatches": 2,
    "hidden": [32, 32],
    "layer_norm": True,
    "trace": "backward",
    "control": "off_policy",
    "trace_kind": "accumulating",
    "lr": 1e-3,
    "gamma": 0.98,
    "lam": 0.9,
    "budget_env_steps": TINY_N * TINY_T * TINY_UPDATES,
    "chunk_updates": 2,
    "eval_episodes": 20,
}


def tiny_raw(**train) -> dict:
    return legacy_raw(
        {
            "env": {"obs_mode": "conditioned"},
            "layout": dict(FIXED_LAYOUT),
            "reward": dict(REWARD),
            "train": {**TINY_TRAIN, **train},
        }
    )


def tiny_config(**train):
    from jaxexo.config import config_from_dict

    return config_from_dict(tiny_raw(**train))


SEED = 3  # the tiny runs' seed

# The small forward-view config of the population and sweep tests: the thesis observation, Base 1,
# 16 environments, 6 updates of 4 steps, one hidden layer of 16.
FORWARD_N, FORWARD_T, FORWARD_UPDATES = 16, 4, 6


def forward_raw(train: dict | None = None, **tables) -> dict:
    """The small forward-view config (legacy_raw), ``train`` over its [train] table and ``tables``
    (e.g. sweep) beside it."""
    return legacy_raw(
        {
            "env": {"obs_mode": "thesis"},
            "layout": dict(FIXED_LAYOUT),
            "train": {
                "num_envs": FORWARD_N,
                "rollout_steps": FORWARD_T,
                "num_minibatches": 2,
                "hidden": [16],
                "layer_norm": False,
                "budget_env_steps": FORWARD_N * FORWARD_T * FORWARD_UPDATES,
                "eval_episodes": 10,
                **(train or {}),
            },
            **tables,
        }
    )


@pytest.fixture
def mixed_raw():
    """A fresh (mutable) copy of the raw mixed config table."""
    return copy.deepcopy(MIXED_RAW)


_CACHE: dict = {}


def get_mixed_config():
    if "config" not in _CACHE:
        from jaxexo.config import config_from_dict

        _CACHE["config"] = config_from_dict(legacy_raw(copy.deepcopy(MIXED_RAW)))
    return _CACHE["config"]


def get_mixed_env():
    """One ExoStepEnv on the mixed config per session (also for unittest-style chex tests)."""
    if "env" not in _CACHE:
        from jaxexo.env import ExoStepEnv

        _CACHE["env"] = ExoStepEnv(get_mixed_config())
    return _CACHE["env"]


def get_mixed_step():
    """The mixed env's auto-resetting step, jitted once per session: JAX compile time dominates the
    suite, so every test that steps one env by hand shares this one."""
    if "step" not in _CACHE:
        import jax

        _CACHE["step"] = jax.jit(get_mixed_env().step)
    return _CACHE["step"]


@pytest.fixture(scope="session")
def mixed_config():
    return get_mixed_config()


@pytest.fixture(scope="session")
def default_config():
    from jaxexo.config import load_config

    return load_config(ROOT / "configs" / "default.toml")


@pytest.fixture(scope="session")
def mixed_env():
    return get_mixed_env()


@pytest.fixture(scope="session")
def default_env(default_config):
    from jaxexo.env import ExoStepEnv

    return ExoStepEnv(default_config)


@pytest.fixture(scope="session")
def mixed_step():
    return get_mixed_step()


# A small config trained briefly from configs/quick.toml (unshielded, so it trains in seconds): a
# policy that reaches the goal on most scenes and fails on some, for the generator and evaluation
# tests (one training per session). The shielded default has its own tests (tests/test_shield.py).
TRAINED_BUDGET = 2_000_000


def session_folder(tmp_path_factory, name: str) -> Path:
    """A folder that every pytest-xdist worker of this session shares (their common temporary root),
    or this session's own without xdist."""
    base = tmp_path_factory.getbasetemp()
    folder = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / name
    folder.mkdir(exist_ok=True)
    return folder


def built_once(folder: Path, build) -> Path:
    """``folder / "out"``, made by ``build(path)`` in the first process of the session that asks for it;
    the others wait for it (a lock file) and reuse it. An unfinished one (its builder failed) is
    built again."""
    import fcntl
    import shutil

    out, done = folder / "out", folder / "done"
    with open(folder / "lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            shutil.rmtree(out, ignore_errors=True)
            build(out)
            done.touch()
    return out


@pytest.fixture(scope="session")
def trained_run(tmp_path_factory):
    """The run directory (read-only to the tests); trained once per session, however many xdist
    workers ask for it."""
    import dataclasses

    from jaxexo.config import load_config
    from jaxexo.train.driver import run_training

    cfg = load_config(ROOT / "configs" / "quick.toml")
    cfg = dataclasses.replace(
        cfg, train=dataclasses.replace(cfg.train, num_envs=512, budget_env_steps=TRAINED_BUDGET)
    )
    return built_once(
        session_folder(tmp_path_factory, "trained_run"),
        lambda out: run_training(cfg, out, seed=0, progress=False, eval_episodes=200),
    )


def eval_against_cfftg(run: Path, out: Path, *args) -> int:
    """``jaxexo eval`` (in this process) of ``run``'s policy against CFFTG into ``out``, with ``args``
    (the scenarios and their numbers); its exit status."""
    from jaxexo.cli import main

    policy = str(run / "policy.npz")
    return main(
        ["eval", "--policy", policy, "--against", "cfftg", *map(str, args), "--out", str(out)]
    )


@pytest.fixture(scope="session")
def tiny_reference(tmp_path_factory):
    """``jaxexo train`` (a subprocess on one CPU device) of the tiny training config
    (tests/train_helpers.py), seed 3, once per session: the uninterrupted run that the driver's and the
    reliability tests' interrupted runs must equal bit for bit, and the CLI test's run.
    {"run", "cfg", "cfg_path", "stdout", "stderr"}."""
    import subprocess
    import sys

    from jaxexo.config.toml_io import config_to_toml

    cfg = tiny_config()

    def build(out):
        out.mkdir()
        (out / "config_in.toml").write_text(config_to_toml(cfg))
        env = {**os.environ, "XLA_FLAGS": "--xla_force_host_platform_device_count=1"}
        r = subprocess.run(
            [
                sys.executable,
                "-m",
                "jaxexo.cli",
                "train",
                str(out / "config_in.toml"),
                "--out",
                str(out / "run"),
                "--quiet",
                "--seed",
                str(SEED),
            ],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=900,
        )
        assert r.returncode == 0, r.stderr[-3000:]
        (out / "stdout.txt").write_text(r.stdout)
        (out / "stderr.txt").write_text(r.stderr)

    out = built_once(session_folder(tmp_path_factory, "tiny_reference"), build)
    return {
        "run": out / "run",
        "cfg": cfg,
        "cfg_path": out / "config_in.toml",
        "stdout": (out / "stdout.txt").read_text(),
        "stderr": (out / "stderr.txt").read_text(),
    }


def random_generator(config, seed: int = 0):
    """A TrajectoryGenerator with random weights (one hidden layer of 16) for ``config``: for tests
    whose rollouts are replaced or whose policy need not be any good."""
    import numpy as np

    from jaxexo.inference import TrajectoryGenerator
    from jaxexo.physics import actions
    from jaxexo.storage.policy_file import QPolicy

    d = actions.obs_dim(config.env.obs_mode, config.env.shape_points)
    rng = np.random.default_rng(seed)
    sizes = [d, 16, actions.NUM_ACTIONS]
    pol = QPolicy(
        kernels=[rng.normal(size=(a, b)).astype(np.float32) for a, b in zip(sizes, sizes[1:])],
        biases=[np.zeros(b, np.float32) for b in sizes[1:]],
        norm_scales=[],
        norm_biases=[],
        metadata={},
    )
    return TrajectoryGenerator(pol, config)


def recorded_swing(sp, rec: dict, heel=None):
    """The RL trajectory of a swing recorded in tests/data (its obstacle outline, pivot, start,
    goal, heel path and deviation), assembled with the kinematics ``sp`` (scalar_params);
    ``heel``: another path in its place."""
    import numpy as np

    from jaxexo.inference import Obstacle
    from jaxexo.physics.scene import make_scene
    from jaxexo.swing.trajectory import assemble

    scene = make_scene(
        Obstacle.profile(rec["obstacle_outline"]),
        rec["pivot_y"],
        rec["start_y"],
        rec["goal_y"] - rec["start_y"],
        foot_length=sp.foot_length,
    )
    heel = np.asarray(rec["heel"] if heel is None else heel, np.float64)
    dev = np.array([rec["deviation"]])
    return assemble("rl", sp, [scene], [heel], heel[None], [float("nan")], deviation=dev)[0]


def lifted_continuation(gen, swing, at: float, lift: float, scene=None):
    """A test continuation of a timed swing from its heel at ``at`` (jaxexo.swing.replan's
    continue_swing takes it as a generator's Trajectory): the swing's own heel path from there,
    raised by ``lift`` * 16 u^2 (1 - u)^2 (u from 0 to 1 along it), over ``scene`` (default: the
    swing's), its joints by the legs' inverse kinematics."""
    import types

    import numpy as np

    from jaxexo.swing.timing import leg_angles

    t = np.linspace(at, swing.duration, 150)
    heel = swing.at(t).heel.copy()
    u = np.linspace(0.0, 1.0, len(t))
    heel[:, 1] += lift * 16.0 * u * u * (1.0 - u) ** 2
    q = leg_angles(gen.sp, swing.scene.pivot_y, heel)
    return types.SimpleNamespace(
        method="test",
        scene=scene or swing.scene,
        heel=heel,
        joint_angles=q,
        notes=(),
        raw=heel,
        ok=True,
    )
