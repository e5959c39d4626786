"""An obstacle outline as a union of convex pieces (the trapezoids under its edges, merged while
convex), for a physics engine's collision geometry; ``check_cover`` checks that they tile the outline,
and an outline that is not a simple polygon is refused with a GeometryError naming it. Units: metres,
(y, z) pairs. See docs/safety.md, "Replayed in a physics engine (MuJoCo)".
"""

from __future__ import annotations

import numpy as np

from jaxexo.physics.geometry import GeometryError

# Relative tolerance of the convexity and cover checks (outlines are built from sums of metres).
EPS = 1e-12


def unpadded(outline) -> np.ndarray:
    """The outline's vertices without repeats (padding repeats the last vertex; a repeated vertex
    is a zero-length edge that changes no distance)."""
    o = np.asarray(outline, dtype=np.float64)
    if o.ndim != 2 or o.shape[1] != 2 or len(o) < 3:
        raise GeometryError(
            f"outline: expected (K >= 3, 2) (y, z) vertices in metres, got shape {o.shape}"
        )
    if not np.all(np.isfinite(o)):
        raise GeometryError("outline: vertices must be finite (no NaN or inf)")
    keep = np.ones(len(o), dtype=bool)
    keep[1:] = np.any(np.diff(o, axis=0) != 0.0, axis=1)
    return o[keep]


def check_simple(outline) -> np.ndarray:
    """The unpadded outline if, closed along the ground, it is a simple polygon of positive area that
    stands on the ground with a height profile on top; GeometryError naming the fault otherwise."""
    o = unpadded(outline)
    if len(o) < 3:
        raise GeometryError(f"outline: fewer than 3 distinct vertices ({len(o)}); not a polygon")
    if o[0, 1] != 0.0 or o[-1, 1] != 0.0:
        raise GeometryError("outline: the first and last vertices must be on the ground (z = 0)")
    if np.any(o[:, 1] < 0.0):
        i = int(np.argmin(o[:, 1]))
        raise GeometryError(f"outline: vertex {i} is below the ground (z = {o[i, 1]:.6g} m)")
    if np.any(np.diff(o[:, 0]) < 0.0):
        i = int(np.argmax(np.diff(o[:, 0]) < 0.0))
        raise GeometryError(
            f"outline: y goes backwards between vertices {i} and {i + 1}; not a height profile"
        )
    if np.any(o[1:-1, 1] == 0.0):
        i = 1 + int(np.argmax(o[1:-1, 1] == 0.0))
        raise GeometryError(
            f"outline: interior vertex {i} touches the ground, so the closed outline "
            "touches itself (two obstacles); give each its own outline"
        )
    # Consecutive vertical edges that fold back (up then down at one y) overlap each other.
    d = np.diff(o, axis=0)
    vert = d[:, 0] == 0.0
    fold = vert[:-1] & vert[1:] & (d[:-1, 1] * d[1:, 1] < 0.0)
    if np.any(fold):
        i = 1 + int(np.argmax(fold))
        raise GeometryError(
            f"outline: the vertical edges at vertex {i} (y = {o[i, 0]:.6g} m) fold back on "
            "themselves; not a simple polygon"
        )
    if o[-1, 0] - o[0, 0] <= 0.0:
        raise GeometryError("outline: zero width; not a polygon")
    return o


def _convex_ccw(poly: np.ndarray) -> bool:
    """Whether a counter-clockwise polygon (y right, z up) turns left (or goes straight) at every vertex."""
    a = poly
    b = np.roll(poly, -1, axis=0)
    c = np.roll(poly, -2, axis=0)
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - b[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - b[:, 0])
    scale = np.abs(poly).max() ** 2
    return bool(np.all(cross >= -EPS * scale))


def region_polygon(top: np.ndarray) -> np.ndarray:
    """The counter-clockwise polygon (n, 2) of the region between the ground and a top chain (its
    vertices left to right): the left foot on the ground, the right foot, then the chain from right
    to left (a foot dropped where the chain already ends on the ground)."""
    pts = [(top[0, 0], 0.0), (top[-1, 0], 0.0)] + [tuple(p) for p in top[::-1]]
    out = []
    for p in pts:
        if not out or p != out[-1]:
            out.append(p)
    if out[0] == out[-1]:
        out.pop()
    return np.asarray(out, dtype=np.float64)


def _area(poly: np.ndarray) -> float:
    """Signed area (shoelace; > 0 counter-clockwise)."""
    y, z = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.sum(y * np.roll(z, -1) - np.roll(y, -1) * z))


def convex_pieces(outline) -> list[np.ndarray]:
    """The region under a ground obstacle's outline (K, 2) (padded or not) as a list of convex
    counter-clockwise polygons (n, 2), left to right, checked by ``check_cover``."""
    o = check_simple(outline)
    chains = []  # index ranges [a, b] of the outline whose region is one piece
    for k in range(len(o) - 1):
        if o[k + 1, 0] == o[k, 0]:
            continue  # a vertical edge: a side of its neighbours, never merged across (a reflex corner)
        if chains and chains[-1][1] == k and _convex_ccw(region_polygon(o[chains[-1][0] : k + 2])):
            chains[-1][1] = k + 1
        else:
            chains.append([k, k + 1])
    pieces = [region_polygon(o[a : b + 1]) for a, b in chains]
    check_cover(o, pieces, chains)
    return pieces


def check_cover(o: np.ndarray, pieces, chains) -> None:
    """That ``pieces`` cover the region under the unpadded outline ``o`` exactly: each piece convex
    with positive area; their y-ranges tile the outline's; each one's top chain is the outline's
    vertices ``o[a:b+1]`` of its range; and their areas add up to the outline's. RuntimeError
    otherwise (a fault of this module, never of the input, which check_simple has passed)."""
    scale = max(float(np.abs(o).max()), 1.0)
    y_prev = o[0, 0]
    total = 0.0
    for (a, b), p in zip(chains, pieces):
        area = _area(p)
        if not area > 0.0 or not _convex_ccw(p):
            raise RuntimeError(
                f"convex_pieces: the piece over vertices {a}..{b} is not a convex polygon"
            )
        if o[a, 0] != y_prev:
            raise RuntimeError(
                f"convex_pieces: a gap or overlap before the piece over vertices {a}..{b}"
            )
        want = {tuple(v) for v in o[a : b + 1]} | {(o[a, 0], 0.0), (o[b, 0], 0.0)}
        if {tuple(v) for v in p} != want or len(p) != len(want):
            raise RuntimeError(
                f"convex_pieces: the piece over vertices {a}..{b} does not follow the outline"
            )
        y_prev = o[b, 0]
        total += area
    if y_prev != o[-1, 0]:
        raise RuntimeError("convex_pieces: the pieces end before the outline does")
    closed = _area(region_polygon(o))
    if abs(total - closed) > 1e-9 * scale * scale:
        raise RuntimeError(
            f"convex_pieces: the pieces' area {total:.12g} m^2 is not the outline's {closed:.12g} m^2"
        )
