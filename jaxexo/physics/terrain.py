"""Procedural obstacle families: uniform numbers -> ground-obstacle outlines, for reset and tools.

Each family is ``outline(xp, u)`` of uniform numbers ``u`` in [0, 1)^D, written once for NumPy and
jax.numpy; outlines follow jaxexo.physics.geometry's convention, padded to ``K_MAX`` vertices.
``family_outline`` selects by id with ``xp.where``, so it jits and vmaps over families; ``place``
puts a drawn obstacle anywhere the gap allows. The families, the train / held-out split and the
clearability check: docs/configuration.md#procedural-terrain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from jaxexo.physics import geometry, kinematics

# Fixed sizes: every family's outline is padded to K_MAX vertices and reads the first D of D_MAX
# uniform numbers, so one (K_MAX, 2) array and one (D_MAX,) draw serve every family in a batch.
K_MAX = 16
D_MAX = 16


class TerrainError(ValueError):
    """An invalid terrain description; the message starts with the bad field's path."""


def _lerp(lo, hi, t):
    return lo + (hi - lo) * t


def _v(y, z):
    """One vertex (..., 2); y and z broadcast (either may be a Python float)."""
    return (y, z)


# --------------------------------------------------------------------------------------------
# The families. Each returns (vertices, width, height); vertices a list of (y, z) pairs with y
# relative to the centre. ``W`` and ``H`` are the (lo, hi) ranges in metres.
# --------------------------------------------------------------------------------------------


def _rectangle(xp, u, W, H):
    w, h = _lerp(*W, u[..., 0]), _lerp(*H, u[..., 1])
    a, b = -0.5 * w, 0.5 * w
    return [_v(a, 0.0 * h), _v(a, h), _v(b, h), _v(b, 0.0 * h)], w, h


def _trapezoid(xp, u, W, H):
    # Top width t of the base (0.15..0.85), its centre shifted within the base (an oblique trapezoid).
    w, h = _lerp(*W, u[..., 0]), _lerp(*H, u[..., 1])
    t = _lerp(0.15, 0.85, u[..., 2])
    s = (u[..., 3] - 0.5) * (1.0 - t)
    return (
        [
            _v(-0.5 * w, 0.0 * h),
            _v((s - 0.5 * t) * w, h),
            _v((s + 0.5 * t) * w, h),
            _v(0.5 * w, 0.0 * h),
        ],
        w,
        h,
    )


def _wedge(xp, u, W, H):
    # Apex position a across the width; a quarter of draws at each end give a ramp (vertical back).
    w, h = _lerp(*W, u[..., 0]), _lerp(*H, u[..., 1])
    a = xp.clip(1.5 * u[..., 2] - 0.25, 0.0, 1.0)
    return [_v(-0.5 * w, 0.0 * h), _v((a - 0.5) * w, h), _v(0.5 * w, 0.0 * h)], w, h


def _mirror(xp, flip, verts):
    """Select the mirror image (y -> -y, order reversed so y stays non-decreasing) where flip."""
    rev = [(-y, z) for (y, z) in reversed(verts)]
    return [(xp.where(flip, ry, y), xp.where(flip, rz, z)) for (y, z), (ry, rz) in zip(verts, rev)]


def _step(xp, u, W, H):
    # Two levels: a lower tread over fraction f of the width at fraction r of the height, then the
    # top; mirrored (falling) for half the draws.
    w, h = _lerp(*W, u[..., 0]), _lerp(*H, u[..., 1])
    f = _lerp(0.3, 0.7, u[..., 2])
    r = _lerp(0.3, 0.7, u[..., 3])
    a, b, m = -0.5 * w, 0.5 * w, -0.5 * w + f * w
    verts = [_v(a, 0.0 * h), _v(a, r * h), _v(m, r * h), _v(m, h), _v(b, h), _v(b, 0.0 * h)]
    return _mirror(xp, u[..., 4] >= 0.5, verts), w, h


