"""The shield's greedy choice for one heel, checking only the move that will be taken: the form
``make_shield("scalar", ...)`` (jaxexo.shield).

The shielded greedy action is ``argmax(where(mask, q, -inf))`` with ``mask`` the admissible moves of
jaxexo.shield.rule.admissible_moves, evaluated in float32 on the heel rounded to float32 (the
generator's reference, ``ShieldRows.admissible``, jaxexo.shield.rows). Checking all 19 forward moves
every step costs ~200 us in NumPy calls; the chosen move, however, is simply the first move, in order
of decreasing Q (ties by index, as argmax), that is admissible. ``SwingShield.certain`` walks that
order and checks one move at a time in plain Python floats:

- the goal-box condition exactly (the move's end is rounded to float32 exactly like the reference's
  float32 arithmetic: a sum of two float32 values is exact in float64, so one rounding gives the
  float32 sum);
- the clearance and the joint limits / reach from float64 arithmetic on the same float32 inputs,
  *certified*: each comparison is decided only when the float64 value lies further from its
  threshold than a bound on float32's rounding error (``MARGIN`` for lengths, a per-leg bound for the
  angles that grows where the knee's square root is ill-conditioned); a comparison that is too close
  to call makes ``certain`` return None, and ``choose`` computes the reference mask (float32 NumPy)
  for that step. The result is therefore always the reference's move.

Cheap exact shortcuts keep the geometry rare: far from the obstacle's bounding box no move can come
within the shield's clearance (the distance is 1-Lipschitz); outline edges whose bounding box is
further than the threshold from the swept region's bounding box are skipped; a move whose end
clearance is already below the threshold fails, and one whose ends' clearances certify the swept
bound (jaxexo.physics.swept.swept_lower_bound) passes.

Where no forward move passes all four conditions the reference falls back (the forward moves that
keep the clearance, then every move): ``certain`` returns None there too, so those steps take the
reference path (``SwingShield.choose``). Exploration (epsilon > 0) always takes it.

``ScalarShield`` is the form behind the shield's one interface (``admissible`` and ``choose`` on
rows of stacked scenes, one heel at a time); ``ScalarShield.swing(scene)`` is one swing's
``SwingShield``, the generator's per-step choice.
"""

from __future__ import annotations

import math
import struct

import numpy as np

from jaxexo.physics import actions, kinematics, transition
from jaxexo.physics.scene import stack_scenes
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


# transition.moves_heel's threshold, and the band around it left to the reference (float32 rounding of
# a difference of coordinates below 1 m is under 1e-7 m).
_MOVE_EPS = transition.MOVE_EPS
MARGIN_MOVE = 1e-7

_F32 = struct.Struct("f")
_pack, _unpack = _F32.pack, _F32.unpack


