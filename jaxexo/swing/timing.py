"""Device-ready swings: the shortest rest-to-rest timing of a swing path within joint velocity and
acceleration limits, sampled at a controller's rate (NumPy only).

The generators (RL, CFFTG) produce *paths*: heel positions with uniform time stamps over a fixed
duration, which ask the joint drives for thousands of deg/s. This module gives any path a time law
s(t) (s in [0, 1] along the path) such that every joint q_j(s(t)) of both legs obeys
|dq/dt| = |q'(s) s'| <= v_max and |d2q/dt2| = |q''(s) s'^2 + q'(s) s''| <= a_max, starting and
ending at rest (zero joint velocity AND acceleration), so the comparison of generators is about their
paths. Neither the thesis nor CFFTG times a swing; the limits come from the config's [device]
section (jaxexo.config.DeviceConfig).

Method (time-optimal up to the end blends and a safety factor, not a fixed time-law shape; a fixed
shape such as a quintic smoothstep must run the whole path at the speed its worst point allows,
while a variable-speed law slows only where the path bends in joint space):

1. Path: the heel samples (N, 2) are interpolated by a monotone cubic in the sample index (PCHIP,
   C1), which never overshoots a sample, so the heel stays above the ground where the smoothed
   path rests on it, and re-parametrised by the arc length s of the joint path (see
   ``_arc_length_map``: in any heel parameter the joints move like a square root at a straight-leg
   lift-off, and a generator's own parameter may crawl, as CFFTG's polynomials do near the ends);
   the joints are the project's kinematics (jaxexo.physics.kinematics,
   thesis eq 2.4-2.11, 2.42, 2.49) of the interpolated heel on a fine s grid (FINE_PER_SAMPLE
   points per sample interval), differentiated there by central differences (q', q'').
2. TOPP (jaxexo.swing.time_law): on that grid, with x = s'^2, the velocity limits cap x by (v_j / |q'_j|)^2 and the
   acceleration limits make the admissible s'' an interval [L(x), U(x)]; a backward pass from rest
   at the end decelerating at L bounds the speeds from which the end can still be reached, and a
   forward pass from rest accelerates at U under that bound (the numerical-integration time-optimal
   path parametrisation of Bobrow 1985 / Pfeiffer-Johanni 1987, passes ordered as in TOPP-RA), with
   the limits shrunk by SAFETY. Time per grid cell assumes constant s'' in the cell.
3. Rest with zero acceleration: the optimal law starts with a jump in s''; its speed s'(t) is
   averaged over a sliding window of BLEND_S = 30 ms, or a / j where a jerk limit j asks for longer
   (``blend_window``; at most a tenth of the swing; a box filter),
   which keeps s' and s'' bounded by the averaged values, adds the window to the duration, and
   makes s'' = 0 at both ends (s''(t) = (s'(t) - s'(t - w)) / w, zero where both speeds are the
   rest speed).
4. Exported samples: the law is sampled at the control rate (the duration rounded up to whole
   periods, never below ``min_duration``); positions come from the path and kinematics, velocities
   and accelerations from the chain rule; then every exported sample is checked, both the
   chain-rule columns and finite differences of the exported positions at the control rate (the
   third difference against the jerk limit), against (1 - tracking headroom) of each limit. Where
   samples exceed a limit (a bend tighter than the grid resolves, a reversal of the joints), the
   bound on s'^2 is lowered around them by the excess and the passes run again (LOCAL_PASSES
   times, all such swings in one batch); after that the whole law is slowed uniformly (t -> k t
   scales velocities by 1/k, accelerations by 1/k^2), which keeps the ends at rest. So the
   guarantee (every exported sample within the limits, ``within_limits``) is measured on what is
   exported, not assumed from the discretised passes.

Known cost: the path interpolant is C1, so q'' jumps at the path's samples; at higher control rates
finite differences resolve those jumps and the corrections lengthen a swing (docs/device-timing.md).

Units: m, rad, s; limits in rad/s and rad/s^2, one value per joint of JOINT_NAMES (hip and knee
limits apply to both legs).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from jaxexo.config import (
    MAX_CONTROL_RATE,
    MAX_SWING_DURATION,
    MAX_TRACKING_HEADROOM,
    MIN_CONTROL_RATE,
)
from jaxexo.physics import kinematics
from jaxexo.physics.scene import Scene
from jaxexo.swing.export import (
    JOINT_NAMES,
    timed_dict,
    timed_table,
    write_timed_csv,
    write_timed_json,
)
from jaxexo.swing.time_law import BLEND_S, TimeLaw, pchip_eval, pchip_slopes, time_law, topp
from jaxexo.swing.trajectory import (
    TrajectoryBatch,
    TrajectoryChecks,
    failure_reasons,
    measure_paths,
)

FINE_PER_SAMPLE = 8  # fine s-grid points per interval of the path's samples
SAFETY = 0.95  # the TOPP passes use this fraction of each limit
CHECK_MARGIN = 1e-3  # exported samples must stay within (1 - this) of each limit
LOCAL_PASSES = 6  # local corrections of the law where exported samples exceed a limit ...
MAX_SLOWDOWNS = 12  # ... then uniform slow-downs (the safety net)
ARC_TABLE_PER_SAMPLE = 32  # arc-length table points per sample interval
BYTES_PER_SAMPLE = 1024  # twice what timing holds per exported sample (docs/reliability.md)


@dataclass(frozen=True)
class DeviceLimits:
    """Peak joint velocity (rad/s), acceleration (rad/s^2) and jerk (rad/s^3; None: unbounded) per
    joint of JOINT_NAMES, the shortest swing allowed (s), and the tracking headroom: the fraction of
    each limit the timed reference leaves free for the feedback controller (a swing is timed, and its
    exported samples checked, against the ``planned`` limits, (1 - headroom) of these)."""

    velocity: tuple[float, float, float, float]
    acceleration: tuple[float, float, float, float]
    min_duration: float = 0.0
    jerk: tuple[float, float, float, float] | None = None
    headroom: float = 0.0

    def __post_init__(self):
        h = self.headroom
        if (
            isinstance(h, bool)
            or not isinstance(h, (int, float))
            or not (0.0 <= h <= MAX_TRACKING_HEADROOM)
        ):
            raise ValueError(
                f"limits.headroom: must be a number in [0, {MAX_TRACKING_HEADROOM:g}] (a fraction of each limit), "
                f"got {h!r}"
            )
        object.__setattr__(self, "headroom", float(h))
        n = len(JOINT_NAMES)
        for name in ("velocity", "acceleration", "jerk"):
            v = getattr(self, name)
            if v is None and name == "jerk":
                continue
            try:
                arr = np.asarray(v, dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(f"limits.{name}: expected {n} numbers, got {v!r}") from None
            if arr.shape != (n,):
                raise ValueError(
                    f"limits.{name}: expected {n} numbers ({', '.join(JOINT_NAMES)}), got {v!r}"
                )
            if not np.all(np.isfinite(arr)) or np.any(arr <= 0):
                raise ValueError(f"limits.{name}: every limit must be finite and > 0, got {v!r}")
            object.__setattr__(self, name, tuple(float(x) for x in arr))
        d = self.min_duration
        if isinstance(d, bool) or not isinstance(d, (int, float)) or not math.isfinite(d) or d < 0:
            raise ValueError(f"limits.min_duration: must be a finite number >= 0 (s), got {d!r}")
        object.__setattr__(self, "min_duration", float(d))

    @classmethod
    def from_config(cls, config) -> "DeviceLimits":
        """The [device] section's (hip, knee) limits, applied to both legs."""
        dev = config.device
        (vh, vk), (ah, ak), (jh, jk) = dev.joint_velocity, dev.joint_acceleration, dev.joint_jerk
        return cls(
            (vh, vk, vh, vk),
            (ah, ak, ah, ak),
            dev.min_swing_duration,
            (jh, jk, jh, jk),
            dev.tracking_headroom,
        )

    def scaled(
        self, velocity: float = 1.0, acceleration: float = 1.0, jerk: float | None = None
    ) -> "DeviceLimits":
        """The limits times these factors (jerk: by the acceleration's factor unless given)."""
        jerk = acceleration if jerk is None else jerk
        return DeviceLimits(
            tuple(velocity * v for v in self.velocity),
            tuple(acceleration * a for a in self.acceleration),
            self.min_duration,
            None if self.jerk is None else tuple(jerk * j for j in self.jerk),
            self.headroom,
        )

    def planned(self) -> "DeviceLimits":
        """What a timed reference may use: (1 - headroom) of each limit, no headroom left to take."""
        f = 1.0 - self.headroom
        return DeviceLimits(
            tuple(f * v for v in self.velocity),
            tuple(f * a for a in self.acceleration),
            self.min_duration,
            None if self.jerk is None else tuple(f * j for j in self.jerk),
            0.0,
        )

    def to_dict(self) -> dict:
        return {
            "joints": list(JOINT_NAMES),
            "joint_velocity_rad_s": list(self.velocity),
            "joint_acceleration_rad_s2": list(self.acceleration),
            "joint_jerk_rad_s3": None if self.jerk is None else list(self.jerk),
            "tracking_headroom": self.headroom,
            "min_duration_s": self.min_duration,
        }


