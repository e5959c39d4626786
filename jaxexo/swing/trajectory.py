"""A checked swing trajectory: the heel path with the exoskeleton's kinematics and its pass/fail
checks. Every generator hands its dense heel path to ``assemble``, so all swings are measured by one
definition (the training environment's kinematics, clearance, goal and limit rules; the clearance
guaranteed between the samples). The verdict: docs/safety.md (a safe swing). Units: m, rad, s.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from jaxexo.physics import geometry, kinematics, outcome, swept, transition
from jaxexo.physics.scene import Scene
from jaxexo.shield.rows import take_rows
from jaxexo.swing.export import CSV_COLUMNS, scene_dict, write_csv, write_json

DEFAULT_DURATION = 1.0  # s, swing duration for the time stamps


class TrajectoryError(RuntimeError):
    """A trajectory failed its checks and ``strict=True`` was asked for; ``.trajectory`` holds it."""

    def __init__(self, trajectory: "Trajectory"):
        super().__init__("trajectory failed its checks: " + "; ".join(trajectory.checks.reasons))
        self.trajectory = trajectory


@dataclass(frozen=True)
class TrajectoryChecks:
    """The safe-swing checks of the final (smoothed) path (docs/safety.md): one swing's, or with a
    leading axis B where a record holds many."""

    reached_goal: bool
    collision_free: bool  # the foot's motion never touches the obstacle
    min_clearance: float  # m, guaranteed clearance of the moving foot (negative: inside)
    joint_limits_ok: bool
    leg_length_ok: bool
    reasons: tuple[str, ...]  # empty when ok
    clearance_ok: bool = True  # min_clearance >= env.min_clearance
    above_ground: bool = True
    heel_backward: float = 0.0  # m, largest backward heel motion (deviation bound included)
    deviation: float = 0.0  # m, bound on the curve's distance from the polyline through the samples

    @property
    def ok(self) -> bool:
        return not self.reasons

    @classmethod
    def row(cls, src, i: int, reasons: tuple[str, ...]) -> "TrajectoryChecks":
        """Swing ``i``'s checks from a record whose check fields have a leading axis (``Measured``,
        ``TrajectoryBatch``), with its failure ``reasons``."""
        return cls(
            reached_goal=bool(src.reached_goal[i]),
            collision_free=bool(src.collision_free[i]),
            min_clearance=float(src.min_clearance[i]),
            joint_limits_ok=bool(src.joint_limits_ok[i]),
            leg_length_ok=bool(src.leg_length_ok[i]),
            reasons=reasons,
            clearance_ok=bool(src.clearance_ok[i]),
            above_ground=bool(src.above_ground[i]),
            heel_backward=float(src.heel_backward[i]),
            deviation=float(src.deviation[i]),
        )


@dataclass(frozen=True)
class Measured:
    """``measure``'s kinematics and checks of B heel paths of N samples: each field has the leading
    axis B. The check fields are those of TrajectoryChecks and jaxexo.physics.outcome.CHECKS."""

    swept_clearance: np.ndarray  # (B, N-1) m, over the moves between samples
    hip: np.ndarray  # (B, N, 2)
    knee_swing: np.ndarray  # (B, N, 2)
    knee_stance: np.ndarray  # (B, N, 2)
    angles: np.ndarray  # (B, N, 4) rad, JOINT_NAMES
    limit_bad: np.ndarray  # (B, N) joints outside their limits
    leg_bad: np.ndarray  # (B, N) a leg longer than thigh + shin
    ok: np.ndarray  # (B,) every check holds (the verdict's success)
    reached_goal: np.ndarray
    collision_free: np.ndarray
    min_clearance: np.ndarray  # (B,) m, guaranteed between the samples
    clearance_ok: np.ndarray
    above_ground: np.ndarray
    heel_backward: np.ndarray  # (B,) m, deviation bound included
    backward_ok: np.ndarray
    joint_limits_ok: np.ndarray
    leg_length_ok: np.ndarray
    deviation: np.ndarray  # (B,) m


@dataclass(frozen=True)
class Trajectory:
    """One swing. Arrays have one row per sample (N); ``raw`` holds the generator's own points."""

    method: str
    scene: Scene
    raw: np.ndarray  # (M, 2) generator points (heel y, z), m; RL: the policy's, then its landing
    heel: np.ndarray  # (N, 2)
    toe: np.ndarray  # (N, 2)
    hip: np.ndarray  # (N, 2)
    knee_swing: np.ndarray  # (N, 2)
    knee_stance: np.ndarray  # (N, 2)
    joint_angles: np.ndarray  # (N, 4) rad, columns JOINT_NAMES
    time: np.ndarray  # (N,) s
    checks: TrajectoryChecks
    smoothing: float  # m^2 actually used; nan: the raw polyline (smoothing fell back)
    notes: tuple[str, ...] = field(default=())

    @property
    def ok(self) -> bool:
        return self.checks.ok

    # Exports -----------------------------------------------------------------------------------
    def table(self) -> np.ndarray:
        """(N, len(CSV_COLUMNS)) array in CSV_COLUMNS order."""
        return np.column_stack(
            [
                self.time,
                self.heel,
                self.toe,
                self.hip,
                self.knee_swing,
                self.knee_stance,
                self.joint_angles,
            ]
        )

    def to_csv(self, path: str | Path | None = None) -> str:
        return write_csv(CSV_COLUMNS, self.table(), path)

    def to_dict(self) -> dict:
        c = self.checks
        return {
            "units": {"length": "m", "angle": "rad", "time": "s"},
            "method": self.method,
            "scene": scene_dict(self.scene),
            "checks": {
                "ok": c.ok,
                "reached_goal": c.reached_goal,
                "collision_free": c.collision_free,
                "min_clearance": c.min_clearance,
                "clearance_ok": c.clearance_ok,
                "above_ground": c.above_ground,
                "heel_backward": c.heel_backward,
                "deviation": c.deviation,
                "joint_limits_ok": c.joint_limits_ok,
                "leg_length_ok": c.leg_length_ok,
                "reasons": list(c.reasons),
            },
            "smoothing": None if math.isnan(self.smoothing) else self.smoothing,
            "notes": list(self.notes),
            "raw": self.raw.tolist(),
            "columns": list(CSV_COLUMNS),
            "samples": self.table().tolist(),
        }

    def to_json(self, path: str | Path | None = None) -> str:
        return write_json(self.to_dict(), path)


