"""The shield's scalar form, ``make_shield("scalar", ...)`` (jaxexo.shield): one heel at a time in
Python floats, checking only the move that will be taken; the NumPy generator's per-step choice.

It decides as the rows form's float32 mask (jaxexo.shield.rows): the rule's own pieces
(``rule.end_conditions``, ``transition.keep_in_world``, kinematics' limits, ``rule.clearance_need``)
on the float32 heel in Python floats, each comparison exact or certified against float32's
rounding, and the full mask on the steps too close to call. The per-move pieces (the end
conditions, keep_in_world's clip, the joint-limit tests) are inlined with the same operations, a
function call costing more than their arithmetic; tests/test_fast_rollout.py holds them to the
rule's and kinematics' functions.
Method: docs/generation.md#speed.
"""

from __future__ import annotations

import dataclasses
import math
import struct

import numpy as np

from jaxexo.physics import actions, kinematics, transition
from jaxexo.physics.scene import stack_scenes
from jaxexo.physics.transition import scalar
from jaxexo.shield import rule
from jaxexo.shield.rows import ShieldRows, ShieldStats, take_rows

# m: a float64 length decides a float32 comparison only when it is at least this far from the
# threshold. float32 rounding of the clearance geometry on coordinates of order 1 m is a few 1e-7 m.
MARGIN = 1e-5
# m: the same for a leg's length (float32 rounding of |hip - heel| is a few 1e-7 m; the stance leg is
# always one leg length long, 1e-5 m (kinematics.LENGTH_EPS) inside its threshold).
LENGTH_MARGIN = 2e-6
# rad: the same for an angle whose legs are well conditioned (added to the per-leg bound).
ANGLE_MARGIN = 1e-5
# (m^2) bound on float32's error in thigh^2 - a^2 (knee_position); its square root bounds the
# error in the knee's offset h where h is near 0 (a straight leg).
_G_ERR = 4e-6
_SQRT_G_ERR = math.sqrt(_G_ERR)
_H_SMALL = _G_ERR / (2.0 * _SQRT_G_ERR)  # below this h, sqrt(|dg|) is the smaller bound
_TWO_PI = 2.0 * math.pi
# Orientation products closer to 0 than this (m^2) are treated as undecidable (float32 sign noise).
_ORIENT_TOL = 1e-9
# m: the same for a heel's distance to the goal box's sides (float32 rounding of a difference of
# coordinates below 2 m is at most 1.2e-7 m).
END_MARGIN = 1e-6


def goal_tolerance_moved(sp, by: float):
    """``sp`` with the goal box's half width (goal_tolerance[0]) widened by ``by`` (m; negative:
    narrowed): the rule's end conditions on float64 values, with it moved by END_MARGIN either way,
    bound their float32 decision (the other comparisons they make are exact on float32 values)."""
    tol = sp.goal_tolerance
    return dataclasses.replace(sp, goal_tolerance=(tol[0] + by, *tol[1:]))


_F32 = struct.Struct("f")
_pack, _unpack = _F32.pack, _F32.unpack


def _f32(x: float) -> float:
    """x rounded to float32 (to nearest, as NumPy's float32 arithmetic rounds each result)."""
    return _unpack(_pack(x))[0]


class _Heel:
    """One step's heel rounded to float32 (y, z), whether it is far from the obstacle's box, and its
    clearance and the swept distance a move must keep (computed on first need)."""

    __slots__ = ("y", "z", "far", "c_here", "need")


def _nearest2(points, cy, cz, ey, ez, inv, best):
    """The smallest of ``best`` and the squared distances (m^2) from ``points`` ((y, z) pairs) to the
    segment (cy, cz) + t (ey, ez), t in [0, 1], with inv = 1 / |e|^2: geometry's point-edge distance in
    Python floats (the shield's hot loop; NumPy calls would cost more than the arithmetic)."""
    for py, pz in points:
        apy, apz = py - cy, pz - cz
        t = (apy * ey + apz * ez) * inv
        t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
        dy, dz = apy - t * ey, apz - t * ez
        d = dy * dy + dz * dz
        if d < best:
            best = d
    return best