@dataclass(frozen=True)
class TimedSwing:
    """A swing sampled at a control rate: one row per control period from lift-off (t = 0) to
    touch-down (t = duration), both at rest. Checks are made on these samples."""

    method: str
    scene: Scene
    rate: float  # Hz
    duration: float  # s
    limits: DeviceLimits
    time: np.ndarray  # (n,) s
    heel: np.ndarray  # (n, 2) m
    toe: np.ndarray
    hip: np.ndarray
    knee_swing: np.ndarray
    knee_stance: np.ndarray
    joint_angles: np.ndarray  # (n, 4) rad, JOINT_NAMES
    joint_velocity: np.ndarray  # (n, 4) rad/s (chain rule: q'(s) s')
    joint_acceleration: np.ndarray  # (n, 4) rad/s^2 (q''(s) s'^2 + q'(s) s'')
    heel_velocity: np.ndarray  # (n, 2) m/s, the same chain rule on the heel path
    heel_acceleration: np.ndarray  # (n, 2) m/s^2
    path_parameter: np.ndarray  # (n,) s(t) in [0, 1]
    checks: (
        TrajectoryChecks  # path checks (goal, clearance, joint range, leg length) on these samples
    )
    within_limits: bool  # chain-rule columns and finite differences within the limits
    peak_velocity: np.ndarray  # (4,) rad/s, max of |column| and |finite difference| per joint
    peak_acceleration: np.ndarray  # (4,) rad/s^2, likewise
    slowdown: float  # uniform slow-down applied after the TOPP passes and local corrections (>= 1)
    peak_jerk: np.ndarray | None = None  # (4,) rad/s^3, the third finite difference of the samples
    notes: tuple[str, ...] = field(default=())

    @property
    def ok(self) -> bool:
        return self.checks.ok and self.within_limits

    @property
    def reasons(self) -> tuple[str, ...]:
        extra = (
            ()
            if self.within_limits
            else (
                "joint velocity/acceleration/jerk limits (less the tracking headroom) exceeded on the exported samples",
            )
        )
        return self.checks.reasons + extra

    def table(self) -> np.ndarray:
        return timed_table(self)

    def to_csv(self, path=None) -> str:
        return write_timed_csv(self, path)

    def to_dict(self) -> dict:
        return timed_dict(self)

    def to_json(self, path=None) -> str:
        return write_timed_json(self, path)