@dataclass(frozen=True)
class TrajectoryBatch:
    """Many trajectories: each field but ``method`` and ``time`` (every row's) has a leading axis B,
    arrays stacked (B, N, ...); ``batch[i]`` is the i-th Trajectory."""

    method: str
    scenes: tuple[Scene, ...]
    raw: tuple[np.ndarray, ...]
    heel: np.ndarray
    toe: np.ndarray
    hip: np.ndarray
    knee_swing: np.ndarray
    knee_stance: np.ndarray
    joint_angles: np.ndarray
    time: np.ndarray
    reached_goal: np.ndarray
    collision_free: np.ndarray
    min_clearance: np.ndarray
    joint_limits_ok: np.ndarray
    leg_length_ok: np.ndarray
    reasons: tuple[tuple[str, ...], ...]
    smoothing: np.ndarray
    notes: tuple[tuple[str, ...], ...]
    clearance_ok: np.ndarray
    above_ground: np.ndarray
    heel_backward: np.ndarray
    deviation: np.ndarray
    row_methods: tuple[str, ...] = ()  # per-row method when rows differ (e.g. "cfftg-fallback")

    def __len__(self) -> int:
        return len(self.scenes)

    @property
    def ok(self) -> np.ndarray:
        return np.array([not r for r in self.reasons], dtype=bool)

    def __getitem__(self, i: int) -> Trajectory:
        return Trajectory(
            method=self.row_methods[i] if self.row_methods else self.method,
            scene=self.scenes[i],
            raw=self.raw[i],
            heel=self.heel[i],
            toe=self.toe[i],
            hip=self.hip[i],
            knee_swing=self.knee_swing[i],
            knee_stance=self.knee_stance[i],
            joint_angles=self.joint_angles[i],
            time=self.time,
            checks=TrajectoryChecks.row(self, i, self.reasons[i]),
            smoothing=float(self.smoothing[i]),
            notes=self.notes[i],
        )

    def __iter__(self):
        return (self[i] for i in range(len(self)))

    def take(self, idx) -> "TrajectoryBatch":
        """The sub-batch of rows ``idx`` (in order)."""
        return take_rows(
            self, idx, ("method", "time") + (() if self.row_methods else ("row_methods",))
        )

    def with_rows(self, idx, other: "TrajectoryBatch") -> "TrajectoryBatch":
        """This batch with rows ``idx`` replaced by ``other``'s rows (in order)."""
        a, b = self._per_row(), other._per_row()
        order = np.arange(len(a))
        order[np.asarray(idx, np.int64)] = len(a) + np.arange(len(b))
        joined = {
            k: v + getattr(b, k) if isinstance(v, tuple) else np.concatenate([v, getattr(b, k)])
            for k, v in vars(a).items()
            if k not in ("method", "time")
        }
        return take_rows(replace(a, **joined), order, ("method", "time"))

    def _per_row(self) -> "TrajectoryBatch":
        return replace(self, row_methods=self.row_methods or (self.method,) * len(self))


