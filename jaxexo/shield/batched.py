"""The shield's mask for a batch of environments in JAX, ``make_shield("jax", ...)``: the decisions of
``jaxexo.shield.rule.admissible_moves`` bit for bit, with the exact swept clearance computed (by
compaction, jaxexo.shield.compact) only for the moves that a cheap box bound leaves open. The bound
and why it is conclusive: docs/safety.md, "The shield".
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxexo.physics import actions, geometry, swept
from jaxexo.shield import compact, rule
from jaxexo.shield.rows import ShieldStats

# m: the box bound must clear shield_clearance by this much before the exact check is skipped.
BOUND_MARGIN = 1e-4
# Open (env, move) pairs checked exactly per round, as a fraction of all pairs of the batch. A round
# has a fixed cost (gathering, scattering, the loop) that a larger buffer pays less often, and padding
# that a smaller one checks for nothing; with the term-by-term exact check one eighth is the faster
# (docs/benchmarks.md, the shield's mask).
BUFFER_FRACTION = 1 / 8


def _box(outline):
    """(y0, y1, z0, z1) (..., ) of the box holding the outline and the region under it (padding
    repeats a vertex, so it changes nothing)."""
    vy, vz = outline[..., 0], outline[..., 1]
    return vy.min(-1), vy.max(-1), jnp.minimum(vz.min(-1), 0.0), vz.max(-1)


def _foot_box_distance(hy, hz, foot_length, y0, y1, z0, z1):
    """Distance (m) from the flat foot [hy, hy + foot_length] x {hz} to the box."""
    dy = jnp.maximum(jnp.maximum(y0 - (hy + foot_length), hy - y1), 0.0)
    dz = jnp.maximum(jnp.maximum(z0 - hz, hz - z1), 0.0)
    return jnp.sqrt(dy * dy + dz * dz)


def _point_foot_distance2(py, pz, hy, hz, foot_length):
    """Squared distance (m^2) from points (py, pz) to the flat foot [hy, hy + foot_length] x {hz}."""
    gap = jnp.maximum(jnp.maximum(hy - py, py - (hy + foot_length)), 0.0)
    return gap * gap + (pz - hz) * (pz - hz)


def _nearest_outline_point(heel_y, heel_z, foot_length, outline):
    """(N,) y, z of a point on the outline nearest the foot at the heel (exact for a foot that does
    not cross the outline: then the nearest pair has an outline vertex, or the projection of the
    heel or the toe on an edge, in it; any candidate would do for an upper bound)."""
    vy, vz = outline[..., 0], outline[..., 1]
    ay, az = vy[:, :-1], vz[:, :-1]
    ey, ez = vy[:, 1:] - ay, vz[:, 1:] - az
    len2 = ey * ey + ez * ez
    inv = jnp.where(len2 > 0.0, 1.0 / jnp.where(len2 > 0.0, len2, 1.0), 0.0)
    cy, cz = [vy], [vz]
    for py in (heel_y, heel_y + foot_length):
        t = jnp.clip(((py[:, None] - ay) * ey + (heel_z[:, None] - az) * ez) * inv, 0.0, 1.0)
        cy.append(ay + t * ey)
        cz.append(az + t * ez)
    cy, cz = jnp.concatenate(cy, axis=-1), jnp.concatenate(cz, axis=-1)
    j = jnp.argmin(
        _point_foot_distance2(cy, cz, heel_y[:, None], heel_z[:, None], foot_length), axis=-1
    )
    return (
        jnp.take_along_axis(cy, j[:, None], axis=-1)[:, 0],
        jnp.take_along_axis(cz, j[:, None], axis=-1)[:, 0],
    )


def bounds(p, heel_y, heel_z, ends, outline, c_here):
    """(sure_pass, sure_fail), (N, F) bool each: the moves whose clearance condition the bounds decide
    (sure_pass only where ``rule.moves_keep_clearance`` is True, sure_fail only where it is False).

    Lower bound on the swept distance (the distance to the outline is 1-Lipschitz in the heel's
    position; the box distance b1 at the end is at most the end's clearance):
    max(c_here - |d|, (c_here + b1 - |d|) / 2), |d| <= step_size (move_heel only clips a step).
    Upper bound: the swept region holds the foot at the end, so the swept distance is at most the end
    foot's distance to any outline point: the vertices, and the point nearest the foot at the start."""
    y0, y1, z0, z1 = (b[:, None] for b in _box(outline))
    b1 = _foot_box_distance(ends[..., 0], ends[..., 1], p.foot_length, y0, y1, z0, z1)
    step = p.step_size * (1.0 + 1e-6)  # 1e-6: a unit direction rounded to float32
    ch = c_here[:, None]
    lower = jnp.maximum(ch - step, 0.5 * (ch + b1 - step))
    sure_pass = lower >= p.shield_clearance + BOUND_MARGIN
    ny, nz = _nearest_outline_point(heel_y, heel_z, p.foot_length, outline)
    # Squared distances compared first (one square root per move), vertex by vertex: an (N, F, K)
    # array of them would leave the cache (as in swept.swept_distance_by_edge).
    upper2 = _point_foot_distance2(
        ny[:, None], nz[:, None], ends[..., 0], ends[..., 1], p.foot_length
    )
    for k in range(outline.shape[-2]):
        upper2 = jnp.minimum(
            upper2,
            _point_foot_distance2(
                outline[:, None, k, 0],
                outline[:, None, k, 1],
                ends[..., 0],
                ends[..., 1],
                p.foot_length,
            ),
        )
    upper = jnp.sqrt(upper2)
    need = rule.clearance_need(jnp, p, ch)
    # From inside the obstacle (c_here <= 0) every move passes: never a sure failure there.
    sure_fail = (ch > 0.0) & (upper < need - BOUND_MARGIN)
    return sure_pass, sure_fail


def _exact_pairs(p, heel, ends, vy, vz, c_here):
    """``moves_keep_clearance``'s comparison for gathered pairs: heel (M, 2), ends (M, 2), the outline
    vertex-major, vy, vz (K, M), c_here (M,) (the foot's clearance at the heel,
    geometry.foot_clearance)."""
    d_move = swept.swept_distance_by_edge(jnp, heel + 0.0 * ends, ends, p.foot_length, vy, vz)
    return d_move >= rule.clearance_need(jnp, p, c_here)


def keep_clearance(p, heel_y, heel_z, ends, outline, buffer: int | None = None):
    """(N, F) bool, equal to ``rule.moves_keep_clearance`` for a batch: the bounds where they are
    conclusive, the exact rule on the open pairs in rounds of ``buffer`` pairs (jaxexo.shield.compact)."""
    n, f = ends.shape[:2]
    total = n * f
    heel = jnp.stack([heel_y, heel_z], axis=-1)
    c_here = geometry.foot_clearance(jnp, heel, p.foot_length, outline)  # as moves_keep_clearance
    sure_pass, sure_fail = bounds(p, heel_y, heel_z, ends, outline, c_here)
    flat_ends = ends.reshape(total, 2)

    # The outline vertex-major, (K, N) per coordinate: each gathered vertex row is contiguous.
    table_y, table_z = outline[..., 0].T, outline[..., 1].T

    def exact(pair):
        env = pair // f
        return _exact_pairs(
            p, heel[env], flat_ends[pair], table_y[:, env], table_z[:, env], c_here[env]
        )

    clear = compact.compacted(
        ~(sure_pass | sure_fail).reshape(total),
        exact,
        sure_pass.reshape(total),
        buffer or compact.buffer_size(total, BUFFER_FRACTION),
    )
    return clear.reshape(n, f)


class BatchedShield:
    """The JAX form: the admissible moves of N environments for parameters ``p`` (EnvParams, or any
    object with their fields), the clearance condition computed by ``keep_clearance`` in rounds of
    ``buffer`` open pairs (None: ``BUFFER_FRACTION`` of them). ``stats`` (ShieldStats) counts the rows
    ``choose`` decides on concrete arrays, every one by its full mask; under ``jit`` nothing is
    counted (a trace runs once for any number of calls, so a count there would be wrong)."""

    kind = "jax"

    def __init__(self, p, sp=None, stats=None, buffer: int | None = None):
        self.p, self.buffer = p, buffer
        self.stats = ShieldStats() if stats is None else stats

    def admissible(self, heel_y, heel_z, layout, last_action=None):
        """(N, NUM_ACTIONS) bool: ``rule.admissible_moves`` of N environments (heel_y, heel_z (N,),
        layout fields with a leading N, ``last_action`` (N,) or None)."""
        p = self.p
        ends = rule.forward_ends(jnp, p, heel_y, heel_z)
        clear = keep_clearance(p, heel_y, heel_z, ends, layout.outline, self.buffer)
        return rule.admissible_moves(
            jnp, p, heel_y, heel_z, layout, clear=clear, last_action=last_action
        )

    def choose(self, heel_y, heel_z, layout, q, last_action=None):
        """(N,) the shielded greedy actions for Q-values ``q`` (N, NUM_ACTIONS)."""
        mask = self.admissible(heel_y, heel_z, layout, last_action)
        if not isinstance(q, jax.core.Tracer):
            n = int(q.shape[0])
            self.stats.rows += n
            self.stats.rows_to_full_mask += n
        return actions.greedy_action(jnp, q, mask)
