"""An episode's obstacle changing mid-swing ([env] obstacle_change, jaxexo.config.changes), written
once for every array module: ``changed_layout`` draws, at reset, the obstacle the episode will switch
to and the step at which it does; ``fires`` decides at that step whether the switch happens (never
onto the foot). Why and what: docs/training.md#obstacle-changes-in-training.

A layout holds one padded outline (K vertices, the last repeated). A second obstacle is a rectangle
written into the last four slots, behind the first one's vertices, when those slots are padding (the
default terrain: at most 8 of 16 vertices used); otherwise the outline becomes one rectangle covering
both (a wider, conservative obstacle). Either way ``center_y``, ``width`` and ``height`` are those of
the pair's bounding box, as the observation and the shield's bounds read them.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from jaxexo.physics import geometry
from jaxexo.physics.terrain import FAR_MARGIN, NEAR_MARGIN

# Uniform numbers per episode: whether, when, which kind, taller, wider, move, and the second
# obstacle's width, height and gap.
N_UNIFORMS = 9
# The second obstacle: a rectangle this wide (m; narrowed to the room before the goal, refused below
# SECOND_MIN_WIDTH, a thin pole) and this tall, as fractions of the first's height.
SECOND_WIDTH = (0.03, 0.12)
SECOND_MIN_WIDTH = 0.02
SECOND_HEIGHT = (0.5, 1.0)
_RECT = 4  # a rectangle's vertices


class Changed(NamedTuple):
    """The changed obstacle's Layout fields (any leading shape ``...``), m, and ``at``, the step count
    at which the episode switches to it (int32; -1: never)."""

    outline: Any  # (..., K, 2) world frame
    shape: Any  # (..., S)
    center_y: Any
    width: Any
    height: Any
    at: Any


def _lerp(r, x):
    return r[..., 0] + (r[..., 1] - r[..., 0]) * x


def _room(xp, p, lay):
    """(behind, ahead), m: how far the obstacle may reach towards the start (the toe at the start plus
    terrain.NEAR_MARGIN) and towards the goal (less terrain.FAR_MARGIN, so the heel lands clear)."""
    left = lay.center_y - 0.5 * lay.width
    right = lay.center_y + 0.5 * lay.width
    behind = xp.maximum(left - (lay.start_y + p.foot_length + NEAR_MARGIN), 0.0)
    ahead = xp.maximum(lay.goal_y - FAR_MARGIN - right, 0.0)
    return behind, ahead


def _safe_ratio(xp, a, b):
    """a / b where b > 0, else 1 (nothing asked, nothing to shrink)."""
    ok = b > 0.0
    return xp.where(ok, a / xp.where(ok, b, 1.0), 1.0)


def _grown(xp, p, lay, u):
    """The obstacle taller by a fraction of ``change_taller`` (at most the layout's tallest), wider by
    one of ``change_wider`` about its centre and moved by ``change_move`` m: growth and move shrunk
    together where they would leave the room (``_room``)."""
    h, w, c = lay.height, lay.width, lay.center_y
    top = xp.minimum(
        h * (1.0 + _lerp(p.change_taller, u[..., 3])), xp.maximum(h, p.change_max_height)
    )
    sz = top / h
    side = 0.5 * w * _lerp(p.change_wider, u[..., 4])  # m added on each side
    d = _lerp(p.change_move, u[..., 5])
    behind, ahead = _room(xp, p, lay)
    k = xp.minimum(
        xp.minimum(_safe_ratio(xp, ahead, side + xp.maximum(d, 0.0)), 1.0),
        _safe_ratio(xp, behind, side + xp.maximum(-d, 0.0)),
    )
    side, d = k * side, k * d
    sy = 1.0 + 2.0 * side / w
    y, z = lay.outline[..., 0], lay.outline[..., 1]
    outline = xp.stack(
        [(c + d)[..., None] + sy[..., None] * (y - c[..., None]), sz[..., None] * z], axis=-1
    )
    return Changed(outline, sz[..., None] * lay.shape, c + d, sy * w, top, at=None)


def _second(xp, p, lay, u):
    """A rectangle appearing between the obstacle and the goal, and whether it fits (at least
    SECOND_MIN_WIDTH wide): the outline with it (or one covering both), the pair's shape, centre,
    width and height."""
    h, K = lay.height, lay.outline.shape[-2]
    left, right = lay.center_y - 0.5 * lay.width, lay.center_y + 0.5 * lay.width
    _, ahead = _room(xp, p, lay)
    w2 = xp.minimum(_lerp(xp.asarray(SECOND_WIDTH, dtype=u.dtype), u[..., 6]), ahead)
    h2 = xp.minimum(
        h * _lerp(xp.asarray(SECOND_HEIGHT, dtype=u.dtype), u[..., 7]),
        xp.maximum(h, p.change_max_height),
    )
    fits = (w2 >= SECOND_MIN_WIDTH) & (K >= _RECT)
    y0 = right + u[..., 8] * xp.maximum(ahead - w2, 0.0)
    y1 = y0 + w2
    top = xp.maximum(h, h2)

    def rect(a, b, z):  # (..., 4, 2): a rectangle [a, b] x [0, z]
        zero = 0.0 * z
        return xp.stack(
            [xp.stack([a, a, b, b], axis=-1), xp.stack([zero, z, z, zero], axis=-1)], axis=-1
        )

    cover = rect(left, y1, top)
    cover = xp.concatenate([cover] + [cover[..., -1:, :]] * max(K - _RECT, 0), axis=-2)[..., :K, :]
    if K > _RECT:  # the last four slots free (the first's last vertex repeated): append it there
        tail = lay.outline[..., K - _RECT - 1 :, :]
        free = ~geometry.any_last(xp, xp.any(tail != tail[..., -1:, :], axis=-1))
        both = xp.concatenate([lay.outline[..., : K - _RECT, :], rect(y0, y1, h2)], axis=-2)
        outline = xp.where(free[..., None, None], both, cover)
    else:
        outline = cover
    center, width = 0.5 * (left + y1), y1 - left
    frac = xp.asarray(geometry.descriptor_fractions(lay.shape.shape[-1]), dtype=width.dtype)
    shape = geometry.profile_height(
        xp, center[..., None] + width[..., None] * frac, outline[..., None, :, :]
    )
    return Changed(outline, shape, center, width, top, at=None), fits


def changed_layout(xp, p, lay, u) -> Changed:
    """The change of the episode on layout ``lay`` (Layout fields, leading shape ``...``) from uniform
    numbers u (..., N_UNIFORMS) and the params' ``change_*`` ranges: with probability
    ``change_chance``, at a step drawn uniformly from ``change_steps``, a second obstacle (probability
    ``change_second``; ``at`` -1 where it finds no room) or the obstacle grown and moved."""
    lo, hi = p.change_steps[..., 0], p.change_steps[..., 1]
    step = xp.minimum(lo + (u[..., 1] * (hi - lo + 1).astype(u.dtype)).astype(lo.dtype), hi)
    grown = _grown(xp, p, lay, u)
    second, fits = _second(xp, p, lay, u)
    use_second = u[..., 2] < p.change_second
    happens = (u[..., 0] < p.change_chance) & (fits | ~use_second)
    pick = [
        xp.where(use_second.reshape(use_second.shape + (1,) * (a.ndim - use_second.ndim)), a, b)
        for a, b in zip(second[:5], grown[:5])
    ]
    return Changed(*pick, at=xp.where(happens, step, -1).astype(np.int32))


def fires(xp, p, heel, time, at, outline):
    """Whether the episode switches to the changed obstacle (``outline`` (..., K, 2)) with the heel at
    ``heel`` (..., 2) after ``time`` steps: at the drawn step ``at``, and only if the foot there keeps
    max(env.min_clearance, env.shield_clearance) from it (a change onto or beside the foot is
    skipped: the episode goes on over the obstacle it has)."""
    clear = geometry.foot_clearance(xp, heel, p.foot_length, outline)
    return (time == at) & (clear >= xp.maximum(p.min_clearance, p.shield_clearance))