class ScalarShield:
    """The scalar form: one heel at a time, each row's scene as a ``SwingShield``, for parameters
    ``p`` (jaxexo.config.numpy_params) and ``sp`` (jaxexo.config.scalar_params); ``stats``
    (ShieldStats; None: a fresh one) counts the steps ``choose`` decides and those it hands to the
    full mask (the rows form, ``reference``)."""

    kind = "scalar"

    def __init__(self, p, sp, stats=None):
        self.p, self.sp = p, sp
        # the rule's end conditions certainly true / certainly false (``goal_tolerance_moved``)
        self.ends_in = goal_tolerance_moved(sp, -END_MARGIN)
        self.ends_out = goal_tolerance_moved(sp, END_MARGIN)
        self.stats = ShieldStats() if stats is None else stats
        self.reference = ShieldRows(p, sp, self.stats)

    def swing(self, scene, layout=None) -> "SwingShield":
        """One swing's choice in ``scene`` (a Scene, or any object with its outline, pivot_y and
        goal_y); ``layout``: the scene stacked as one float32 row (None: stacked here)."""
        return SwingShield(self.sp, self.p, scene, self, layout)

    def _rows(self, layout, last_action):
        n = len(layout.goal_y)
        last = np.full(n, -1, np.int64) if last_action is None else np.asarray(last_action)
        for i in range(n):
            row = take_rows(layout, i)
            yield i, self.swing(row, take_rows(layout, [i])), int(last[i])

    def admissible(self, hy, hz, layout, last_action=None) -> np.ndarray:
        """(B, A): the rows form's mask, each row decided move by move in Python floats
        (``SwingShield.mask``), the rows' full mask where a move is too close to call."""
        if not bool(self.p.shield):
            return np.ones((len(hy), actions.NUM_ACTIONS), bool)
        out = np.zeros((len(hy), actions.NUM_ACTIONS), bool)
        for i, one, last in self._rows(layout, last_action):
            out[i] = one.mask(float(hy[i]), float(hz[i]), last)
        return out

    def choose(self, hy, hz, layout, q, last_action=None) -> np.ndarray:
        """(B,) the shielded greedy actions, one heel at a time (``SwingShield.choose``)."""
        if not bool(self.p.shield):
            return actions.greedy_action(np, q)
        out = np.zeros(len(hy), np.int64)
        for i, one, last in self._rows(layout, last_action):
            out[i] = one.choose(float(hy[i]), float(hz[i]), q[i], last)
        return out