def _bump(xp, u, W, H):
    # One polygonal hump: peak at fraction p, shoulders half-way to the ends at fraction q >= 0.5 of
    # the height (q > 0.5 makes it bulge above the triangle through the peak).
    w, h = _lerp(*W, u[..., 0]), _lerp(*H, u[..., 1])
    p = _lerp(0.3, 0.7, u[..., 2])
    q = _lerp(0.5, 0.9, u[..., 3])
    a, b = -0.5 * w, 0.5 * w
    yp = a + p * w
    return (
        [
            _v(a, 0.0 * h),
            _v(0.5 * (a + yp), q * h),
            _v(yp, h),
            _v(0.5 * (yp + b), q * h),
            _v(b, 0.0 * h),
        ],
        w,
        h,
    )


_POLY_INNER = 6


def _polyline(xp, u, W, H):
    # Six interior vertices at random spacing (gaps 0.2..1.2, normalised) and random heights made
    # unimodal by z_i = min(max of z up to i, max of z from i on): the profile climbs to its top and
    # descends without an interior dip (held-out 'bumps' have dips), then scaled so the top is h.
    w, h = _lerp(*W, u[..., 0]), _lerp(*H, u[..., 1])
    n = _POLY_INNER
    gaps = [0.2 + u[..., 2 + i] for i in range(n + 1)]
    total = gaps[0]
    for g in gaps[1:]:
        total = total + g
    ys, acc = [], 0.0 * total
    for g in gaps[:-1]:
        acc = acc + g
        ys.append(-0.5 * w + w * acc / total)
    z = [_lerp(0.2, 1.0, u[..., 3 + n + i]) for i in range(n)]
    pre, suf = list(z), list(z)
    for i in range(1, n):
        pre[i] = xp.maximum(pre[i - 1], z[i])
    for i in range(n - 2, -1, -1):
        suf[i] = xp.maximum(suf[i + 1], z[i])
    top = pre[-1]
    zs = [xp.minimum(pre[i], suf[i]) / top * h for i in range(n)]
    return (
        [_v(-0.5 * w, 0.0 * h)] + [_v(y, zz) for y, zz in zip(ys, zs)] + [_v(0.5 * w, 0.0 * h)],
        w,
        h,
    )


def _pole(xp, u, W, H):
    # A thin post with a pointed cap up to half its width tall.
    w, h = _lerp(*W, u[..., 0]), _lerp(*H, u[..., 1])
    cap = 0.5 * w * u[..., 2]
    a, b = -0.5 * w, 0.5 * w
    return [_v(a, 0.0 * h), _v(a, h - cap), _v(0.0 * w, h), _v(b, h - cap), _v(b, 0.0 * h)], w, h


def _stairs(xp, u, W, H):
    # Three equal treads rising to levels l1 < l2 < h (then a vertical drop), mirrored for half.
    w, h = _lerp(*W, u[..., 0]), _lerp(*H, u[..., 1])
    l1 = _lerp(0.2, 0.45, u[..., 2]) * h
    l2 = _lerp(0.55, 0.8, u[..., 3]) * h
    a, b = -0.5 * w, 0.5 * w
    t1, t2 = a + w / 3.0, a + 2.0 * w / 3.0
    z0 = 0.0 * h
    verts = [
        _v(a, z0),
        _v(a, l1),
        _v(t1, l1),
        _v(t1, l2),
        _v(t2, l2),
        _v(t2, h),
        _v(b, h),
        _v(b, z0),
    ]
    return _mirror(xp, u[..., 4] >= 0.5, verts), w, h


def _curb(xp, u, W, H):
    # Wide and low, with bevelled edges up to 3 cm wide.
    w, h = _lerp(*W, u[..., 0]), _lerp(*H, u[..., 1])
    bev = 0.03 * u[..., 2]
    a, b = -0.5 * w, 0.5 * w
    return [_v(a, 0.0 * h), _v(a + bev, h), _v(b - bev, h), _v(b, 0.0 * h)], w, h


