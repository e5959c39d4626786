"""The generator's fast paths against their plain references: the shield's move checked one at a time
(jaxexo.shield's scalar form for one swing, its rows form's ``choose`` for a batch) against the full
mask, and the
generator's one-pass candidate smoothings, on thousands of scenes of the training distribution and
of the held-out families. Policies: random weights (no training), shielded default config."""

from __future__ import annotations

import types

import numpy as np
import pytest

from jaxexo.config import load_config
from jaxexo.inference import TrajectoryGenerator
from jaxexo.inference.generator import plain_reference
from jaxexo.physics import actions, scenarios
from jaxexo.shield import rule
from jaxexo.shield.scalar import SwingShield
from jaxexo.storage.policy_file import QPolicy
from jaxexo.swing import smoothing as sm

from conftest import ROOT
from test_speed import _same


def _random_generator(seed=0, hidden=(32, 32), scale=0.3, layer_norm=False):
    """A generator on configs/default.toml (shielded) with random weights."""
    cfg = load_config(ROOT / "configs" / "default.toml")
    assert cfg.env.shield
    d = actions.obs_dim(cfg.env.obs_mode, cfg.env.shape_points)
    rng = np.random.default_rng(seed)
    sizes = [d, *hidden, actions.NUM_ACTIONS]
    pol = QPolicy(
        kernels=[
            rng.normal(size=(a, b)).astype(np.float32) * scale for a, b in zip(sizes, sizes[1:])
        ],
        biases=[rng.normal(size=b).astype(np.float32) * 0.1 for b in sizes[1:]],
        norm_scales=[rng.normal(size=h).astype(np.float32) for h in hidden] if layer_norm else [],
        norm_biases=[rng.normal(size=h).astype(np.float32) * 0.1 for h in hidden]
        if layer_norm
        else [],
        metadata={},
    )
    return TrajectoryGenerator(pol, cfg)


def _scenes(gen, n_train, n_unseen, seed=5):
    from jaxexo.evaluation.compare import make_scenarios

    sc = (
        make_scenarios(gen.config, "train", n_train, seed)
        + make_scenarios(gen.config, "unseen", n_unseen)[:n_unseen]
    )
    return sc, [gen.scene(s.obstacle, s.pivot, None, s.start_y, s.step_length) for s in sc]