class SwingShield:
    """Per-scene constants (Python floats, the float32 values the reference uses), ``certain`` (the
    greedy move where every comparison it needs is certain) and ``choose`` (else the full mask's)."""

    def __init__(self, sp, np_params, scene, form: ScalarShield | None = None, layout=None):
        self.form = ScalarShield(np_params, sp) if form is None else form
        self.scene, self._layout, self.sp = scene, layout, sp
        self.goal = float(np.float32(scene.goal_y))
        # transition.move_heel's step (step_size * direction) in float32, as the rows form's
        self.offsets = (np_params.step_size * np_params.directions).astype(np.float32).tolist()
        self.fwd_idx = rule.FORWARD.tolist()
        self.fl, self.step, self.shield_c = sp.foot_length, sp.step_size, sp.shield_clearance
        self.t, self.s = sp.thigh, sp.shin
        self.leg = float(np.float32(sp.thigh) + np.float32(sp.shin))  # hip_position's, in float32
        self.min_hz2 = (kinematics.MIN_HIP_HEIGHT_FRACTION * self.leg) ** 2
        # a near-straight knee (angle <= 1e-5 rad up to rounding) cannot exceed this upper limit
        self.knee_hi_free = sp.knee_limits[1] + kinematics.ANGLE_EPS >= 1e-5
        self.limits = (*sp.hip_limits, *sp.knee_limits)
        self.pivot = float(np.float32(scene.pivot_y))
        # ``_admissible``'s inlined rule pieces (keep_in_world's clip, end_conditions with the goal
        # box moved by END_MARGIN either way): their constants, each sum computed as the rule does
        f = self.form
        self._world = (sp.bounds_y[0], sp.bounds_y[1], sp.max_z_world)
        self._floor = sp.floor_clearance
        self._tol_in, self._tol_out = f.ends_in.goal_tolerance[0], f.ends_out.goal_tolerance[0]
        self._far_in, self._far_out = self.goal + self._tol_in, self.goal + self._tol_out
        ol = np.asarray(scene.outline, np.float32).astype(np.float64)
        self.vy, self.vz = ol[:, 0].tolist(), ol[:, 1].tolist()
        self.box = (min(self.vy), max(self.vy), min(min(self.vz), 0.0), max(self.vz))
        edges = []
        for i in range(len(ol) - 1):
            cy, cz = self.vy[i], self.vz[i]
            ey, ez = self.vy[i + 1] - cy, self.vz[i + 1] - cz
            len2 = ey * ey + ez * ez
            if len2 > 1e-24:  # padding (repeated vertices): their distances are the vertices'
                ys, zs = sorted((cy, cy + ey)), sorted((cz, cz + ez))
                edges.append((cy, cz, ey, ez, 1.0 / len2, *ys, *zs))
        self.edges = edges
        self.pairs = [
            (self.vy[i], self.vz[i], self.vy[i + 1], self.vz[i + 1]) for i in range(len(ol) - 1)
        ]
        self.unsure = 0  # steps handed to the reference (diagnostics)

    # Geometry (float64 on float32 inputs) -------------------------------------------------------
    def _box_distance(self, y0, y1, z0, z1):
        """Distance between the box [y0, y1] x [z0, z1] and the obstacle's bounding box (which holds the
        outline and the region under it)."""
        by0, by1, bz0, bz1 = self.box
        dy = max(by0 - y1, y0 - by1, 0.0)
        dz = max(bz0 - z1, z0 - bz1, 0.0)
        return math.sqrt(dy * dy + dz * dz)

    def foot_distance(self, y0, z):
        """geometry.flat_foot_distance of the foot at heel (y0, z): 0 when crossing."""
        y1 = y0 + self.fl
        best = math.inf
        ends = ((y0, z), (y1, z))
        for cy, cz, ey, ez, inv, *_ in self.edges:
            best = _nearest2(ends, cy, cz, ey, ez, inv, best)
        for vy, vz in zip(self.vy, self.vz):
            gap = max(y0 - vy, vy - y1, 0.0)
            d = gap * gap + (vz - z) * (vz - z)
            if d < best:
                best = d
        for ay, az, by, bz in self.pairs:
            sa, sb = az - z, bz - z
            if sa * sb < 0.0:
                yc = ay + sa / (sa - sb) * (by - ay)
                if y0 <= yc <= y1:
                    return 0.0
        return math.sqrt(best)

    def inside(self, py, pz):
        """geometry.point_in_obstacle."""
        odd = False
        for ay, az, by, bz in self.pairs:
            if (az > pz) != (bz > pz):
                dz = bz - az
                if py < ay + (pz - az) * (by - ay) / (1.0 if dz == 0.0 else dz):
                    odd = not odd
        return odd and pz >= 0.0

    def swept_vs(self, y0, z0, dy, dz, lo, hi):
        """Compare swept.swept_distance of the move (y0, z0) -> (y0 + dy, z0 + dz) with the band
        [lo, hi]: -1 if certainly below lo, +1 if certainly at least hi, 0 otherwise."""
        f = self.fl
        y1, z1 = y0 + dy, z0 + dz
        py0, py1 = (y0, y1 + f) if dy >= 0.0 else (y1, y0 + f)
        pz0, pz1 = (z0, z1) if dz >= 0.0 else (z1, z0)
        hi2 = hi * hi
        # Only the outline edges whose bounding box comes within hi of P's bounding box can matter
        # (edges further away, and their vertices, are at least hi from P).
        near = []
        for e in self.edges:
            ey0, ey1, ez0, ez1 = e[5], e[6], e[7], e[8]
            gy = ey0 - py1 if ey0 > py1 else (py0 - ey1 if py0 > ey1 else 0.0)
            gz = ez0 - pz1 if ez0 > pz1 else (pz0 - ez1 if pz0 > ez1 else 0.0)
            if gy * gy + gz * gz < hi2:
                near.append(e)
        if not near:
            return 1
        lo2 = lo * lo if lo > 0.0 else -1.0
        best = math.inf
        corners = ((y0, z0), (y0 + f, z0), (y1, z1), (y1 + f, z1))
        len2 = dy * dy + dz * dz
        iu = 1.0 / len2 if len2 > 1e-24 else 0.0
        i_f = 1.0 / (f * f)
        # P's sides a -> a + u with 1 / |u|^2: the foot at both ends, the heel's and the toe's chords
        sides = (
            (y0, z0, f, 0.0, i_f),
            (y1, z1, f, 0.0, i_f),
            (y0, z0, dy, dz, iu),
            (y0 + f, z0, dy, dz, iu),
        )
        verts = set()
        for cy, cz, ey, ez, inv, *_ in near:
            verts.add((cy, cz))
            verts.add((cy + ey, cz + ez))
            best = _nearest2(corners, cy, cz, ey, ez, inv, best)  # P's corners against the edge
            for ay, az, uy, uz, _ in sides:  # proper crossings of P's sides and the edge
                o1 = uy * (cz - az) - uz * (cy - ay)
                o2 = uy * (cz + ez - az) - uz * (cy + ey - ay)
                o3 = ey * (az - cz) - ez * (ay - cy)
                o4 = ey * (az + uz - cz) - ez * (ay + uy - cy)
                if (abs(o1) < _ORIENT_TOL or abs(o2) < _ORIENT_TOL) and (
                    abs(o3) < _ORIENT_TOL or abs(o4) < _ORIENT_TOL
                ):
                    return 0  # collinear within rounding: float32 might decide either way
                if o1 * o2 < 0.0 and o3 * o4 < 0.0:
                    return -1 if lo > 0.0 else 0
            if best < lo2:
                return -1
        for vy, vz in verts:
            vertex = ((vy, vz),)
            for ay, az, uy, uz, iv in sides:  # the outline's vertices against P's sides
                best = _nearest2(vertex, ay, az, uy, uz, iv, best)
            if dz != 0.0:  # ... and strictly inside P
                t = (vz - z0) / dz
                if 0.0 <= t <= 1.0:
                    s = (vy - y0 - t * dy) / f
                    if 0.0 <= s <= 1.0:
                        return -1 if lo > 0.0 else 0
        if best < lo2:
            return -1
        d = math.sqrt(best)
        if d < lo:
            return -1
        return 1 if d >= hi else 0

    # Kinematics --------------------------------------------------------------------------------
    def _leg(self, hy, hz, fy, fz):
        """(r, hip angle, knee angle, hip-angle error bound, knee-angle error bound, near straight) of
        the leg from hip (hy, hz) to the heel (fy, fz): kinematics.knee_position and joint_angles."""
        t, s = self.t, self.s
        dy, dz = fy - hy, fz - hz
        r = math.sqrt(dy * dy + dz * dz)
        rs = r if r > 1e-12 else 1e-12
        uy, uz = dy / rs, dz / rs
        a = (t * t - s * s + r * r) / (2.0 * rs)
        a = -t if a < -t else (t if a > t else a)
        g = t * t - a * a
        h = math.sqrt(g) if g > 0.0 else 0.0
        ky, kz = hy + a * uy - h * uz, hz + a * uz + h * uy
        thigh = math.atan2(ky - hy, hz - kz)
        knee = (math.atan2(fy - ky, kz - fz) - thigh + math.pi) % _TWO_PI - math.pi
        # float32 error in h: |dg| / (2 h) where h is well away from 0, else sqrt(|dg|)
        dh = _G_ERR / (2.0 * h) if h > _H_SMALL else _SQRT_G_ERR
        e_thigh = (dh + 1e-5) / t + ANGLE_MARGIN  # the knee's position error (m) over the thigh
        return r, thigh, knee, e_thigh, e_thigh + (dh + 1e-5) / s + ANGLE_MARGIN, g < 1e-3

    def reachable(self, y, z):
        """1 / 0 / -1: the end (y, z) certainly within the joint limits and reach / too close to call /
        certainly not (rule.shield_conditions' kinematic conditions: kinematics' limits, each
        compared with its float64 value's error bound to either side)."""
        leg, p = self.leg, self.pivot
        dist = 0.5 * (p - y)
        hz2 = leg * leg - dist * dist
        hz = math.sqrt(hz2 if hz2 > self.min_hz2 else self.min_hz2)
        hy = 0.5 * (p + y)
        unsure = False
        h0, h1, k0, k1 = self.limits
        eps = kinematics.ANGLE_EPS
        swing, stance = self._leg(hy, hz, y, z), self._leg(hy, hz, p, 0.0)
        for _, hip, knee, e_h, e_k, straight in (swing, stance):
            # The knee is built on its flexing side (knee angle <= 0 up to rounding of a few 1e-7
            # rad), so a near-straight leg never exceeds an upper limit >= 1e-5 rad.
            k = math.inf if straight and self.knee_hi_free and knee <= 1e-5 else k1
            # kinematics.joint_limit_violation with limits narrowed by the error bounds (not
            # certainly within: certainly outside with them widened, or too close to call); inlined,
            # the same sums and comparisons
            if (
                hip > (h1 - e_h) + eps
                or hip < (h0 + e_h) - eps
                or knee > (k - e_k) + eps
                or knee < (k0 + e_k) - eps
            ):
                if (
                    hip > (h1 + e_h) + eps
                    or hip < (h0 - e_h) - eps
                    or knee > (k + e_k) + eps
                    or knee < (k0 - e_k) - eps
                ):
                    return -1
                unsure = True
        tol, t, s = self.sp.leg_length_tolerance, self.t, self.s
        if kinematics.leg_too_long(scalar, swing[0], stance[0], t, s, tol - LENGTH_MARGIN):
            return (
                -1
                if kinematics.leg_too_long(scalar, swing[0], stance[0], t, s, tol + LENGTH_MARGIN)
                else 0
            )
        return 0 if unsure else 1

    # The choice ---------------------------------------------------------------------------------
    def _reference(self, heel: _Heel, last: int) -> np.ndarray:
        """(A,) the full mask of the float32 heel (the rows form, ``ScalarShield.reference``), on the
        scene stacked as one float32 row (stacked here on first use when not given)."""
        if self._layout is None:
            self._layout = stack_scenes([self.scene], np.float32)
        return self.form.reference.admissible(
            np.array([heel.y], np.float32),
            np.array([heel.z], np.float32),
            self._layout,
            last_action=np.array([last]),
        )[0]

    def _heel(self, hy: float, hz: float) -> _Heel:
        """The heel (hy, hz) rounded to float32, as the reference rounds it."""
        h = _Heel()
        h.y, h.z, h.need = _unpack(_pack(hy))[0], _unpack(_pack(hz))[0], None  # _f32, inlined
        # Far from the obstacle's box no move of one step comes within the shield's clearance.
        h.far = (
            self._box_distance(h.y, h.y + self.fl, h.z, h.z) - self.step >= self.shield_c + MARGIN
        )
        return h

    def choose(self, hy: float, hz: float, q: np.ndarray, last: int = -1) -> int:
        """The shielded greedy action: ``certain``'s, else the full mask's (counted in the form's
        ``stats``: every step, and those handed to the full mask)."""
        a = self.certain(hy, hz, q, last)
        stats = self.form.stats
        if a is None:
            mask = self._reference(self._heel(hy, hz), last)
            a = int(actions.greedy_action(np, q, mask))
            stats.steps_to_full_mask += 1
        stats.steps += 1
        return a

    def mask(self, hy: float, hz: float, last: int = -1) -> np.ndarray:
        """(A,) the admissible moves: every forward move decided by ``_admissible`` where all are
        certain and one passes (then the reference's fallbacks do not apply), else the full mask."""
        heel = self._heel(hy, hz)
        undo = actions.opposite(last) if last >= 0 else -1
        out = np.zeros(actions.NUM_ACTIONS, bool)
        for a in self.fwd_idx:
            v = a != undo and self._admissible(a, heel)
            if v is None:
                return self._reference(heel, last)
            out[a] = v
        return out if out.any() else self._reference(heel, last)

    def certain(self, hy: float, hz: float, q: np.ndarray, last: int = -1):
        """The reference's shielded greedy action for heel (hy, hz) (Python floats; rounded to float32
        here as the reference does), Q-values ``q`` (NUM_ACTIONS,) and the move just made ``last`` (-1:
        none), or None when some needed comparison is too close to call or the reference's fallbacks
        would apply."""
        ql = q.tolist()
        total = sum(ql)
        if total - total != 0.0:  # a nan or an infinity: argmax's own rules
            return self._miss()
        heel = self._heel(hy, hz)
        undo = actions.opposite(last) if last >= 0 else -1  # never admissible (actions.undoes)
        # The best forward move first (max returns the first of equal values, as argmax); only on a
        # miss the rest in order of Q (a stable sort: ties by index).
        best = max(self.fwd_idx, key=ql.__getitem__)
        v = best != undo and self._admissible(best, heel)
        if v is not False:
            return best if v else self._miss()
        for a in sorted(self.fwd_idx, key=ql.__getitem__, reverse=True):
            if a == best or a == undo:
                continue
            v = self._admissible(a, heel)
            if v is not False:
                return a if v else self._miss()
        return self._miss()  # no forward move passes everything: the reference's fallbacks

    def _admissible(self, a: int, heel: _Heel):
        """True / False / None (too close to call) for forward move a from ``heel``."""
        # The float32 heel plus a float32 offset is exact in float64, then rounded as float32 rounds
        # it (``_f32``); then transition.keep_in_world and rule.end_conditions (certainly true with
        # ``ends_in``, possibly with ``ends_out``), inlined with the same comparisons
        # (tests/test_fast_rollout.py holds them to the rule's functions).
        py, pz = self.offsets[a]
        y, z = _unpack(_pack(heel.y + py))[0], _unpack(_pack(heel.z + pz))[0]
        y_lo, y_hi, z_hi = self._world
        y = y_lo if y < y_lo else (y_hi if y > y_hi else y)
        z = 0.0 if z < 0.0 else (z_hi if z > z_hi else z)
        moved = abs(y - heel.y) > transition.MOVE_EPS or abs(z - heel.z) > transition.MOVE_EPS
        off_floor, to_goal = z >= self._floor, abs(y - self.goal)
        if not (y <= self._far_in and moved and (off_floor or to_goal <= self._tol_in)):
            if y <= self._far_out and moved and (off_floor or to_goal <= self._tol_out):
                return None
            return False
        k = self.reachable(y, z)
        if k <= 0:
            return None if k == 0 else False
        if heel.far:
            return True
        if heel.need is None:
            c_here = self.foot_distance(heel.y, heel.z)
            if c_here < MARGIN:
                return None  # touching or inside: the sign may be rounding
            heel.c_here = -c_here if self.inside(heel.y, heel.z) else c_here
            heel.need = rule.clearance_need(scalar, self.sp, heel.c_here)
        # 1-Lipschitz: the foot moved by at most a step stays at least c_here - step from the outline
        if heel.c_here - self.step >= heel.need + MARGIN:
            return True
        need = heel.need
        v = self.swept_vs(heel.y, heel.z, y - heel.y, z - heel.z, need - MARGIN, need + MARGIN)
        return None if v == 0 else v > 0

    def _miss(self):
        self.unsure += 1
        return None
