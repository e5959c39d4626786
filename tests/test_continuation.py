"""Continuation paths from a mid-air foot state (jaxexo.swing.continuation): the policy's rollout from
any heel (``rollout_from``) against the loop written with the transition rules, the RL and CFFTG
continuations' start, landing and verdict on the new obstacle against an independent dense
clearance, CFFTG's quintic start against the state's derivatives, and the refusals. Policy: the
reference policy (tests/data/reference/policy.npz)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from jaxexo.baselines.cfftg import CFFTG
from jaxexo.inference import TrajectoryGenerator
from jaxexo.inference.scenarios import safety_scenarios
from jaxexo.physics import geometry, transition
from jaxexo.physics.geometry import Obstacle
from jaxexo.physics.transition import scalar
from jaxexo.swing.continuation import policy_clock
from jaxexo.swing.replan import foot_state
from jaxexo.swing.timing import time_swing

from conftest import ROOT
from test_fast_rollout import _reference_rollout

POLICY = ROOT / "tests" / "data" / "reference" / "policy.npz"


def taller(ob: Obstacle, factor: float) -> Obstacle:
    if ob.shape == "profile":
        return Obstacle.profile(ob.outline * [1.0, factor])
    return dataclasses.replace(ob, height=ob.height * factor)


def same_feet(gen, old, obstacle, step_shift: float = 0.0):
    return gen.scene(
        obstacle,
        pivot_y=old.pivot_y,
        start_y=old.start_y,
        step_length=old.goal_y - old.start_y + step_shift,
    )


@pytest.fixture(scope="module")
def cases():
    """(gen, cfftg, [(old scene, new scene, state)]): RL swings over unseen shapes, the obstacle made
    30-60 % taller, the state at 20-40 % of the swing where the foot is still clear of it."""
    gen = TrajectoryGenerator.load(POLICY)
    cf = CFFTG(gen.config)
    rng = np.random.default_rng(7)
    out = []
    for s in safety_scenarios(gen.config, 14, unseen=True):
        tr = gen.generate(s.obstacle, pivot=s.pivot, start_y=s.start_y, step_length=s.step_length)
        sw = time_swing(tr, gen.config)
        new = same_feet(gen, tr.scene, taller(s.obstacle, rng.uniform(1.3, 1.6)))
        st = foot_state(sw, rng.uniform(0.2, 0.4) * sw.duration)
        c = geometry.foot_clearance(np, st.heel[None], gen.sp.foot_length, new.outline)[0]
        if tr.ok and c >= gen.sp.min_clearance:
            out.append((tr.scene, new, st))
    assert len(out) >= 8
    return gen, cf, out


def test_rollout_from_the_start_is_the_rollout_and_from_mid_air_the_rules_loop(cases):
    gen, _, rows = cases
    for old, new, st in rows[:4]:
        for scene in (old, new):
            pts, acts = gen.rollout(scene)
            p2, a2 = gen.rollout_from(
                scene, heel=(float(scene.start_y), 0.0), steps=0, visited=False
            )
            assert np.array_equal(pts, p2) and np.array_equal(acts, a2)
        steps, visited = policy_clock(st, new, gen.sp, gen.max_steps)
        heel = (float(st.heel[0]), float(st.heel[1]))
        got, _ = gen.rollout_from(new, heel=heel, steps=steps, visited=visited)
        assert np.array_equal(got, _reference_rollout(gen, new, heel, steps, visited)[0])
        assert 0 < steps < gen.max_steps and got[0].tolist() == list(heel)


def test_the_policy_clock_is_the_path_so_far(cases):
    gen, _, rows = cases
    old, new, st = rows[0]
    length = np.linalg.norm(np.diff(st.past_heel, axis=0), axis=1).sum()
    steps, visited = policy_clock(st, new, gen.sp, gen.max_steps)
    assert steps == round(length / gen.sp.step_size)
    mid_y, mid_z = new.center_y, new.height + gen.sp.mid_goal_clearance
    inside = (np.abs(st.past_heel[:, 0] - mid_y) <= gen.sp.mid_goal_half_size[0]) & (
        np.abs(st.past_heel[:, 1] - mid_z) <= gen.sp.mid_goal_half_size[1]
    )
    assert visited == bool(inside.any())
    # a path through the new mid-goal box sets the flag; a very long one is clipped
    through = dataclasses.replace(st, past_heel=np.vstack([st.past_heel, [[mid_y, mid_z]]]))
    assert policy_clock(through, new, gen.sp, gen.max_steps)[1]
    long = dataclasses.replace(st, past_heel=np.array([[old.start_y, 0.0], [old.start_y, 50.0]]))
    assert policy_clock(long, new, gen.sp, gen.max_steps)[0] == gen.max_steps - 1


def _dense_clearance(heel, foot_length, outline, factor=10):
    """The foot's clearance at 10x more points on the polyline through the samples."""
    s = np.linspace(0.0, len(heel) - 1, factor * (len(heel) - 1) + 1)
    dense = np.column_stack([np.interp(s, np.arange(len(heel)), heel[:, k]) for k in (0, 1)])
    return geometry.foot_clearance(np, dense, foot_length, outline).min()


