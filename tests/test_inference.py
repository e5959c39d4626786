"""The NumPy-only generator (jaxexo.inference): network and rollout parity with flax and the JAX
environment, smoothing and its fallback, checks, exports, load errors, CLI, and importing it with
JAX unavailable."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

from jaxexo.config import load_config
from jaxexo.inference import Obstacle, TrajectoryError, TrajectoryGenerator
from jaxexo.inference.network import FoldedQNetwork, StepNetwork
from jaxexo.physics import geometry, kinematics, swept
from jaxexo.physics.kinematics import PIVOT_CONDITIONS
from jaxexo.storage.policy_file import PolicyFileError, load_policy
from jaxexo.swing import smoothing as sm

from conftest import ROOT

jax = pytest.importorskip("jax")
import jax.numpy as jnp  # noqa: E402

from jaxexo.env import ExoStepEnv  # noqa: E402
from jaxexo.train import export  # noqa: E402
from jaxexo.train.evaluate import make_rollout  # noqa: E402
from jaxexo.train.network import QNetwork  # noqa: E402
from jaxexo.train.trainer import Trainer  # noqa: E402

SCENE_OBSTACLES = {
    "base1": Obstacle.named("base1"),
    "base2": Obstacle.named("base2"),
    "base3": Obstacle.named("base3"),
    "triangle": Obstacle.named("triangle"),
    "half_circle": Obstacle.named("half_circle"),
    "rectangle": Obstacle.rectangle(0.12, 0.18, center_y=0.42),
    "half_ellipse": Obstacle.half_ellipse(0.16, 0.10, center_y=0.47),
    "profile": Obstacle.profile(
        [[0.37, 0.0], [0.37, 0.06], [0.45, 0.12], [0.53, 0.06], [0.53, 0.0]]
    ),
}


def flax_params(policy):
    """The flax parameter tree of an exported policy (QNetwork's layer names)."""
    p = {}
    n = len(policy.kernels)
    for i in range(n):
        name = "out" if i == n - 1 else f"dense_{i}"
        p[name] = {"kernel": jnp.asarray(policy.kernels[i]), "bias": jnp.asarray(policy.biases[i])}
    for i, (s, b) in enumerate(zip(policy.norm_scales, policy.norm_biases)):
        p[f"norm_{i}"] = {"scale": jnp.asarray(s), "bias": jnp.asarray(b)}
    return {"params": p}


def export_random(path, cfg, seed=0, scale_signs=False):
    trainer = Trainer(cfg)
    params = trainer.net.init(jax.random.PRNGKey(seed), jnp.zeros((trainer.env.obs_dim,)))
    if scale_signs:
        # LayerNorm scales of every sign, zero included: the folding must handle each case.
        def f(path_, x):
            names = [getattr(k, "key", "") for k in path_]
            if "scale" in names:
                r = np.random.default_rng(seed).normal(size=x.shape).astype(np.float32)
                r[::7] = 0.0
                return jnp.asarray(r)
            if names[-1] == "bias" and any(str(n).startswith("norm") for n in names):
                return jnp.asarray(
                    np.random.default_rng(seed + 1).normal(size=x.shape).astype(np.float32)
                )
            return x

        params = jax.tree_util.tree_map_with_path(f, params)
    return export.export_policy(path, cfg, trainer, params)


def small_config(shield: bool = False, **train):
    """configs/default.toml with ``train`` overrides; unshielded unless ``shield`` (collisions and
    free moves are what most tests here exercise; the "shield" policy covers the shielded rollout)."""
    cfg = load_config(ROOT / "configs" / "default.toml")
    return dataclasses.replace(
        cfg,
        env=dataclasses.replace(cfg.env, shield=shield),
        train=dataclasses.replace(cfg.train, **train),
    )


@pytest.fixture(scope="module")
def trained_policy(trained_run):
    """The session's trained default model (a training run: the tests that need it are slow)."""
    return trained_run / "policy.npz"


def _policy(request, policies, which):
    return request.getfixturevalue("trained_policy") if which == "trained" else policies[which]


SLOW_TRAINED = pytest.param("trained", marks=pytest.mark.slow)


@pytest.fixture(scope="module")
def policies(tmp_path_factory):
    """Policies with random weights (no training): LayerNorm scales of every sign, the thesis network,
    collisions that terminate. The trained model is ``trained_policy``."""
    d = tmp_path_factory.mktemp("policies")
    thesis = load_config(ROOT / "configs" / "thesis" / "final.toml")
    return {
        "ln_signs": export_random(
            d / "ln.npz", small_config(hidden=[32, 24]), seed=3, scale_signs=True
        ),
        "thesis": export_random(d / "thesis.npz", thesis, seed=4),
        "terminate": export_random(
            d / "term.npz",
            dataclasses.replace(
                small_config(hidden=[16]),
                env=dataclasses.replace(small_config().env, collision="terminate"),
            ),
            seed=5,
        ),
        "shield": export_random(
            d / "shield.npz", small_config(shield=True, hidden=[32, 32]), seed=6
        ),
    }


# --------------------------------------------------------------------------------------------
# Network parity
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("which", [SLOW_TRAINED, "ln_signs", "thesis"])
def test_numpy_network_matches_flax(request, policies, which):
    policy = load_policy(_policy(request, policies, which))
    layers = policy.metadata["layers"]
    net = QNetwork(
        hidden=tuple(layers[1:-1]), num_actions=layers[-1], layer_norm=policy.metadata["layer_norm"]
    )
    x = np.random.default_rng(0).normal(size=(256, policy.obs_dim)).astype(np.float32)
    ref = np.asarray(net.apply(flax_params(policy), jnp.asarray(x)))
    np.testing.assert_allclose(policy.q_values(x), ref, rtol=1e-5, atol=1e-5)
    folded = FoldedQNetwork(policy)
    np.testing.assert_allclose(folded.q(x), ref, rtol=1e-5, atol=1e-5)
    # The single-step path: observation given as affine coordinates folded into layer 0.
    step = StepNetwork(folded)
    basis = np.vstack(
        [np.eye(4, policy.obs_dim) * 0.3, x[0][None] - 0.3 * np.eye(4, policy.obs_dim).sum(0)]
    )
    step.set_scene(basis)
    for c in ([1.0, 1.0, 1.0, 1.0], [0.2, -0.1, 7.0, 0.0]):
        obs = np.asarray(c) @ basis[:4] + basis[4]
        q = np.asarray(net.apply(flax_params(policy), jnp.asarray(obs, jnp.float32)))
        assert step.greedy(*c) == int(np.argmax(q))


# --------------------------------------------------------------------------------------------
# Rollout parity with the JAX environment
# --------------------------------------------------------------------------------------------


def jax_paths(gen, scenes_args):
    """Greedy heel paths of the JAX environment on the same scenes (flax network, float32)."""
    cfg = gen.config
    cfg = dataclasses.replace(
        cfg, env=dataclasses.replace(cfg.env, max_vertices=geometry.MAX_PROFILE_VERTICES)
    )
    env = ExoStepEnv(cfg)
    params = env.default_params
    layouts = [env.layout_for(*a) for a in scenes_args]
    stacked = jax.tree.map(lambda *x: jnp.stack(x), *layouts)
    layers = gen.policy.metadata["layers"]
    net = QNetwork(
        hidden=tuple(layers[1:-1]),
        num_actions=layers[-1],
        layer_norm=gen.policy.metadata["layer_norm"],
    )
    rollout = make_rollout(env, net.apply, cfg.env.max_steps, record=True)
    out, path = jax.jit(jax.vmap(rollout, in_axes=(None, 0, None)))(
        flax_params(gen.policy), stacked, params
    )
    steps = np.asarray(out.steps)
    start = np.stack([np.asarray([l.start_y for l in layouts]), np.zeros(len(layouts))], -1)
    return [
        np.vstack([start[i], np.asarray(path)[i, : steps[i]]]) for i in range(len(layouts))
    ], out


@pytest.mark.parametrize("which", [SLOW_TRAINED, "thesis", "terminate", "shield"])
def test_numpy_rollouts_take_the_jax_environments_actions(request, policies, which):
    gen = TrajectoryGenerator.load(_policy(request, policies, which))
    args = [
        (ob, pv, sy, 0.70)
        for ob in SCENE_OBSTACLES.values()
        for pv in PIVOT_CONDITIONS
        for sy in (0.0, 0.04)
    ]
    ref, out = jax_paths(gen, args)
    scenes = [gen.scene(ob, pivot=pv, start_y=sy, step_length=sl) for ob, pv, sy, sl in args]
    single = [gen.rollout(s)[0] for s in scenes]
    batch, _ = gen.rollout_batch(scenes)
    for i, (r, a, b) in enumerate(zip(ref, single, batch)):
        assert len(a) == len(r) == len(b), (i, args[i][1:], len(a), len(r), len(b))
        np.testing.assert_allclose(a, r, atol=2e-5, err_msg=str(args[i][1:]))
        np.testing.assert_allclose(b, r, atol=2e-5, err_msg=str(args[i][1:]))
    if which == "trained":
        # The rules that end an episode were exercised: some scenes reach the goal, by the same step.
        # (The session's policy is small: 2 M steps of quick.toml; 1 M reached the goal in none of these 48
        # on an Intel Xeon, 2 M succeed in a third of the test layouts there.)
        reached = np.asarray(out.reached)
        assert reached.sum() >= len(args) // 6
        lengths = np.array([len(a) - 1 for a in single])
        np.testing.assert_array_equal(lengths, np.asarray(out.steps))
    if which == "terminate":
        # Collisions end episodes early here, at the same step in both.
        steps = np.asarray(out.steps)
        assert np.any(np.asarray(out.collided) & (steps < gen.max_steps))


@pytest.mark.slow
def test_batch_equals_single_generation(trained_policy):
    gen = TrajectoryGenerator.load(trained_policy)
    obs = list(SCENE_OBSTACLES.values())
    pivots = [PIVOT_CONDITIONS[i % 3] for i in range(len(obs))]
    batch = gen.generate_batch(obs, pivot=pivots, start_y=0.02)
    assert len(batch) == len(obs)
    for i, ob in enumerate(obs):
        t = gen.generate(ob, pivot=pivots[i], start_y=0.02)
        b = batch[i]
        assert len(b.raw) == len(t.raw)
        np.testing.assert_allclose(b.heel, t.heel, atol=1e-4)
        assert (
            b.checks.ok == t.checks.ok and b.checks.reasons.__len__() == t.checks.reasons.__len__()
        )


# --------------------------------------------------------------------------------------------
# Trajectories: kinematics, checks, smoothing, exports
# --------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_trajectory_fields_follow_the_shared_kinematics(trained_policy):
    gen = TrajectoryGenerator.load(trained_policy)
    ob = Obstacle.named("base2")
    t = gen.generate(ob, pivot="between", n_points=80, duration=0.8)
    n = 80
    for name in ("heel", "toe", "hip", "knee_swing", "knee_stance"):
        assert getattr(t, name).shape == (n, 2)
    assert t.joint_angles.shape == (n, 4)
    np.testing.assert_allclose(t.time, np.linspace(0, 0.8, n))
    sp = gen.sp
    np.testing.assert_allclose(t.toe - t.heel, np.tile([sp.foot_length, 0.0], (n, 1)), atol=1e-12)
    kin = kinematics.leg_state(np, t.scene.pivot_y, t.heel, sp.thigh, sp.shin)
    np.testing.assert_allclose(t.hip, kin.hip, atol=1e-9)
    np.testing.assert_allclose(t.knee_swing, kin.knee_swing, atol=1e-9)
    np.testing.assert_allclose(t.joint_angles[:, 1], kin.knee_swing_angle, atol=1e-6)
    np.testing.assert_allclose(t.joint_angles[:, 2], kin.hip_stance, atol=1e-6)
    # Thigh and shin keep their lengths wherever the leg can reach.
    np.testing.assert_allclose(np.linalg.norm(t.knee_swing - t.hip, axis=1), sp.thigh, atol=1e-6)
    # The clearance is the exact swept clearance over the moves between samples less the
    # spline's chord-deviation bound: never more than the samples' own clearance.
    clear = ob.clearance(t.heel, sp.foot_length)
    sw = swept.path_swept_clearance(np, t.heel, sp.foot_length, t.scene.outline)
    assert t.checks.min_clearance == pytest.approx(sw.min() - t.checks.deviation, abs=1e-9)
    assert t.checks.min_clearance <= clear.min()
    assert t.checks.collision_free == bool(t.checks.min_clearance > geometry.TOUCH_EPS)
    # Starts at the start, ends where the agent ended, never below the ground.
    np.testing.assert_allclose(t.heel[0], t.raw[0])
    np.testing.assert_allclose(t.heel[-1], t.raw[-1])
    assert t.heel[:, 1].min() >= 0.0


def test_a_failed_trajectory_says_why_and_strict_raises(policies):
    gen = TrajectoryGenerator.load(
        policies["ln_signs"]
    )  # an untrained network: it cannot get there
    ob = Obstacle.named("base1")
    t = gen.generate(ob, fallback=None)  # the RL swing alone (the CFFTG fallback is tested apart)
    assert not t.ok and not t.checks.reached_goal
    assert any("did not reach the goal" in r for r in t.checks.reasons)
    with pytest.raises(TrajectoryError, match="did not reach the goal") as e:
        gen.generate(ob, strict=True, fallback=None)
    assert not e.value.trajectory.ok


@pytest.mark.slow
def test_smoothing_that_would_touch_the_obstacle_falls_back(trained_policy):
    gen = TrajectoryGenerator.load(trained_policy)
    ob = Obstacle.rectangle(0.10, 0.20, center_y=0.40)
    scene = gen.scene(ob, pivot="obstacle")
    foot = gen.sp.foot_length
    # A raw path that hugs the obstacle's near-top corner: straight up just before it, across just
    # above it, straight down after it, keeping the 2 cm safety margin (the fallback keeps
    # the raw path's margin). Smoothing cuts the corners into the obstacle.
    up = [(0.12, z) for z in np.arange(0.0, 0.231, 0.03)]
    over = [(y, 0.23) for y in np.arange(0.15, 0.46, 0.03)]
    down = [(0.48, z) for z in np.arange(0.20, -0.001, -0.03)] + [(0.48, 0.0)]
    raw = np.array([(0.0, 0.0), (0.06, 0.0)] + up + over + down + [(0.70, 0.0)])
    assert np.all(ob.clearance(raw, foot) > 0)
    assert (
        swept.path_swept_clearance(np, raw, foot, scene.outline).min()
        >= gen.config.env.min_clearance
    )
    smooth = sm.bspline_smooth(raw, 100, 0.05)
    assert (
        ob.clearance(smooth, foot).min() <= geometry.TOUCH_EPS
    )  # the premise: plain smoothing collides
    # First the corrected spline (jaxexo.swing.clearing, on by default): the same smoothing, moved
    # away from the obstacle where it cut the margin.
    t = gen.finish([scene], [raw], 100, 0.05, 1.0, None)[0]
    assert t.smoothing == 0.05 and any("jaxexo.swing.clearing" in n for n in t.notes)
    assert t.checks.clearance_ok and t.checks.min_clearance >= gen.config.env.min_clearance
    # The retries below it (less smoothing, down to the raw polyline), with the correction off.
    gen = gen.with_options(clearing=False)
    t = gen.finish([scene], [raw], 100, 0.05, 1.0, None)[0]
    assert t.checks.collision_free and t.checks.min_clearance > geometry.TOUCH_EPS
    assert (np.isnan(t.smoothing) or t.smoothing < 0.05) and t.notes
    # In a batch, only the rows that need it fall back; the others keep the full smoothing.
    arc = np.linspace(0.0, np.pi, 25)
    plain = np.column_stack([0.35 * (1 - np.cos(arc)), 0.45 * np.sin(arc)])  # high above it
    both = gen.finish([scene, scene], [plain, raw], 100, 0.05, 1.0, None)
    assert both[0].smoothing == 0.05 and not both[0].notes and both[0].checks.collision_free
    np.testing.assert_allclose(both[1].heel, t.heel)
    np.testing.assert_equal(both[1].smoothing, t.smoothing)  # nan (the raw polyline) equals nan
    assert both[1].checks == t.checks
    # A raw path that itself touches the obstacle keeps its smoothing, and the checks say so.
    bad = raw.copy()
    bad[len(up) + 4, 1] = 0.15
    t = gen.finish([scene], [bad], 100, 0.05, 1.0, None)[0]
    assert t.smoothing == 0.05 and not t.checks.collision_free and not t.notes
    # With no smoothing asked for, the raw polyline is returned as it is.
    t = gen.finish([scene], [raw], 100, 0.0, 1.0, None)[0]
    assert np.isnan(t.smoothing)
    np.testing.assert_allclose(t.heel[[0, -1]], raw[[0, -1]])


@pytest.mark.parametrize("s", [0.0, 1e-4, sm.DEFAULT_SMOOTHING, 0.05])
def test_smoothing_spends_exactly_the_residual_budget(s):
    """Thesis 2.7's s bounds the (weighted) sum of squared residuals at the agent's points; the fit is
    the smoothest that uses all of it. Sampled at the points' own parameters, the residual is s."""
    t = np.linspace(0, np.pi, 33)
    raw = np.column_stack([0.35 * (1 - np.cos(t)), 0.25 * np.sin(t)])
    raw[1:-1] += np.random.default_rng(0).normal(scale=0.01, size=(31, 2))
    fit = sm.bspline_smooth(raw, len(raw), s)
    w = np.ones(len(raw))
    w[[0, -1]] = sm.END_WEIGHT
    assert np.sum((w[:, None] * (fit - raw)) ** 2) == pytest.approx(s, rel=1e-4, abs=1e-12)
    np.testing.assert_allclose(fit[[0, -1]], raw[[0, -1]])


@pytest.mark.parametrize("m", [4, 5, 11, 60])
def test_bspline_basis_matches_scipy(m):
    from scipy.interpolate import BSpline
    from scipy.linalg import eigh

    t = np.concatenate([[0.0] * 3, np.linspace(0.0, 1.0, m - 2), [1.0] * 3])
    u = np.concatenate([np.linspace(0.0, 1.0, 97), [0.0, 1.0, 0.5]])
    np.testing.assert_allclose(
        sm.bspline_design(u, t, 3), BSpline.design_matrix(u, t, 3).toarray(), atol=1e-14
    )
    b = sm.bspline_design(np.linspace(0, 1, m), t, 3)
    a = b.T @ b + np.eye(m)
    p = np.diff(np.eye(m), n=2, axis=0)
    p = p.T @ p
    d, v = sm._generalized_eigh(p, a)
    np.testing.assert_allclose(d, eigh(p, a, eigvals_only=True), atol=1e-10)
    np.testing.assert_allclose(v.T @ a @ v, np.eye(m), atol=1e-9)


def test_smoothing_batches_handle_ragged_repeated_and_short_paths():
    t = np.linspace(0, np.pi, 30)
    raw = np.column_stack([0.35 * (1 - np.cos(t)), 0.25 * np.sin(t)])
    rep = np.vstack([raw[:3], raw[2:3], raw[2:3], raw[3:]])  # a move clipped to nothing, twice
    paths = [raw, raw[:17], rep, raw[:3], raw[:2], raw[:1]]
    out = sm.smooth_paths(paths, 50, sm.DEFAULT_SMOOTHING)
    assert out.shape == (6, 50, 2) and np.isfinite(out).all()
    for p, o in zip(paths, out):
        np.testing.assert_allclose(o, sm.bspline_smooth(p, 50), atol=1e-12)
        np.testing.assert_allclose(o[[0, -1]], p[[0, -1]])
    np.testing.assert_allclose(out[2], out[0], atol=1e-12)  # repeats change nothing
    np.testing.assert_allclose(out[4], sm.linear_resample(raw[:2], 50))
    assert (out[..., 1] >= 0).all()


@pytest.mark.slow
def test_exports_round_trip(trained_policy, tmp_path):
    gen = TrajectoryGenerator.load(trained_policy)
    t = gen.generate(Obstacle.named("triangle"), pivot="agent")
    text = t.to_csv(tmp_path / "sub" / "t.csv")
    data = np.loadtxt(tmp_path / "sub" / "t.csv", delimiter=",", skiprows=1)
    assert text.splitlines()[0].split(",")[0] == "time_s"
    np.testing.assert_allclose(data, t.table(), atol=1e-6)
    doc = json.loads(t.to_json(tmp_path / "t.json"))
    assert doc["units"] == {"length": "m", "angle": "rad", "time": "s"}
    assert doc["checks"]["ok"] == t.ok
    np.testing.assert_allclose(np.asarray(doc["samples"]), t.table())
    assert doc["scene"]["pivot"] == "agent"


# --------------------------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------------------------


def _rewrite_meta(src, dst, **changes):
    with np.load(src) as z:
        files = {k: z[k] for k in z.files}
    meta = json.loads(str(files["metadata"]))
    meta.update(changes)
    # A valid checksum for the changed file, so that the check under test is the one that refuses it.
    from jaxexo.storage.policy_file import policy_checksum

    meta["sha256"] = policy_checksum({k: v for k, v in files.items() if k != "metadata"}, meta)
    files["metadata"] = np.array(json.dumps(meta))
    np.savez(dst, **files)
    return dst


@pytest.mark.slow
def test_load_refuses_what_it_cannot_drive(trained_policy, tmp_path):
    src = trained_policy
    cases = {
        "config": (
            _rewrite_meta(src, tmp_path / "a.npz", config_toml="[env]\nstep_size = -1\n"),
            "config_toml",
        ),
        "no_config": (
            _rewrite_meta(src, tmp_path / "b.npz", config_toml=None),
            "config_toml is missing",
        ),
        "obs": (_rewrite_meta(src, tmp_path / "c.npz", obs_dim=3), "inputs"),
        "angles": (
            _rewrite_meta(src, tmp_path / "d.npz", action_angles_rad=[0.0] * 36),
            "action_angles_rad",
        ),
        "scale": (_rewrite_meta(src, tmp_path / "e.npz", length_scale=1.0), "length_scale"),
    }
    data = src.read_bytes()
    (tmp_path / "t.npz").write_bytes(data[: len(data) // 3])
    cases["truncated"] = (tmp_path / "t.npz", "truncated or corrupt")
    cases["version"] = (
        _rewrite_meta(src, tmp_path / "v.npz", format_version=99),
        "format_version 99",
    )
    for name, (path, msg) in cases.items():
        with pytest.raises(PolicyFileError, match=msg):
            TrajectoryGenerator.load(path)


@pytest.mark.slow
def test_bad_generation_arguments_name_the_field(trained_policy):
    gen = TrajectoryGenerator.load(trained_policy)
    ob = Obstacle.named("base1")
    for kwargs, msg in [
        ({"pivot": "left"}, "pivot must be one of"),
        ({"start_y": float("nan")}, "start_y"),
        ({"step_length": 0.3}, "step_length"),
        ({"n_points": 1}, "n_points"),
        ({"smoothing": -1.0}, "smoothing"),
        ({"duration": 0.0}, "duration"),
        ({"pivot_y": float("inf")}, "pivot_y"),
    ]:
        with pytest.raises(ValueError, match=msg):
            gen.generate(ob, **kwargs)
    with pytest.raises(ValueError, match="start_y: 2 values for 3"):
        gen.generate_batch([ob] * 3, start_y=[0.0, 0.1])
    with pytest.raises(ValueError, match="obstacle: its near edge"):
        gen.generate(Obstacle.named("base1", center_y=0.2))


# --------------------------------------------------------------------------------------------
# Without JAX, and the CLI
# --------------------------------------------------------------------------------------------

BLOCK_JAX = """
import sys, importlib.abc
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split('.')[0] in ('jax', 'jaxlib', 'flax', 'optax', 'chex', 'matplotlib', 'torch', 'ray'):
            raise ImportError('blocked for this test: ' + name)
sys.meta_path.insert(0, Block())
"""


@pytest.mark.slow
def test_inference_runs_where_jax_cannot_be_imported(trained_policy):
    code = BLOCK_JAX + (
        "from jaxexo.inference import TrajectoryGenerator, Obstacle\n"
        f"gen = TrajectoryGenerator.load({str(trained_policy)!r})\n"
        "t = gen.generate(Obstacle.profile([[0.38, 0.0], [0.45, 0.1], [0.52, 0.0]]), pivot='between')\n"
        "b = gen.generate_batch([Obstacle.named('base3')] * 3, start_y=[0.0, 0.02, 0.04])\n"
        "print('OK', t.heel.shape, len(b), sorted(m for m in sys.modules if m.split('.')[0] in ('jax', 'flax')))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120
    )
    assert out.returncode == 0, out.stderr
    assert "OK (100, 2) 3 []" in out.stdout
    # The probe works: importing jax under the block fails.
    out = subprocess.run(
        [sys.executable, "-c", BLOCK_JAX + "import jax"], capture_output=True, text=True, timeout=60
    )
    assert out.returncode != 0 and "blocked for this test" in out.stderr


@pytest.mark.slow
def test_cli_generate_writes_csv_json_and_plot(trained_policy, tmp_path):
    from jaxexo.cli import main

    out = tmp_path / "t.csv"
    rc = main(
        [
            "generate",
            "--policy",
            str(trained_policy),
            "--obstacle",
            "triangle",
            "--width",
            "0.16",
            "--height",
            "0.12",
            "--center-y",
            "0.42",
            "--pivot-y",
            "0.3",
            "--out",
            str(out),
            "--json",
            str(tmp_path / "t.json"),
            "--plot",
            str(tmp_path / "t.png"),
        ]
    )
    doc = json.loads((tmp_path / "t.json").read_text())
    assert rc == (0 if doc["checks"]["ok"] else 1)
    assert doc["scene"]["width"] == pytest.approx(0.16) and doc["scene"][
        "pivot_y"
    ] == pytest.approx(0.3)
    assert (tmp_path / "t.png").stat().st_size > 10_000
    assert np.loadtxt(out, delimiter=",", skiprows=1).shape == (100, 15)
    assert (
        main(
            [
                "generate",
                "--policy",
                str(tmp_path / "none.npz"),
                "--obstacle",
                "base1",
                "--out",
                str(out),
            ]
        )
        == 2
    )
