"""The shield's three forms behind its one interface (jaxexo.shield.make_shield): the JAX batch, the
NumPy rows and the scalar choice give the same mask, the same greedy moves and the same statistics
record on a batch of random scenes and heels, equal to the rule (jaxexo.shield.rule.admissible_moves,
which tests/test_shield.py checks against a dense brute-force look at every move); and
``import jaxexo.shield`` imports no JAX."""

from __future__ import annotations

import subprocess
import sys
import types

import numpy as np
import pytest

from jaxexo.config import load_config, numpy_params, scalar_params
from jaxexo.physics import actions
from jaxexo.shield import KINDS, ShieldStats, make_shield, rule

from conftest import ROOT
from test_shield import _states


def _batch(cfg, n, seed):
    """n random terrain scenes and heels around their obstacles (test_shield's states: some low,
    some in the goal box's column), some a shield's clearance from the obstacle's side or top;
    random last moves (straight up before a best move straight down too), Q-values with ties."""
    p, lay, hy, hz = _states(cfg, n, seed)
    rng = np.random.default_rng(seed + 1)
    k = n // 4
    near = rng.uniform(0.02, 0.03, k)
    side = rng.uniform(size=k) < 0.5
    left = lay.center_y[1:k:2] - 0.5 * lay.width[1:k:2] - p.foot_length - near[1::2]
    hy[1:k:2] = np.where(side[1::2], left, hy[1:k:2]).astype(np.float32)
    top = lay.height[1:k:2] + near[1::2]
    hz[1:k:2] = np.where(side[1::2], hz[1:k:2], top).astype(np.float32)
    q = rng.normal(size=(n, actions.NUM_ACTIONS)).astype(np.float32)
    q[::3] = np.round(q[::3] * 2) / 2
    q[1::5, 27] = 10.0
    last = rng.choice(np.array([-1, 0, 9, 27, 30, 5]), size=n)
    last[1::5] = 9
    return p, lay, hy, hz, q, last


def test_every_form_gives_the_rules_mask_moves_and_statistics():
    import jax
    import jax.numpy as jnp

    from jaxexo.env import ExoStepEnv

    cfg = load_config(ROOT / "configs" / "default.toml")
    assert cfg.env.shield
    n = 600
    p, lay, hy, hz, q, last = _batch(cfg, n, 11)
    sp = scalar_params(cfg)
    want = rule.admissible_moves(np, p, hy, hz, lay, last_action=last)
    greedy = actions.greedy_action(np, q, want)
    assert (~want[:, rule.FORWARD]).any(axis=1).mean() > 0.5  # moves refused in most rows
    env_p = ExoStepEnv(cfg).default_params
    jlay = types.SimpleNamespace(
        **{k: jnp.asarray(getattr(lay, k)) for k in ("outline", "pivot_y", "goal_y")}
    )
    args = {
        "jax": (env_p, (jnp.asarray(hy), jnp.asarray(hz), jlay), jnp.asarray(q), jnp.asarray(last)),
        "rows": (p, (hy, hz, lay), q, last),
        "scalar": (p, (hy, hz, lay), q, last),
    }
    stats = {}
    for kind in KINDS:
        params, heels, qk, lk = args[kind]
        shield = make_shield(kind, params, sp)
        assert shield.kind == kind and shield.stats == ShieldStats()
        np.testing.assert_array_equal(np.asarray(shield.admissible(*heels, last_action=lk)), want)
        assert shield.stats == ShieldStats()  # a mask is no choice: nothing counted
        np.testing.assert_array_equal(np.asarray(shield.choose(*heels, qk, lk)), greedy)
        stats[kind] = shield.stats
    # every form counts its choices in one record: the JAX form every row by its full mask, the rows
    # form the rows its best moves did not decide, the scalar form the steps it could not certify
    assert stats["jax"] == ShieldStats(rows=n, rows_to_full_mask=n)
    # under jit a trace runs once for any number of calls: the JAX form counts nothing there
    traced = make_shield("jax", env_p, sp)
    choose = jax.jit(lambda qk, lk: traced.choose(*args["jax"][1], qk, lk))
    for _ in range(2):
        np.testing.assert_array_equal(np.asarray(choose(*args["jax"][2:])), greedy)
    assert traced.stats == ShieldStats()
    assert stats["rows"].rows == n and 0 < stats["rows"].rows_to_full_mask < n / 2
    assert stats["rows"].steps == stats["rows"].steps_to_full_mask == 0
    assert stats["scalar"].steps == n and 0 < stats["scalar"].steps_to_full_mask < n / 2
    assert stats["scalar"].rows == stats["scalar"].rows_to_full_mask == 0


def test_the_forms_without_the_shield_admit_every_move():
    from jaxexo.config import config_from_dict

    from conftest import legacy_raw

    cfg = config_from_dict(legacy_raw({"env": {"shield": False}}))
    p, lay, hy, hz, q, last = _batch(cfg, 40, 2)
    for kind in ("rows", "scalar"):
        shield = make_shield(kind, p, scalar_params(cfg))
        assert shield.admissible(hy, hz, lay, last_action=last).all()
        np.testing.assert_array_equal(
            shield.choose(hy, hz, lay, q, last), actions.greedy_action(np, q)
        )


def test_make_shield_refuses_what_it_cannot_build():
    cfg = load_config(ROOT / "configs" / "default.toml")
    p, sp = numpy_params(cfg), scalar_params(cfg)
    with pytest.raises(ValueError, match="shield kind must be one of"):
        make_shield("numpy", p, sp)
    with pytest.raises(TypeError, match="scalar parameters"):
        make_shield("rows", p)
    with pytest.raises(TypeError, match="unexpected options"):
        make_shield("scalar", p, sp, buffer=8)


def test_import_shield_and_its_numpy_forms_without_jax():
    code = (
        "import sys\n"
        "import jaxexo.shield, jaxexo.shield.rule, jaxexo.shield.rows, jaxexo.shield.scalar\n"
        "bad = sorted(m for m in sys.modules if m == 'jax' or m.startswith(('jax.', 'jaxlib')))\n"
        "print(bad)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]", out.stdout
