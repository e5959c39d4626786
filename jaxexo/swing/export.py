"""Exports of swings: the CSV columns and JSON documents of a checked trajectory
(jaxexo.swing.trajectory.Trajectory) and of a device-ready timed swing
(jaxexo.swing.timing.TimedSwing). Units: metres, radians, seconds."""

from __future__ import annotations

import csv
import io
import json
import re
from pathlib import Path

import numpy as np

from jaxexo.physics.geometry import exact_text
from jaxexo.storage.atomic import atomic_write

JOINT_NAMES = ("hip_swing", "knee_swing", "hip_stance", "knee_stance")

# A ROS name (the ROS 2 naming rules, which a controller's joint parameters follow): tokens of
# letters, digits and underscores, none starting with a digit, separated by single slashes.
ROS_NAME = re.compile(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*")

CSV_COLUMNS = (
    "time_s",
    "heel_y_m",
    "heel_z_m",
    "toe_y_m",
    "toe_z_m",
    "hip_y_m",
    "hip_z_m",
    "knee_swing_y_m",
    "knee_swing_z_m",
    "knee_stance_y_m",
    "knee_stance_z_m",
    "hip_swing_rad",
    "knee_swing_rad",
    "hip_stance_rad",
    "knee_stance_rad",
)


def scene_dict(sc) -> dict:
    """A scene (jaxexo.physics.scene.Scene) as JSON values."""
    return {
        "obstacle": sc.obstacle.kind,
        "shape": sc.obstacle.shape,
        "center_y": sc.center_y,
        "width": sc.width,
        "height": sc.height,
        "outline": sc.obstacle.outline.tolist(),
        "pivot": sc.pivot,
        "pivot_y": sc.pivot_y,
        "start_y": sc.start_y,
        "goal_y": sc.goal_y,
    }


TIMED_CSV_COLUMNS = (
    CSV_COLUMNS
    + tuple(f"{j}_vel_rad_s" for j in JOINT_NAMES)
    + tuple(f"{j}_acc_rad_s2" for j in JOINT_NAMES)
    + ("heel_vel_y_m_s", "heel_vel_z_m_s", "heel_acc_y_m_s2", "heel_acc_z_m_s2")
)


def timed_table(swing) -> np.ndarray:
    """(n, len(TIMED_CSV_COLUMNS)) array of a TimedSwing: the path columns, then joint velocities
    and accelerations and the heel's velocity and acceleration, one row per control period."""
    return np.column_stack(
        [
            swing.time,
            swing.heel,
            swing.toe,
            swing.hip,
            swing.knee_swing,
            swing.knee_stance,
            swing.joint_angles,
            swing.joint_velocity,
            swing.joint_acceleration,
            swing.heel_velocity,
            swing.heel_acceleration,
        ]
    )


def write_timed_csv(swing, path: str | Path | None = None) -> str:
    return write_csv(TIMED_CSV_COLUMNS, timed_table(swing), path)


# A CSV number (geometry.exact_text): the shortest text that reads back to the same float64, so
# that finite differences of the read values at 10 kHz hold the limits as the curve does (9 digits
# broke the jerk limit 15-fold).
csv_number = exact_text


def write_csv(columns, table: np.ndarray, path: str | Path | None = None) -> str:
    """CSV text of a (N, len(columns)) table, each number at full precision (``csv_number``);
    written atomically to ``path`` when given."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for row in table:
        w.writerow([csv_number(x) for x in row])
    text = buf.getvalue()
    if path is not None:
        atomic_write(path, text)
    return text


def units(**extra: str) -> dict:
    """The units of a timed record's JSON: lengths, angles, times and joint rates, then ``extra``,
    then the sampling rate."""
    return {
        "length": "m",
        "angle": "rad",
        "time": "s",
        "joint velocity": "rad/s",
        "joint acceleration": "rad/s^2",
        **extra,
        "rate": "Hz",
    }


def timed_dict(swing) -> dict:
    c = swing.checks
    return {
        "units": units(**{"heel velocity": "m/s", "heel acceleration": "m/s^2"}),
        "method": swing.method,
        "scene": scene_dict(swing.scene),
        "rate_hz": swing.rate,
        "duration_s": swing.duration,
        "limits": swing.limits.to_dict(),
        "peak_joint_velocity_rad_s": [float(x) for x in swing.peak_velocity],
        "peak_joint_acceleration_rad_s2": [float(x) for x in swing.peak_acceleration],
        "checks": {
            "ok": swing.ok,
            "within_limits": swing.within_limits,
            "reached_goal": c.reached_goal,
            "collision_free": c.collision_free,
            "min_clearance": c.min_clearance,
            "joint_limits_ok": c.joint_limits_ok,
            "leg_length_ok": c.leg_length_ok,
            "reasons": list(swing.reasons),
        },
        "notes": list(swing.notes),
        # s: where the swing was replanned in flight (jaxexo.swing.replan); [] for none
        "switch_times_s": list(swing.switch_times),
        "columns": list(TIMED_CSV_COLUMNS),
        "samples": timed_table(swing).tolist(),
        # The curve itself, for a controller that evaluates it at its own rate.
        "piecewise": swing.curve.piecewise() if swing.curve is not None else None,
    }


def check_joint_names(names, option: str = "joint_names", given=None) -> tuple[str, ...]:
    """The ROS 2 joint names for JOINT_NAMES' four joints, in that order: None gives JOINT_NAMES;
    else four distinct ROS names (``ROS_NAME``), refused naming ``option`` and the value as
    ``given`` (default: its repr)."""
    if names is None:
        return JOINT_NAMES
    shown = repr(names) if given is None else given
    want = f"four distinct joint names, for {', '.join(JOINT_NAMES)} in that order"
    if isinstance(names, (str, bytes)) or not isinstance(names, (list, tuple)):
        raise ValueError(f"{option}: expected a list of {want}, got {shown}")
    if len(names) != len(JOINT_NAMES):
        raise ValueError(f"{option}: expected {want}, got {len(names)}: {shown}")
    for i, n in enumerate(names):
        if not isinstance(n, str) or not ROS_NAME.fullmatch(n):
            raise ValueError(
                f"{option}: name {i + 1} ({n!r}) is not a ROS name (letters, digits and _, not "
                f"starting with a digit; / between parts), got {shown}"
            )
        if n in names[:i]:
            raise ValueError(f"{option}: {n!r} is given twice; expected {want}, got {shown}")
    return tuple(names)


def joint_trajectory_dict(swing, joint_names=None) -> dict:
    """A timed swing in the layout of ROS 2 ``trajectory_msgs/msg/JointTrajectory``: the header
    (stamp 0: start on receipt; no frame), joint_names (``check_joint_names``; default
    JOINT_NAMES), and per sample positions (rad), velocities (rad/s), accelerations (rad/s^2) and
    time_from_start (sec, nanosec), which a ``joint_trajectory_controller`` interpolates with
    quintic splines."""
    names = check_joint_names(joint_names)
    points = []
    for t, q, v, a in zip(
        swing.time, swing.joint_angles, swing.joint_velocity, swing.joint_acceleration
    ):
        ns = int(round(float(t) * 1e9))
        points.append(
            {
                "positions": [float(x) for x in q],
                "velocities": [float(x) for x in v],
                "accelerations": [float(x) for x in a],
                "effort": [],
                "time_from_start": {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000},
            }
        )
    # std_msgs/Header is stamp then frame_id; a zero stamp is "start now" to a controller.
    header = {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""}
    return {"header": header, "joint_names": list(names), "points": points}


def write_joint_trajectory(swing, path: str | Path | None = None, joint_names=None) -> str:
    return write_json(joint_trajectory_dict(swing, joint_names), path)


def write_timed_json(swing, path: str | Path | None = None) -> str:
    return write_json(timed_dict(swing), path)


def write_json(doc: dict, path: str | Path | None = None) -> str:
    """JSON text of ``doc``; written atomically to ``path`` when given."""
    text = json.dumps(doc, indent=1)
    if path is not None:
        atomic_write(path, text)
    return text
