"""The one-swing rollout's inlined pieces against the functions they inline, bit for bit: the loop's
rules (jaxexo.physics.transition), the Q-network's step (the plain per-element form) and the scalar
shield's end conditions and joint limits (jaxexo.shield.rule, jaxexo.physics.kinematics). Policy:
the trained reference policy (tests/data/reference/policy.npz, LayerNorm)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from jaxexo.inference import TrajectoryGenerator
from jaxexo.inference.scenarios import safety_scenarios
from jaxexo.physics import actions, kinematics, transition
from jaxexo.physics.scene import stack_scenes
from jaxexo.physics.transition import scalar
from jaxexo.shield import rule
from jaxexo.shield.scalar import LENGTH_MARGIN, _f32

from conftest import ROOT

POLICY = ROOT / "tests" / "data" / "reference" / "policy.npz"


@pytest.fixture(scope="module")
def gen_scenes():
    gen = TrajectoryGenerator.load(POLICY)
    sc = safety_scenarios(gen.config, 40, unseen=True)
    return gen, [
        gen.scene(s.obstacle, pivot=s.pivot, start_y=s.start_y, step_length=s.step_length)
        for s in sc
    ]


def _reference_rollout(gen, scene, heel=None, steps: int = 0, visited: bool = False):
    """``TrajectoryGenerator.rollout``'s loop (``rollout_from``'s, from ``heel`` with the clock at
    ``steps`` and the mid-goal flag ``visited``; None: the scene's start) written with the
    transition functions themselves."""
    sp, step = gen.sp, gen.step_net
    step.set_scene(gen._basis(scene))
    mid_y, mid_z = transition.mid_goal(scalar, sp, scene.center_y, scene.height)
    (hy, hz) = (float(scene.start_y), 0.0) if heel is None else heel
    t, last = steps, -1
    pts, acts = [(hy, hz)], []
    single = gen._shield("scalar").swing(scene, stack_scenes([scene], np.float32))
    while True:
        a = single.choose(hy, hz, _plain_q(step, hy, hz, t, 1.0 if visited else 0.0), last)
        hy, hz = transition.move_heel(scalar, sp, hy, hz, *gen.directions[a])
        t += 1
        visited = visited or transition.in_mid_goal(scalar, sp, hy, hz, mid_y, mid_z)
        pts.append((hy, hz))
        acts.append(a)
        last = int(a)
        reached = transition.goal_reached(scalar, sp, hy, hz, scene.goal_y)
        if transition.terminated(
            scalar, reached, False, bool(gen.np_params.terminate_on_collision)
        ) or transition.truncated(t, gen.max_steps):
            break
    return np.asarray(pts), np.asarray(acts, dtype=np.int64)


def _plain_q(step, heel_y, heel_z, time, visited):
    """StepNetwork.q_values written element by element, a Python float scaling in place."""
    c = np.ones(5, np.float32)
    c[0], c[1], c[2], c[3] = heel_y, heel_z, time, visited
    x = c
    for w, pre, _, shift, inv_h in step._layers:
        h = np.dot(x, w)
        if shift is not None:
            h *= 1.0 / math.sqrt(float(np.dot(h, h)) * inv_h + step.net.eps)
            h += shift
        x = np.append(np.maximum(h, 0.0), np.float32(1.0))
    return np.dot(x, step.net.weights[-1])


def test_the_rollout_is_the_transition_rules_loop(gen_scenes):
    """The same points and actions as the loop written with jaxexo.physics.transition."""
    gen, scenes = gen_scenes
    assert not gen.terminate_on_collision  # the reference loop leaves collisions out
    steps = 0
    for scene in scenes:
        pts, acts = gen.rollout(scene)
        ref_pts, ref_acts = _reference_rollout(gen, scene)
        np.testing.assert_array_equal(acts, ref_acts)
        np.testing.assert_array_equal(pts, ref_pts)
        steps += len(acts)
    assert steps > 500


def test_the_step_network_is_the_plain_one_bit_for_bit(gen_scenes):
    gen, scenes = gen_scenes
    rng = np.random.default_rng(0)
    step = gen.step_net
    for scene in scenes[:10]:
        step.set_scene(gen._basis(scene))
        for _ in range(50):
            hy, hz = rng.uniform(-0.2, 1.0), rng.uniform(0.0, 0.4)
            t, v = int(rng.integers(0, 60)), float(rng.integers(0, 2))
            want = _plain_q(step, hy, hz, t, v)
            np.testing.assert_array_equal(step.q_values(hy, hz, t, v), want)


def _plain_admissible(sh, a, heel):
    """SwingShield._admissible's end conditions and reach through the rule's own functions: False /
    None as the shield decides there, else "next" (the clearance part, unchanged, follows)."""
    py, pz = sh.offsets[a]
    y, z = transition.keep_in_world(scalar, sh.sp, _f32(heel.y + py), _f32(heel.z + pz))
    if not rule.end_conditions(scalar, sh.form.ends_in, heel.y, heel.z, y, z, sh.goal):
        if rule.end_conditions(scalar, sh.form.ends_out, heel.y, heel.z, y, z, sh.goal):
            return None
        return False
    k = _plain_reachable(sh, y, z)
    if k <= 0:
        return None if k == 0 else False
    return "next"


def _plain_reachable(sh, y, z):
    """SwingShield.reachable with kinematics' own limit test."""
    leg, p = sh.leg, sh.pivot
    dist = 0.5 * (p - y)
    hz2 = leg * leg - dist * dist
    hz = math.sqrt(hz2 if hz2 > sh.min_hz2 else sh.min_hz2)
    hy = 0.5 * (p + y)
    unsure = False
    h0, h1, k0, k1 = sh.limits
    swing, stance = sh._leg(hy, hz, y, z), sh._leg(hy, hz, p, 0.0)
    for _, hip, knee, e_h, e_k, straight in (swing, stance):
        k = math.inf if straight and sh.knee_hi_free and knee <= 1e-5 else k1
        if kinematics.joint_limit_violation(
            scalar, hip, knee, h0 + e_h, h1 - e_h, k0 + e_k, k - e_k
        ):
            if kinematics.joint_limit_violation(
                scalar, hip, knee, h0 - e_h, h1 + e_h, k0 - e_k, k + e_k
            ):
                return -1
            unsure = True
    tol = sh.sp.leg_length_tolerance
    if kinematics.leg_too_long(scalar, swing[0], stance[0], sh.t, sh.s, tol - LENGTH_MARGIN):
        wide = kinematics.leg_too_long(scalar, swing[0], stance[0], sh.t, sh.s, tol + LENGTH_MARGIN)
        return -1 if wide else 0
    return 0 if unsure else 1