def _bumps(xp, u, W, H):
    # Two (u2 < 0.5) or three humps of heights 0.5..1 (the tallest scaled to h), separated by valleys
    # down to fraction 0..0.5 of the lower neighbour. Seven vertices always: with two humps the third
    # peak and second valley coincide with the second peak (zero-length edges, allowed by the
    # padded-outline convention).
    w, h = _lerp(*W, u[..., 0]), _lerp(*H, u[..., 1])
    three = u[..., 2] >= 0.5
    p = [_lerp(0.5, 1.0, u[..., 3 + i]) for i in range(3)]
    p[2] = xp.where(three, p[2], 0.0 * p[2])
    top = xp.maximum(xp.maximum(p[0], p[1]), p[2])
    p = [pi / top * h for pi in p]
    dv = _lerp(0.0, 0.5, u[..., 6])
    v1 = dv * xp.minimum(p[0], p[1])
    v2 = dv * xp.minimum(p[1], p[2])
    a = -0.5 * w
    x3 = [1 / 6, 2 / 6, 3 / 6, 4 / 6, 5 / 6]
    x2 = [1 / 4, 2 / 4, 3 / 4, 3 / 4, 3 / 4]
    ys = [a + w * xp.where(three, x3[i], x2[i]) for i in range(5)]
    zs = [p[0], v1, p[1], xp.where(three, v2, p[1]), xp.where(three, p[2], p[1])]
    return [_v(a, 0.0 * h)] + [_v(y, z) for y, z in zip(ys, zs)] + [_v(-a, 0.0 * h)], w, h


_SMOOTH_INNER = 13


def _smooth_bump(xp, u, W, H):
    # z = h ((1 + cos(pi x)) / 2)^e over x in [-1, 1], sampled at 13 interior points (x = 0 among
    # them, so the top is exactly h); e in 0.5..2 runs from a broad dome to a peaked bell.
    w, h = _lerp(*W, u[..., 0]), _lerp(*H, u[..., 1])
    e = _lerp(0.5, 2.0, u[..., 2])
    xs = np.linspace(-1.0, 1.0, _SMOOTH_INNER + 2)[1:-1]
    verts = [_v(-0.5 * w, 0.0 * h)]
    for x in xs:
        base = 0.5 * (1.0 + math.cos(math.pi * x))
        verts.append(_v(0.5 * w * x + 0.0 * h, h * xp.exp(e * math.log(base))))
    verts.append(_v(0.5 * w, 0.0 * h))
    return verts, w, h


@dataclass(frozen=True)
class Family:
    """One obstacle family: ``fid`` its id, ``d`` the uniform numbers it reads, ``k`` its vertices
    before padding, ``width`` and ``height`` its (lo, hi) ranges in metres."""

    name: str
    fid: int
    d: int
    k: int
    width: tuple[float, float]
    height: tuple[float, float]
    held_out: bool
    build: Callable = field(repr=False, compare=False)

    def outline(self, xp, u):
        verts, w, h = self.build(xp, u, self.width, self.height)
        return verts, w, h


_TABLE = (
    # name,        D, K,  width (m),     height (m),    held out, builder
    ("rectangle", 2, 4, (0.08, 0.30), (0.06, 0.30), False, _rectangle),
    ("trapezoid", 4, 4, (0.08, 0.36), (0.06, 0.28), False, _trapezoid),
    ("wedge", 3, 3, (0.08, 0.36), (0.06, 0.28), False, _wedge),
    ("step", 5, 6, (0.10, 0.36), (0.06, 0.28), False, _step),
    ("bump", 4, 5, (0.08, 0.36), (0.06, 0.28), False, _bump),
    ("polyline", 15, 8, (0.08, 0.36), (0.06, 0.28), False, _polyline),
    ("pole", 3, 5, (0.02, 0.05), (0.10, 0.30), True, _pole),
    ("stairs", 5, 8, (0.18, 0.40), (0.08, 0.28), True, _stairs),
    ("curb", 3, 4, (0.25, 0.40), (0.02, 0.05), True, _curb),
    ("bumps", 7, 7, (0.16, 0.40), (0.06, 0.28), True, _bumps),
    ("smooth_bump", 3, 15, (0.10, 0.40), (0.06, 0.28), True, _smooth_bump),
)
FAMILIES: dict[str, Family] = {
    name: Family(name, i, d, k, w, h, held, fn)
    for i, (name, d, k, w, h, held, fn) in enumerate(_TABLE)
}
FAMILY_NAMES = tuple(FAMILIES)
TRAIN_FAMILIES = tuple(n for n, f in FAMILIES.items() if not f.held_out)
HELD_OUT_FAMILIES = tuple(n for n, f in FAMILIES.items() if f.held_out)
assert all(f.k <= K_MAX and f.d <= D_MAX for f in FAMILIES.values())