def _point_clearances(foot_length: float, heel: np.ndarray, scenes) -> np.ndarray:
    """Signed foot clearance (B, N) of heel paths (B, N, 2) from each scene's obstacle; scenes are
    grouped by outline size so that a 16-vertex half-ellipse does not pad every rectangle."""
    out = np.empty(heel.shape[:2])
    for idx, outline in _outline_groups(scenes):
        out[idx] = geometry.foot_clearance(np, heel[idx], foot_length, outline[:, None])
    return out


def _outline_groups(scenes):
    """(rows, stacked outlines) per outline size; one group without sorting when all sizes agree
    (the common case, and always for one scene)."""
    if len(scenes) == 1:
        return [(slice(None), scenes[0].outline[None])]
    sizes = [len(sc.outline) for sc in scenes]
    if len(set(sizes)) == 1:
        return [(slice(None), np.stack([sc.outline for sc in scenes]))]
    sizes = np.array(sizes)
    return [
        (idx, np.stack([scenes[i].outline for i in idx]))
        for idx in (np.flatnonzero(sizes == k) for k in np.unique(sizes))
    ]


def _move_clearances(
    foot_length: float, heel: np.ndarray, scenes, point_clearance: np.ndarray, exact: bool
) -> np.ndarray:
    """Signed clearance (B, N-1) of the foot over each move between consecutive samples
    (jaxexo.physics.swept), grouped by outline size like ``_point_clearances``. ``exact``: exact for
    every move; otherwise exact for each path's closest move, a lower bound above that minimum for
    the moves that cannot be the closest (``swept.path_swept_min``), which is all the verdict and
    its reasons read."""
    b, n = heel.shape[:2]
    out = np.empty((b, max(n - 1, 0)))
    for idx, outline in _outline_groups(scenes):
        if exact:
            out[idx] = swept.path_swept_clearance(
                np, heel[idx], foot_length, outline, point_clearance[idx]
            )
        else:
            out[idx] = swept.path_swept_min(heel[idx], foot_length, outline, point_clearance[idx])
    return out


def _backward_reason(bound: float, heel: np.ndarray, tolerance: float) -> str:
    """The failed backward check in words: ``bound`` is a bound over the curve between the samples
    (backward_bound), not a measurement; the samples' own backward motion is said beside it."""
    sampled = float(swept.backward_motion(np, heel[:, 0]))
    return (
        f"the heel may move backward by up to {bound:.4f} m (a bound over the curve between samples: "
        f"the samples themselves move back {sampled:.4f} m), more than env.backward_tolerance = "
        f"{tolerance:.4f} m; more samples (n_points, --points) tighten the bound"
    )