def test_scalar_shield_picks_the_full_masks_greedy_move():
    """At random heels around terrain obstacles (close to the shield's clearance too) and random
    Q-values (ties included), ``SwingShield.certain`` returns the greedy move of the full float32
    mask, or None (then ``SwingShield.choose`` computes that mask)."""
    gen = _random_generator()
    p = gen.np_params
    n = 4000
    lay = scenarios.scenario_layouts(np, p, 3, n, False)
    rng = np.random.default_rng(1)
    hy = (lay.center_y + rng.uniform(-0.45, 0.2, n)).astype(np.float32)
    hz = rng.uniform(0.0, 0.45, n).astype(np.float32)
    # a quarter of the heels on the shield's boundary: the foot 2.5 cm (+-1 mm) left of or above the obstacle
    k = n // 4
    near = rng.uniform(0.024, 0.026, k)
    side = rng.uniform(size=k) < 0.5
    left = lay.center_y[:k] - 0.5 * lay.width[:k] - p.foot_length - near
    hy[:k] = np.where(side, left, hy[:k]).astype(np.float32)
    hz[:k] = np.where(side, rng.uniform(0, 1, k) * lay.height[:k], lay.height[:k] + near).astype(
        np.float32
    )
    hz[k : 2 * k : 3] = 0.0  # on the ground: a move down is cancelled (transition.moves_heel)
    ok = (hy > lay.start_y - 0.05) & (hy < lay.goal_y)
    q = rng.normal(size=(n, actions.NUM_ACTIONS)).astype(np.float32)
    q[::3] = np.round(q[::3] * 2) / 2  # ties between moves
    q[1::5, 27] = 10.0  # straight down is the best move ...
    last = rng.choice(np.array([-1, 0, 9, 27, 30, 5]), size=n)
    last[1::5] = 9  # ... right after straight up
    mask = rule.admissible_moves(np, p, hy, hz, lay, last_action=last)
    want = actions.greedy_action(np, q, mask)
    decided = agree = 0
    for i in np.flatnonzero(ok):
        scene = types.SimpleNamespace(
            outline=lay.outline[i], pivot_y=lay.pivot_y[i], goal_y=lay.goal_y[i]
        )
        a = SwingShield(gen.sp, p, scene).certain(float(hy[i]), float(hz[i]), q[i], int(last[i]))
        if a is not None:
            decided += 1
            agree += a == want[i]
            assert a == want[i], (i, a, want[i])
    assert decided == agree
    # undecided: heels inside or touching the obstacle, steps where no forward move passes every
    # condition (the mask's fallbacks), and comparisons within rounding of their threshold
    assert decided > 0.6 * ok.sum()
    # the rule is exercised: rows whose best move (down) undoes the last one (up) get another move
    # (down stays only where no move passes every condition: the mask's fall-backs)
    assert (~mask[1::5, 27]).mean() > 0.8 and (want[1::5] != 27).mean() > 0.8
    assert (~mask[k : 2 * k : 3, 27]).mean() > 0.8
    # the floor rule is exercised: from the ground short of the goal box's column, the move along the
    # floor (0 deg) is refused, and the scalar shield agreed with that mask above
    ground = np.arange(k, 2 * k, 3)
    short = ground[np.abs(hy[ground] - lay.goal_y[ground]) > p.goal_tolerance[0] + 0.03]
    assert p.floor_clearance > 0 and len(short) > 100 and (~mask[short, 0]).mean() > 0.95
    # a nan among the Q-values: argmax's own rules, left to the full mask
    scene = types.SimpleNamespace(
        outline=lay.outline[0], pivot_y=lay.pivot_y[0], goal_y=lay.goal_y[0]
    )
    bad = q[0].copy()
    bad[3] = np.nan
    assert SwingShield(gen.sp, p, scene).certain(float(hy[0]), float(hz[0]), bad) is None


@pytest.mark.slow
@pytest.mark.parametrize("layer_norm", [False, True])
def test_fast_rollouts_take_the_references_actions(layer_norm):
    """One swing (``rollout``) and a batch (``rollout_batch``), fast against ``plain_reference`` (the
    full mask every step): the same actions and points, on the training distribution and the held-out
    families."""
    gen = _random_generator(seed=2 if layer_norm else 4, layer_norm=layer_norm)
    sc, scenes = _scenes(gen, 1000, 1000)
    fb, ab = gen.rollout_batch(scenes)
    plain = plain_reference(gen)
    rb, rab = plain.rollout_batch(scenes)
    for x, y, u, v in zip(fb, rb, ab, rab):
        np.testing.assert_array_equal(u, v)
        np.testing.assert_array_equal(x, y)
    assert gen.shield_stats.rows_to_full_mask > 0  # some rows needed the full mask
    steps = 0
    for scene in scenes[::8] + scenes[1::40]:
        pf, af = gen.rollout(scene)
        pr, ar = plain.rollout(scene)
        np.testing.assert_array_equal(af, ar)
        np.testing.assert_array_equal(pf, pr)
        steps += len(af)
    assert steps > 3000
    stats = gen.shield_stats
    assert 0 < stats.steps_to_full_mask < 0.2 * stats.steps  # steps left to the full mask


