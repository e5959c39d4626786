"""Obstacle geometry in the sagittal plane (outlines, the exact foot-obstacle distance), written
once for the array module ``xp`` (numpy or jax.numpy) and shared by the JAX environment and the
NumPy generator. Frame, outline convention and the modelling decisions (flat foot, exact
distance, touching is collision): docs/training.md#modelling-decisions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# Vertices of the polygon inscribed in a half-ellipse; a user profile may have at most
# MAX_PROFILE_VERTICES. The fixed size K of a batch is the largest count among its obstacle kinds.
HALF_ELLIPSE_VERTICES = 16
MAX_PROFILE_VERTICES = 64
# Number of points of the shape descriptor (heights at fractions of the obstacle's width) that the
# conditioned observation carries.
DEFAULT_SHAPE_POINTS = 9
# Collision tolerance: a foot closer than this to the outline touches it (metres).
TOUCH_EPS = 1e-6

# The five obstacles of thesis Table 3.1: (shape, width m, height m, used in training).
THESIS_OBSTACLES = {
    "base1": ("rectangle", 0.20, 0.10),
    "base2": ("rectangle", 0.10, 0.15),
    "base3": ("rectangle", 0.05, 0.20),
    "triangle": ("triangle", 0.20, 0.20),
    "half_circle": ("half_ellipse", 0.20, 0.25),
}
SHAPES = ("rectangle", "triangle", "half_ellipse", "profile")
# The one bound of an obstacle's size (m), for the config and every generator's input: no swing of
# legs of at most 2 m steps over more (docs/reliability.md).
MAX_OBSTACLE_HEIGHT = 0.6
MAX_OBSTACLE_WIDTH = 1.0


class GeometryError(ValueError):
    """An obstacle that cannot exist (bad size, NaN, malformed profile). Names the bad field."""


# --------------------------------------------------------------------------------------------
# Array-module-generic geometry (numpy or jax.numpy). Shapes: points (..., 2); outline (..., K, 2).
# --------------------------------------------------------------------------------------------


# Up to CHAIN_MAX entries, min / any / parity over the last axis are a chain of elementwise
# operations, exact and several times faster in NumPy than a reduction (docs/decisions.md).
CHAIN_MAX = 8


# Vertices per iteration of the term-by-term loops under JAX (foot_clearance_by_edge,
# swept.swept_distance_by_edge): most of a full unroll's speed at a fraction of its compile time.
BY_EDGE_UNROLL = 3


def is_jax(xp) -> bool:
    """Whether the array module is jax.numpy (the term-by-term forms are for XLA; any other module,
    NumPy or a namespace standing in for it, takes the broadcast ones)."""
    return getattr(xp, "__name__", "").startswith("jax")


def vertex_loop(xp, count: int, body, carry):
    """``carry = body(k, carry)`` for k = 0 .. count-1: the term-by-term forms' loop over outline
    vertices. Under JAX a ``fori_loop`` unrolled by BY_EDGE_UNROLL, otherwise a Python loop."""
    if is_jax(xp):
        import jax  # only under JAX: jaxexo.physics stays importable without it

        return jax.lax.fori_loop(0, count, body, carry, unroll=BY_EDGE_UNROLL)
    for k in range(count):
        carry = body(k, carry)
    return carry


def _chain_last(xp, op, reduce, x):
    k = x.shape[-1]
    if not 0 < k <= CHAIN_MAX:
        return reduce(x, axis=-1)
    out = x[..., 0]
    for j in range(1, k):
        out = op(out, x[..., j])
    return out


def min_last(xp, x, axes: int = 1):
    """xp.min over the last ``axes`` axes (module note above CHAIN_MAX)."""
    for _ in range(axes):
        x = _chain_last(xp, xp.minimum, xp.min, x)
    return x


def any_last(xp, x, axes: int = 1):
    """xp.any over the last ``axes`` axes."""
    for _ in range(axes):
        x = _chain_last(xp, xp.logical_or, xp.any, x)
    return x


def odd_last(xp, x):
    """Whether an odd number of the booleans along the last axis are True (xp.sum(x, -1) % 2 == 1)."""
    if not 0 < x.shape[-1] <= CHAIN_MAX:
        return xp.sum(x.astype(np.int32), axis=-1) % 2 == 1
    return _chain_last(xp, xp.logical_xor, None, x)


def _point_edge_dist2(xp, py, pz, ay, az, ey, ez, inv_len2):
    """Squared distance from a point to the edges a + t e, t in [0, 1] (components broadcast)."""
    apy = py - ay
    apz = pz - az
    # Degenerate (padding) edges have inv_len2 = 0: t = 0 gives the distance to the vertex.
    t = (apy * ey + apz * ez) * inv_len2
    t = xp.minimum(xp.maximum(t, 0.0), 1.0)  # = clip(t, 0, 1): NumPy's clip is slower
    dy = apy - t * ey
    dz = apz - t * ez
    return dy * dy + dz * dz


def _inv_edge_len2(xp, ey, ez):
    """1 / |e|^2 of edges e, 0 for edges shorter than 1e-12 m (counted as points: 1 / len2 of a
    shorter one can overflow to inf, and t = 0 * inf is nan)."""
    len2 = ey * ey + ez * ez
    ok = len2 > 1e-24
    return xp.where(ok, 1.0 / xp.where(ok, len2, 1.0), 0.0)


def _foot_edge_terms(xp, y0, y1, z, ay, az, by, bz):
    """The flat foot [y0, y1] x {z} against outline edges a -> b: the heel's and the toe's squared
    distances to the edge, and whether the edge crosses the foot (strictly between its ends' heights)."""
    ey, ez = by - ay, bz - az
    inv_len2 = _inv_edge_len2(xp, ey, ez)
    d_heel = _point_edge_dist2(xp, y0, z, ay, az, ey, ez, inv_len2)
    d_toe = _point_edge_dist2(xp, y1, z, ay, az, ey, ez, inv_len2)
    sa = az - z
    sb = bz - z
    straddle = sa * sb < 0.0
    frac = sa / xp.where(straddle, sa - sb, 1.0)
    y_cross = ay + frac * ey
    return d_heel, d_toe, straddle & (y_cross >= y0) & (y_cross <= y1)


def _foot_vertex_term(xp, y0, y1, z, vy, vz):
    """Squared distance from outline vertices to the flat foot [y0, y1] x {z}."""
    gap = xp.maximum(xp.maximum(y0 - vy, vy - y1), 0.0)
    return gap * gap + (vz - z) * (vz - z)


def _ray_hits(xp, py, pz, ay, az, by, bz):
    """Whether the ray from (py, pz) towards +y crosses the edge a -> b (crossing-number test)."""
    straddles = (az > pz) != (bz > pz)
    dz = bz - az
    y_at = ay + (pz - az) * (by - ay) / xp.where(dz == 0.0, 1.0, dz)
    return straddles & (py < y_at)


def flat_foot_distance(xp, heel, foot_length, outline):
    """Exact minimum distance between the flat foot [heel, heel + (foot_length, 0)] and the outline.

    For two segments that do not cross, the minimum distance is attained at an endpoint of one of
    them: the heel or the toe to an edge, or an outline vertex to the foot. The foot is horizontal,
    so the vertex distances and the crossing test reduce to a few comparisons; components are kept
    apart (structure of arrays) so that XLA vectorises them over the batch. Zero when they cross."""
    y0 = heel[..., 0, None]
    z = heel[..., 1, None]
    y1 = y0 + foot_length
    vy = outline[..., 0]
    vz = outline[..., 1]
    d_heel, d_toe, crosses = _foot_edge_terms(
        xp, y0, y1, z, vy[..., :-1], vz[..., :-1], vy[..., 1:], vz[..., 1:]
    )
    d_vert = _foot_vertex_term(xp, y0, y1, z, vy, vz)
    d2 = xp.minimum(xp.minimum(min_last(xp, d_heel), min_last(xp, d_toe)), min_last(xp, d_vert))
    return xp.where(any_last(xp, crosses), 0.0, xp.sqrt(d2))


def point_in_obstacle(xp, p, outline):
    """True where point p (..., 2) lies in the ground obstacle (region under the outline, z >= 0).

    Crossing-number test with a ray towards +y over the outline edges; the closing edge along the
    ground is horizontal and never crosses a horizontal ray, so it can be left out."""
    a = outline[..., :-1, :]
    b = outline[..., 1:, :]
    hits = _ray_hits(
        xp, p[..., None, 0], p[..., None, 1], a[..., 0], a[..., 1], b[..., 0], b[..., 1]
    )
    return odd_last(xp, hits) & (p[..., 1] >= 0.0)


def foot_clearance_by_edge(xp, heel, foot_length, vy, vz):
    """``foot_clearance`` term by term (as jaxexo.physics.swept.swept_distance_by_edge, and for the
    same reason: XLA on a CPU, thousands of feet): the outline vertex-major, vy, vz (K, ...)
    broadcasting against the heels' (...,); each term is the same expression as in
    ``flat_foot_distance`` and ``point_in_obstacle``."""
    vy, vz = xp.asarray(vy), xp.asarray(vz)  # indexed by the loop's counter
    y0, z = heel[..., 0], heel[..., 1]
    y1 = y0 + foot_length

    def edge(k, carry):
        d2, crosses, odd = carry
        d_heel, d_toe, c = _foot_edge_terms(xp, y0, y1, z, vy[k], vz[k], vy[k + 1], vz[k + 1])
        d2 = xp.minimum(xp.minimum(d2, d_heel), d_toe)
        d2 = xp.minimum(d2, _foot_vertex_term(xp, y0, y1, z, vy[k], vz[k]))
        return d2, crosses | c, odd ^ _ray_hits(xp, y0, z, vy[k], vz[k], vy[k + 1], vz[k + 1])

    k_last = vy.shape[0] - 1
    shape = xp.broadcast_shapes(y0.shape, vy.shape[1:])
    carry = (
        xp.full(shape, np.inf, dtype=y0.dtype),
        xp.zeros(shape, dtype=bool),
        xp.zeros(shape, dtype=bool),
    )
    d2, crosses, odd = vertex_loop(xp, k_last, edge, carry)
    d2 = xp.minimum(d2, _foot_vertex_term(xp, y0, y1, z, vy[k_last], vz[k_last]))
    dist = xp.where(crosses, 0.0, xp.sqrt(d2))
    return xp.where(odd & (z >= 0.0), -dist, dist)


def foot_clearance(xp, heel, foot_length, outline):
    """Signed clearance of the flat foot (heel-toe segment) from the obstacle, metres.

    Positive: the exact distance to the outline. Zero or negative: the foot touches or is inside
    (negative of the distance to the outline when the whole foot is buried). Under JAX computed term
    by term (``foot_clearance_by_edge``), in NumPy all at once."""
    if is_jax(xp):
        return foot_clearance_by_edge(
            xp,
            heel,
            foot_length,
            xp.moveaxis(outline[..., 0], -1, 0),
            xp.moveaxis(outline[..., 1], -1, 0),
        )
    dist = flat_foot_distance(xp, heel, foot_length, outline)
    inside = point_in_obstacle(xp, heel, outline)
    return xp.where(inside, -dist, dist)


def default_center(foot_length, step_length):
    """Default obstacle centre (m): the middle of the free gap between the toe at the (unshifted)
    start and the heel at the goal (any array module: plain arithmetic)."""
    return 0.5 * (foot_length + step_length)


def foot_collides(xp, clearance):
    """The foot touches or enters the obstacle (thesis eq 2.30 / 3.1, with the foot's length)."""
    return clearance <= TOUCH_EPS


def profile_height(xp, y, outline):
    """Height of the obstacle's upper profile at horizontal positions y (...,) -> (...,).

    Over a vertical edge the higher end counts; outside the obstacle the height is 0."""
    a = outline[..., :-1, :]
    b = outline[..., 1:, :]
    ye = y[..., None]
    dy = b[..., 0] - a[..., 0]
    within = (ye >= a[..., 0]) & (ye <= b[..., 0])
    frac = xp.clip((ye - a[..., 0]) / xp.where(dy == 0.0, 1.0, dy), 0.0, 1.0)
    z = xp.where(
        dy == 0.0, xp.maximum(a[..., 1], b[..., 1]), a[..., 1] + frac * (b[..., 1] - a[..., 1])
    )
    return xp.max(xp.where(within, z, 0.0), axis=-1)


# --------------------------------------------------------------------------------------------
# Building obstacles (NumPy, at the boundary: every input is validated here, never in a jit).
# --------------------------------------------------------------------------------------------


def as_given(value) -> str:
    """A number as a message echoes it: exactly the value given, never rounded (10000.0001 is not
    10000): its short form (``:g``) where that reads back as the same number, else its shortest
    exact one (repr, an integral float without ".0"); anything but a number as repr."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(
        value, (int, float, np.integer, np.floating)
    ):
        return repr(value)
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    v = float(value)
    short = f"{v:g}"
    if not math.isfinite(v) or float(short) == v:
        return short
    return exact_text(v)


def exact_text(value) -> str:
    """A float64 as the shortest text that reads back to the same bits (Python's repr), a whole
    number without its ".0"."""
    text = repr(float(value))
    return text[:-2] if text.endswith(".0") else text


def finite(name: str, value, unit: str = "metres") -> float:
    """``value`` as a finite float; GeometryError naming ``name`` otherwise (bools and strings refused)."""
    # A bool is an int to Python (True == 1): Obstacle.rectangle(True, 0.1) would be 1 m wide.
    if isinstance(value, (bool, np.bool_)):
        raise GeometryError(f"{name} must be a number in {unit}, got the boolean {value!r}")
    # float("0.1") would parse a string: a number is never taken from text.
    if isinstance(value, (str, bytes, np.str_, np.bytes_)):
        raise GeometryError(f"{name} must be a number in {unit}, got the string {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise GeometryError(f"{name} must be a number in {unit}, got {value!r}") from None
    if not math.isfinite(v):
        raise GeometryError(f"{name} must be finite, got {v}")
    return v


def finite_positive(name: str, value, unit: str = "metres", hi: float | None = None) -> float:
    """``finite`` and > 0 (and <= ``hi`` when given)."""
    v = finite(name, value, unit)
    if v <= 0.0:
        raise GeometryError(f"{name} must be > 0 {unit}, got {as_given(v)}")
    if hi is not None and v > hi:
        raise GeometryError(f"{name} must be <= {hi:g} {unit}, got {as_given(v)}")
    return v


def obstacle_size(name: str, value) -> float:
    """An obstacle's width or height (m) within the one size bound (MAX_OBSTACLE_WIDTH, _HEIGHT)."""
    return finite_positive(
        name, value, hi=MAX_OBSTACLE_HEIGHT if "height" in name else MAX_OBSTACLE_WIDTH
    )


def unit_profile(shape: str) -> np.ndarray:
    """Outline vertices of a shape in the unit frame: y in [-0.5, 0.5] (times width), z in [0, 1]
    (times height), unpadded."""
    if shape == "rectangle":
        pts = [(-0.5, 0.0), (-0.5, 1.0), (0.5, 1.0), (0.5, 0.0)]
    elif shape == "triangle":
        pts = [(-0.5, 0.0), (0.0, 1.0), (0.5, 0.0)]
    elif shape == "half_ellipse":
        # Vertices on the ellipse at equal angle steps from the left foot to the right foot.
        ang = np.linspace(np.pi, 0.0, HALF_ELLIPSE_VERTICES)
        pts = np.column_stack([0.5 * np.cos(ang), np.sin(ang)])
        pts[0], pts[-1] = (-0.5, 0.0), (0.5, 0.0)
    else:
        raise GeometryError(
            f"shape must be one of {SHAPES[:-1]} (profiles take points), got {shape!r}"
        )
    return np.asarray(pts, dtype=np.float64)


def pad_outline(pts: np.ndarray, max_vertices: int) -> np.ndarray:
    """The fixed-size (K, 2) representation: vertices padded by repeating the last one."""
    if len(pts) > max_vertices:
        raise GeometryError(
            f"obstacle has {len(pts)} outline vertices, more than max_vertices={max_vertices}"
        )
    out = np.empty((max_vertices, 2), dtype=np.float64)
    out[: len(pts)] = pts
    out[len(pts) :] = pts[-1]
    return out


_DESCRIPTOR_CACHE: dict = {}


def cached_shape_descriptor(
    unit_vertices: np.ndarray, n_points: int = DEFAULT_SHAPE_POINTS
) -> np.ndarray:
    """shape_descriptor, remembered per unit outline (the built-in shapes recur in every scene)."""
    key = (unit_vertices.tobytes(), unit_vertices.shape, n_points)
    out = _DESCRIPTOR_CACHE.get(key)
    if out is None:
        if len(_DESCRIPTOR_CACHE) > 256:
            _DESCRIPTOR_CACHE.clear()
        out = _DESCRIPTOR_CACHE[key] = shape_descriptor(unit_vertices, n_points)
        out.setflags(write=False)
    return out


def shape_descriptor(unit_vertices: np.ndarray, n_points: int = DEFAULT_SHAPE_POINTS) -> np.ndarray:
    """Heights (unit frame, 0..1) at n_points equally spaced fractions across the width.

    Precomputed per obstacle kind so that the conditioned observation costs nothing per step: an
    obstacle scaled to height h has descriptor h * this."""
    return profile_height(np, descriptor_fractions(n_points), unit_vertices)


def descriptor_fractions(n_points: int = DEFAULT_SHAPE_POINTS) -> np.ndarray:
    """The n_points fractions of the width (centre 0, ends -0.5 and 0.5) where the shape descriptor
    samples the height: equally spaced, just inside the ends so that vertical sides count."""
    return np.clip(np.linspace(-0.5, 0.5, n_points), -0.5 + 1e-6, 0.5 - 1e-6)


@dataclass(frozen=True)
class Obstacle:
    """One ground obstacle, in metres. ``outline`` is the fixed-size (K, 2) world-frame array."""

    kind: str
    shape: str
    center_y: float
    width: float
    height: float
    unit_vertices: np.ndarray  # (n, 2), unit frame, unpadded

    @property
    def outline(self) -> np.ndarray:
        """World-frame outline vertices (n, 2), unpadded."""
        o = self.unit_vertices.copy()
        o[:, 0] = self.center_y + self.width * o[:, 0]
        o[:, 1] = self.height * o[:, 1]
        return o

    def outline_array(self, max_vertices: int) -> np.ndarray:
        """World-frame outline in the fixed-size (K, 2) representation."""
        return pad_outline(self.outline, max_vertices)

    @property
    def left(self) -> float:
        return self.center_y - 0.5 * self.width

    @property
    def right(self) -> float:
        return self.center_y + 0.5 * self.width

    # Constructors ---------------------------------------------------------------------------
    @classmethod
    def named(cls, kind: str, center_y: float = 0.45) -> "Obstacle":
        """One of the five thesis obstacles (Table 3.1): base1, base2, base3, triangle, half_circle."""
        if kind not in THESIS_OBSTACLES:
            raise GeometryError(f"kind must be one of {sorted(THESIS_OBSTACLES)}, got {kind!r}")
        shape, w, h = THESIS_OBSTACLES[kind]
        return cls._make(kind, shape, center_y, w, h)

    @classmethod
    def rectangle(cls, width: float, height: float, center_y: float = 0.45):
        return cls._make("rectangle", "rectangle", center_y, width, height)

    @classmethod
    def triangle(cls, width: float, height: float, center_y: float = 0.45):
        return cls._make("triangle", "triangle", center_y, width, height)

    @classmethod
    def half_ellipse(cls, width: float, height: float, center_y: float = 0.45):
        return cls._make("half_ellipse", "half_ellipse", center_y, width, height)

    @classmethod
    def profile(cls, points) -> "Obstacle":
        """Any ground obstacle from its height profile: world-frame (y, z) points, y non-decreasing.

        Missing ground end points are added (the profile drops vertically to the ground)."""
        if isinstance(points, (list, tuple)) and any(
            isinstance(x, (bool, np.bool_))
            for p in points
            if isinstance(p, (list, tuple))
            for x in p
        ):
            raise GeometryError("points must be (y, z) numbers in metres, got a boolean")
        try:
            pts = np.asarray(points, dtype=np.float64)
        except (TypeError, ValueError):
            raise GeometryError("points must be a sequence of (y, z) pairs in metres") from None
        if np.asarray(points).dtype == np.bool_:
            raise GeometryError("points must be (y, z) numbers in metres, got booleans")
        if np.asarray(points).dtype.kind in "USO" and any(
            isinstance(x, (str, bytes)) for x in np.asarray(points, dtype=object).ravel()
        ):
            raise GeometryError("points must be (y, z) numbers in metres, got strings")
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2:
            raise GeometryError(f"points must have shape (n >= 2, 2), got {pts.shape}")
        if len(pts) > MAX_PROFILE_VERTICES - 2:
            raise GeometryError(
                f"points: at most {MAX_PROFILE_VERTICES - 2} points, got {len(pts)}"
            )
        if not np.all(np.isfinite(pts)):
            raise GeometryError("points must be finite (no NaN or inf)")
        if np.any(np.diff(pts[:, 0]) < 0):
            raise GeometryError("points must have non-decreasing y (a height profile)")
        if np.any(pts[:, 1] < 0):
            raise GeometryError("points must have z >= 0 (a ground obstacle)")
        if pts[0, 1] > 0:
            pts = np.vstack([[pts[0, 0], 0.0], pts])
        if pts[-1, 1] > 0:
            pts = np.vstack([pts, [pts[-1, 0], 0.0]])
        y0, y1 = pts[0, 0], pts[-1, 0]
        width = obstacle_size("points (width)", y1 - y0)
        height = obstacle_size("points (height)", pts[:, 1].max())
        center = 0.5 * (y0 + y1)
        unit = np.column_stack([(pts[:, 0] - center) / width, pts[:, 1] / height])
        return cls("profile", "profile", center, width, height, unit)

    @classmethod
    def _make(cls, kind, shape, center_y, width, height):
        width = obstacle_size("width", width)
        height = obstacle_size("height", height)
        center_y = finite("center_y", center_y)
        return cls(kind, shape, center_y, width, height, unit_profile(shape))

    def clearance(self, heel: np.ndarray, foot_length: float) -> np.ndarray:
        """Signed foot clearance (m) for heel positions (..., 2)."""
        return foot_clearance(np, np.asarray(heel, dtype=np.float64), foot_length, self.outline)