# --------------------------------------------------------------------------------------------
# Path interpolation and joint paths
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# Timing a swing
# --------------------------------------------------------------------------------------------


def _arc_length_map(sp, pivot_y: float, heel: np.ndarray, slopes: np.ndarray):
    """(s, v) table: joint-space arc-length fraction s against v, the heel's sample coordinate
    u = (N - 1) smoothstep(v).

    Why joint space: a straight leg makes the joints move like the square root of the heel's
    displacement at lift-off and touch-down (the knee must bend at once to lift the heel), so in
    any heel parameter q'(s) is unbounded at the ends and no smooth time law can start there with
    bounded joint acceleration; along the joint path itself |q'(s)| is constant and q'' is its
    curvature. The table is dense near the ends (u = smoothstep of a uniform grid), where s grows
    like the square root of u."""
    n = len(heel)
    v = np.linspace(0.0, 1.0, ARC_TABLE_PER_SAMPLE * (n - 1) + 1)
    u = (n - 1) * v * v * (3.0 - 2.0 * v)
    q = np.unwrap(leg_angles(sp, pivot_y, pchip_eval(heel, slopes, u)), axis=0)
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q, axis=0), axis=1))])
    if length[-1] <= 0:
        raise ValueError("trajectory: the joints do not move along this path; nothing to time")
    # Stretches where no joint moves get a sliver of length so that s -> u is a function.
    length += 1e-9 * length[-1] * v
    return length / length[-1], v


