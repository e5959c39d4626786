"""Every swing ends with the whole foot on the floor (jaxexo.swing.finish.landed): the policy stops in
its goal box, up to env.goal_tolerance[1] above the floor, and the raw path's descent to the floor is
then smoothed, corrected and judged with the rest of the swing; a walk appends nothing to it.

The RL swings here come from raw paths a policy could walk: CFFTG's safe path for the scene, walked
in moves of env.step_size and stopped at the first point in the goal box (the environment's
termination), so that about half of them stop above the floor, over the thesis five and shapes never
trained on, without training a policy."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.config import Config
from jaxexo.inference import Terrain, TrajectoryGenerator, plan_course
from jaxexo.inference.scenarios import safety_scenarios
from jaxexo.physics import transition
from jaxexo.swing import smoothing as sm
from jaxexo.swing.finish import landed
from jaxexo.swing.trajectory import assemble

from conftest import random_generator

# The default model with the thesis's goal box (2 cm): its rollouts stop up to 2 cm above the floor,
# which exercises the landing more than the default's 5 mm.
CFG = dataclasses.replace(
    Config(), env=dataclasses.replace(Config().env, goal_tolerance=(0.04, 0.02))
)
FLOOR_TOL = 0.002  # m: the heel at the end of a swing at most this far above the floor
N_POINTS = sm.DEFAULT_POINTS


def _generator(seed=0) -> TrajectoryGenerator:
    """A generator of random weights: its network is never asked here (the rollouts are replaced)."""
    return random_generator(CFG, seed)


def _walked(heel: np.ndarray, goal_y: float, sp) -> np.ndarray:
    """A heel path (N, 2) walked in moves of step_size along it, stopped at the first point in the goal
    box (transition.goal_reached), as a policy's rollout stops."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(heel, axis=0), axis=1))])
    u = np.arange(0.0, s[-1], sp.step_size)
    pts = np.vstack(
        [np.column_stack([np.interp(u, s, heel[:, 0]), np.interp(u, s, heel[:, 1])]), heel[-1:]]
    )
    inside = transition.goal_reached(np, sp, pts[:, 0], pts[:, 1], goal_y)
    return pts[: int(np.argmax(inside)) + 1]


class _Walker:
    """Rollouts replaced by ``_walked`` CFFTG paths: (raw, actions) as the generator's own return them."""

    def __init__(self, gen):
        self.gen, self.cfftg = gen, CFFTG(gen.config)

    def raws(self, scenes):
        plans = self.cfftg.finish(list(scenes), N_POINTS, 1.0)
        return [_walked(p.heel, sc.goal_y, self.gen.sp) for p, sc in zip(plans, scenes)]

    def install(self, monkeypatch):
        # on the class: a walk plans with generators built from this one (with_options), which
        # share its policy but not its instance attributes
        none = np.zeros(0, np.int64)
        cls = type(self.gen)
        monkeypatch.setattr(cls, "rollout", lambda g, scene: (self.raws([scene])[0], none))
        monkeypatch.setattr(
            cls, "rollout_batch", lambda g, scenes: (self.raws(scenes), [none] * len(scenes))
        )


def _scene_sets(n=40):
    return {
        "thesis five": safety_scenarios(CFG, n, seed=5),
        "unseen shapes": safety_scenarios(CFG, n, seed=5, unseen=True),
    }


def _kw(sc):
    return dict(
        pivot=[s.pivot for s in sc],
        start_y=[s.start_y for s in sc],
        step_length=[s.step_length for s in sc],
    )


def test_the_landing_rule():
    sp = _generator().sp
    goal = 0.70
    # Already on the floor, or short of the goal (that swing fails however it ends): unchanged.
    on_floor = np.array([[0.0, 0.0], [0.35, 0.2], [0.69, 0.0]])
    short = np.array([[0.0, 0.0], [0.35, 0.2], [0.60, 0.01]])
    np.testing.assert_array_equal(landed(sp, on_floor, goal), on_floor)
    np.testing.assert_array_equal(landed(sp, short, goal), short)
    # A last move that descends: the landing continues it to the floor.
    # (ends 3 mm up: inside the default's goal box too, z <= 5 mm)
    diag = np.array([[0.0, 0.0], [0.35, 0.2], [0.67, 0.007], [0.68, 0.003]])
    out = landed(sp, diag, goal)
    np.testing.assert_array_equal(out[:-1], diag)
    np.testing.assert_allclose(out[-1], [0.68 + 0.003 * 0.01 / 0.004, 0.0])
    # ... unless that leaves the goal box: straight down, in the box as the end is.
    far = np.array([[0.0, 0.0], [0.35, 0.2], [0.72, 0.007], [0.735, 0.003]])
    np.testing.assert_allclose(landed(sp, far, goal)[-1], [0.735, 0.0])
    # A last move straight down, sideways or up: straight down.
    for prev in ([0.68, 0.045], [0.66, 0.003], [0.66, 0.001]):
        np.testing.assert_allclose(
            landed(sp, np.array([[0.0, 0.0], prev, [0.68, 0.003]]), goal)[-1], [0.68, 0.0]
        )
    for out in (landed(sp, diag, goal), landed(sp, far, goal)):
        assert transition.goal_reached(np, sp, out[-1, 0], out[-1, 1], goal)


