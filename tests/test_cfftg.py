"""CFFTG (jaxexo.baselines.cfftg): valid on every training and test obstacle, the polynomial's end
conditions, re-planning, reported failure, batch = single, NumPy-only import, the CLI switch."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.baselines.cfftg import APEX_FRAC_RANGE, FLATNESS, plan_basis, plan_paths
from jaxexo.config import load_config
from jaxexo.inference import Obstacle, TrajectoryError
from jaxexo.inference.scenarios import sample_scenarios, training_scenarios
from jaxexo.physics import geometry
from jaxexo.physics.kinematics import PIVOT_CONDITIONS
from jaxexo.physics.scenarios import Scenario

from conftest import ROOT


@pytest.fixture(scope="module")
def cfg():
    return load_config(ROOT / "configs" / "default.toml")


@pytest.fixture(scope="module")
def gen(cfg):
    return CFFTG(cfg)


def _batch(gen, scenarios):
    return gen.generate_batch(
        [s.obstacle for s in scenarios],
        pivot=[s.pivot for s in scenarios],
        start_y=[s.start_y for s in scenarios],
        step_length=[s.step_length for s in scenarios],
    )


@pytest.mark.parametrize(
    "which",
    [
        # Known CFFTG limitation, also on main's scenario draw with other seeds (3, 5): rectangles near the
        # corner of the "rectangle" range (about 0.2 m wide, 0.27 m high) with a short step exhaust the
        # 10 plans on joint limits; about 1 scene in 300 of the training distribution.
        pytest.param(
            "train",
            marks=pytest.mark.xfail(
                strict=True,
                reason="CFFTG gives up on ~1/300 wide, tall "
                "training rectangles (joint limits); to be fixed in CFFTG",
            ),
        ),
        "test",
    ],
)
def test_always_valid_on_training_and_test_obstacles(gen, cfg, which):
    # Base 1-3 and random rectangles (the default config's training mixture) and the five thesis
    # obstacles, every pivot condition, shifted starts and step lengths.
    sc = training_scenarios(cfg, 300) if which == "train" else sample_scenarios(cfg, 300)
    b = _batch(gen, sc)
    assert b.ok.all(), [b[i].checks.reasons for i in np.flatnonzero(~b.ok)[:3]]
    # Planned with the safety distance as margin: the exact clearance at every sample is at least that,
    # and the guaranteed clearance between samples keeps the safe-swing margin.
    c = np.stack(
        [
            geometry.foot_clearance(np, b.heel[i], gen.sp.foot_length, b.scenes[i].outline)
            for i in range(len(b))
        ]
    )
    assert c.min() >= gen.margin - 1e-9
    assert b.min_clearance.min() >= cfg.env.min_clearance
    assert {s.pivot for s in sc} == set(PIVOT_CONDITIONS)


def _end_rates(t):
    """Finite-difference velocity and acceleration (m/s, m/s^2) at both ends of a trajectory."""
    h, dt = t.heel, t.time[1] - t.time[0]
    out = []
    for end in (h[:3], h[::-1][:3]):
        out.append(
            (np.abs(end[1] - end[0]).max() / dt, np.abs(end[2] - 2 * end[1] + end[0]).max() / dt**2)
        )
    return np.array(out)


def test_path_starts_and_ends_on_the_ground_at_rest_and_never_steps_back(gen):
    kw = dict(pivot="agent", start_y=0.03, step_length=0.72)
    t = gen.generate(Obstacle.named("half_circle"), **kw)
    h = t.heel
    np.testing.assert_allclose(h[0], [0.03, 0.0], atol=1e-12)
    np.testing.assert_allclose(h[-1], [0.75, 0.0], atol=1e-12)
    # Zero velocity and acceleration at lift-off and touch-down (triple roots): with 10x finer
    # sampling the first differences shrink like dt^2 (100x) and the second like dt (10x); a path
    # with nonzero end acceleration would shrink its velocity only 10x and keep its acceleration.
    fine = gen.generate(Obstacle.named("half_circle"), n_points=991, **kw)
    ratio = _end_rates(t) / _end_rates(fine)
    assert np.all(ratio[:, 0] > 60) and np.all(ratio[:, 1] > 7), ratio
    assert np.all(np.diff(h[:, 0]) >= 0.0)
    assert np.all(h[:, 1] >= 0.0)
    assert t.method == "cfftg" and t.raw.shape == (3, 2) and t.smoothing == 0.0
    # The via points: start, apex (the path's highest point, at s = 1/2 between two samples), goal.
    assert t.raw[1, 1] >= h[:, 1].max()
    np.testing.assert_allclose(t.raw[1, 1], h[:, 1].max(), rtol=1e-6)


def test_plan_polynomials_hit_their_apex():
    s, mj, g, phi = plan_basis(101)
    assert phi.shape == (len(FLATNESS), 101)
    np.testing.assert_allclose(phi[:, 50], 1.0)
    assert np.all(phi.argmax(axis=1) == 50)  # one apex at s = 1/2 for every flatness
    ob = Obstacle.named("base1")
    out = np.asarray([ob.outline_array(4)])
    for frac in (0.40, 0.5, 0.6, 0.9):
        paths, h = plan_paths(
            np.array([0.0]), np.array([0.7]), out, np.array([frac]), np.array([0.03]), 0.2, 101
        )
        np.testing.assert_allclose(
            paths[0, 50, 0], 0.7 * np.clip(frac, *APEX_FRAC_RANGE), atol=1e-12
        )
        np.testing.assert_allclose(paths[0, 50, 1], h[0], atol=1e-12)
        # The lowest apex that clears the obstacle: 3 cm above its top at least, not much more.
        assert ob.height + 0.03 <= h[0] < ob.height + 0.25


def test_a_first_plan_that_touches_is_replanned_higher(cfg):
    # With no margin the lowest apex grazes the obstacle (touching counts as a collision); the
    # re-plan raises the apex by margin_step and passes.
    g0 = CFFTG(cfg, margin=0.0, margin_step=0.03)
    t = g0.generate(Obstacle.named("base1"), pivot="obstacle")
    assert t.ok
    assert t.notes[0].startswith("cfftg: 2 plan(s)")
    p = g0.plan([g0.scene(Obstacle.named("base1"))])
    assert p.plans[0] == 2 and not p.gave_up[0]
    assert p.checks.min_clearance[0] >= cfg.env.min_clearance


def test_impossible_obstacle_is_a_reported_failure(gen):
    too_high = Obstacle.rectangle(0.20, 0.50)
    t = gen.generate(too_high, pivot="obstacle")
    assert not t.ok
    assert any("joint limits" in r for r in t.checks.reasons)
    assert f"gave up after {gen.max_plans} plans" in t.notes[0]
    # Joint-limit failures move the apex along y on every re-plan.
    p = gen.plan([gen.scene(too_high)])
    via = p.via
    assert p.plans[0] == gen.max_plans and p.gave_up[0]
    assert not np.isclose(
        via[0, 1, 0], too_high.center_y - 0.5 * 0.2
    )  # apex moved from its first place
    with pytest.raises(TrajectoryError, match="joint limits"):
        gen.generate(too_high, strict=True)
    # In a batch, the failure stays with its scene.
    b = gen.generate_batch([Obstacle.named("base2"), too_high, Obstacle.named("triangle")])
    assert b.ok.tolist() == [True, False, True]


def test_batch_equals_single(gen, cfg):
    sc = sample_scenarios(cfg, 15, seed=3) + [
        Scenario("x", Obstacle.rectangle(0.2, 0.5), "agent", 0.0, 0.7)
    ]
    b = _batch(gen, sc)
    for i, s in enumerate(sc):
        t = gen.generate(s.obstacle, pivot=s.pivot, start_y=s.start_y, step_length=s.step_length)
        np.testing.assert_array_equal(t.heel, b.heel[i])
        np.testing.assert_array_equal(t.joint_angles, b.joint_angles[i])
        assert t.checks.reasons == b.reasons[i] and t.notes == b.notes[i]


def test_checks_are_the_shared_ones(gen):
    # The clearance reported is the exact swept clearance of jaxexo.physics.swept over the moves
    # between samples, less the plan's deviation bound; never more than the samples' own clearance.
    from jaxexo.physics import swept

    t = gen.generate(Obstacle.named("triangle"), pivot="between")
    c = geometry.foot_clearance(np, t.heel, gen.sp.foot_length, t.scene.outline)
    sw = swept.path_swept_clearance(np, t.heel, gen.sp.foot_length, t.scene.outline)
    assert 0.0 < t.checks.deviation < 2e-3
    np.testing.assert_allclose(t.checks.min_clearance, sw.min() - t.checks.deviation)
    assert t.checks.min_clearance < c.min()


def test_bad_options_name_the_field(cfg):
    with pytest.raises(ValueError, match="margin"):
        CFFTG(cfg, margin=-0.01)
    with pytest.raises(ValueError, match="max_plans"):
        CFFTG(cfg, max_plans=0)
    with pytest.raises(geometry.GeometryError, match="apex_step"):
        CFFTG(cfg, apex_step=float("nan"))
    with pytest.raises(ValueError, match="n_points"):
        CFFTG(cfg).generate(Obstacle.named("base1"), n_points=1)
    with pytest.raises(ValueError, match="pivot"):
        CFFTG(cfg).generate(Obstacle.named("base1"), pivot="left")


def test_cfftg_needs_no_jax():
    from test_inference import BLOCK_JAX

    code = BLOCK_JAX + (
        "from jaxexo.baselines import CFFTG\nfrom jaxexo.inference import Obstacle\n"
        "t = CFFTG().generate(Obstacle.named('base3'), pivot='between')\n"
        "print('OK', t.ok, sorted(m for m in sys.modules if m.split('.')[0] in ('jax', 'flax', 'torch')))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120
    )
    assert out.returncode == 0, out.stderr
    assert "OK True []" in out.stdout


def test_cli_generate_method_cfftg(tmp_path):
    from jaxexo.cli import main

    def generate(*args):
        return main(["generate", "--method", "cfftg", *map(str, args)])

    out = tmp_path / "c.csv"
    scene = ("--obstacle", "triangle", "--pivot", "agent")
    assert generate(*scene, "--out", out, "--json", tmp_path / "c.json") == 0
    rows = np.loadtxt(out, delimiter=",", skiprows=1)
    assert rows.shape == (100, 15)
    assert rows[0, 1] == 0.0 and abs(rows[-1, 1] - 0.70) < 1e-6
    # An impossible obstacle: written, reported, exit status 1.
    assert (
        generate("--obstacle", "rectangle", "--height", "0.5", "--out", tmp_path / "bad.csv") == 1
    )
    # The RL method still needs its policy.
    assert main(["generate", "--obstacle", "triangle", "--out", str(tmp_path / "x.csv")]) == 2