def backward_bound(heel: np.ndarray, deviation) -> np.ndarray:
    """How far the heel moves backward (m) on the curve through paths (..., N, 2): the samples' y
    drawdown (jaxexo.physics.swept.backward_motion) plus twice the curve's deviation bound (...,)."""
    return swept.backward_motion(np, heel[..., 0]) + 2.0 * np.asarray(deviation)


def joints_outside(angles: np.ndarray, sp) -> np.ndarray:
    """Where joint angles (..., 4) (JOINT_NAMES) leave their range: kinematics.legs_outside_limits's
    comparisons (eq 2.50, ANGLE_EPS), the same booleans, in a few NumPy calls for all four joints."""
    (h0, h1), (k0, k1) = sp.hip_limits, sp.knee_limits
    lo, hi = _joint_bounds(float(h0), float(h1), float(k0), float(k1))
    bad = (angles < lo) | (angles > hi)
    # Any of a row's four booleans (bytes 0 or 1, made contiguous): its four bytes as one integer.
    return np.ascontiguousarray(bad).view(np.uint32)[..., 0] != 0


@functools.lru_cache(maxsize=16)
def _joint_bounds(h0: float, h1: float, k0: float, k1: float) -> tuple[np.ndarray, np.ndarray]:
    """The (4,) bounds ``joints_outside`` compares against, per hip and knee limits (read-only)."""
    eps = kinematics.ANGLE_EPS
    lo = np.array([h0 - eps, k0 - eps, h0 - eps, k0 - eps])
    hi = np.array([h1 + eps, k1 + eps, h1 + eps, k1 + eps])
    lo.setflags(write=False)
    hi.setflags(write=False)
    return lo, hi


def measure(
    sp,
    heel: np.ndarray,
    clearance: np.ndarray,
    pivot_y: np.ndarray,
    goal_y: np.ndarray,
    swept_clearance: np.ndarray,
    deviation,
) -> Measured:
    """Kinematics and safe-swing checks of heel paths (B, N, 2), vectorised, from their clearances at
    the samples (B, N), over the moves between them (B, N-1, ``path_clearances``) and the bound
    ``deviation`` (B,) of the curve from the polyline through the samples (m).

    ``sp`` holds the constants (jaxexo.config.scalar_params or numpy_params)."""
    dev = np.zeros(heel.shape[:1])
    dev[:] = deviation
    # The guaranteed clearance: the polyline's exact swept clearance (or the samples' own, for a
    # path of one sample) less the deviation bound.
    guaranteed = lowest_clearance(clearance, swept_clearance) - dev
    backward = backward_bound(heel, dev)
    # kinematics.leg_state's equations, with both legs stacked on a leading axis (fewer NumPy calls).
    hip = kinematics.hip_position(np, pivot_y[:, None], heel, sp.thigh, sp.shin)
    feet = np.zeros((2,) + heel.shape)  # the swing heel, then the pivot heel on the ground
    feet[0] = heel
    feet[1, ..., 0] = pivot_y[:, None]
    knees, legs = kinematics.knee_position(np, hip[None], feet, sp.thigh, sp.shin)
    hips, qs = kinematics.joint_angles(np, hip[None], knees, feet)
    angles = np.empty(
        heel.shape[:-1] + (4,)
    )  # JOINT_NAMES order (filled in place: cheaper than stack)
    angles[..., 0], angles[..., 1], angles[..., 2], angles[..., 3] = hips[0], qs[0], hips[1], qs[1]
    limit_bad = joints_outside(angles, sp)
    leg_bad = kinematics.leg_too_long(
        np, legs[0], legs[1], sp.thigh, sp.shin, sp.leg_length_tolerance
    )
    reached = transition.goal_reached(np, sp, heel[:, -1, 0], heel[:, -1, 1], goal_y)
    above_ground = heel[..., 1].min(axis=-1) >= 0.0
    # The one safe-swing verdict (jaxexo.physics.outcome), on what is guaranteed between the samples.
    v = outcome.verdict(
        np,
        reached,
        guaranteed,
        ~np.any(limit_bad, axis=-1),
        ~np.any(leg_bad, axis=-1),
        backward,
        above_ground,
        **outcome.rule(sp),
    )
    return Measured(
        swept_clearance=swept_clearance,
        hip=hip,
        knee_swing=knees[0],
        knee_stance=knees[1],
        angles=angles,
        limit_bad=limit_bad,
        leg_bad=leg_bad,
        ok=v.success,
        collision_free=v.collision_free,
        min_clearance=guaranteed,
        heel_backward=backward,
        deviation=dev,
        **{c: getattr(v, c) for c in outcome.CHECKS},
    )