def _heel_at(heel, slopes, table, s):
    """Heel at joint-arc-length fractions s: linear in v between table points (s is about linear in
    v near the ends too, where it is about the square root of u)."""
    v = np.interp(s, table[0], table[1])
    return pchip_eval(heel, slopes, (len(heel) - 1) * v * v * (3.0 - 2.0 * v))


def _joint_paths(sp, pivot_y: float, heel: np.ndarray):
    """The path by joint-space arc length: fine s grid (K,), the interpolation data, and the joint
    angles' s-derivatives (K, 4) each."""
    n = len(heel)
    k = FINE_PER_SAMPLE * (n - 1) + 1
    s = np.linspace(0.0, 1.0, k)
    m = pchip_slopes(heel)
    table = _arc_length_map(sp, pivot_y, heel, m)
    h = _heel_at(heel, m, table, s)
    q = np.unwrap(leg_angles(sp, pivot_y, h), axis=0)
    ds = 1.0 / (k - 1)
    dq = np.gradient(q, ds, axis=0, edge_order=2)
    ddq = np.gradient(dq, ds, axis=0, edge_order=2)
    dh = np.gradient(h, ds, axis=0, edge_order=2)
    ddh = np.gradient(dh, ds, axis=0, edge_order=2)
    return s, (m, table, dh, ddh), dq, ddq


def _finite_differences(q: np.ndarray, dt: float):
    # Velocity, acceleration and jerk of samples at period dt: first, second and third differences.
    return (
        np.diff(q, axis=0) / dt,
        np.diff(q, n=2, axis=0) / (dt * dt),
        np.diff(q, n=3, axis=0) / dt**3,
    )


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
            f"got {rate:g}"
        )
    return rate


def time_swings(
    trajs, config, rate: float | None = None, limits: DeviceLimits | None = None, sp=None
) -> list[TimedSwing]:
    """Time every swing of ``trajs`` (Trajectory objects or a TrajectoryBatch) with the device
    limits (default: ``config.device``) and sample each at ``rate`` Hz (default:
    ``config.device.control_rate``). ``config`` also supplies the kinematics (pass the generator's
    ``config``). The TOPP passes run on all swings at once."""
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
    limits = DeviceLimits.from_config(config) if limits is None else limits
    if not isinstance(limits, DeviceLimits):
        raise ValueError(f"limits: expected a DeviceLimits, got {type(limits).__name__}")
    sp = _scalars(config) if sp is None else sp
    device, limits = limits, limits.planned()
    vmax = np.asarray(limits.velocity)
    amax = np.asarray(limits.acceleration)
    blend = blend_window(limits)
    heels = [np.asarray(t.heel, np.float64) for t in trajs]
    for i, h in enumerate(heels):
        if h.ndim != 2 or h.shape[1] != 2 or len(h) < 2 or not np.all(np.isfinite(h)):
            raise ValueError(
                f"trajs[{i}].heel: expected a finite (N >= 2, 2) path, got shape {h.shape}"
            )
    paths = [_joint_paths(sp, t.scene.pivot_y, h) for t, h in zip(trajs, heels)]
    caps = [np.full(len(p[0]), np.inf) for p in paths]
    laws = _topp_laws(paths, list(range(len(paths))), caps, vmax, amax, blend)
    t_opt = [law.duration for law in laws]
    slow = [1.0] * len(trajs)  # uniform slow-down beyond the (locally corrected) TOPP law
    evals: list = [None] * len(trajs)
    todo = list(range(len(trajs)))
    stuck: set[int] = set()
    for it in range(LOCAL_PASSES + MAX_SLOWDOWNS):
        redo = []
        for i in todo:
            e = evals[i] = _evaluate(
                trajs[i], heels[i], paths[i], laws[i], slow[i], sp, limits, rate
            )
            if e["ratio"] <= 1.0 - CHECK_MARGIN:
                continue
            if it < LOCAL_PASSES:
                _lower_cap(caps[i], paths[i][0], e, limits)
                redo.append(i)
            else:
                # Never slower than the longest swing a config may ask for: a path no slow-down helps
                # (a jump in the joints, a heel out of reach) ends there, not within the limits.
                longest = max(1.0, MAX_SWING_DURATION / laws[i].duration)
                # at least one control period more: the samples span whole periods, so a smaller
                # slow-down would export the same samples again
                base = laws[i].duration * max(1.0, limits.min_duration / laws[i].duration)
                one_more = (e["t"][-1] + 1.0 / rate) / base
                slowed = min(
                    max(slow[i] * e["ratio"] / (1.0 - 2.0 * CHECK_MARGIN), one_more), longest
                )
                if slowed == slow[i]:
                    stuck.add(i)
                slow[i] = slowed
        if redo:
            for i, law in zip(redo, _topp_laws(paths, redo, caps, vmax, amax, blend)):
                laws[i] = law
        todo = [i for i in todo if evals[i]["ratio"] > 1.0 - CHECK_MARGIN and i not in stuck]
        if not todo:
            break
    return [
        _finish(trajs[i], evals[i], sp, device, limits, rate, t_opt[i], slow[i])
        for i in range(len(trajs))
    ]