def family_id(name: str) -> int:
    if name not in FAMILIES:
        raise TerrainError(f"family must be one of {FAMILY_NAMES}, got {name!r}")
    return FAMILIES[name].fid


def _stack(xp, verts):
    """Vertex list -> (..., K_MAX, 2), padded by repeating the last vertex."""
    verts = list(verts) + [verts[-1]] * (K_MAX - len(verts))
    ys = xp.stack([xp.asarray(y) + 0.0 * xp.asarray(z) for y, z in verts], axis=-1)
    zs = xp.stack([xp.asarray(z) + 0.0 * xp.asarray(y) for y, z in verts], axis=-1)
    return xp.stack([ys, zs], axis=-1)


def one_family_outline(xp, name: str, u):
    """(outline (..., K_MAX, 2), width (...), height (...)) of a named family, in its own frame."""
    fam = FAMILIES[name]
    verts, w, h = fam.outline(xp, u)
    # Constants (Python floats) would promote NumPy float32 input to float64: keep u's dtype.
    dt = u.dtype
    return _stack(xp, verts).astype(dt), w.astype(dt), h.astype(dt)


def family_outline(xp, fid, u, names=None):
    """The outline of family ``fid`` (int or int array (...)) from uniforms ``u`` (..., D_MAX):
    (outline (..., K_MAX, 2) in the obstacle frame, width (...), height (...)), metres.

    Every family is evaluated and the result selected with ``xp.where`` (a few hundred flops), so a
    traced ``fid`` jits and vmaps; an id outside the table gives family 0. ``names`` (static) limits
    the evaluation to those families (the ones a config can draw: a smaller program, same result
    for their ids; an id outside them gives the first)."""
    fid = xp.asarray(fid)
    out = w_out = h_out = None
    for fam in FAMILIES.values() if names is None else [FAMILIES[n] for n in names]:
        o, w, h = one_family_outline(xp, fam.name, u)
        if out is None:
            out, w_out, h_out = o, w, h
            continue
        sel = fid == fam.fid
        out = xp.where(sel[..., None, None], o, out)
        w_out = xp.where(sel, w, w_out)
        h_out = xp.where(sel, h, h_out)
    return out, w_out, h_out


def shape(xp, outline, width, n_points: int = geometry.DEFAULT_SHAPE_POINTS):
    """The observation's height-profile descriptor (..., n_points), metres: the outline's height at
    ``geometry.descriptor_fractions`` of its width (= height * geometry.shape_descriptor(unit))."""
    frac = geometry.descriptor_fractions(n_points)
    # outline[..., None, :, :]: one outline per batch entry, evaluated at its n_points positions.
    return geometry.profile_height(xp, width[..., None] * frac, outline[..., None, :, :])


def unpad(outline: np.ndarray) -> np.ndarray:
    """NumPy: the outline without its trailing padding (repeats of the last vertex)."""
    o = np.asarray(outline)
    n = len(o)
    while n > 1 and np.array_equal(o[n - 1], o[n - 2]):
        n -= 1
    return o[:n]


def to_obstacle(outline: np.ndarray, center_y: float) -> geometry.Obstacle:
    """NumPy: an obstacle-frame outline placed at ``center_y`` as a geometry.Obstacle (profile)."""
    pts = unpad(np.asarray(outline, dtype=np.float64)).copy()
    pts[:, 0] += center_y
    return geometry.Obstacle.profile(pts)


