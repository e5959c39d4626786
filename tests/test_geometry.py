"""jaxexo.physics.geometry: obstacles, exact flat-foot distance, clearance, inside test, height profile."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from jaxexo.physics import geometry
from jaxexo.physics.geometry import (
    MAX_PROFILE_VERTICES,
    THESIS_OBSTACLES,
    TOUCH_EPS,
    GeometryError,
    Obstacle,
    flat_foot_distance,
    foot_clearance,
    foot_clearance_by_edge,
    foot_collides,
    point_in_obstacle,
    profile_height,
    shape_descriptor,
)

FOOT = 0.20


def clearance(ob: Obstacle, heel, foot=FOOT) -> float:
    return float(foot_clearance(np, np.asarray(heel, dtype=np.float64), foot, ob.outline))


def distance(ob: Obstacle, heel, foot=FOOT) -> float:
    return float(flat_foot_distance(np, np.asarray(heel, dtype=np.float64), foot, ob.outline))


def inside(ob: Obstacle, p) -> bool:
    return bool(point_in_obstacle(np, np.asarray(p, dtype=np.float64), ob.outline))


# A rectangle 0.20 wide, 0.10 high, from y = 0.35 to 0.55 (Base 1 at its default centre).
RECT = Obstacle.rectangle(0.20, 0.10, center_y=0.45)
# A triangle 0.20 wide, 0.20 high: (0.35, 0) - (0.45, 0.2) - (0.55, 0).
TRI = Obstacle.triangle(0.20, 0.20, center_y=0.45)
# A half-ellipse 0.20 wide, 0.25 high (the thesis half-circle).
ELL = Obstacle.half_ellipse(0.20, 0.25, center_y=0.45)
# A two-level step given as a profile without ground end points (they are added):
# (0.30, 0) (0.30, 0.05) (0.40, 0.05) (0.40, 0.15) (0.50, 0.15) (0.50, 0).
STEP = Obstacle.profile([(0.30, 0.05), (0.40, 0.05), (0.40, 0.15), (0.50, 0.15)])


# --------------------------------------------------------------------------------------------
# Rectangle
# --------------------------------------------------------------------------------------------


def test_rectangle_outline_vertices():
    np.testing.assert_allclose(
        RECT.outline, [[0.35, 0.0], [0.35, 0.10], [0.55, 0.10], [0.55, 0.0]], atol=1e-12
    )
    assert RECT.left == pytest.approx(0.35) and RECT.right == pytest.approx(0.55)


@pytest.mark.parametrize(
    "heel, expected",
    [
        ((0.40, 0.15), 0.05),  # above the top edge
        ((0.10, 0.05), 0.05),  # toe 5 cm before the near side
        ((0.60, 0.05), 0.05),  # heel 5 cm beyond the far side
        ((0.58, 0.14), 0.05),  # heel diagonal to the far top corner (3-4-5)
        ((0.12, 0.14), 0.05),  # toe diagonal to the near top corner (3-4-5)
        ((0.00, 0.00), 0.15),  # on the ground behind: toe to the near bottom corner
        ((0.30, 0.40), 0.30),  # high above the top, overlapping it in y
    ],
)
def test_rectangle_clearance_outside(heel, expected):
    assert distance(RECT, heel) == pytest.approx(expected, abs=1e-12)
    assert clearance(RECT, heel) == pytest.approx(expected, abs=1e-12)
    assert not inside(RECT, heel)
    assert not bool(foot_collides(np, clearance(RECT, heel)))


@pytest.mark.parametrize(
    "heel",
    [
        (0.40, 0.10),  # lying on the top edge
        (0.15, 0.10),  # toe exactly on the near top corner
        (0.55, 0.05),  # heel on the far side
        (0.15, 0.00),  # toe touching the near bottom corner on the ground
    ],
)
def test_rectangle_touching_is_collision(heel):
    assert distance(RECT, heel) == pytest.approx(0.0, abs=1e-12)
    assert clearance(RECT, heel) <= TOUCH_EPS
    assert bool(foot_collides(np, clearance(RECT, heel)))


def test_rectangle_crossing_an_edge():
    # Heel outside, toe inside: the foot crosses the near side at y = 0.35.
    heel = (0.30, 0.05)
    assert not inside(RECT, heel)
    assert distance(RECT, heel) == 0.0
    assert clearance(RECT, heel) == 0.0
    assert bool(foot_collides(np, clearance(RECT, heel)))
    # Crossing both sides (foot longer than the obstacle) with both ends outside.
    assert distance(RECT, (0.30, 0.05), foot=0.40) == 0.0


def test_rectangle_fully_inside_gives_negative_clearance():
    # A 10 cm foot buried in the rectangle: 4 cm under the top, 5 cm from each side.
    c = clearance(RECT, (0.40, 0.06), foot=0.10)
    assert c == pytest.approx(-0.04, abs=1e-12)
    assert bool(foot_collides(np, c))
    # A wide rectangle and the full 20 cm foot: 5 cm under the top.
    wide = Obstacle.rectangle(1.0, 0.20, center_y=0.5)
    assert clearance(wide, (0.30, 0.15)) == pytest.approx(-0.05, abs=1e-12)


def test_clearance_method_matches_function():
    heels = np.array([[0.40, 0.15], [0.30, 0.05], [0.40, 0.06]])
    np.testing.assert_allclose(
        RECT.clearance(heels, FOOT), foot_clearance(np, heels, FOOT, RECT.outline)
    )


def test_foot_collides_threshold():
    c = np.array([-0.1, 0.0, TOUCH_EPS, 2 * TOUCH_EPS, 0.05])
    np.testing.assert_array_equal(foot_collides(np, c), [True, True, True, False, False])


# --------------------------------------------------------------------------------------------
# Triangle
# --------------------------------------------------------------------------------------------


def test_triangle_above_apex():
    assert clearance(TRI, (0.40, 0.25)) == pytest.approx(0.05, abs=1e-12)


def test_triangle_beside_slope():
    # Toe 5 cm out from the near slope, along its outward normal (-2, 1)/sqrt(5) from (0.40, 0.10).
    n = np.array([-2.0, 1.0]) / math.sqrt(5.0)
    toe = np.array([0.40, 0.10]) + 0.05 * n
    heel = toe - [FOOT, 0.0]
    assert clearance(TRI, heel) == pytest.approx(0.05, abs=1e-12)


def test_triangle_crossing_slope():
    # At z = 0.1 the triangle spans y in [0.40, 0.50]; the foot [0.30, 0.50] enters it.
    assert clearance(TRI, (0.30, 0.10)) == 0.0


def test_triangle_fully_inside():
    # A 2 cm foot at z = 0.05 centred under the apex: distance to each slope is 0.13/sqrt(5).
    c = clearance(TRI, (0.44, 0.05), foot=0.02)
    assert c == pytest.approx(-0.13 / math.sqrt(5.0), abs=1e-12)
    assert bool(foot_collides(np, c))


# --------------------------------------------------------------------------------------------
# Half-ellipse
# --------------------------------------------------------------------------------------------


def test_half_ellipse_outline_is_inscribed_polygon():
    o = ELL.outline
    assert o.shape == (geometry.HALF_ELLIPSE_VERTICES, 2)
    np.testing.assert_allclose(o[0], [0.35, 0.0], atol=1e-12)
    np.testing.assert_allclose(o[-1], [0.55, 0.0], atol=1e-12)
    # Every vertex on the ellipse ((y - c) / a)^2 + (z / b)^2 = 1.
    r = ((o[:, 0] - 0.45) / 0.10) ** 2 + (o[:, 1] / 0.25) ** 2
    np.testing.assert_allclose(r, 1.0, atol=1e-12)
    # Within 1.5 mm of the true curve and inside it (docs/training.md): edge midpoints.
    t = np.linspace(0.0, np.pi, 20001)
    curve = np.column_stack([0.45 + 0.10 * np.cos(t), 0.25 * np.sin(t)])
    mids = 0.5 * (o[1:] + o[:-1])
    dev = np.min(np.linalg.norm(mids[:, None, :] - curve[None], axis=-1), axis=-1)
    assert dev.max() < 1.5e-3
    assert np.all(((mids[:, 0] - 0.45) / 0.10) ** 2 + (mids[:, 1] / 0.25) ** 2 <= 1.0)


def test_half_ellipse_above_top():
    # The top edge of the 16-gon joins the vertices at 7pi/15 and 8pi/15: horizontal at 0.25 sin(7pi/15).
    top = 0.25 * math.sin(7 * math.pi / 15)
    assert clearance(ELL, (0.40, 0.30)) == pytest.approx(0.30 - top, abs=1e-12)


def test_half_ellipse_beside_and_inside():
    # On the ground behind: toe at 0.20, nearest the left foot vertex (0.35, 0).
    assert clearance(ELL, (0.0, 0.0)) == pytest.approx(0.15, abs=1e-12)
    # A short foot buried under the top: negative, and exactly minus the distance.
    c = clearance(ELL, (0.43, 0.10), foot=0.04)
    assert c < -0.05
    assert c == pytest.approx(-distance(ELL, (0.43, 0.10), foot=0.04))
    assert inside(ELL, (0.43, 0.10))
    # Crossing the curved side.
    assert clearance(ELL, (0.25, 0.10)) == 0.0


# --------------------------------------------------------------------------------------------
# Profile (a two-level step with a vertical riser inside)
# --------------------------------------------------------------------------------------------


def test_profile_adds_ground_end_points():
    np.testing.assert_allclose(
        STEP.outline,
        [[0.30, 0.0], [0.30, 0.05], [0.40, 0.05], [0.40, 0.15], [0.50, 0.15], [0.50, 0.0]],
        atol=1e-12,
    )
    assert STEP.kind == "profile" and STEP.shape == "profile"
    assert STEP.width == pytest.approx(0.20) and STEP.height == pytest.approx(0.15)
    assert STEP.center_y == pytest.approx(0.40)


@pytest.mark.parametrize(
    "heel, foot, expected",
    [
        ((0.05, 0.10), FOOT, math.hypot(0.05, 0.05)),  # toe diagonal to the low step's corner
        ((0.12, 0.08), FOOT, 0.03),  # toe above the low step
        ((0.42, 0.20), FOOT, 0.05),  # above the high part
        ((0.31, 0.02), 0.05, -0.01),  # buried: 1 cm from the near wall
        ((0.25, 0.10), FOOT, 0.0),  # crossing the interior riser at y = 0.40
        ((0.20, 0.15), FOOT, 0.0),  # lying on the high top's level, toe on its corner
    ],
)
def test_profile_clearance(heel, foot, expected):
    assert clearance(STEP, heel, foot) == pytest.approx(expected, abs=1e-12)


def test_profile_collision_flags():
    c = np.array([clearance(STEP, h) for h in [(0.25, 0.10), (0.42, 0.20), (0.20, 0.15)]])
    np.testing.assert_array_equal(foot_collides(np, c), [True, False, True])


# --------------------------------------------------------------------------------------------
# point_in_obstacle
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "ob, p, expected",
    [
        (RECT, (0.45, 0.05), True),
        (RECT, (0.45, 0.00), True),  # on the ground under the obstacle
        (RECT, (0.45, 0.11), False),  # above
        (RECT, (0.30, 0.05), False),  # before
        (RECT, (0.60, 0.05), False),  # after
        (RECT, (0.00, 0.00), False),  # on the ground behind
        (RECT, (0.45, -0.01), False),  # below the ground
        (TRI, (0.45, 0.19), True),
        (TRI, (0.38, 0.10), False),  # left of the slope (slope at y = 0.40 there)
        (TRI, (0.42, 0.10), True),
        (ELL, (0.45, 0.24), True),
        (ELL, (0.54, 0.20), False),  # outside the curve near the far foot
        (STEP, (0.35, 0.04), True),
        (STEP, (0.35, 0.10), False),  # above the low step, below the high one's level
        (STEP, (0.45, 0.10), True),
        (STEP, (0.55, 0.10), False),
    ],
)
def test_point_in_obstacle(ob, p, expected):
    assert inside(ob, p) is expected


def test_point_in_obstacle_two_bumps():
    # A profile with a ground gap between two bumps: the gap is outside.
    two = Obstacle.profile(
        [
            (0.0, 0.0),
            (0.0, 0.1),
            (0.1, 0.1),
            (0.1, 0.0),
            (0.2, 0.0),
            (0.2, 0.1),
            (0.3, 0.1),
            (0.3, 0.0),
        ]
    )
    pts = np.array([[0.05, 0.05], [0.15, 0.05], [0.25, 0.05], [0.15, 0.0]])
    np.testing.assert_array_equal(
        point_in_obstacle(np, pts, two.outline), [True, False, True, False]
    )


# --------------------------------------------------------------------------------------------
# profile_height and shape_descriptor
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "ob, y, expected",
    [
        (RECT, 0.45, 0.10),
        (RECT, 0.35, 0.10),  # on the vertical side: the higher end counts
        (RECT, 0.55, 0.10),
        (RECT, 0.20, 0.0),
        (RECT, 0.70, 0.0),
        (TRI, 0.45, 0.20),
        (TRI, 0.40, 0.10),
        (TRI, 0.525, 0.05),
        (STEP, 0.30, 0.05),  # near wall: vertical edge 0 .. 0.05
        (STEP, 0.35, 0.05),
        (STEP, 0.40, 0.15),  # interior riser 0.05 .. 0.15: the higher end
        (STEP, 0.45, 0.15),
        (STEP, 0.50, 0.15),
        (STEP, 0.51, 0.0),
    ],
)
def test_profile_height(ob, y, expected):
    assert float(profile_height(np, np.asarray(y), ob.outline)) == pytest.approx(
        expected, abs=1e-12
    )


def test_profile_height_vectorised_and_padded():
    ys = np.array([0.2, 0.35, 0.45, 0.55, 0.7])
    padded = RECT.outline_array(16)
    np.testing.assert_allclose(
        profile_height(np, ys, padded), [0.0, 0.1, 0.1, 0.1, 0.0], atol=1e-12
    )


def test_shape_descriptor_rectangle_and_triangle():
    np.testing.assert_allclose(
        shape_descriptor(geometry.unit_profile("rectangle")), np.ones(9), atol=1e-12
    )
    tri = shape_descriptor(geometry.unit_profile("triangle"))
    np.testing.assert_allclose(tri, [0, 0.25, 0.5, 0.75, 1.0, 0.75, 0.5, 0.25, 0], atol=1e-5)
    assert len(shape_descriptor(geometry.unit_profile("rectangle"), 5)) == 5


def test_shape_descriptor_half_ellipse_under_true_curve():
    d = shape_descriptor(geometry.unit_profile("half_ellipse"), 11)
    u = np.clip(np.linspace(-0.5, 0.5, 11), -0.5 + 1e-6, 0.5 - 1e-6)
    true = np.sqrt(1.0 - (2.0 * u) ** 2)
    assert np.all(d <= true + 1e-12)
    assert np.all(d[1:-1] >= true[1:-1] - 0.03)
    assert d[5] == pytest.approx(math.sin(7 * math.pi / 15), abs=1e-12)


def test_shape_descriptor_padding_invariant():
    unit = geometry.unit_profile("triangle")
    np.testing.assert_allclose(
        shape_descriptor(unit), shape_descriptor(geometry.pad_outline(unit, 16))
    )


# --------------------------------------------------------------------------------------------
# Constructors and their errors
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kind, shape, width, height",
    [
        ("base1", "rectangle", 0.20, 0.10),
        ("base2", "rectangle", 0.10, 0.15),
        ("base3", "rectangle", 0.05, 0.20),
        ("triangle", "triangle", 0.20, 0.20),
        ("half_circle", "half_ellipse", 0.20, 0.25),
    ],
)
def test_named_obstacles_have_thesis_sizes(kind, shape, width, height):
    ob = Obstacle.named(kind)
    assert (ob.kind, ob.shape) == (kind, shape)
    assert ob.width == pytest.approx(width) and ob.height == pytest.approx(height)
    assert ob.center_y == pytest.approx(0.45)
    # The half-ellipse is an inscribed 16-gon (no vertex at the apex): within 1.5 mm below.
    assert height - 1.5e-3 <= ob.outline[:, 1].max() <= height + 1e-12
    assert np.ptp(ob.outline[:, 0]) == pytest.approx(width)
    assert ob.outline[0, 1] == 0.0 and ob.outline[-1, 1] == 0.0
    assert THESIS_OBSTACLES[kind] == (shape, width, height)


def test_named_center():
    assert Obstacle.named("base2", center_y=0.5).left == pytest.approx(0.45)


def test_outline_array_padding():
    arr = TRI.outline_array(6)
    assert arr.shape == (6, 2)
    np.testing.assert_allclose(arr[:3], TRI.outline)
    np.testing.assert_allclose(arr[3:], np.repeat(TRI.outline[-1:], 3, axis=0))
    # Padding changes neither the distance nor the inside test.
    heels = np.array([[0.40, 0.25], [0.30, 0.10], [0.44, 0.05]])
    np.testing.assert_allclose(
        foot_clearance(np, heels, 0.02, arr), foot_clearance(np, heels, 0.02, TRI.outline)
    )
    with pytest.raises(GeometryError, match="max_vertices"):
        TRI.outline_array(2)


@pytest.mark.parametrize("ctor", [Obstacle.rectangle, Obstacle.triangle, Obstacle.half_ellipse])
@pytest.mark.parametrize(
    "width, height, field",
    [
        (0.0, 0.1, "width"),
        (-0.1, 0.1, "width"),
        (float("nan"), 0.1, "width"),
        (float("inf"), 0.1, "width"),
        ("wide", 0.1, "width"),
        (0.1, 0.0, "height"),
        (0.1, -0.2, "height"),
        (0.1, float("nan"), "height"),
        (0.1, float("-inf"), "height"),
    ],
)
def test_constructor_errors_name_field(ctor, width, height, field):
    with pytest.raises(GeometryError, match=rf"^{field}\b"):
        ctor(width, height)


def test_center_y_must_be_finite():
    with pytest.raises(GeometryError, match=r"^center_y"):
        Obstacle.rectangle(0.1, 0.1, center_y=float("nan"))


def test_named_unknown_kind():
    with pytest.raises(GeometryError, match=r"^kind"):
        Obstacle.named("hexagon")


def test_unit_profile_unknown_shape():
    with pytest.raises(GeometryError, match=r"^shape"):
        geometry.unit_profile("profile")


@pytest.mark.parametrize(
    "points, message",
    [
        ([(0.1, 0.1), (0.0, 0.1)], "non-decreasing"),  # non-monotone y
        ([(0.0, 0.1), (0.1, -0.01)], r"z >= 0"),  # negative z
        ([(0.0, float("nan")), (0.1, 0.1)], "finite"),
        ([(0.0, 0.1), (float("inf"), 0.1)], "finite"),
        ([(0.0, 0.1)], "shape"),  # a single point
        ([0.0, 0.1, 0.2], "shape"),  # not pairs
        ([(0.0, 0.0), (0.1, 0.0)], "height"),  # flat: zero height
        ([(0.1, 0.0), (0.1, 0.1), (0.1, 0.0)], "width"),  # zero width
        ([(0.01 * i, 0.1) for i in range(MAX_PROFILE_VERTICES - 1)], "at most"),  # too many points
        ("not points", ""),
    ],
)
def test_profile_errors_name_points(points, message):
    with pytest.raises(GeometryError, match=rf"^points.*{message}"):
        Obstacle.profile(points)


def test_profile_max_points_accepted():
    pts = [(0.01 * i, 0.1) for i in range(MAX_PROFILE_VERTICES - 2)]
    ob = Obstacle.profile(pts)
    assert len(ob.outline) == MAX_PROFILE_VERTICES  # two ground points added
    assert ob.outline_array(MAX_PROFILE_VERTICES).shape == (MAX_PROFILE_VERTICES, 2)


# --------------------------------------------------------------------------------------------
# Property: exact distance vs a brute-force reference
# --------------------------------------------------------------------------------------------

N_SAMPLES = 2001  # points on the foot for the brute force


def _point_segment_distance(p, a, b):
    """Exact distances from points p (N, 2) to segments a-b (E, 2) -> (N, E)."""
    ab = b - a
    l2 = np.sum(ab * ab, axis=-1)
    ap = p[:, None, :] - a[None]
    t = np.where(l2 > 0, np.sum(ap * ab, axis=-1) / np.where(l2 > 0, l2, 1.0), 0.0)
    t = np.clip(t, 0.0, 1.0)
    d = ap - t[..., None] * ab
    return np.sqrt(np.sum(d * d, axis=-1))


def _segments_cross(p0, p1, a, b):
    """Whether segment p0-p1 intersects any segment a-b (closed segments, orientation test)."""

    def orient(o, q, r):
        return (q[..., 0] - o[..., 0]) * (r[..., 1] - o[..., 1]) - (q[..., 1] - o[..., 1]) * (
            r[..., 0] - o[..., 0]
        )

    # Signs, not products (a product of two tiny orientations underflows to 0).
    d1 = np.sign(orient(a, b, p0))
    d2 = np.sign(orient(a, b, p1))
    d3 = np.sign(orient(p0, p1, a))
    d4 = np.sign(orient(p0, p1, b))
    general = (d1 * d2 <= 0) & (d3 * d4 <= 0) & ~((d1 == 0) & (d2 == 0))
    # Collinear: the projections on the foot's line (y, the foot is horizontal) must overlap.
    collinear = (
        (d1 == 0)
        & (d2 == 0)
        & (np.maximum(a[:, 0], b[:, 0]) >= p0[0])
        & (np.minimum(a[:, 0], b[:, 0]) <= p1[0])
    )
    return bool(np.any((general | collinear) & (np.sum((b - a) ** 2, axis=-1) > 0)))


def brute_force_distance(heel, foot, outline):
    heel = np.asarray(heel, dtype=np.float64)
    toe = heel + [foot, 0.0]
    a, b = outline[:-1], outline[1:]
    if _segments_cross(heel, toe, a, b):
        return 0.0
    s = np.linspace(0.0, 1.0, N_SAMPLES)[:, None]
    pts = heel + s * (toe - heel)
    return float(_point_segment_distance(pts, a, b).min())


def _random_obstacle(draw):
    shape = draw(st.sampled_from(["rectangle", "triangle", "half_ellipse", "profile", "named"]))
    if shape == "named":
        return Obstacle.named(
            draw(st.sampled_from(sorted(THESIS_OBSTACLES))), center_y=draw(st.floats(0.3, 0.6))
        )
    if shape == "profile":
        n = draw(st.integers(2, 8))
        # Millimetre-rounded points (no sub-nanometre edges, whose 1/len^2 overflows).
        ys = sorted(
            round(y, 3) for y in draw(st.lists(st.floats(0.2, 0.7), min_size=n, max_size=n))
        )
        zs = [round(z, 3) for z in draw(st.lists(st.floats(0.0, 0.3), min_size=n, max_size=n))]
        assume(ys[-1] - ys[0] > 1e-3 and max(zs) > 1e-3)
        return Obstacle.profile(list(zip(ys, zs)))
    w = draw(st.floats(0.02, 0.4))
    h = draw(st.floats(0.02, 0.4))
    c = draw(st.floats(0.3, 0.6))
    return getattr(Obstacle, shape)(w, h, center_y=c)


@st.composite
def scenes(draw):
    ob = _random_obstacle(draw)
    heel = (draw(st.floats(-0.2, 1.0)), draw(st.floats(0.0, 0.5)))
    foot = draw(st.floats(0.01, 0.35))
    return ob, heel, foot


@given(scenes())
def test_flat_foot_distance_matches_brute_force(scene):
    ob, heel, foot = scene
    exact = distance(ob, heel, foot)
    bf = brute_force_distance(heel, foot, ob.outline)
    spacing = foot / (N_SAMPLES - 1)
    assert exact >= 0.0
    assert exact <= bf + 1e-9
    assert bf <= exact + spacing + 1e-9
    # Clearance sign: negative only when the heel is inside, and then it is minus the distance.
    c = clearance(ob, heel, foot)
    if inside(ob, heel):
        assert c == pytest.approx(-exact, abs=1e-15)
    else:
        assert c == pytest.approx(exact, abs=1e-15)
    # the term-by-term form JAX uses: the same terms, the same value
    by_edge = foot_clearance_by_edge(
        np, np.asarray(heel, np.float64), foot, ob.outline[:, 0], ob.outline[:, 1]
    )
    assert float(by_edge) == c
    # Collision iff touching/inside: any foot sample strictly inside the region collides.
    s = np.linspace(0.0, 1.0, 51)[:, None]
    pts = np.asarray(heel) + s * np.array([foot, 0.0])
    if np.any(point_in_obstacle(np, pts, ob.outline)):
        assert bool(foot_collides(np, c))


@given(
    st.floats(0.02, 0.4),
    st.floats(0.02, 0.4),
    st.floats(0.3, 0.6),
    st.floats(-0.2, 1.0),
    st.floats(-0.05, 0.5),
)
def test_point_in_rectangle_and_triangle_analytic(w, h, c, y, z):
    rect = Obstacle.rectangle(w, h, center_y=c)
    tri = Obstacle.triangle(w, h, center_y=c)
    # Stay away from the boundaries, where the answer is a matter of convention.
    margin = 1e-9
    in_rect = (c - w / 2 + margin < y < c + w / 2 - margin) and (0 <= z < h - margin)
    out_rect = y < c - w / 2 - margin or y > c + w / 2 + margin or z > h + margin or z < 0
    if in_rect:
        assert inside(rect, (y, z))
    if out_rect:
        assert not inside(rect, (y, z))
    tri_h = h * max(0.0, 1.0 - 2.0 * abs(y - c) / w)
    if 0 <= z < tri_h - 1e-9:
        assert inside(tri, (y, z))
    if z > tri_h + 1e-9 or z < 0:
        assert not inside(tri, (y, z))
    assert float(profile_height(np, np.asarray(y), tri.outline)) == pytest.approx(tri_h, abs=1e-9)


# --------------------------------------------------------------------------------------------
# NumPy (float64) vs jax.numpy (float32) on the same inputs
# --------------------------------------------------------------------------------------------


def _numpy_vs_jax_inputs():
    obstacles = [RECT, TRI, ELL, STEP, Obstacle.named("base3"), Obstacle.named("half_circle")]
    K = 16
    outlines = np.stack([ob.outline_array(K) for ob in obstacles])
    # A grid of heels offset so that no heel lies exactly on an outline.
    ys = np.linspace(-0.1, 0.8, 37) + 0.00123
    zs = np.linspace(0.0, 0.35, 15) + 0.00071
    heels = np.stack(np.meshgrid(ys, zs, indexing="ij"), axis=-1).reshape(-1, 2)
    return outlines, heels


def test_numpy_and_jax_agree():
    jnp = pytest.importorskip("jax.numpy")
    outlines, heels = _numpy_vs_jax_inputs()
    # (N, 1, 2) heels against (1, B, K, 2) outlines: every heel against every obstacle.
    h = heels[:, None, :]
    o = outlines[None]
    hj = jnp.asarray(h, dtype=jnp.float32)
    oj = jnp.asarray(o, dtype=jnp.float32)
    for foot in (0.05, 0.2):
        d_np = flat_foot_distance(np, np.broadcast_to(h, (len(heels), len(outlines), 2)), foot, o)
        d_j = flat_foot_distance(
            jnp, jnp.broadcast_to(hj, (len(heels), len(outlines), 2)), foot, oj
        )
        assert d_np.shape == d_j.shape == (len(heels), len(outlines))
        np.testing.assert_allclose(np.asarray(d_j), d_np, atol=1e-5)
        c_np = foot_clearance(np, np.broadcast_to(h, d_np.shape + (2,)), foot, o)
        c_j = foot_clearance(jnp, jnp.broadcast_to(hj, d_np.shape + (2,)), foot, oj)
        np.testing.assert_allclose(np.asarray(c_j), c_np, atol=1e-5)
        np.testing.assert_array_equal(np.asarray(foot_collides(jnp, c_j)), foot_collides(np, c_np))
    in_np = point_in_obstacle(np, np.broadcast_to(h, d_np.shape + (2,)), o)
    in_j = point_in_obstacle(jnp, jnp.broadcast_to(hj, d_np.shape + (2,)), oj)
    np.testing.assert_array_equal(np.asarray(in_j), in_np)
    assert in_np.any() and (~in_np).any()
    ys = np.linspace(-0.1, 0.8, 91) + 0.00123
    ph_np = profile_height(
        np, np.broadcast_to(ys[:, None], (len(ys), len(outlines))), outlines[None]
    )
    ph_j = profile_height(
        jnp, jnp.broadcast_to(jnp.asarray(ys, jnp.float32)[:, None], ph_np.shape), oj
    )
    np.testing.assert_allclose(np.asarray(ph_j), ph_np, atol=1e-5)
    assert ph_np.max() == pytest.approx(0.25, abs=1e-2)