def blend_window(limits: DeviceLimits) -> float:
    """The box filter's window (s) on s'(t): BLEND_S, or longer where a jerk limit asks for it. The
    filtered s'' changes by at most its range over one window, so a joint's jerk from the time law
    is about q' d3s/dt3 <= a / w: w = max_j a_j / j_j keeps it at the limit from rest."""
    if limits.jerk is None:
        return BLEND_S
    return max(BLEND_S, max(a / j for a, j in zip(limits.acceleration, limits.jerk)))


@functools.lru_cache(maxsize=8)
def _scalars(config):
    """scalar_params of a config, kept: a config is frozen, and the view costs as much as timing a
    swing (docs/decisions.md; read only here)."""
    from jaxexo.config import scalar_params

    return scalar_params(config)


def _topp_laws(paths, idx, caps, vmax, amax, blend: float) -> list[TimeLaw]:
    """Time laws of paths[idx], one batched TOPP per grid size."""
    out = {}
    sizes = np.array([len(paths[i][0]) for i in idx])
    for k in np.unique(sizes):
        sub = [i for i, n in zip(idx, sizes) if n == k]
        dq = np.stack([paths[i][2] for i in sub])
        ddq = np.stack([paths[i][3] for i in sub])
        cap = np.stack([caps[i] for i in sub])
        x, floor = topp(dq, ddq, SAFETY * vmax, SAFETY * amax, 1.0 / (k - 1), cap)
        for j, i in enumerate(sub):
            out[i] = time_law(paths[i][0], x[j], floor[j], blend_s=blend)
    return [out[i] for i in idx]