def test_the_scalar_shields_inlined_rules_are_the_rules(gen_scenes):
    """At random heels (on the floor, near the goal box, at the world's edges, out of reach too),
    every forward move: the shield's inlined end conditions and joint limits decide as the rule's
    and kinematics' functions."""
    gen, scenes = gen_scenes
    rng = np.random.default_rng(3)
    sp = gen.sp
    seen = {False: 0, None: 0, "next": 0}
    for scene in scenes[:12]:
        sh = gen._shield("scalar").swing(scene)
        goal = float(scene.goal_y)
        for _ in range(60):
            hy = float(rng.choice([rng.uniform(sp.bounds_y[0] - 0.01, goal + 0.1), goal]))
            hy += float(rng.choice([0.0, sp.goal_tolerance[0], -sp.goal_tolerance[0]]))
            hz = float(rng.choice([0.0, rng.uniform(0.0, 0.6), sp.max_z_world]))
            heel = sh._heel(hy, hz)
            for a in sh.fwd_idx:
                want = _plain_admissible(sh, a, heel)
                got = sh._admissible(a, heel)
                seen[want] += 1
                if want == "next":  # the clearance part follows, unchanged
                    end = _end(sh, a, heel)
                    assert sh.reachable(*end) == _plain_reachable(sh, *end) == 1
                else:
                    assert got is want, (a, hy, hz, got, want)
    assert min(seen.values()) > 20, seen
    assert actions.NUM_ACTIONS == len(sh.offsets)


def _end(sh, a, heel):
    py, pz = sh.offsets[a]
    return transition.keep_in_world(scalar, sh.sp, _f32(heel.y + py), _f32(heel.z + pz))


def test_the_scalar_shields_reach_is_kinematics_near_every_limit(gen_scenes):
    """SwingShield.reachable against kinematics' own tests at ends on either side of the reach's
    boundary (found by bisection, then probed within its error bounds): 1, 0 and -1 all occur."""
    gen, scenes = gen_scenes
    rng = np.random.default_rng(4)
    seen = {-1: 0, 0: 0, 1: 0}
    for scene in scenes[:6]:
        sh = gen._shield("scalar").swing(scene)
        for _ in range(40):
            inside = np.array([sh.pivot - rng.uniform(0.1, 0.5), rng.uniform(0.0, 0.2)])
            far = inside + rng.normal(size=2) * 1.5
            if _plain_reachable(sh, *far) == 1 or _plain_reachable(sh, *inside) != 1:
                continue
            lo, hi = 0.0, 1.0
            for _ in range(50):
                mid = 0.5 * (lo + hi)
                lo, hi = (
                    (mid, hi)
                    if _plain_reachable(sh, *(inside + mid * (far - inside))) == 1
                    else (lo, mid)
                )
            d = far - inside
            for k in range(-40, 41):
                y, z = inside + lo * d + k * 1e-6 * d / np.linalg.norm(d)
                want = _plain_reachable(sh, float(y), float(z))
                assert sh.reachable(float(y), float(z)) == want
                seen[want] += 1
    assert min(seen.values()) > 50, seen
