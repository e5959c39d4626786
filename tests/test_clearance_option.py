"""The clearance a caller asks of a swing (``generate(..., clearance=C)``, ``jaxexo generate --clearance``):
the RL generator's shield keeps C plus its smoothing budget on every raw move, the verdict judges
against C (checked here by an independent dense look at the delivered curve), CFFTG plans for C, and
a clearance below the model's env.min_clearance or above MAX_CLEARANCE is refused by name."""

from __future__ import annotations

import numpy as np
import pytest

from jaxexo.baselines import CFFTG
from jaxexo.config import config_from_dict
from jaxexo.inference import Obstacle, TrajectoryGenerator
from jaxexo.inference.scenarios import safety_scenarios
from jaxexo.physics import actions, geometry
from jaxexo.storage.policy_file import QPolicy

from conftest import legacy_raw, run_cli

SHIELD, MARGIN = 0.025, 0.02


def _config():
    raw = {
        "env": {"shield": True, "shield_clearance": SHIELD, "min_clearance": MARGIN},
        "layout": {"terrain": {"start_shift": [0.0, 0.12], "step_length": [0.55, 0.85]}},
    }
    return config_from_dict(legacy_raw(raw))


def _random_generator(cfg, seed=0):
    """A shielded generator with random weights: the shield and the verdict alone must keep C."""
    d = actions.obs_dim(cfg.env.obs_mode, cfg.env.shape_points)
    rng = np.random.default_rng(seed)
    sizes = [d, 32, 32, actions.NUM_ACTIONS]
    pol = QPolicy(
        kernels=[
            rng.normal(size=(a, b)).astype(np.float32) * 0.3 for a, b in zip(sizes, sizes[1:])
        ],
        biases=[np.zeros(b, np.float32) for b in sizes[1:]],
        norm_scales=[],
        norm_biases=[],
        metadata={},
    )
    return TrajectoryGenerator(pol, cfg)


def _dense_min(heel, outline, foot, per=20):
    """Foot clearance at ``per`` positions on every sample interval of the delivered samples
    (geometry.foot_clearance only; no swept code)."""
    t = np.linspace(0.0, 1.0, per, endpoint=False)[None, :, None]
    pts = (heel[:-1, None] + t * (heel[1:, None] - heel[:-1, None])).reshape(-1, 2)
    return float(
        geometry.foot_clearance(np, np.vstack([pts, heel[-1:]]), foot, outline[None]).min()
    )


@pytest.mark.parametrize("clearance", [0.03, 0.04])
def test_shielded_raw_moves_keep_the_clearance_asked(clearance):
    """Random weights: the shield alone keeps C plus the smoothing budget over every raw move (or
    does not come closer where the foot starts closer), by a dense look at each move."""
    cfg = _config()
    gen = _random_generator(cfg)
    foot = cfg.kinematics.foot_length
    sc = safety_scenarios(cfg, 60, seed=5)
    batch = gen.generate_batch(
        [s.obstacle for s in sc],
        fallback=None,
        clearance=clearance,
        pivot=[s.pivot for s in sc],
        start_y=[s.start_y for s in sc],
        step_length=[s.step_length for s in sc],
    )
    for t in batch:
        outline = np.asarray(t.scene.outline, float)
        raw = np.asarray(t.raw, float)
        c0 = float(geometry.foot_clearance(np, raw[0], foot, outline))
        assert (
            _dense_min(raw, outline, foot, per=200) >= min(SHIELD + clearance - MARGIN, c0) - 1e-5
        )
        # a swing closer than C is never ok, and says so
        if t.checks.min_clearance < clearance:
            assert not t.ok and any(
                "safety margin" in r or "touches" in r for r in t.checks.reasons
            )


@pytest.mark.parametrize("clearance", [0.03, 0.045])
def test_swings_called_ok_keep_the_clearance_under_a_denser_look(trained_run, clearance):
    """The trained test model at clearance C: every swing flagged ok keeps C between its samples
    (dense, geometry only), and RL and CFFTG are judged by the same C."""
    gen = TrajectoryGenerator.load(trained_run / "policy.npz")
    foot = gen.config.kinematics.foot_length
    sc = safety_scenarios(gen.config, 150, seed=9)
    kw = dict(
        pivot=[s.pivot for s in sc],
        start_y=[s.start_y for s in sc],
        step_length=[s.step_length for s in sc],
    )
    n_ok = 0
    for g, extra in ((gen, {"fallback": None}), (CFFTG(gen.config), {})):
        batch = g.generate_batch([s.obstacle for s in sc], clearance=clearance, **kw, **extra)
        for t in batch:
            if t.ok:
                n_ok += 1
                assert t.checks.min_clearance >= clearance - 1e-12
                assert (
                    _dense_min(np.asarray(t.heel, float), np.asarray(t.scene.outline, float), foot)
                    >= clearance - 1e-9
                )
            elif t.checks.min_clearance < clearance:
                assert any("safety margin" in r or "touches" in r for r in t.checks.reasons), (
                    t.checks.reasons
                )
    assert n_ok >= 100


def test_one_swing_equals_the_batch_at_a_clearance():
    cfg = _config()
    gen = _random_generator(cfg, seed=1)
    ob = Obstacle.named("base2", center_y=0.42)
    one = gen.generate(ob, pivot="between", clearance=0.035, fallback=None)
    batch = gen.generate_batch([ob], pivot="between", clearance=0.035, fallback=None)
    # the same swing up to the batch's float32 rounding (as without a clearance: test_inference)
    assert len(one.raw) == len(batch[0].raw)
    np.testing.assert_allclose(one.heel, batch[0].heel, atol=1e-4)
    assert one.ok == batch[0].ok
    # the generator itself is unchanged by a call at another clearance
    assert gen.clearance is None and gen.sp.min_clearance == pytest.approx(MARGIN, abs=1e-9)


def test_cfftg_keeps_the_clearance_asked():
    cfg = _config()
    cf = CFFTG(cfg)
    foot = cfg.kinematics.foot_length
    for c in (0.03, 0.05):
        t = cf.generate(Obstacle.named("triangle", center_y=0.42), pivot="between", clearance=c)
        assert t.ok and t.checks.min_clearance >= c
        assert (
            _dense_min(np.asarray(t.heel, float), np.asarray(t.scene.outline, float), foot)
            >= c - 1e-9
        )


@pytest.mark.parametrize("bad", [0.01, 0.2, float("nan"), "0.03", True])
def test_bad_clearance_is_refused_naming_it(bad):
    cfg = _config()
    gen = _random_generator(cfg)
    ob = Obstacle.named("base1")
    for g in (gen, CFFTG(cfg)):
        with pytest.raises((ValueError, TypeError), match="clearance"):
            g.generate(ob, clearance=bad)
        with pytest.raises((ValueError, TypeError), match="clearance"):
            g.generate_batch([ob], clearance=bad)


def test_cli_refuses_a_clearance_below_the_margin(tmp_path):
    out = tmp_path / "t.csv"
    r = run_cli(
        "generate", "--method", "cfftg", "--obstacle", "base1", "--clearance", "0.01", "--out", out
    )
    assert r.returncode == 2 and "--clearance" in r.stderr and "Traceback" not in r.stderr
    assert not out.exists()
    r = run_cli(
        "generate", "--method", "cfftg", "--obstacle", "base1", "--clearance", "0.04", "--out", out
    )
    assert r.returncode == 0, r.stderr
    assert out.exists()
