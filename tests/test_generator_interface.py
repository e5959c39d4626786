"""Adding a generator: a third one, written here alone (a lift-over-lower curve), registered by name
and run through every path the built-in ones take: ``generate``, ``generate_batch``,
``at_clearance``, ``replan``, a walk (``plan_course``) and ``jaxexo eval``'s comparison. Nothing in
the package names it (docs/architecture.md, Adding a generator)."""

from __future__ import annotations

import numpy as np
import pytest

from jaxexo.config import Config, scalar_params
from jaxexo.inference import Obstacle, time_swing
from jaxexo.inference.registry import generator_class, names, register
from jaxexo.physics.scene import check_clearance, with_clearance
from jaxexo.swing.generator import SwingGenerator
from jaxexo.swing.options import SwingOptions
from jaxexo.swing.trajectory import assemble

CFG = Config()


def _bell(n: int):
    """The path parameter s (n,), a minimum-jerk profile and a bell with peak 1 at s = 1/2."""
    s = np.linspace(0.0, 1.0, n)
    return s, s**3 * (10.0 - 15.0 * s + 6.0 * s * s), 64.0 * s**3 * (1.0 - s) ** 3


class LiftOver(SwingGenerator):
    """The foot lifted ``lift`` (m) above the obstacle's top at mid-swing and lowered to the goal:
    y minimum-jerk, z a bell. No checks or re-plans of its own (the interface's verdict judges it)."""

    name = "liftover"

    def __init__(self, config=None, *, clearance=None, lift=0.08, defaults=None):
        self.config = CFG if config is None else config
        self.clearance = check_clearance(clearance, self.config.env.min_clearance)
        self.sp = with_clearance(scalar_params(self.config), self.clearance)
        self.lift = lift
        self.defaults = SwingOptions() if defaults is None else defaults

    def _assemble(self, scenes, paths, duration):
        dev = np.full(len(scenes), 1e-3)  # a generous bound on the curve between samples
        vias = [p[[0, len(p) // 2, -1]] for p in paths]
        return assemble(self.name, self.sp, scenes, vias, paths, np.zeros(len(scenes)), duration,
                        [()] * len(scenes), deviation=dev)  # fmt: skip

    def plan_batch(self, scenes, o):
        _, mj, bell = _bell(o.n_points)
        paths = np.stack(
            [np.stack([sc.start_y + (sc.goal_y - sc.start_y) * mj,
                       (sc.height + self.lift) * bell], -1) for sc in scenes]
        )  # fmt: skip
        return self._assemble(scenes, paths, o.duration)

    def continue_from(self, scene, state, o, swing_scene):
        _, mj, bell = _bell(o.n_points)
        (y0, z0), top = state.heel, scene.height + self.lift
        path = np.stack([y0 + (scene.goal_y - y0) * mj,
                         z0 * (1.0 - mj) + max(top - z0, 0.0) * bell], -1)  # fmt: skip
        return self._assemble([scene], path[None], o.duration)[0]


@pytest.fixture(scope="module")
def liftover():
    if "liftover" not in names():
        register(LiftOver)
    return generator_class("liftover").from_config(CFG)


def test_generate_batch_and_clearance(liftover):
    ob = Obstacle.named("triangle")
    one = liftover.generate(ob, pivot="obstacle")
    assert one.method == "liftover" and one.ok
    batch = liftover.generate_batch([ob, Obstacle.named("base1")], pivot=["obstacle", "between"])
    assert len(batch) == 2 and batch.method == "liftover"
    np.testing.assert_array_equal(batch[0].heel, one.heel)
    far = liftover.at_clearance(0.05)
    assert far is not liftover and far.sp.min_clearance == 0.05 and liftover.clearance is None
    # the same path, judged against the clearance asked for (5.4 cm from the triangle)
    strict = liftover.generate(ob, clearance=0.1)
    assert not strict.ok and not strict.checks.clearance_ok
    np.testing.assert_array_equal(strict.heel, liftover.generate(ob).heel)
    with pytest.raises(TypeError, match="^smoothing: not an option of generate"):
        liftover.generate(ob, smoothing=0.01)


def test_replan(liftover):
    traj = liftover.generate(Obstacle.named("triangle"))
    swing = time_swing(traj, CFG)
    new = liftover.replan(swing, Obstacle.rectangle(0.04, 0.12, center_y=0.45), at=0.3)
    assert new.method == "liftover" and new.switch_times == (0.3,)
    np.testing.assert_array_equal(new.heel[new.time <= 0.3], swing.heel[swing.time <= 0.3])


def test_walk(liftover):
    from jaxexo.course import Terrain, plan_course

    block = [[0.0, 0.0], [0.5, 0.0], [0.55, 0.1], [0.65, 0.1], [0.7, 0.0], [1.4, 0.0]]
    course = plan_course(liftover, Terrain.from_points(block), rate=50)
    assert course.method == "liftover" and set(course.methods) == {"liftover"}


def test_eval_comparison(liftover):
    from jaxexo.evaluation.compare import compared_generators, evaluate_generators, make_scenarios

    from conftest import ROOT

    rl = generator_class("rl").from_policy(ROOT / "tests/data/reference/policy.npz")
    gens = compared_generators(rl, "liftover")
    assert list(gens) == ["rl", "liftover"]
    report, trajs = evaluate_generators(gens, make_scenarios(CFG, "test", 3), batch_size=3,
                                        batch_repeats=1, device=False)  # fmt: skip
    assert set(report) == {"rl", "liftover"} and len(trajs["liftover"]) == len(trajs["rl"])
