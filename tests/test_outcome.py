"""jaxexo.physics.outcome: the one safe-swing verdict, checked against a plain-Python reference,
the same in NumPy and JAX, the same whether folded step by step or reduced over samples, and used
by the trainer's per-episode counts."""

from types import SimpleNamespace

import numpy as np
import pytest

from jaxexo.physics import geometry, outcome, swept, transition


def _reference(reached, clearance, limit_bad, leg_bad, heel_y, margin=0.0, back_tol=np.inf):
    """A safe swing written out sample by sample: the heel must not fall back more than ``back_tol``
    behind the furthest y it reached before."""
    ok = bool(reached)
    furthest = -np.inf
    for j in range(len(clearance)):
        if clearance[j] - margin <= geometry.TOUCH_EPS or limit_bad[j] or leg_bad[j]:
            ok = False
        furthest = max(furthest, heel_y[j])
        if furthest - heel_y[j] > back_tol:
            ok = False
    return ok


def _from_samples(xp, reached, clearance, limit_bad, leg_bad, heel_y, **rule):
    """The verdict on per-sample arrays (..., N), reduced the way a sampled path is: the smallest
    clearance, the largest fall behind the furthest y (jaxexo.physics.swept.backward_motion)."""
    v = outcome.verdict(
        xp,
        reached,
        clearance.min(-1),
        ~limit_bad.any(-1),
        ~leg_bad.any(-1),
        swept.backward_motion(xp, heel_y),
        **rule,
    )
    return SimpleNamespace(**v._asdict(), max_backward=swept.backward_motion(xp, heel_y))


def _random_paths(rng, b=400, n=30):
    # Each path's closest approach drawn in [-1, 4] cm, so that every rule sees passes and failures.
    clearance = rng.uniform(-0.01, 0.04, (b, 1)) + rng.uniform(0, 0.1, (b, n))
    limit_bad = rng.uniform(size=(b, n)) < 0.002
    leg_bad = rng.uniform(size=(b, n)) < 0.002
    steps = rng.uniform(0, 0.05, (b, n))
    back = rng.uniform(size=b) < 0.5  # half of the paths step back once, up to 2 cm
    steps[back, rng.integers(1, n, back.sum())] = -rng.uniform(0, 0.02, back.sum())
    heel_y = np.cumsum(steps, axis=1)
    reached = rng.uniform(size=b) < 0.8
    return reached, clearance, limit_bad, leg_bad, heel_y


@pytest.mark.parametrize(
    "rule",
    [
        {},
        {"min_clearance_margin": 0.02},
        {"backward_tolerance": 0.005},
        {"min_clearance_margin": 0.01, "backward_tolerance": 0.0},
    ],
)
def test_verdict_on_samples_matches_reference(rule):
    rng = np.random.default_rng(0)
    reached, c, lb, gb, hy = _random_paths(rng)
    v = _from_samples(np, reached, c, lb, gb, hy, **rule)
    ref = [
        _reference(
            reached[i],
            c[i],
            lb[i],
            gb[i],
            hy[i],
            rule.get("min_clearance_margin", outcome.DEFAULT_MIN_CLEARANCE),
            rule.get("backward_tolerance", outcome.DEFAULT_BACKWARD_TOLERANCE),
        )
        for i in range(len(reached))
    ]
    np.testing.assert_array_equal(v.success, ref)
    assert 0.05 < np.mean(ref) < 0.95, "the random paths must exercise both verdicts"
    # Accuracy (eq 3.1) ignores the margin.
    np.testing.assert_array_equal(v.collision_free, (c > geometry.TOUCH_EPS).all(axis=1))


def test_margin_zero_and_no_backward_check_is_the_contact_rule():
    """Margin 0 and an infinite backward tolerance: success = goal & never touched & limits & leg length
    (the rule before the safe-swing margin, kept reachable through the config)."""
    rng = np.random.default_rng(1)
    reached, c, lb, gb, hy = _random_paths(rng)
    v = _from_samples(
        np, reached, c, lb, gb, hy, min_clearance_margin=0.0, backward_tolerance=np.inf
    )
    contact_rule = reached & ~(c <= geometry.TOUCH_EPS).any(1) & ~lb.any(1) & ~gb.any(1)
    np.testing.assert_array_equal(v.success, contact_rule)


def test_defaults_are_the_configs_safe_swing():
    """The rule's defaults are declared once (here) and are the config's env defaults."""
    from jaxexo.config import Config

    env = Config().env
    assert (
        (env.min_clearance, env.backward_tolerance)
        == (outcome.DEFAULT_MIN_CLEARANCE, outcome.DEFAULT_BACKWARD_TOLERANCE)
        == (0.02, 0.005)
    )
    assert outcome.rule(env) == {"min_clearance_margin": 0.02, "backward_tolerance": 0.005}


def test_margin_and_backward_tolerance_fail_the_right_check():
    hy = np.array([[0.0, 0.1, 0.09, 0.3]])  # one 1 cm step backwards
    c = np.array([[0.05, 0.015, 0.03, 0.05]])  # 1.5 cm closest approach
    no = np.zeros((1, 4), bool)
    yes = np.array([True])
    contact_rule = {"min_clearance_margin": 0.0, "backward_tolerance": np.inf}
    assert _from_samples(np, yes, c, no, no, hy, **contact_rule).success[0]
    v = _from_samples(np, yes, c, no, no, hy, min_clearance_margin=0.02, backward_tolerance=np.inf)
    assert outcome.failed_checks(v, 0) == ("clearance_ok",) and v.collision_free[0]
    v = _from_samples(np, yes, c, no, no, hy, min_clearance_margin=0.0, backward_tolerance=0.005)
    assert outcome.failed_checks(v, 0) == ("backward_ok",)
    np.testing.assert_allclose(v.max_backward, [0.01])