# --------------------------------------------------------------------------------------------
# Placement
# --------------------------------------------------------------------------------------------

# m between the toe at the start and the obstacle's near edge: the safe-swing margin (2 cm) with
# 5 mm to spare, so that no scene's verdict is decided by float rounding at its start.
NEAR_MARGIN = 0.025
FAR_MARGIN = (
    0.06  # m between the obstacle's far edge and the goal (> the goal box's 0.04 half width)
)


def min_step_length(
    width, foot_length: float, near_margin: float = NEAR_MARGIN, far_margin: float = FAR_MARGIN
):
    """The shortest step that fits an obstacle this wide between the toe at the start and the goal."""
    return foot_length + near_margin + width + far_margin


def place(
    xp,
    u,
    width,
    start_shift,
    step_length,
    foot_length: float,
    near_margin: float = NEAR_MARGIN,
    far_margin: float = FAR_MARGIN,
):
    """(start_y, step_length, center_y), metres, from uniforms u (..., 3): the start shift drawn from
    its range, the step length from [max(lo, min_step_length(width)), hi] (a wide obstacle only gets
    steps it fits in), and the centre anywhere between the toe at the start + near_margin and the
    goal - far_margin. A config's ``TerrainSpec`` guarantees the widest family fits the longest step."""
    start = _lerp(start_shift[0], start_shift[1], u[..., 0])
    lo = xp.maximum(step_length[0], min_step_length(width, foot_length, near_margin, far_margin))
    L = lo + (step_length[1] - lo) * u[..., 1]
    c_lo = start + foot_length + near_margin + 0.5 * width
    c_hi = start + L - far_margin - 0.5 * width
    return start, L, c_lo + (c_hi - c_lo) * u[..., 2]


def unclearable(
    spec, *, foot_length, thigh, shin, hip_limits, knee_limits, heel_lift, grid: int = 3
) -> list[tuple]:
    """NumPy: the (family, pivot, start, step length, centre) placements, on a grid x grid x grid
    of each family's placement range at its widest and narrowest, where the heel over the centre at
    the family's tallest top + heel_lift is out of reach or joint limits (kinematics.swing_heel_unreachable,
    as jaxexo.config.consistency._check_clearable). Empty when every pivot with weight > 0 clears."""
    out = []
    t = np.linspace(0.0, 1.0, grid)
    uu = np.stack(np.meshgrid(t, t, t, indexing="ij"), -1).reshape(-1, 3)
    for name in spec.families:
        fam = FAMILIES[name]
        for width in fam.width:
            start, L, c = place(
                np,
                uu,
                np.full(len(uu), width),
                spec.start_shift,
                spec.step_length,
                foot_length,
                spec.near_margin,
                spec.far_margin,
            )
            heel = np.stack([c, np.full_like(c, fam.height[1] + heel_lift)], -1)
            for k, piv in enumerate(kinematics.PIVOT_CONDITIONS):
                if spec.pivot[k] <= 0:
                    continue
                bad = kinematics.swing_heel_unreachable(
                    np,
                    kinematics.pivot_position(np, k, start, c),
                    heel,
                    thigh,
                    shin,
                    hip_limits,
                    knee_limits,
                )
                for i in np.flatnonzero(bad):
                    out.append((name, piv, float(start[i]), float(L[i]), float(c[i])))
    return out


# --------------------------------------------------------------------------------------------
# NumPy drawing (tools, the unseen benchmark)
# --------------------------------------------------------------------------------------------


def draw_uniforms(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(n, D_MAX) shape uniforms and (n, 3) placement uniforms, float32 (what jax.random.uniform
    gives reset), so that NumPy tools and the JAX environment read the same numbers alike."""
    u_shape = rng.random((n, D_MAX), dtype=np.float32)
    u_place = rng.random((n, 3), dtype=np.float32)
    return u_shape, u_place