def max_samples() -> int:
    """The most samples one timed swing may have: half the machine's memory (8 GiB if unknown) at
    BYTES_PER_SAMPLE, and at least 100,000 (10 s at 10 kHz)."""
    from jaxexo.config.memory import machine_memory_bytes

    return max(100_000, (machine_memory_bytes() or 8 * 2**30) // 2 // BYTES_PER_SAMPLE)


def _is_trajectory(t) -> bool:
    return hasattr(t, "heel") and hasattr(t, "scene")


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


def _evaluate(
    traj, heel, path, law: TimeLaw, slow: float, sp, limits: DeviceLimits, rate: float
) -> dict:
    """The exported samples of a law (stretched to the minimum duration and whole control periods,
    and by ``slow``), and how far they are from the limits: ``ratio`` the largest of |v| / v_max and
    sqrt(|a| / a_max) over the chain-rule columns and the finite differences."""
    s_grid, (slopes, table, dh, ddh), dq, ddq = path
    vmax = np.asarray(limits.velocity)
    amax = np.asarray(limits.acceleration)
    scale = max(1.0, limits.min_duration / law.duration) * slow
    cur = law.slowed(scale)
    n = cur.duration * rate
    if not n < max_samples():  # bounded before anything is allocated (an inf or NaN is refused too)
        raise ValueError(
            f"rate: a {cur.duration:.4g} s swing at {rate:g} Hz needs {n:.4g} samples, more than "
            f"half this machine's memory holds ({max_samples()}); lower the rate or check the device "
            "limits (joint_velocity, joint_acceleration, min_swing_duration)"
        )
    periods = max(2, math.ceil(n - 1e-9))
    cur = cur.slowed(periods / (cur.duration * rate))  # whole control periods: never faster
    t = np.arange(periods + 1) / rate
    s, sd, sdd = cur.at(t)
    s[0], s[-1] = 0.0, 1.0
    h = _heel_at(heel, slopes, table, s)
    h[0], h[-1] = heel[0], heel[-1]
    q = leg_angles(sp, traj.scene.pivot_y, h)
    dq_t = np.stack([np.interp(s, s_grid, dq[:, j]) for j in range(dq.shape[1])], axis=-1)
    ddq_t = np.stack([np.interp(s, s_grid, ddq[:, j]) for j in range(ddq.shape[1])], axis=-1)
    vel = dq_t * sd[:, None]
    acc = ddq_t * (sd * sd)[:, None] + dq_t * sdd[:, None]
    vel[0] = vel[-1] = acc[0] = acc[-1] = 0.0  # s' = s'' = 0 exactly at the ends
    dh_t = np.stack([np.interp(s, s_grid, dh[:, j]) for j in range(2)], axis=-1)
    ddh_t = np.stack([np.interp(s, s_grid, ddh[:, j]) for j in range(2)], axis=-1)
    heel_vel = dh_t * sd[:, None]
    heel_acc = ddh_t * (sd * sd)[:, None] + dh_t * sdd[:, None]
    heel_vel[0] = heel_vel[-1] = heel_acc[0] = heel_acc[-1] = 0.0
    fv, fa, fj = _finite_differences(np.unwrap(q, axis=0), 1.0 / rate)
    peak_v = np.maximum(np.abs(vel).max(axis=0), np.abs(fv).max(axis=0))
    peak_a = np.maximum(np.abs(acc).max(axis=0), np.abs(fa).max(axis=0))
    peak_j = np.abs(fj).max(axis=0) if len(fj) else np.zeros(len(vmax))
    # Slowing the law by k scales velocity by 1/k, acceleration by 1/k^2, jerk by 1/k^3.
    ratio = max(float(np.max(peak_v / vmax)), math.sqrt(float(np.max(peak_a / amax))))
    if limits.jerk is not None:
        ratio = max(ratio, float(np.max(peak_j / np.asarray(limits.jerk))) ** (1.0 / 3.0))
    return {
        "t": t,
        "s": s,
        "sd": sd / scale,
        "h": h,
        "vel": vel,
        "acc": acc,
        "fv": fv,
        "fa": fa,
        "heel_vel": heel_vel,
        "heel_acc": heel_acc,
        "fj": fj,
        "peak_v": peak_v,
        "peak_a": peak_a,
        "peak_j": peak_j,
        "ratio": ratio,
    }


def _excess(x: np.ndarray, power: float) -> np.ndarray:
    """Per sample, the factor by which the speed must fall for ratios x (samples, joints) of a
    quantity that scales with the speed to this power on a smooth path: x^(1 / power) up to the
    limit, x itself beyond it (at a kink it scales with the speed alone)."""
    x = x.max(axis=1)
    return np.maximum(x ** (1.0 / power), x)


def _lower_cap(cap, s_grid, e: dict, limits: DeviceLimits) -> None:
    """Where exported samples exceed a limit (a bend too tight for the grid's q''), lower the speed
    bound around them by the excess; the passes are then run again for this path."""
    vel, acc, fv, fa, s = e["vel"], e["acc"], e["fv"], e["fa"], e["s"]
    vmax, amax = np.asarray(limits.velocity), np.asarray(limits.acceleration)
    r = np.maximum(np.abs(vel) / vmax, np.sqrt(np.abs(acc) / amax)).max(axis=1)
    rv = (np.abs(fv) / vmax).max(axis=1)
    # A kink or a C1 knot of the path gives finite differences that fall only linearly with the
    # speed, not with its square: above the limit the excess is taken linearly (one pass suffices).
    ra = _excess(np.abs(fa) / amax, 2.0)
    r[:-1] = np.maximum(r[:-1], rv)
    r[1:] = np.maximum(r[1:], rv)
    for k in range(3):
        r[k : len(r) - 2 + k] = np.maximum(r[k : len(r) - 2 + k], ra)
    if limits.jerk is not None and len(e["fj"]):
        rj = _excess(np.abs(e["fj"]) / np.asarray(limits.jerk), 3.0)
        for k in range(4):
            r[k : len(r) - 3 + k] = np.maximum(r[k : len(r) - 3 + k], rj)
    x_now = np.interp(s_grid, s, e["sd"] ** 2)  # the law's own s'^2 (before stretching)
    k = np.flatnonzero(r > 1.0 - CHECK_MARGIN)
    if k.size == 0:
        return
    # Each flagged sample k lowers the cap on the grid points in [s[k-2], s[k+2]] to x (c / r[k])^2:
    # all (sample, grid point) pairs at once, then the smallest per grid point (min is exact, so this
    # is the per-sample loop's result bit for bit). The square is the scalar pow the loop took (NumPy's
    # array square can differ from it in the last bit).
    # Widened by one grid point each way: at high rates the samples around k can fall inside one
    # grid cell, whose ends then bound its speed.
    lo = np.maximum(np.searchsorted(s_grid, s[np.maximum(k - 2, 0)], side="left") - 1, 0)
    hi = np.minimum(
        np.searchsorted(s_grid, s[np.minimum(k + 2, len(s) - 1)], side="right") + 1, len(s_grid)
    )
    count = np.maximum(hi - lo, 0)
    total = int(count.sum())
    if total == 0:
        return
    grid = np.repeat(lo - (np.cumsum(count) - count), count) + np.arange(total)
    factor = np.fromiter(
        (math.pow(q, 2.0) for q in ((1.0 - 4.0 * CHECK_MARGIN) / r[k]).tolist()), float, k.size
    )
    np.minimum.at(cap, grid, x_now[grid] * np.repeat(factor, count))


def _finish(
    traj,
    e: dict,
    sp,
    device: DeviceLimits,
    limits: DeviceLimits,
    rate: float,
    t_opt: float,
    slow: float,
) -> TimedSwing:
    # ``limits``: the planned ones (the device's less its tracking headroom), which the samples keep.
    notes = []
    if limits.min_duration > t_opt:
        notes.append(
            f"the limits allow {t_opt:.3f} s; the minimum swing duration {limits.min_duration:.3f} s is used"
        )
    vmax = np.asarray(limits.velocity)
    amax = np.asarray(limits.acceleration)
    t, s, h, vel, acc, peak_v, peak_a = (
        e[k] for k in ("t", "s", "h", "vel", "acc", "peak_v", "peak_a")
    )
    within = bool(
        np.all(peak_v <= vmax)
        and np.all(peak_a <= amax)
        and (limits.jerk is None or np.all(e["peak_j"] <= np.asarray(limits.jerk)))
    )
    sc = traj.scene
    # The safe-swing checks of the retimed samples, with the trajectory's own bound on its
    # curve's distance from the polyline through its samples.
    m = measure_paths(sp, h[None], [sc], traj.checks.deviation)
    reasons = failure_reasons(m, 0, h, sc.goal_y, t, sp)
    checks = TrajectoryChecks(
        bool(m["reached_goal"][0]),
        bool(m["collision_free"][0]),
        float(m["min_clearance"][0]),
        bool(m["joint_limits_ok"][0]),
        bool(m["leg_length_ok"][0]),
        reasons,
        bool(m["clearance_ok"][0]),
        bool(m["above_ground"][0]),
        float(m["heel_backward"][0]),
        float(m["deviation"][0]),
    )
    kin = m["kin"]
    toe = h.copy()
    toe[:, 0] += sp.foot_length
    return TimedSwing(
        method=traj.method,
        scene=sc,
        rate=rate,
        duration=float(t[-1]),
        limits=device,
        time=t,
        heel=h,
        toe=toe,
        hip=kin["hip"][0],
        knee_swing=kin["knee_swing"][0],
        knee_stance=kin["knee_stance"][0],
        joint_angles=m["angles"][0],
        joint_velocity=vel,
        joint_acceleration=acc,
        heel_velocity=e["heel_vel"],
        heel_acceleration=e["heel_acc"],
        path_parameter=s,
        checks=checks,
        within_limits=within,
        peak_velocity=peak_v,
        peak_acceleration=peak_a,
        slowdown=slow,
        peak_jerk=e["peak_j"],
        notes=tuple(getattr(traj, "notes", ())) + tuple(notes),
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
]