def _f32(x: float) -> float:
    """x rounded to float32 (to nearest, as NumPy's float32 arithmetic rounds each result)."""
    return _unpack(_pack(x))[0]


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
        p = np_params
        self.form = ScalarShield(p, sp) if form is None else form
        self.scene, self._layout = scene, layout
        self.sp = sp
        self.fl = sp.foot_length
        self.step = sp.step_size
        self.b0, self.b1 = sp.bounds_y
        self.zmax = sp.max_z_world
        self.shield_c = sp.shield_clearance
        self.t, self.s = sp.thigh, sp.shin
        self.leg = _f32(np.float32(sp.thigh) + np.float32(sp.shin))
        self.hip_lim = sp.hip_limits
        self.knee_lim = sp.knee_limits
        self.leg_tol = sp.leg_length_tolerance + kinematics.LENGTH_EPS
        self.hip_lo = self.hip_lim[0] - kinematics.ANGLE_EPS
        self.hip_hi = self.hip_lim[1] + kinematics.ANGLE_EPS
        self.knee_lo = self.knee_lim[0] - kinematics.ANGLE_EPS
        self.knee_hi = self.knee_lim[1] + kinematics.ANGLE_EPS
        self.min_hz2 = (kinematics.MIN_HIP_HEIGHT_FRACTION * self.leg) ** 2
        # every forward move: (action, float32 step * direction per axis)
        fwd = rule.FORWARD
        prod = (p.step_size * p.directions).astype(np.float32)
        self.forward = np.zeros(actions.NUM_ACTIONS, bool)
        self.forward[fwd] = True
        self.fwd_list = self.forward.tolist()
        self.fwd_idx = fwd.tolist()
        self.prod = [(float(prod[a, 0]), float(prod[a, 1])) for a in range(actions.NUM_ACTIONS)]
        # the scene as float32 values
        f = lambda v: float(np.float32(v))  # noqa: E731
        self.pivot = f(scene.pivot_y)
        self.goal_limit = float(np.float32(scene.goal_y) + p.goal_tolerance[0])
        # transition.keeps_off_floor in the reference's float32: exact here (a float32 difference is
        # exact in float64, then rounded as float32 rounds it)
        self.goal_y32 = f(scene.goal_y)
        self.goal_tol32 = float(np.float32(p.goal_tolerance[0]))
        self.floor32 = float(np.float32(p.floor_clearance))
        ol = np.asarray(scene.outline, np.float32).astype(np.float64)
        self.vy, self.vz = ol[:, 0].tolist(), ol[:, 1].tolist()
        self.box = (min(self.vy), max(self.vy), min(min(self.vz), 0.0), max(self.vz))
        edges = []
        for i in range(len(ol) - 1):
            cy, cz = self.vy[i], self.vz[i]
            ey, ez = self.vy[i + 1] - cy, self.vz[i + 1] - cz
            len2 = ey * ey + ez * ez
            if len2 > 1e-24:  # padding (repeated vertices): their distances are the vertices'
                edges.append(
                    (
                        cy,
                        cz,
                        ey,
                        ez,
                        1.0 / len2,
                        min(cy, cy + ey),
                        max(cy, cy + ey),
                        min(cz, cz + ez),
                        max(cz, cz + ez),
                    )
                )
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
        certainly not (rule.admissible_moves' kinematic conditions)."""
        leg = self.leg
        p = self.pivot
        dist = 0.5 * (p - y)
        hz2 = leg * leg - dist * dist
        hz = math.sqrt(hz2 if hz2 > self.min_hz2 else self.min_hz2)
        hy = 0.5 * (p + y)
        unsure = False
        worst_r = 0.0
        lo_h, hi_h, lo_k, hi_k = self.hip_lo, self.hip_hi, self.knee_lo, self.knee_hi
        for fy, fz in ((y, z), (p, 0.0)):
            r, hip, knee, e_hip, e_knee, straight = self._leg(hy, hz, fy, fz)
            if r > worst_r:
                worst_r = r
            if hip > hi_h + e_hip or hip < lo_h - e_hip or knee < lo_k - e_knee:
                return -1
            if hip > hi_h - e_hip or hip < lo_h + e_hip or knee < lo_k + e_knee:
                unsure = True
            # The knee is built on its flexing side (knee angle <= 0 up to rounding of a few 1e-7
            # rad), so a near-straight leg never exceeds an upper limit >= 1e-5 rad.
            if not (straight and hi_k >= 1e-5 and knee <= 1e-5):
                if knee > hi_k + e_knee:
                    return -1
                if knee > hi_k - e_knee:
                    unsure = True
        over = worst_r - leg
        if over > self.leg_tol + LENGTH_MARGIN:
            return -1
        if over > self.leg_tol - LENGTH_MARGIN:
            unsure = True
        return 0 if unsure else 1

    # The choice ---------------------------------------------------------------------------------
    def _reference(self, hy: float, hz: float, last: int) -> np.ndarray:
        """(A,) the full mask of the float32 heel (the rows form, ``ScalarShield.reference``), on the
        scene stacked as one float32 row (stacked here on first use when not given)."""
        if self._layout is None:
            self._layout = stack_scenes([self.scene], np.float32)
        return self.form.reference.admissible(
            np.array([hy], np.float32),
            np.array([hz], np.float32),
            self._layout,
            last_action=np.array([last]),
        )[0]

    def choose(self, hy: float, hz: float, q: np.ndarray, last: int = -1) -> int:
        """The shielded greedy action: ``certain``'s, else the full mask's (counted in the form's
        ``stats``: every step, and those handed to the full mask)."""
        a = self.certain(hy, hz, q, last)
        stats = self.form.stats
        if a is None:
            a = int(actions.greedy_action(np, q, self._reference(hy, hz, last)))
            stats.steps_to_full_mask += 1
        stats.steps += 1
        return a

    def mask(self, hy: float, hz: float, last: int = -1) -> np.ndarray:
        """(A,) the admissible moves: every forward move decided by ``_admissible`` where all are
        certain and one passes (then the reference's fallbacks do not apply), else the full mask."""
        hy, hz = _f32(hy), _f32(hz)
        far = self._box_distance(hy, hy + self.fl, hz, hz) - self.step >= self.shield_c + MARGIN
        state = [None]
        undo = (last + actions.NUM_ACTIONS // 2) % actions.NUM_ACTIONS if last >= 0 else -1
        out = np.zeros(actions.NUM_ACTIONS, bool)
        for a in self.fwd_idx:
            v = a != undo and self._admissible(a, hy, hz, far, state)
            if v is None:
                return self._reference(hy, hz, last)
            out[a] = v
        return out if out.any() else self._reference(hy, hz, last)

    def certain(self, hy: float, hz: float, q: np.ndarray, last: int = -1):
        """The reference's shielded greedy action for heel (hy, hz) (Python floats; rounded to float32
        here as the reference does), Q-values ``q`` (NUM_ACTIONS,) and the move just made ``last`` (-1:
        none), or None when some needed comparison is too close to call or the reference's fallbacks
        would apply."""
        ql = q.tolist()
        total = sum(ql)
        if total - total != 0.0:  # a nan or an infinity: argmax's own rules
            return self._miss()
        hy, hz = _f32(hy), _f32(hz)
        # Far from the obstacle's box no move of one step comes within the shield's clearance.
        far = self._box_distance(hy, hy + self.fl, hz, hz) - self.step >= self.shield_c + MARGIN
        state = [None]  # the clearance threshold, computed once when needed
        # the move that would undo the last one (actions.undoes) is never admissible
        undo = (last + actions.NUM_ACTIONS // 2) % actions.NUM_ACTIONS if last >= 0 else -1
        # The best forward move first (max returns the first of equal values, as argmax); only on a
        # miss the rest in order of Q (a stable sort: ties by index).
        best = max(self.fwd_idx, key=ql.__getitem__)
        v = best != undo and self._admissible(best, hy, hz, far, state)
        if v is not False:
            return best if v else self._miss()
        for a in sorted(self.fwd_idx, key=ql.__getitem__, reverse=True):
            if a == best or a == undo:
                continue
            v = self._admissible(a, hy, hz, far, state)
            if v is not False:
                return a if v else self._miss()
        return self._miss()  # no forward move passes everything: the reference's fallbacks

    def _admissible(self, a, hy, hz, far, state):
        """True / False / None (too close to call) for forward move a from the float32 heel (hy, hz)."""
        py, pz = self.prod[a]
        y = _f32(hy + py)
        y = self.b0 if y < self.b0 else (self.b1 if y > self.b1 else y)
        if y > self.goal_limit:
            return False
        z = _f32(hz + pz)
        z = 0.0 if z < 0.0 else (self.zmax if z > self.zmax else z)
        if z < self.floor32 and abs(_f32(y - self.goal_y32)) > self.goal_tol32:
            return False
        moved = max(abs(y - hy), abs(z - hz))  # transition.moves_heel, certified like the rest
        if moved <= _MOVE_EPS + MARGIN_MOVE:
            return False if moved <= _MOVE_EPS - MARGIN_MOVE else None
        k = self.reachable(y, z)
        if k <= 0:
            return None if k == 0 else False
        if far:
            return True
        need = state[0]
        if need is None:
            c_here = self.foot_distance(hy, hz)
            if c_here < MARGIN:
                return None  # touching or inside: the sign may be rounding
            if self.inside(hy, hz):
                c_here = -c_here
            need = state[0] = rule.clearance_need(transition.scalar, self.sp, c_here)
            state.append(c_here)
        # 1-Lipschitz: the foot moved by at most a step stays at least c_here - step from the outline
        if state[1] - self.step >= need + MARGIN:
            return True
        v = self.swept_vs(hy, hz, y - hy, z - hz, need - MARGIN, need + MARGIN)
        return None if v == 0 else v > 0

    def _miss(self):
        self.unsure += 1
        return None