def _info(**fields) -> transition.StepInfo:
    """A step's info with the given fields, the others None (the verdict reads five)."""
    return transition.StepInfo(**{**dict.fromkeys(transition.StepInfo._fields), **fields})


def test_step_by_step_equals_samples_and_jax_equals_numpy():
    """Folding per-step env flags (``accumulate``, with steps after the end masked) gives the verdict
    of reducing the same steps as samples; jax.numpy gives NumPy's verdict."""
    jnp = pytest.importorskip("jax.numpy")
    rng = np.random.default_rng(2)
    reached, c, lb, gb, hy = _random_paths(rng, b=200, n=20)
    end = rng.integers(5, 20, size=200)  # episode length; later steps are junk
    goal_step = np.zeros((200, 20), bool)
    goal_step[np.arange(200), end - 1] = reached
    # the step's info.backward: how far the heel is behind its furthest y before the step
    furthest = np.maximum.accumulate(np.concatenate([hy[:, :1], hy[:, :-1]], axis=1), axis=1)
    rule = {"min_clearance_margin": 0.01, "backward_tolerance": 0.02}
    for xp in (np, jnp):
        acc = outcome.start(xp, (200,))
        for j in range(20):
            info = _info(
                goal_reached=xp.asarray(goal_step[:, j]),
                clearance=xp.asarray(c[:, j], dtype=xp.float32),
                joint_limit_violation=xp.asarray(lb[:, j]),
                leg_length_violation=xp.asarray(gb[:, j]),
                backward=xp.asarray(furthest[:, j] - hy[:, j], dtype=xp.float32),
            )
            acc = outcome.accumulate(xp, acc, info, xp.asarray(j < end))
        v = outcome.episode_verdict(xp, acc, **rule)
        ref = [
            _reference(
                reached[i],
                c[i, : end[i]].astype(np.float32),
                lb[i, : end[i]],
                gb[i, : end[i]],
                hy[i, : end[i]],
                **{"margin": 0.01, "back_tol": 0.02},
            )
            for i in range(200)
        ]
        np.testing.assert_array_equal(np.asarray(v.success), ref)


def test_trainer_counts_successes_with_the_verdict():
    """Trainer._episode_stats counts, per finished episode, the verdict of its own steps."""
    jax = pytest.importorskip("jax")
    import jax.numpy as jnp

    from jaxexo.train.trainer import EpisodeStats, Trainer

    rng = np.random.default_rng(3)
    n, T = 16, 40
    stats = EpisodeStats(ret=jnp.zeros(n), outcome=outcome.start(jnp, (n,)))
    steps_in_ep = np.zeros(n, int)
    ep = [dict(c=[], lb=[], gb=[]) for _ in range(n)]
    want_succ = want_acc = want_done = 0
    # The contact rule (margin 0, no backward check), which _reference's defaults write out.
    contact_rule = SimpleNamespace(min_clearance=0.0, backward_tolerance=np.inf)
    step = jax.jit(lambda *a: Trainer._episode_stats(*a, contact_rule))
    total = np.zeros(4)
    for _ in range(T):
        goal = rng.uniform(size=n) < 0.15
        trunc = (steps_in_ep + 1 >= 8) & ~goal
        clearance = jnp.asarray(rng.uniform(-0.002, 0.2, n), jnp.float32)
        info = _info(
            goal_reached=jnp.asarray(goal),
            clearance=clearance,
            collision=clearance <= geometry.TOUCH_EPS,
            joint_limit_violation=jnp.asarray(rng.uniform(size=n) < 0.02),
            leg_length_violation=jnp.asarray(rng.uniform(size=n) < 0.02),
            backward=jnp.zeros(n),
        )
        out = transition.Step(
            *(None,) * 4,
            terminated=jnp.asarray(goal),
            truncated=jnp.asarray(trunc),
            reward=jnp.ones(n),
            info=info,
            max_y=None,
        )
        stats, row = step(stats, out)
        total += [
            float(row.episodes),
            float(row.return_sum),
            float(row.successes),
            float(row.accurate),
        ]
        for i in range(n):
            e = ep[i]
            e["c"].append(float(info.clearance[i]))
            e["lb"].append(bool(info.joint_limit_violation[i]))
            e["gb"].append(bool(info.leg_length_violation[i]))
            if goal[i] or trunc[i]:
                want_done += 1
                ok = _reference(goal[i], e["c"], e["lb"], e["gb"], np.zeros(len(e["c"])))
                want_succ += ok
                want_acc += all(x > geometry.TOUCH_EPS for x in e["c"])
                ep[i] = dict(c=[], lb=[], gb=[])
                steps_in_ep[i] = 0
            else:
                steps_in_ep[i] += 1
    # Totals: [episodes finished, return sum, successes, accurate]; counts are exact in float32.
    assert (total[0], total[2], total[3]) == (want_done, want_succ, want_acc)
    assert 0 < want_succ < want_acc < want_done