def failure_reasons(
    m: Measured, i: int, heel: np.ndarray, goal_y: float, time: np.ndarray, sp
) -> tuple[str, ...]:
    """The failed checks of path i (jaxexo.physics.outcome.CHECKS, in order), each with where it failed."""
    out = []
    for check in outcome.failed_checks(m, i):
        if check == "reached_goal":
            y, z = heel[-1]
            out.append(
                f"did not reach the goal: ends at y={y:.3f} m, z={z:.3f} m, goal y={goal_y:.3f} m"
            )
        elif check == "clearance_ok":
            sw = m.swept_clearance[i]
            j = int(np.argmin(sw)) if sw.size else 0
            when = f"between t={time[j]:.3f} s and t={time[min(j + 1, len(time) - 1)]:.3f} s"
            if not m.collision_free[i]:
                out.append(
                    f"the foot touches the obstacle (min clearance {m.min_clearance[i]:.4f} m {when})"
                )
            else:
                out.append(
                    f"the foot passes within {m.min_clearance[i]:.4f} m of the obstacle {when}, closer "
                    f"than the safety margin env.min_clearance = {sp.min_clearance:.4f} m"
                )
        elif check == "above_ground":
            out.append(f"the heel goes below the ground (z={heel[:, 1].min():.4f} m)")
        elif check == "backward_ok":
            out.append(_backward_reason(m.heel_backward[i], heel, sp.backward_tolerance))
        elif check == "joint_limits_ok":
            j = int(np.argmax(m.limit_bad[i]))
            a = np.degrees(m.angles[i, j])
            out.append(
                f"joint limits exceeded at t={time[j]:.3f} s (hip/knee swing {a[0]:.1f}/{a[1]:.1f} deg, "
                f"stance {a[2]:.1f}/{a[3]:.1f} deg)"
            )
        else:
            j = int(np.argmax(m.leg_bad[i]))
            out.append(f"a leg would have to stretch beyond thigh + shin at t={time[j]:.3f} s")
    return tuple(out)


def measure_paths(sp, paths: np.ndarray, scenes, deviation, clearances=None) -> Measured:
    """``measure`` of heel paths (B, N, 2) on their scenes, clearances included: ``clearances`` (point,
    move) when known, else ``path_clearances``."""
    pivot_y = np.array([sc.pivot_y for sc in scenes])
    goal_y = np.array([sc.goal_y for sc in scenes])
    c, sw = path_clearances(sp.foot_length, paths, scenes) if clearances is None else clearances
    return measure(sp, paths, c, pivot_y, goal_y, sw, deviation)


def path_clearances(foot_length: float, paths: np.ndarray, scenes):
    """A path's clearances, as the verdict reads them: (at the samples (B, N), over the moves (B, N-1))
    of heel paths (B, N, 2) on their scenes, each path's closest move and sample exact, lower bounds
    above that minimum elsewhere (all that the verdict and its reasons read)."""
    if len(scenes) >= PRUNE_POINTS_FROM:
        return _pruned_clearances(foot_length, paths, scenes)
    c = _point_clearances(foot_length, paths, scenes)
    return c, _move_clearances(foot_length, paths, scenes, c, exact=False)


def exact_path_clearances(foot_length: float, paths: np.ndarray, scenes):
    """``path_clearances`` with every sample and move exact: the reference it is tested against."""
    c = _point_clearances(foot_length, paths, scenes)
    return c, _move_clearances(foot_length, paths, scenes, c, exact=True)


def lowest_clearance(point_clearance: np.ndarray, move_clearance: np.ndarray) -> np.ndarray:
    """The polyline's clearance (...,): its moves' minimum, or its one sample's for a path of one."""
    return move_clearance.min(axis=-1) if move_clearance.shape[-1] else point_clearance.min(axis=-1)