@pytest.mark.parametrize("name", ["thesis five", "unseen shapes"])
def test_generated_swings_end_on_the_floor_in_the_goal_and_keep_the_verdict(name, monkeypatch):
    gen = _generator()
    sc = _scene_sets()[name]
    walker = _Walker(gen)
    walker.install(monkeypatch)
    scenes = [
        gen.scene(s.obstacle, s.pivot, start_y=s.start_y, step_length=s.step_length) for s in sc
    ]
    raws = walker.raws(scenes)
    above = np.array([r[-1, 1] > FLOOR_TOL for r in raws])
    assert above.mean() > 0.3  # the premise: many rollouts stop above the floor
    cfftg_ok = CFFTG(CFG).finish(scenes, N_POINTS, 1.0).ok
    batch = gen.generate_batch([s.obstacle for s in sc], fallback=None, **_kw(sc))
    assert (
        len(batch) == len(sc) and batch.heel.shape[1] == N_POINTS
    )  # nothing appended to the curve
    # Every swing ends with heel and toe on the floor, inside the goal box, and passes where the path
    # it was walked along does (CFFTG's, whose clearance it keeps).
    np.testing.assert_array_less(batch.heel[:, -1, 1], FLOOR_TOL)
    np.testing.assert_array_less(batch.toe[:, -1, 1], FLOOR_TOL)
    np.testing.assert_allclose(
        batch.toe[:, -1, 0] - batch.heel[:, -1, 0], CFG.kinematics.foot_length
    )
    assert transition.goal_reached(
        np, gen.sp, batch.heel[:, -1, 0], batch.heel[:, -1, 1], np.array([s.goal_y for s in scenes])
    ).all()
    assert batch.ok[cfftg_ok].all(), [
        batch.reasons[i] for i in np.flatnonzero(cfftg_ok & ~batch.ok)
    ]
    for i, t in enumerate(batch):
        # The raw path kept, plus its landing where it stopped above the floor; the curve ends there.
        k = len(raws[i])
        np.testing.assert_array_equal(t.raw[:k], raws[i])
        assert len(t.raw) == k + (raws[i][-1, 1] > 0.0) and t.raw[-1, 1] == 0.0
        np.testing.assert_allclose(t.heel[-1], t.raw[-1])
        # The descent is the spline's own where the requested smoothing was kept as it is.
        if not t.notes and t.smoothing == gen.smoothing:
            np.testing.assert_allclose(
                t.heel, sm.smooth_paths([t.raw], N_POINTS, t.smoothing)[0], atol=1e-12
            )
        # The verdict is the complete swing's: measured afresh on the delivered path, the same.
        again = assemble(
            "rl",
            gen.sp,
            [t.scene],
            [t.raw],
            t.heel[None],
            [t.smoothing],
            duration=1.0,
            deviation=[t.checks.deviation],
        )[0]
        assert again.checks == t.checks
    # One swing at a time lands the same way.
    for i in np.flatnonzero(above)[:5]:
        one = gen.generate(
            sc[i].obstacle,
            pivot=sc[i].pivot,
            start_y=sc[i].start_y,
            step_length=sc[i].step_length,
            fallback=None,
        )
        np.testing.assert_allclose(one.heel, batch.heel[i], atol=1e-9)
        assert one.checks.reasons == batch[i].checks.reasons
        assert one.checks.min_clearance == pytest.approx(batch[i].checks.min_clearance, abs=1e-12)


def test_a_walk_lands_every_swing_on_the_floor_without_a_touch_down(monkeypatch):
    gen = _generator()
    _Walker(gen).install(monkeypatch)
    ter = Terrain.from_points(
        [[0.0, 0.0], [0.5, 0.0], [0.55, 0.1], [0.65, 0.1], [0.7, 0.0], [2.2, 0.0]]
    )
    course = plan_course(gen, ter, rate=50, fallback=None)
    assert course.ok, course.reasons
    assert set(course.methods) == {"rl"} and len(course.steps) >= 3
    for st in course.steps:
        t = st.trajectory
        assert len(t.heel) == N_POINTS and t.heel[-1, 1] == 0.0 and t.toe[-1, 1] == 0.0
        assert not any("touch-down" in n for n in t.notes)
        assert st.timed.heel[-1, 1] == pytest.approx(0.0, abs=1e-12)
    # Some of these swings stopped above the floor before landing (the rule had work to do).
    assert any(
        len(st.trajectory.raw) >= 2 and st.trajectory.raw[-2, 1] > FLOOR_TOL for st in course.steps
    )