@pytest.mark.slow
@pytest.mark.parametrize("clearing", [False, True])
def test_fast_generation_with_candidate_smoothings_matches_the_reference(clearing):
    """``generate`` and ``generate_batch`` against ``plain_reference``: the same samples, checks, notes and
    smoothing; the per-path candidate smoothings occur (without the corrected spline, which comes
    first when on) or the corrected splines do, and each swing's curve is reproduced from its raw
    path: by smoothing it with its reported smoothing, or by the correction (jaxexo.swing.clearing)."""
    from jaxexo.swing.clearing import clear_smooth

    gen = _random_generator(seed=6).with_options(clearing=clearing)
    sc, _ = _scenes(gen, 700, 700)
    obstacles, kw = [s.obstacle for s in sc], scenarios.batch_options(sc)
    fast = gen.generate_batch(obstacles, fallback=None, **kw)
    plain = plain_reference(gen)
    ref = plain.generate_batch(obstacles, fallback=None, **kw)
    for a, b in zip(fast, ref):
        _same(a, b)
    cleared = "jaxexo.swing.clearing"  # the note of a swing the correction moved
    marker = cleared if clearing else "per-path candidate"
    assert any(any(marker in n for n in t.notes) for t in fast)
    for s in sc[::7]:
        one = s.options()
        a = gen.generate(s.obstacle, fallback=None, **one)
        _same(a, plain.generate(s.obstacle, fallback=None, **one))
        if any(cleared in n for n in a.notes):
            again = clear_smooth(
                a.raw,
                a.scene.outline,
                gen.sp.foot_length,
                gen.sp.min_clearance,
                len(a.heel),
                a.smoothing,
            )[0]
            np.testing.assert_allclose(again, a.heel, rtol=0, atol=1e-9)
        elif not np.isnan(a.smoothing) and a.smoothing > 0:
            np.testing.assert_allclose(
                sm.smooth_paths([a.raw], len(a.heel), a.smoothing)[0], a.heel, rtol=0, atol=1e-9
            )


def test_candidate_smoothings_are_decreasing_and_per_path():
    from jaxexo.swing.finish import CANDIDATE_RESIDUALS, candidates

    raw = np.column_stack([np.linspace(0, 0.7, 30), np.sin(np.linspace(0, np.pi, 30)) * 0.2])
    c = candidates(raw, 0.005)
    assert c[0] == 0.005 and all(a > b for a, b in zip(c, c[1:]))
    assert c[1:] == [30 * r * r for r in CANDIDATE_RESIDUALS if 30 * r * r < 0.005]
    assert candidates(raw[:3], 0.005) == [0.005]  # too short to smooth
    assert candidates(raw, 1e-6) == [1e-6]


def test_smooth_candidates_is_smooth_paths_of_the_repeated_path():
    rng = np.random.default_rng(3)
    for n in (2, 3, 4, 9, 31, 60):
        u = np.linspace(0.0, 1.0, n)
        raw = np.column_stack(
            [0.7 * u + rng.normal(0, 0.005, n), 0.2 * np.sin(np.pi * u) + rng.normal(0, 0.005, n)]
        )
        raw[:, 1] = np.maximum(raw[:, 1], 0.0)
        s = [0.005, n * 0.008**2, n * 0.0025**2, 0.0]
        a, da = sm.smooth_candidates(raw, 100, s)
        b, db = sm.smooth_paths([raw] * len(s), 100, np.array(s), with_deviation=True)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
        np.testing.assert_allclose(da, db, rtol=0, atol=1e-12)


def test_a_shielded_models_smoothing_is_its_clearance_budget():
    """Without a smoothing given, a shielded model's spline asks for the residual whose RMS over a
    long swing (1.2 m of raw path: 40 points of 3 cm, 20 of 6 cm) is the shield's excess over the margin
    (jaxexo.inference.generator.model_smoothing); an unshielded model keeps the thesis's s."""
    from jaxexo.evaluation.compare import make_scenarios
    from jaxexo.inference.generator import model_smoothing

    gen = _random_generator()
    excess = gen.config.env.shield_clearance - gen.config.env.min_clearance
    assert excess > 0
    points = 1.2 / gen.config.env.step_size
    assert gen.smoothing == pytest.approx(points * excess**2, rel=1e-12)
    assert model_smoothing(0.025, 0.02, True, 0.03) == pytest.approx(40 * 0.005**2, rel=1e-12)
    assert model_smoothing(0.025, 0.02, True, 0.06) == pytest.approx(20 * 0.005**2, rel=1e-12)
    assert gen.smoothing < sm.DEFAULT_SMOOTHING
    assert model_smoothing(0.025, 0.02, False) == sm.DEFAULT_SMOOTHING
    s = make_scenarios(gen.config, "train", 3, 11)
    kw = [dict(pivot=x.pivot, start_y=x.start_y, step_length=x.step_length) for x in s]
    for x, k in zip(s, kw):
        a = gen.generate(x.obstacle, fallback=None, **k)
        _same(a, gen.generate(x.obstacle, fallback=None, smoothing=gen.smoothing, **k))
    obstacles, per = [x.obstacle for x in s], {key: [k[key] for k in kw] for key in kw[0]}
    for a, b in zip(
        gen.generate_batch(obstacles, fallback=None, **per),
        gen.generate_batch(obstacles, fallback=None, smoothing=gen.smoothing, **per),
    ):
        _same(a, b)


