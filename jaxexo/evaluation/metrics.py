"""The figures of ``jaxexo eval`` per trajectory and per group: the thesis's metrics (3.3: accuracy
eq 3.1, hip and knee angles of Tables 3.2-3.9), the safe-swing verdict, clearance, lift, path length,
heel jerk, and the swing timed for the exoskeleton (jaxexo.swing.timing)."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from jaxexo.physics import outcome, swept
from jaxexo.summary import Summary

# Backward heel motion (m, at the samples) counted in the report: the default env.backward_tolerance.
BACKWARD_REPORT = outcome.DEFAULT_BACKWARD_TOLERANCE


def path_length(heel: np.ndarray) -> np.ndarray:
    """Length of heel paths (..., N, 2), metres."""
    return np.linalg.norm(np.diff(heel, axis=-2), axis=-1).sum(axis=-1)


def squared_jerk(heel: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Integrated squared jerk of heel paths (..., N, 2) sampled at equally spaced times t (N,):
    sum over the third differences of |d^3 p / dt^3|^2 dt, m^2/s^5."""
    dt = float(t[1] - t[0])
    j = np.diff(heel, n=3, axis=-2) / dt**3
    return (j * j).sum(axis=(-1, -2)) * dt


@dataclass(frozen=True)
class TrajectoryMetrics:
    """Per-trajectory figures [N] of N trajectories (``trajectory_metrics``): collision free
    (accuracy), safe (success), goal reached; the hip's and knee's mean, the hip's largest and the
    knee's smallest angle (rad); the smallest clearance (m) and whether it kept the margin; the heel's
    peak above the obstacle, backward motion and path length (m); whether CFFTG's plan replaced the
    RL swing (fallback); the heel's squared jerk (m^2/s^5)."""

    accurate: np.ndarray
    success: np.ndarray
    reached_goal: np.ndarray
    hip_mean: np.ndarray
    knee_mean: np.ndarray
    hip_max: np.ndarray
    knee_min: np.ndarray
    min_clearance: np.ndarray
    clearance_ok: np.ndarray
    peak_above: np.ndarray
    backward: np.ndarray
    fallback: np.ndarray
    path_length: np.ndarray
    jerk: np.ndarray


def trajectory_metrics(trajs) -> TrajectoryMetrics:
    """The figures of each of the trajectories."""
    return TrajectoryMetrics(
        accurate=np.array([t.checks.collision_free for t in trajs]),
        success=np.array([t.ok for t in trajs]),
        reached_goal=np.array([t.checks.reached_goal for t in trajs]),
        hip_mean=np.array([t.joint_angles[:, 0].mean() for t in trajs]),
        knee_mean=np.array([t.joint_angles[:, 1].mean() for t in trajs]),
        hip_max=np.array([t.joint_angles[:, 0].max() for t in trajs]),
        knee_min=np.array([t.joint_angles[:, 1].min() for t in trajs]),
        min_clearance=np.array([t.checks.min_clearance for t in trajs]),
        clearance_ok=np.array([t.checks.clearance_ok for t in trajs]),
        peak_above=np.array([t.heel[:, 1].max() - t.scene.height for t in trajs]),
        backward=np.array([float(swept.backward_motion(np, t.heel[:, 0])) for t in trajs]),
        fallback=np.array([t.method == "cfftg-fallback" for t in trajs]),
        path_length=np.array([path_length(t.heel) for t in trajs]),
        jerk=np.array([squared_jerk(t.heel, t.time) for t in trajs]),
    )


@dataclass(frozen=True)
class DeviceMetrics:
    """Per-trajectory device timing [N] (``device_metrics``): the swing's duration (s), its peak hip
    and knee velocity over both legs (rad/s), whether its samples keep the limits, the path's peak
    joint velocity at its own uniform time stamps (rad/s) and the timed swing's joint jerk."""

    swing_s: np.ndarray
    peak_hip_vel: np.ndarray
    peak_knee_vel: np.ndarray
    within_limits: np.ndarray
    uniform_peak_vel: np.ndarray
    joint_jerk: np.ndarray