@pytest.mark.parametrize("method", ["rl", "cfftg"])
def test_a_continuation_starts_at_the_foot_and_lands_clear_of_the_new_obstacle(cases, method):
    gen, cf, rows = cases
    sp, oks = gen.sp, 0
    for old, new, st in rows:
        if method == "rl":
            traj = gen.continuation(new, st, fallback=None, swing_scene=old)
        else:
            traj = cf.continuation(new, st, swing_scene=old)
        assert np.array_equal(traj.heel[0], st.heel)  # exactly
        assert np.array_equal(traj.raw[0], st.heel)  # the policy's (or the plan's) own start
        assert traj.scene is new
        end_y, end_z = traj.heel[-1]
        landed = abs(end_y - new.goal_y) <= sp.goal_tolerance[0] and end_z == 0.0
        assert traj.checks.reached_goal == transition.goal_reached(
            scalar, sp, end_y, end_z, new.goal_y
        )
        dense = _dense_clearance(traj.heel, sp.foot_length, new.outline)
        old_dense = _dense_clearance(traj.heel, sp.foot_length, old.outline)
        # judged against the new obstacle: its clearance is the lower (the new one is taller)
        assert traj.checks.min_clearance <= dense + 1e-9 and dense <= old_dense + 1e-9
        if traj.ok:
            oks += 1
            assert landed and dense >= sp.min_clearance
            assert np.diff(traj.heel[:, 0]).min() >= -sp.backward_tolerance
        else:
            assert traj.checks.reasons
    assert oks >= (len(rows) - 1 if method == "rl" else len(rows) // 2)


def test_the_fallback_replaces_a_failing_rl_continuation_by_cfftgs(cases):
    gen, cf, rows = cases
    old, new, st = next(r for r in rows if cf.continuation(r[1], r[2]).ok)
    # a path so far long enough to leave the policy's clock one move (then truncated): it fails
    late = dataclasses.replace(
        st, past_heel=np.vstack([st.past_heel, st.past_heel[-1] + [0.0, 10.0], st.heel])
    )
    alone = gen.continuation(new, late, fallback=None, swing_scene=old)
    assert not alone.ok and len(alone.raw) <= 3
    both = gen.continuation(new, late, fallback="cfftg", swing_scene=old)
    planned = cf.continuation(new, late, swing_scene=old)
    assert planned.ok and both.ok and both.method == "cfftg-fallback"
    assert np.array_equal(both.heel, planned.heel) and np.array_equal(both.heel[0], st.heel)
    assert any("RL swing failed" in n for n in both.notes)


def test_cfftgs_continuation_matches_the_heels_motion_at_its_start(cases):
    _, cf, rows = cases
    n = 20001  # finite differences of error O(du^2): 2.5e-9 here
    for old, new, st in rows[:6]:
        plan = cf.plan_continuation([new], [st], n)
        p, tc = plan.paths[0], plan.tc[0]
        du = 1.0 / (n - 1)
        d1 = (-3.0 * p[0] + 4.0 * p[1] - p[2]) / (2.0 * du)
        d2 = (2.0 * p[0] - 5.0 * p[1] + 4.0 * p[2] - p[3]) / (du * du)
        v, a = np.asarray(st.heel_velocity), np.asarray(st.heel_acceleration)
        assert np.array_equal(p[0], st.heel)
        cos = d1 @ v / (np.linalg.norm(d1) * np.linalg.norm(v))
        assert cos > 1.0 - 1e-6  # the finite differences err by O(du^2)
        np.testing.assert_allclose(d1 / tc, v, rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(d2 / tc**2, a, rtol=1e-3, atol=1e-3)
        # the T_c rule: the length estimate over the speed, at most 0.5 s, halved until monotone
        top = new.height + cf.margin
        length = (new.goal_y - st.heel[0]) + abs(top - st.heel[1]) + top
        t0 = min(length / np.linalg.norm(v), 0.5)
        assert any(np.isclose(tc, t0 / 2**k) for k in range(7))
        assert np.diff(p[:, 0]).min() >= -1e-9  # monotone in y (up to rounding)
        traj = cf.continuation(new, st, n_points=n, swing_scene=old)
        assert np.array_equal(traj.heel, p) and f"T_c={tc:.3f} s" in traj.notes[0]
        assert traj.heel[-1].tolist() == [new.goal_y, 0.0]


def test_continuations_refuse_bad_input(cases):
    gen, cf, rows = cases
    old, new, st = rows[0]
    y, z = st.heel
    foot = gen.sp.foot_length
    # an obstacle whose left side is 1 cm ahead of the toe, 60 cm high: the foot is within the margin
    wall = same_feet(gen, old, Obstacle.rectangle(0.05, 0.6, center_y=y + foot + 0.01 + 0.025))
    for fn in (gen.continuation, cf.continuation):
        with pytest.raises(ValueError, match="within the margin env.min_clearance"):
            fn(wall, st)
        with pytest.raises(ValueError, match="goal_y"):
            fn(same_feet(gen, old, new.obstacle, step_shift=0.05), st, swing_scene=old)
        with pytest.raises(ValueError, match="n_points must be an integer"):
            fn(new, st, n_points=5)
        with pytest.raises(TypeError, match="state: expected a FootState"):
            fn(new, st.heel)
        with pytest.raises(ValueError, match="state.heel_velocity"):
            fn(new, dataclasses.replace(st, heel_velocity=[np.nan, 0.0]))
        with pytest.raises(ValueError, match="state.past_heel: starts at"):
            fn(new, dataclasses.replace(st, past_heel=st.past_heel[50:]))
    with pytest.raises(ValueError, match="smoothing must be >= 0"):
        gen.continuation(new, st, smoothing=-1.0)
    assert z > 0.0


def test_cfftgs_batch_is_its_continuations_one_by_one(cases):
    _, cf, rows = cases
    scenes, states = [r[1] for r in rows], [r[2] for r in rows]
    batch = cf.continuation_batch(scenes, states, swing_scenes=[r[0] for r in rows])
    for i, (old, new, st) in enumerate(rows):
        one = cf.continuation(new, st, swing_scene=old)
        # the same plans (a batched product may round the last bit differently), the same verdicts
        np.testing.assert_allclose(batch.heel[i], one.heel, rtol=0, atol=1e-12)
        assert batch.ok[i] == one.ok and np.array_equal(batch.heel[i, 0], st.heel)
    with pytest.raises(ValueError, match="one state .* per scene"):
        cf.continuation_batch(scenes, states[:-1])