@pytest.mark.parametrize("clearing", [False, True])
def test_a_swing_short_of_the_goal_is_not_retried_down_to_the_raw_polyline(clearing):
    """A raw path that stops short of the goal fails whatever its smoothing (every curve ends where the
    raw path does): it keeps the requested smoothing (corrected or not), no retry note, the verdict
    says the goal was not reached; the same raw path continued to the goal is retried as before
    (without the correction: down to less smoothing), and fast equals the reference."""
    from jaxexo.inference import Obstacle

    gen = _random_generator().with_options(clearing=clearing)
    scene = gen.scene(Obstacle.rectangle(0.10, 0.20, center_y=0.40), pivot="obstacle")
    up = [(0.12, z) for z in np.arange(0.0, 0.231, 0.03)]
    over = [(y, 0.23) for y in np.arange(0.15, 0.46, 0.03)]
    down = [(0.48, z) for z in np.arange(0.20, -0.001, -0.03)] + [(0.48, 0.0)]
    whole = np.array([(0.0, 0.0), (0.06, 0.0)] + up + over + down + [(0.70, 0.0)])
    short = whole[: 2 + len(up) + len(over)]  # stops on top of the obstacle
    for g in (gen, plain_reference(gen)):
        t = g.finish([scene], [short], 100, 0.05, 1.0, None)[0]
        assert not t.ok and not t.checks.reached_goal and t.smoothing == 0.05
        assert not any("brought the foot" in n for n in t.notes)
        w = g.finish([scene], [whole], 100, 0.05, 1.0, None)[0]
        assert w.checks.reached_goal and w.checks.clearance_ok
        if not clearing:
            assert np.isnan(w.smoothing) or w.smoothing < 0.05
            assert any("brought the foot" in n for n in w.notes)
    _same(
        gen.finish([scene], [short], 100, 0.05, 1.0, None)[0],
        plain_reference(gen).finish([scene], [short], 100, 0.05, 1.0, None)[0],
    )
    # in a batch too, beside a row that is retried
    b = gen.finish([scene, scene], [short, whole], 100, 0.05, 1.0, None)
    assert b[0].smoothing == 0.05 and not b[0].checks.reached_goal
    assert b[1].checks.clearance_ok


def test_time_breakdown_replays_the_rollouts_own_steps():
    """bench_generate's breakdown (benchlib.generate_bench.time_breakdown) times the parts of
    real swings: its step count is the rollout's own (an independent count here), every part positive."""
    from jaxexo.baselines import CFFTG

    from benchlib.generate_bench import scene_set, time_breakdown

    gen = _random_generator()
    sc = scene_set(gen.config, "unseen", 3)
    b = time_breakdown(gen, CFFTG(gen.config), sc, repeats=1)
    steps = [
        len(gen.rollout(gen.scene(s.obstacle, s.pivot, None, s.start_y, s.step_length))[1])
        for s in sc
    ]
    assert b["steps"] == float(np.median(steps))
    for k in (
        "rollout",
        "network_per_step",
        "shield_per_step",
        "observation",
        "smoothing_correction",
        "rl_total",
        "cfftg_plan",
        "cfftg_total",
    ):
        assert b[k] > 0.0, k
