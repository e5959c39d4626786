"""One step rule: the JAX environment (ExoStepEnv.step_env, as the trainer and the JAX
evaluation's ``make_rollouts`` step it) and the NumPy rollouts (``TrajectoryGenerator.rollout`` and
``rollout_batch``) end every episode at the same step with the same outcome, on thousands of
unshielded episodes whose collisions terminate, where the rule that ends an episode decides the most.
Random-weight policies on randomized layouts (procedural terrain, the obstacle mixture with its
rectangles, the thesis's five obstacles); the set must contain moves that clip a corner: the foot at
the end of the move is clear of the obstacle while the region it sweeps is not (the collision the
swept rule catches and an end-pose test misses)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from jaxexo.config import load_config
from jaxexo.inference.scenarios import sample_scenarios, training_scenarios
from jaxexo.physics import geometry, swept, transition
from jaxexo.physics.scene import stack_scenes
from jaxexo.shield.rows import take_rows

from conftest import ROOT, random_generator

jax = pytest.importorskip("jax")
import jax.numpy as jnp  # noqa: E402

from jaxexo.env import ExoStepEnv  # noqa: E402
from jaxexo.env.exo_step import Layout  # noqa: E402
from jaxexo.train.evaluate import make_rollouts  # noqa: E402
from jaxexo.train.network import QNetwork  # noqa: E402

# Random-weight policies (conftest.random_generator's seeds) and scenes per policy: one compiled
# program for every policy (the batch's shape is the same). Most random networks steer every swing
# one way (seeds 3 and 11 run every episode to the step limit); these four collide often, clip
# corners (seeds 0, 7, 12) and reach the goal (seed 10), measured over seeds 0-15.
SEEDS = (0, 7, 10, 12)
SCENES = 768
# Episodes whose single-swing rollout (``rollout``, one Python step at a time) is also compared: every
# episode a corner-clipping move ends, and this many more per policy.
SINGLE_EXTRA = 96


def _config():
    """configs/default.toml without the shield, collisions terminating the episode."""
    cfg = load_config(ROOT / "configs" / "default.toml")
    return dataclasses.replace(
        cfg, env=dataclasses.replace(cfg.env, shield=False, collision="terminate")
    )


def _scenes(gen, seed: int):
    """SCENES scenes: half procedural terrain (the config's training draw), a quarter the obstacle
    mixture (terrain off: base1-3 and rectangles, whose square corners a diagonal move can clip), a
    quarter the thesis's five test obstacles; as Scenes and as the environment's layout arrays (the
    same float32 numbers on both sides)."""
    cfg = gen.config
    mixture = dataclasses.replace(cfg, layout=dataclasses.replace(cfg.layout, terrain=None))
    q = SCENES // 4
    sc = (
        training_scenarios(cfg, 2 * q, seed)
        + training_scenarios(mixture, q, seed + 100)
        + sample_scenarios(cfg, q, seed + 200)
    )
    scenes = [gen.scene(s.obstacle, s.pivot, None, s.start_y, s.step_length) for s in sc]
    lay = stack_scenes(scenes, np.float32)._replace(kind=np.zeros(len(scenes), np.int32))
    return scenes, lay


def _flax_params(policy):
    """The flax parameters (QNetwork's layer names) of a policy without LayerNorm."""
    n = len(policy.kernels)
    return {
        "params": {
            ("out" if i == n - 1 else f"dense_{i}"): {
                "kernel": jnp.asarray(policy.kernels[i]),
                "bias": jnp.asarray(policy.biases[i]),
            }
            for i in range(n)
        }
    }


@pytest.fixture(scope="module")
def episodes():
    """Per policy: the scenes, their layouts, the JAX greedy rollouts (outcomes and heel paths) and
    the NumPy batch rollouts (paths and actions), and the generator."""
    cfg = _config()
    env = ExoStepEnv(cfg)
    params = env.default_params
    net = QNetwork(hidden=(16,), num_actions=env.num_actions, layer_norm=False)
    run = jax.jit(make_rollouts(env, net.apply, cfg.env.max_steps, record=True))
    out = []
    for seed in SEEDS:
        gen = random_generator(cfg, seed)
        scenes, lay = _scenes(gen, seed)
        res, path = run(_flax_params(gen.policy), Layout(**lay._asdict()), params)
        paths, acts = gen.rollout_batch(scenes)
        out.append(
            {
                "gen": gen,
                "scenes": scenes,
                "lay": lay,
                "jax": jax.tree.map(np.asarray, res),
                "jax_path": np.asarray(path),
                "paths": paths,
                "acts": acts,
            }
        )
    return out


def _padded(paths, n):
    """Paths (list of (L_i, 2)) as one (B, n, 2) array, each repeating its last point."""
    return np.stack([np.vstack([p, np.repeat(p[-1:], n - len(p), axis=0)]) for p in paths])


def _numpy_outcome(gen, lay, paths):
    """(steps, reached, collided, first colliding move + 1 (0: none)) of NumPy heel paths, judged
    afresh by jaxexo.physics (every move's exact swept clearance where it is under the touch
    tolerance, jaxexo.physics.swept.path_clearance_pruned), not by the rollout's own test."""
    p = gen.np_params
    steps = np.array([len(x) - 1 for x in paths])
    path = _padded(paths, gen.max_steps + 1)
    _, move = swept.path_clearance_pruned(
        path,
        p.foot_length,
        lay.outline.astype(np.float64),
        below=np.full(len(paths), 2 * geometry.TOUCH_EPS),
    )
    hit = geometry.foot_collides(np, move)
    first = np.where(hit.any(1), hit.argmax(1) + 1, 0)
    end = path[np.arange(len(paths)), steps]
    reached = transition.goal_reached(np, p, end[:, 0], end[:, 1], lay.goal_y)
    return steps, reached, first > 0, first


def _clips(gen, lay, paths):
    """(B,) bool: the path's last move clips the obstacle: the foot clear at the move's end (and start)
    while the region it sweeps touches."""
    p = gen.np_params
    h0 = np.array([x[-2] if len(x) > 1 else x[-1] for x in paths])
    h1 = np.array([x[-1] for x in paths])
    ol = lay.outline.astype(np.float64)
    c0 = geometry.foot_clearance(np, h0, p.foot_length, ol)
    c1 = geometry.foot_clearance(np, h1, p.foot_length, ol)
    sweep = swept.swept_clearance(np, h0, h1, p.foot_length, ol)
    return (
        ~geometry.foot_collides(np, c0)
        & ~geometry.foot_collides(np, c1)
        & geometry.foot_collides(np, sweep)
    )


def test_jax_and_numpy_rollouts_end_every_episode_at_the_same_step(episodes):
    """Greedy random-weight policies, unshielded, collisions terminating: the JAX evaluation's rollouts
    and the NumPy batch rollouts take the same path, end at the same step, and end it the same way
    (goal, collision or step limit); corner-clipping moves are among the collisions."""
    clips = collisions = reached_goal = limited = total = 0
    for e in episodes:
        j, gen, lay, paths = e["jax"], e["gen"], e["lay"], e["paths"]
        steps, reached, collided, first = _numpy_outcome(gen, lay, paths)
        np.testing.assert_array_equal(steps, j.steps)
        np.testing.assert_array_equal(reached, j.reached)
        np.testing.assert_array_equal(collided, j.collided)
        # a collision ends the episode on the move that makes it, in both
        np.testing.assert_array_equal(first[collided], steps[collided])
        for i, x in enumerate(paths):
            np.testing.assert_allclose(x[1:], e["jax_path"][i, : steps[i]], atol=2e-5)
        clip = _clips(gen, lay, paths)
        assert not (clip & ~collided).any()
        clips += int(clip.sum())
        collisions += int(collided.sum())
        reached_goal += int(reached.sum())
        limited += int((steps == gen.max_steps).sum())
        total += len(paths)
    assert total == len(SEEDS) * SCENES
    # every way to end an episode is exercised (measured: 980 collisions, 7 goals, 2,088 limits)
    assert collisions > total // 10 and reached_goal > 0 and limited > 0
    # the moves an end-pose test misses are in the set (measured: 74)
    assert clips >= 30, clips


def test_single_swing_rollout_ends_where_the_batch_ends(episodes):
    """``rollout`` (one swing, Python floats) against ``rollout_batch`` on every episode a
    corner-clipping move ends and SINGLE_EXTRA others per policy: the same path, the same length."""
    compared = clipped = 0
    for e in episodes:
        gen, lay, paths, scenes = e["gen"], e["lay"], e["paths"], e["scenes"]
        clip = _clips(gen, lay, paths)
        rest = np.flatnonzero(~clip)
        pick = np.r_[np.flatnonzero(clip), rest[:: max(1, len(rest) // SINGLE_EXTRA)]]
        for i in pick:
            one, acts = gen.rollout(scenes[i])
            assert len(one) == len(paths[i]), (i, len(one), len(paths[i]))
            np.testing.assert_allclose(one, paths[i], atol=2e-5)
            np.testing.assert_array_equal(acts, e["acts"][i])
        compared += len(pick)
        clipped += int(clip.sum())
    assert clipped >= 20 and compared > len(SEEDS) * SINGLE_EXTRA


def test_thesis_baseline_environment_ends_where_the_rollouts_end(episodes):
    """The thesis-style NumPy environment (benchlib.thesis_baseline.NumpyExoEnv, stepped one
    action at a time through jaxexo.physics.transition) replaying the rollouts' actions ends each
    episode on the same step, clipped corners included."""
    from benchlib.thesis_baseline import NumpyExoEnv

    e = episodes[0]
    gen, lay, paths, acts = e["gen"], e["lay"], e["paths"], e["acts"]
    clip = _clips(gen, lay, paths)
    pick = np.r_[np.flatnonzero(clip), np.flatnonzero(~clip)[:: len(paths) // 24]]
    assert clip.sum() >= 20
    for i in pick:
        pool = take_rows(lay, slice(i, i + 1))
        env = NumpyExoEnv(gen.config, pool)
        env.reset()
        for k, a in enumerate(acts[i]):
            _, _, terminated, truncated, _ = env.step(int(a))
            np.testing.assert_allclose(env.heel, paths[i][k + 1], atol=2e-5)
            if terminated or truncated:
                break
        assert k + 1 == len(acts[i]), (i, k + 1, len(acts[i]))
