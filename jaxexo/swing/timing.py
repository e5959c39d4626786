"""Device-ready swings: a swing path timed rest to rest within the drives' limits, as a curve
(jaxexo.swing.curve) with continuous joint acceleration and bounded jerk, and its samples at a
controller's rate (NumPy only): the joint path, the time-optimal passes (jaxexo.swing.time_law),
the check on the curve (jaxexo.swing.curve_check), the path checks and the samples. Method and
measurements: docs/device-timing.md. Units: m, rad, s; limits per joint of JOINT_NAMES.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace

import numpy as np

from jaxexo.config import MAX_CONTROL_RATE, MAX_SWING_DURATION, MIN_CONTROL_RATE
from jaxexo.physics import kinematics
from jaxexo.physics.geometry import as_given
from jaxexo.physics.scene import Scene
from jaxexo.physics.swept import polyline_clearances
from jaxexo.swing.curve import (
    GROUND_ROUNDING,
    CurveState,
    SwingCurve,
    check_points,
    chord_knots,
    curves_at,
    distinct_samples,
    law_from_speeds,
    median,
    paths_at,
    pchip_eval,
    pchip_slopes,
    thinned,
    unwrapped,
)
from jaxexo.swing.curve_check import (
    CHECK_MARGIN,
    FinalLaw,
    Plan,
    final_law,
    lowered_cap,
    max_samples,
    with_bounds,
)
from jaxexo.swing.export import (
    JOINT_NAMES,
    timed_dict,
    timed_table,
    write_joint_trajectory,
    write_timed_csv,
    write_timed_json,
)
from jaxexo.swing.knots import few_knot_paths
from jaxexo.swing.limits import DeviceLimits, GridView, passes_rows, peak_ratio, speed_ratio
from jaxexo.swing.time_law import topp
from jaxexo.swing.trajectory import (
    Measured,
    TrajectoryBatch,
    TrajectoryChecks,
    failure_reasons,
    joints_outside,
    measure_paths,
    path_clearances,
)

GRID_PER_KNOT = 3  # TOPP grid points per piece of the joint path, ...
GRID_MIN = 192  # ... at least this many, ...
GRID_STEP = 32  # ... a multiple of this (plus the end)
REFINE = 2.0  # a sample interval with a joint step over this many median steps is subdivided ...
# ... into parts of at least 1/REFINE_BUDGET of the whole joint path: at most REFINE_BUDGET + N
# joint samples (the most a swing of tests/reference_outputs.py has: 1,279, a CFFTG swing)
REFINE_BUDGET = 4096
CHUNK = 64  # at most this many swings timed in one batch ...
CHUNK_SAMPLES = 16384  # ... and this many joint samples (time_swings' temporaries follow them)
SAFETY = 0.95  # the TOPP passes use this fraction of each limit
LOCAL_PASSES = 2  # local corrections of the passes' caps, then one uniform slow-down
LOCAL_FROM = 1.02  # ... for a curve over a limit by more than this factor (less: the slow-down)
BLEND_S = 0.03  # s: the time law's smoothing window, or longer where the jerk limit asks ...
BLEND_FRACTION = 0.1  # ... at most this fraction of the time-optimal duration
CURVE_TOL = 5e-5  # m: the checked polyline's largest distance from the heel curve


@dataclass(frozen=True)
class TimedSwing:
    """A swing timed at the device's limits: the curve (``at(t)``, any instant) and its samples at
    one control rate, one row per period from lift-off (t = 0) to touch-down, both at rest.
    ``checks`` and ``within_limits`` are made on the curve, so they hold at any rate: the peaks are
    proven bounds on the curve's maxima (jaxexo.swing.limit_proof: never below them, at most a
    fraction of a percent above), so a swing within the limits is within them at every instant."""

    method: str
    scene: Scene
    rate: float  # Hz
    duration: float  # s, the curve's
    limits: DeviceLimits
    time: np.ndarray  # (n,) s
    heel: np.ndarray  # (n, 2) m
    toe: np.ndarray
    hip: np.ndarray
    knee_swing: np.ndarray
    knee_stance: np.ndarray
    joint_angles: np.ndarray  # (n, 4) rad, JOINT_NAMES
    joint_velocity: np.ndarray  # (n, 4) rad/s
    joint_acceleration: np.ndarray  # (n, 4) rad/s^2
    heel_velocity: np.ndarray  # (n, 2) m/s
    heel_acceleration: np.ndarray  # (n, 2) m/s^2
    path_parameter: np.ndarray  # (n,) s(t) in [0, 1]
    checks: TrajectoryChecks  # path checks (goal, clearance, joint range, leg length) on the curve
    within_limits: bool  # every constraint (limits.DeviceLimits.constraints) within, on the curve
    peak_velocity: np.ndarray  # (4,) rad/s: a proven upper bound on max |q-dot| over the curve
    peak_acceleration: np.ndarray  # (4,) rad/s^2: the same for |q-ddot|
    # Uniform slow-down applied after the passes and local corrections (>= 1; < 1: a path the
    # limits cannot cross within MAX_SWING_DURATION, sped up to it, notes and within_limits say so).
    slowdown: float
    peak_jerk: np.ndarray | None = None  # (4,) rad/s^3: the same for |q-dddot|
    notes: tuple[str, ...] = field(default=())
    curve: SwingCurve | None = None
    joint_jerk: np.ndarray | None = None  # (n, 4) rad/s^3
    # s: where the swing was replanned in flight (jaxexo.swing.replan), in order; () for none
    switch_times: tuple[float, ...] = ()

    @property
    def ok(self) -> bool:
        return self.checks.ok and self.within_limits

    @property
    def reasons(self) -> tuple[str, ...]:
        extra = (
            ()
            if self.within_limits
            else (
                "joint velocity/acceleration/jerk limits (less the tracking headroom) exceeded on "
                "the timed curve",
            )
        )
        return self.checks.reasons + extra

    def at(self, t) -> CurveState:
        """The swing at times t (s): joints and heel/toe with velocity, acceleration and jerk."""
        return self.curve.at(t)

    def sample(self, rate: float) -> "TimedSwing":
        """The same curve sampled at ``rate`` Hz (MIN_CONTROL_RATE to MAX_CONTROL_RATE): one row per
        period from 0 until the first period at or after touch-down (the legs rest from there)."""
        rate = check_rate(rate)
        return replace(self, rate=rate, **_samples([self.curve], rate)[0].columns())

    def table(self) -> np.ndarray:
        return timed_table(self)

    def to_csv(self, path=None) -> str:
        return write_timed_csv(self, path)

    def to_dict(self) -> dict:
        return timed_dict(self)

    def to_json(self, path=None) -> str:
        return write_timed_json(self, path)

    def to_joint_trajectory(self, path=None, *, joint_names=None) -> str:
        """JSON in the layout of ROS 2 trajectory_msgs/JointTrajectory (jaxexo.swing.export), the
        joints named ``joint_names`` (four distinct ROS names; default JOINT_NAMES)."""
        return write_joint_trajectory(self, path, joint_names)


def leg_angles(sp, pivot_y: float, heel: np.ndarray) -> np.ndarray:
    """Joint angles (K, 4) in JOINT_NAMES order for swing heels (K, 2) and a pivot heel at pivot_y,
    by jaxexo.physics.kinematics (the same calls as trajectory.measure)."""
    hip = kinematics.hip_position(np, pivot_y, heel, sp.thigh, sp.shin)
    pivot = np.zeros_like(heel)
    pivot[:, 0] = pivot_y
    feet = np.stack([heel, pivot])
    knees, _ = kinematics.knee_position(np, hip[None], feet, sp.thigh, sp.shin)
    hips, qs = kinematics.joint_angles(np, hip[None], knees, feet)
    return np.stack([hips[0], qs[0], hips[1], qs[1]], axis=-1)


def check_rate(rate, name: str = "rate") -> float:
    """A control rate (Hz) in [MIN_CONTROL_RATE, MAX_CONTROL_RATE], the bounds of [device]
    control_rate; TypeError or ValueError naming ``name``."""
    if isinstance(rate, (bool, np.bool_)) or not isinstance(
        rate, (int, float, np.integer, np.floating)
    ):
        raise TypeError(f"{name}: expected a number in Hz, got {rate!r}")
    rate = float(rate)
    if not (math.isfinite(rate) and MIN_CONTROL_RATE <= rate <= MAX_CONTROL_RATE):
        raise ValueError(
            f"{name}: control rate must be between {MIN_CONTROL_RATE:g} and {MAX_CONTROL_RATE:g} Hz, "
            f"got {as_given(rate)}"
        )
    return rate


def blend_window(limits: DeviceLimits) -> float:
    """The time law's window (s): BLEND_S, or max_j a_j / j_j where the jerk limit asks for longer
    (the averaged s'' then changes by at most its range over one window)."""
    if limits.jerk is None:
        return BLEND_S
    return max(BLEND_S, max(a / j for a, j in zip(limits.acceleration, limits.jerk)))


def _kept(fn):
    """``fn`` (an lru_cache of one frozen argument) with its last argument's result kept by
    identity: hashing a frozen config or limits costs a few microseconds a swing, and a caller
    times its swings with one config."""
    last = [(object(), None)]  # one tuple, swapped whole: a reader never sees half an update

    @functools.wraps(fn)
    def get(arg):
        key, value = last[0]
        if key is not arg:
            value = fn(arg)
            last[0] = (arg, value)
        return value

    return get


@_kept
@functools.lru_cache(maxsize=8)
def _scalars(config):
    """scalar_params of a config, kept: a config is frozen, and the view costs as much as timing a
    swing (docs/decisions.md; read only here)."""
    from jaxexo.config import scalar_params

    return scalar_params(config)


@_kept
@functools.lru_cache(maxsize=8)
def _config_limits(config) -> DeviceLimits:
    """DeviceLimits.from_config, kept (a frozen config, frozen limits: building and validating
    them cost as much as a tenth of a swing's passes)."""
    return DeviceLimits.from_config(config)


@_kept
@functools.lru_cache(maxsize=8)
def _planned(device: DeviceLimits):
    """What a swing is timed against, kept per (frozen) limits: the planned limits, the time law's
    window, the passes' and the check's constraints."""
    planned = device.planned()
    return (
        planned,
        blend_window(planned),
        planned.constraints(SAFETY),
        planned.constraints(1.0 - CHECK_MARGIN),
    )


def _on_floor(points: np.ndarray) -> None:
    """Heights (points[:, 1]) within GROUND_ROUNDING of the floor set to it, in place: the forward
    kinematics' rounding, not a motion."""
    points[:, 1] = np.where(np.abs(points[:, 1]) < GROUND_ROUNDING, 0.0, points[:, 1])


def _is_trajectory(t) -> bool:
    return hasattr(t, "heel") and hasattr(t, "scene")


# --------------------------------------------------------------------------------------------
# Timing
# --------------------------------------------------------------------------------------------


def time_swing(
    traj, config, rate: float | None = None, limits: DeviceLimits | None = None
) -> TimedSwing:
    """One swing: ``time_swings([traj], ...)[0]``."""
    if not _is_trajectory(traj) or isinstance(traj, TrajectoryBatch):
        raise TypeError(
            f"traj: expected one Trajectory (from generate), got {type(traj).__name__}"
            + (" (time_swings times a batch)" if isinstance(traj, TrajectoryBatch) else "")
        )
    return time_swings([traj], config, rate, limits)[0]


def _checked_inputs(trajs, config, rate, limits):
    from jaxexo.config import Config

    if _is_trajectory(trajs) and not isinstance(trajs, TrajectoryBatch):
        raise TypeError(
            "trajs: expected a list of trajectories or a TrajectoryBatch, got one trajectory "
            "(time_swing times one)"
        )
    try:
        trajs = list(trajs)
    except TypeError:
        raise TypeError(
            f"trajs: expected a list of trajectories or a TrajectoryBatch, got "
            f"{type(trajs).__name__}"
        ) from None
    if not trajs:
        raise ValueError("trajs: need at least one trajectory")
    for i, t in enumerate(trajs):
        if not _is_trajectory(t):
            raise TypeError(
                f"trajs[{i}]: expected a Trajectory (from generate), got {type(t).__name__}"
            )
    if not isinstance(config, Config):
        raise TypeError(
            f"config: expected a jaxexo Config (the generator's .config), got {type(config).__name__}"
        )
    rate = check_rate(config.device.control_rate if rate is None else rate)
    limits = _config_limits(config) if limits is None else limits
    if not isinstance(limits, DeviceLimits):
        raise ValueError(f"limits: expected a DeviceLimits, got {type(limits).__name__}")
    for i, t in enumerate(trajs):
        h = np.asarray(t.heel, np.float64)
        if h.ndim != 2 or h.shape[1] != 2 or len(h) < 2 or not np.isfinite(h).all():
            raise ValueError(
                f"trajs[{i}].heel: expected a finite (N >= 2, 2) path, got shape {h.shape}"
            )
    for i, t in enumerate(trajs):
        _check_legs(t, config, f"trajs[{i}]")
    return trajs, rate, limits


def _check_legs(traj, config, where: str) -> None:
    """A swing is timed with the legs it was made for: its stance leg (hip, stance knee, pivot
    heel) and its foot (heel to toe) measured at the start against ``config.kinematics``; ValueError
    naming each differing field with both values. A swing without those points is not checked."""
    if not all(hasattr(traj, a) for a in ("hip", "knee_stance", "toe")):
        return
    # Python floats: three np.linalg.norm calls cost more than the rest of the check.
    hy, hz = (float(v) for v in traj.hip[0])
    ky, kz = (float(v) for v in traj.knee_stance[0])
    ty, tz = (float(v) for v in traj.toe[0])
    ey, ez = (float(v) for v in traj.heel[0])
    py = float(traj.scene.pivot_y)
    legs = {
        "thigh": math.sqrt((hy - ky) ** 2 + (hz - kz) ** 2),
        "shin": math.sqrt((ky - py) ** 2 + kz**2),
        "foot_length": math.sqrt((ty - ey) ** 2 + (tz - ez) ** 2),
    }
    config.kinematics.check_legs(
        legs,
        f"{where} was made for legs with",
        "time a swing with its generator's config (generator.config)",
    )


def time_swings(
    trajs, config, rate: float | None = None, limits: DeviceLimits | None = None, sp=None
) -> list[TimedSwing]:
    """Time every swing of ``trajs`` (Trajectory objects or a TrajectoryBatch) with the device
    limits (default: ``config.device``) and sample each at ``rate`` Hz (default:
    ``config.device.control_rate``). ``config`` also supplies the kinematics (pass the generator's
    ``config``). Paths, passes and checks run batched."""
    trajs, rate, device = _checked_inputs(trajs, config, rate, limits)
    sp = _scalars(config) if sp is None else sp
    # In chunks: a batch's temporaries grow with its swings' joint samples (the passes' grid, the
    # law and the check follow them), bounded per swing (_joint_samples), so per chunk too. A
    # batch times each swing as it is timed alone, so the chunks change no result.
    qs = [_joint_samples(sp, t) for t in trajs]
    return [
        sw
        for c in _chunks([len(q) for q in qs])
        for sw in _time_chunk([trajs[i] for i in c], sp, rate, device, [qs[i] for i in c])
    ]


def _chunks(sizes) -> list[range]:
    """Consecutive ranges of at most CHUNK swings and CHUNK_SAMPLES joint samples (or one swing)."""
    out, start, total = [], 0, 0
    for i, n in enumerate(sizes):
        if i > start and (i - start >= CHUNK or total + n > CHUNK_SAMPLES):
            out.append(range(start, i))
            start, total = i, 0
        total += n
    return out + [range(start, len(sizes))]


def _time_chunk(trajs, sp, rate: float, device: DeviceLimits, qs) -> list[TimedSwing]:
    """``time_swings`` of a few swings, checked, in one batch."""
    planned, window, passes, check = _planned(device)
    plans = _joint_paths(trajs, sp, qs)
    plans = _run_passes(plans, range(len(plans)), passes, window)
    t_opt = [p.law.duration for p in plans]
    for _ in range(LOCAL_PASSES):
        redo = []
        for i, p in enumerate(plans):
            # A law over the longest swing is not slowed further (final_law samples it faster).
            if (
                p.law.duration <= MAX_SWING_DURATION
                and peak_ratio(check, p.check.peaks) > LOCAL_FROM
            ):
                ratio = speed_ratio(check, p.check.bound)  # per piece of the curve
                plans[i] = replace(p, cap=lowered_cap(p, ratio))
                redo.append(i)
        if not redo:
            break
        plans = _run_passes(plans, redo, passes, window)
    checks = _path_checks(trajs, plans, sp)
    most = max_samples()  # once per batch: it reads a few /proc files
    finals = [final_law(p, planned, rate, t, most) for p, t in zip(plans, t_opt)]
    curves = [
        SwingCurve(p.path, f.law, float(t.scene.pivot_y), (sp.thigh, sp.shin), sp.foot_length)
        for t, p, f in zip(trajs, plans, finals)
    ]
    samples = _samples(curves, rate, most)
    return [
        _timed(
            trajs[i],
            _curve_verdict(trajs[i], plans[i], checks, i, finals[i].scale, sp),
            finals[i],
            curves[i],
            samples[i],
            device,
            rate,
        )
        for i in range(len(plans))
    ]


def _joint_samples(sp, traj) -> np.ndarray:
    """The joints (M, 4) the spline goes through: the trajectory's, with every sample interval whose
    joint step is over REFINE times the median subdivided along the heel's monotone cubic through
    the samples, the joints there by the kinematics. Near a leg
    straightening on the floor a small heel step is a large joint step (a square root); without
    the points in between, a cubic through that chord swings wide of it."""
    q = unwrapped(np.asarray(traj.joint_angles, np.float64))
    heel = np.asarray(traj.heel, np.float64)
    # A dense path (n_points in the thousands) is thinned first (curve.MAX_PATH_SAMPLES).
    keep = thinned(len(q))
    q, heel = np.take(q, keep, axis=0), np.take(heel, keep, axis=0)  # rows (take: no fancy index)
    step = np.linalg.norm(np.diff(q, axis=0), axis=1)
    moving = step[step > 0]
    mid = median(moving) if moving.size else 0.0
    long = np.flatnonzero(step > REFINE * mid) if moving.size else []
    if not len(long):
        return q
    parts = np.ones(len(step), np.int64)
    # Parts no shorter than 1/REFINE_BUDGET of the path: a path that mostly stands still (a median
    # step of rounding noise) would otherwise ask for billions; so at most REFINE_BUDGET + N
    # samples (far more than a normal swing needs: REFINE_BUDGET).
    unit = max(mid, float(step.sum()) / REFINE_BUDGET)
    parts[long] = np.ceil(step[long] / unit).astype(np.int64)
    i = np.repeat(np.arange(len(step)), parts)
    x = (np.arange(len(i)) - np.repeat(np.cumsum(parts) - parts, parts)) / parts[i]
    # Along the heel's monotone cubic through the samples (C1, never beyond the samples), graded
    # towards both ends of the interval (a smoothstep), where a straightening leg moves fastest.
    pts = pchip_eval(heel, pchip_slopes(heel), np.append(i + x * x * (3.0 - 2.0 * x), len(step)))
    fine = unwrapped(leg_angles(sp, traj.scene.pivot_y, pts))
    fine += q[0] - fine[0]  # the same branch of each angle as the trajectory's (whole turns)
    # The trajectory's own joints at its samples (the same kinematics; kept exactly).
    fine[np.concatenate([np.cumsum(parts) - parts, [len(pts) - 1]])] = q
    return fine


def _joint_paths(trajs, sp, samples=None) -> list[Plan]:
    """The joint paths of the swings, each in the few pieces its geometry needs
    (knots.few_knot_paths), and their passes' grids (``grid_size``); ``samples``: each swing's
    ``_joint_samples`` when known. Each swing's path is its own: a batch gives each what it gets
    alone (the batch's splines and evaluations are the single swing's, bit for bit)."""
    qs, ss = [], []
    for j, t in enumerate(trajs):
        q = _joint_samples(sp, t) if samples is None else samples[j]
        q = np.take(q, distinct_samples(q), axis=0)
        qs.append(q)
        ss.append(chord_knots(q))
    paths = few_knot_paths(qs, ss, (sp.thigh, sp.shin))
    grids = [np.linspace(0.0, 1.0, grid_size(len(p.knots) - 1)) for p in paths]
    plans = []
    for p, s, (q, dq, ddq) in zip(paths, grids, paths_at(paths, grids, 2)):
        k = len(s)
        view = GridView(s, q[None], dq[None], ddq[None])
        plans.append(Plan(p, view, np.full(k, np.inf), np.zeros(k), None))
    return plans


def grid_size(pieces: int) -> int:
    """The passes' grid points for a joint path of ``pieces`` pieces: GRID_PER_KNOT per piece, at
    least GRID_MIN, rounded up to a multiple of GRID_STEP (a batch's passes run per grid size)."""
    k = max(GRID_MIN, GRID_PER_KNOT * pieces)
    return -(-k // GRID_STEP) * GRID_STEP + 1


def _run_passes(plans, idx, constraints, window: float) -> list[Plan]:
    """The passes for plans[idx], batched per grid size; returns the plans with new laws."""
    plans = list(plans)
    idx = list(idx)
    sizes = np.array([len(plans[i].view.s) for i in idx])
    for k in np.unique(sizes):
        sub = [i for i, n in zip(idx, sizes) if n == k]
        view = GridView(
            plans[sub[0]].view.s,
            *(np.concatenate([getattr(plans[i].view, f) for i in sub]) for f in ("q", "dq", "ddq")),
        )
        cap, rows = passes_rows(constraints, view, np.stack([plans[i].cap for i in sub]))
        x, floor = topp(rows, 1.0 / (k - 1), cap, both_ends=True)
        for j, i in enumerate(sub):
            law = law_from_speeds(view.s, x[j], floor[j], window, BLEND_FRACTION)
            plans[i] = replace(plans[i], x=x[j], law=law)
    return with_bounds(plans, idx)


@dataclass(frozen=True)
class _PathChecks:
    """``_path_checks`` of B curves: ``measure``'s record of their heel polylines (B, N, 2), padded
    to a common length N, at path parameters s (B, N), and where each curve's joints first leave
    their range (s; None: never)."""

    measured: Measured
    heel: np.ndarray
    s: np.ndarray
    outside: list


def _path_checks(trajs, plans, sp) -> _PathChecks:
    """The safe-swing checks of each curve, batched: the heel at ``curve.check_points`` (every
    knot, and spaced so that the curve strays at most CURVE_TOL from the polyline through them),
    measured as that polyline less CURVE_TOL, its clearances by ``swept.polyline_clearances`` (or
    the exact functions where that does not apply). Paths are padded with their last point to a
    common length (a repeated point adds no motion; its moves are not the closest)."""
    lengths = (sp.thigh, sp.shin)
    heels, grids, outside, clear = [], [], [], []
    for t, p in zip(trajs, plans):
        s, q, h = check_points(lengths, t.scene.pivot_y, p.path, CURVE_TOL)
        # The joint range on the joints the drives follow (the verdict's own angles are the
        # inverse kinematics of the heel, with the hip of eq 2.42).
        bad = joints_outside(q, sp)
        outside.append(float(s[np.argmax(bad)]) if bad.any() else None)
        c = polyline_clearances(h, sp.foot_length, t.scene.outline)
        if c is None:
            c = tuple(x[0] for x in path_clearances(sp.foot_length, h[None], [t.scene]))
        heels.append(h)
        grids.append(s)
        clear.append(c)
    if len(heels) == 1:  # nothing to pad
        padded, pad = heels[0][None], grids[0][None]
        c, sw = (x[None] for x in clear[0])
    else:
        n = max(len(h) for h in heels)
        padded = np.stack([np.concatenate([h, np.repeat(h[-1:], n - len(h), 0)]) for h in heels])
        pad = np.stack([np.concatenate([g, np.ones(n - len(g))]) for g in grids])
        c = np.stack([np.concatenate([a, np.repeat(a[-1:], n - len(a))]) for a, _ in clear])
        sw = np.stack([np.concatenate([b, np.full(n - 1 - len(b), np.inf)]) for _, b in clear])
    scenes = [t.scene for t in trajs]
    m = measure_paths(sp, padded, scenes, np.full(len(trajs), CURVE_TOL), (c, sw))
    return _PathChecks(m, padded, pad, outside)


def _curve_verdict(traj, p: Plan, chk: _PathChecks, j: int, scale: float, sp) -> TrajectoryChecks:
    """Curve j's path checks (``_path_checks``), with their times on the final law."""
    m, outside = chk.measured, chk.outside[j]
    s_chk, t_chk = p.check.s, p.check.t
    reasons = ()
    if not m.ok[j]:  # the times only where a reason says them
        t_grid = np.interp(chk.s[j], s_chk, t_chk) * scale
        reasons = failure_reasons(m, j, chk.heel[j], traj.scene.goal_y, t_grid, sp)
    if outside is not None and m.joint_limits_ok[j]:
        t_out = float(np.interp(outside, s_chk, t_chk) * scale)
        reasons += (f"the joints leave their range at t={t_out:.3f} s",)
    checks = TrajectoryChecks.row(m, j, reasons)
    return checks if outside is None else replace(checks, joint_limits_ok=False)


def _timed(traj, checks, f: FinalLaw, curve, samples, device, rate) -> TimedSwing:
    return TimedSwing(
        method=traj.method,
        scene=traj.scene,
        rate=rate,
        limits=device,
        checks=checks,
        within_limits=f.within,
        peak_velocity=f.peaks[0],
        peak_acceleration=f.peaks[1],
        slowdown=f.slow,
        peak_jerk=f.peaks[2],
        notes=tuple(getattr(traj, "notes", ())) + f.notes,
        curve=curve,
        **samples.columns(),
    )


# The columns of a TimedSwing's samples that the curve's state at the sample times gives.
_STATE_COLUMNS = (
    "heel",
    "toe",
    "hip",
    "knee_swing",
    "knee_stance",
    "joint_angles",
    "joint_velocity",
    "joint_acceleration",
    "heel_velocity",
    "heel_acceleration",
    "path_parameter",
    "joint_jerk",
)


@dataclass(frozen=True)
class _Samples:
    """One curve's samples: its duration (s), the sample times (n,) and the curve's state there
    (the last sample at touch-down)."""

    duration: float
    time: np.ndarray
    state: CurveState

    def columns(self) -> dict:
        """TimedSwing's sample fields, by name."""
        st = self.state
        return {"duration": self.duration, "time": self.time} | {
            k: getattr(st, k) for k in _STATE_COLUMNS
        }


def _samples(curves, rate: float, most: int | None = None) -> list[_Samples]:
    """Each curve's samples at ``rate``: t = k / rate from 0 to the first period at or after
    touch-down (all curves in one evaluation); ``most``: ``max_samples()`` when known."""
    most = max_samples() if most is None else most
    times = []
    for c in curves:
        periods = max(2, math.ceil(c.duration * rate - 1e-9))
        if not periods < most:
            raise ValueError(
                f"rate: a {c.duration:.4g} s swing at {rate:g} Hz needs {periods} samples, more "
                f"than half the memory this process may use holds ({most}); lower the rate"
            )
        times.append(np.arange(periods + 1) / rate)
    # the last sample is at or after touch-down: the legs at rest in the landing pose
    at = [np.concatenate([t[:-1], [c.duration]]) for t, c in zip(times, curves)]
    out = []
    for c, t, st in zip(curves, times, curves_at(curves, at, heel_jerk=False)):
        for h in (st.heel, st.toe):  # the forward kinematics' rounding at the floor
            _on_floor(h)
        out.append(_Samples(c.duration, t, st))
    return out


# --------------------------------------------------------------------------------------------
# Figures of a timed swing
# --------------------------------------------------------------------------------------------


def _finite_differences(q: np.ndarray, dt: float):
    # Velocity, acceleration and jerk of samples at period dt: first, second and third differences.
    return (
        np.diff(q, axis=0) / dt,
        np.diff(q, n=2, axis=0) / (dt * dt),
        np.diff(q, n=3, axis=0) / dt**3,
    )


def joint_jerk(swing: TimedSwing) -> float:
    """Integrated squared jerk of a timed swing's four joint angles (rad^2/s^5): the third finite
    difference of the exported samples at the control rate, squared, summed over the joints, times
    the period. What a wearer feels as the smoothness of the delivered motion."""
    q = np.asarray(swing.joint_angles, dtype=np.float64)
    if len(q) < 4:
        return 0.0
    dt = 1.0 / swing.rate
    j = np.diff(q, n=3, axis=0) / dt**3
    return float((j * j).sum() * dt)


def uniform_peaks(traj) -> tuple[np.ndarray, np.ndarray]:
    """Peak |joint velocity| (4,) and |acceleration| (4,) of a trajectory as generated, at its own
    uniform time stamps (finite differences), for comparison with a timed swing."""
    dt = float(traj.time[1] - traj.time[0])
    fv, fa, _ = _finite_differences(np.unwrap(np.asarray(traj.joint_angles), axis=0), dt)
    return np.abs(fv).max(axis=0), np.abs(fa).max(axis=0)


__all__ = [
    "DeviceLimits",
    "TimedSwing",
    "time_swing",
    "time_swings",
    "joint_jerk",
    "leg_angles",
    "uniform_peaks",
    "JOINT_NAMES",
]