def device_metrics(trajs, config) -> DeviceMetrics:
    """The device timing of each trajectory (jaxexo.swing.timing, the config's [device] limits).

    A generator that stood still (the heel never leaves its start: a policy that learned not to move,
    e.g. the faithful thesis configs) has nothing to time: its swing counts as 0 s at zero velocity,
    within the limits; its success and goal figures already say it failed."""
    from jaxexo.swing.timing import CHUNK, joint_jerk, time_swings, uniform_peaks

    trajs = list(trajs)
    n = len(trajs)
    moving = [i for i, t in enumerate(trajs) if np.any(np.asarray(t.heel) != np.asarray(t.heel)[0])]
    zeros = {f.name: np.zeros(n) for f in fields(DeviceMetrics)}
    out = DeviceMetrics(**zeros | {"within_limits": np.ones(n, bool)})
    # The moving swings' rows filled in place, before the record leaves, a chunk at a time: only
    # a chunk's timed swings (their samples) are held at once.
    for c in range(0, len(moving), CHUNK):
        moves = moving[c : c + CHUNK]
        timed = time_swings([trajs[i] for i in moves], config)
        out.swing_s[moves] = [t.duration for t in timed]
        out.peak_hip_vel[moves] = [max(t.peak_velocity[0], t.peak_velocity[2]) for t in timed]
        out.peak_knee_vel[moves] = [max(t.peak_velocity[1], t.peak_velocity[3]) for t in timed]
        out.within_limits[moves] = [t.within_limits for t in timed]
        out.joint_jerk[moves] = [joint_jerk(t) for t in timed]
        out.uniform_peak_vel[moves] = [uniform_peaks(trajs[i])[0].max() for i in moves]
    return out


def summarize_device(m: DeviceMetrics, mask: np.ndarray) -> dict:
    """Device-timing figures of one group [N] mask (seconds; velocities in deg/s): the report's JSON."""
    d = np.degrees
    swing, jerk = Summary.of(m.swing_s[mask]), Summary.of(m.joint_jerk[mask])
    return {
        "swing_s_mean": swing.mean,
        "swing_s_median": swing.median,
        "swing_s_p95": swing.p95,
        "swing_s_max": swing.max,
        "joint_jerk_median": jerk.median,
        "joint_jerk_p95": jerk.p95,
        "peak_hip_vel_deg_s_mean": float(d(m.peak_hip_vel[mask].mean())),
        "peak_knee_vel_deg_s_mean": float(d(m.peak_knee_vel[mask].mean())),
        "device_within_limits": float(m.within_limits[mask].mean()),
        "uniform_peak_joint_vel_deg_s_median": float(
            d(Summary.of(m.uniform_peak_vel[mask]).median)
        ),
    }


def summarize(m: TrajectoryMetrics, times_s: np.ndarray, mask: np.ndarray) -> dict:
    """Figures of one group [N] mask of trajectories (angles in degrees, lengths in metres, times in
    ms; times_s [N]): the report's JSON."""
    t = Summary.of(times_s[mask] * 1e3)
    clear, lift = Summary.of(m.min_clearance[mask]), Summary.of(m.peak_above[mask])
    d = np.degrees
    return {
        "n": int(mask.sum()),
        "accuracy": float(m.accurate[mask].mean()),
        "success": float(m.success[mask].mean()),
        "reached_goal": float(m.reached_goal[mask].mean()),
        "time_ms_mean": t.mean,
        "time_ms_median": t.median,
        "time_ms_p95": t.p95,
        "hip_swing_mean_deg": float(d(m.hip_mean[mask].mean())),
        "knee_swing_mean_deg": float(d(m.knee_mean[mask].mean())),
        "hip_swing_max_deg": float(d(m.hip_max[mask].mean())),
        "knee_swing_min_deg": float(d(m.knee_min[mask].mean())),
        "min_clearance_m_mean": clear.mean,
        "min_clearance_m_median": clear.median,
        "min_clearance_m_worst": clear.min,
        "clearance_ok": float(m.clearance_ok[mask].mean()),
        "peak_above_obstacle_m_median": lift.median,
        "peak_above_obstacle_m_p95": lift.p95,
        "heel_backward_rate": float((m.backward[mask] > BACKWARD_REPORT).mean()),
        "fallback_rate": float(m.fallback[mask].mean()),
        "path_length_m_mean": float(m.path_length[mask].mean()),
        "squared_jerk_mean": float(m.jerk[mask].mean()),
    }