def passes(sp, low, deviation, backward, headroom: float = 0.0) -> np.ndarray:
    """The verdict's clearance and backward checks (jaxexo.physics.outcome.verdict: clearance_ok and
    backward_ok) of curves whose polyline keeps ``low`` (m) from the obstacle, with ``deviation`` the
    curve's bound and ``backward`` its backward motion, the margin env.min_clearance kept with
    ``headroom`` (m) to spare. The generators' retries accept a curve by this rule."""
    g = low - deviation
    return (
        ~geometry.foot_collides(np, g)
        & ~geometry.foot_collides(np, g - sp.min_clearance - headroom)
        & (backward <= sp.backward_tolerance)
    )


# From this many paths on, ``path_clearances`` also skips the exact point clearances that cannot matter
# (swept.path_clearance_pruned): worth it where the arrays are large; for a few paths the extra
# NumPy calls cost more than they save.
PRUNE_POINTS_FROM = 8


def _pruned_clearances(foot_length: float, heel: np.ndarray, scenes):
    """(point clearances (B, N), per-move clearances (B, N-1)) by ``swept.path_clearance_pruned``,
    grouped by outline size: exact at each path's closest move; elsewhere lower bounds above it."""
    b, n = heel.shape[:2]
    c = np.empty((b, n))
    sw = np.empty((b, max(n - 1, 0)))
    for idx, outline in _outline_groups(scenes):
        c[idx], sw[idx] = swept.path_clearance_pruned(heel[idx], foot_length, outline)
    return c, sw


@functools.lru_cache(maxsize=64)
def _time_stamps(n: int, duration: float) -> np.ndarray:
    """np.linspace(0, duration, n), computed once per (n, duration) (read-only; callers copy it)."""
    t = np.linspace(0.0, duration, n)
    t.setflags(write=False)
    return t


def assemble(
    method: str,
    sp,
    scenes,
    raws,
    paths: np.ndarray,
    smoothing,
    duration: float = DEFAULT_DURATION,
    notes=None,
    measured: Measured | None = None,
    deviation=None,
) -> TrajectoryBatch:
    """Checked trajectories from dense heel paths (B, N, 2), one per scene; ``raws`` the generator's
    own points per scene, ``smoothing`` (B,) the smoothing each path used (nan for a raw polyline),
    ``deviation`` (B,) the bound (m) on each curve's distance from the polyline through its samples
    (required unless ``measured`` is given). ``measured``: ``measure``'s result for exactly these
    paths, when the generator already has it (CFFTG checks every plan while planning)."""
    paths = np.asarray(paths, dtype=np.float64)
    b, n = paths.shape[:2]
    if measured is None:
        if deviation is None:
            raise ValueError(
                "deviation: the bound on the curve's distance from its samples' polyline is needed"
            )
        measured = measure_paths(sp, paths, scenes, deviation)
    m = measured
    time = _time_stamps(n, float(duration)).copy()
    reasons = tuple(failure_reasons(m, i, paths[i], scenes[i].goal_y, time, sp) for i in range(b))
    toe = paths.copy()
    toe[..., 0] += sp.foot_length
    return TrajectoryBatch(
        method=method,
        scenes=tuple(scenes),
        raw=tuple(np.asarray(r, np.float64) for r in raws),
        heel=paths,
        toe=toe,
        hip=m.hip,
        knee_swing=m.knee_swing,
        knee_stance=m.knee_stance,
        joint_angles=m.angles,
        time=time,
        reached_goal=m.reached_goal,
        collision_free=m.collision_free,
        min_clearance=m.min_clearance,
        joint_limits_ok=m.joint_limits_ok,
        leg_length_ok=m.leg_length_ok,
        reasons=reasons,
        smoothing=np.asarray(smoothing, np.float64).reshape(b),
        notes=tuple(notes) if notes is not None else ((),) * b,
        clearance_ok=m.clearance_ok,
        above_ground=m.above_ground,
        heel_backward=m.heel_backward,
        deviation=m.deviation,
    )
