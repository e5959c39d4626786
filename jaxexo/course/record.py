"""A planned walk as a record: each swing (``CourseStep``), the walk (``Course``) and its one timed
table of both legs (``walk_table``, ``WALK_COLUMNS``), with its CSV and JSON."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from jaxexo.course.placement import Footholds
from jaxexo.storage.terrain_file import Terrain
from jaxexo.swing.export import timed_dict, units, write_csv, write_json
from jaxexo.swing.trajectory import Trajectory

JUNCTION_TOL = 1e-6  # rad, largest joint-angle jump allowed where one swing hands over to the next

LEGS = ("left", "right")
WALK_JOINTS = ("hip_left", "knee_left", "hip_right", "knee_right")
WALK_COLUMNS = (
    (
        "time_s",
        "step",
        "swing_leg",
        "left_heel_y_m",
        "left_heel_z_m",
        "left_toe_y_m",
        "left_toe_z_m",
        "right_heel_y_m",
        "right_heel_z_m",
        "right_toe_y_m",
        "right_toe_z_m",
        "hip_y_m",
        "hip_z_m",
        "left_knee_y_m",
        "left_knee_z_m",
        "right_knee_y_m",
        "right_knee_z_m",
    )
    + tuple(f"{j}_rad" for j in WALK_JOINTS)
    + tuple(f"{j}_vel_rad_s" for j in WALK_JOINTS)
    + tuple(f"{j}_acc_rad_s2" for j in WALK_JOINTS)
)


@dataclass(frozen=True)
class TerrainUpdate:
    """The terrain as known from ``time`` on (s on the walk's clock: 0 at the first lift-off): a
    Terrain, a terrain file's path or (y, z) points, as ``plan_course`` takes its terrain. The swing
    in flight then is replanned over it, the swings after are planned on it; the footholds stay
    (docs/replanning.md, "Command line and walks")."""

    time: float
    terrain: object


@dataclass(frozen=True)
class SwingPlace:
    """Where one swing of the walk goes: its index, which leg, where it starts, pivots and lands (m)."""

    index: int
    leg: str
    start_y: float
    pivot_y: float
    goal_y: float  # the planned foothold
    landing_y: float  # where the heel came down
    flat: bool  # no obstacle under the swing (planned over FLAT_OBSTACLE)


@dataclass(frozen=True)
class CourseStep(SwingPlace):
    """One swing of the walk: its place (``SwingPlace``), the checked path (``trajectory``), its
    device timing (``timed``, a TimedSwing) and when it runs in the walk (s)."""

    trajectory: Trajectory
    timed: object  # TimedSwing; None for a failed swing (not timed)
    start_s: float
    end_s: float
    # The swing as planned before a terrain update replanned it in flight (a TimedSwing; None: not
    # replanned); ``timed`` is then the replanned swing (``timed.switch_times``, swing time).
    replanned_from: object = None

    @property
    def method(self) -> str:
        return self.trajectory.method

    @property
    def ok(self) -> bool:
        return self.trajectory.ok and self.timed is not None and self.timed.ok

    @property
    def reasons(self) -> tuple[str, ...]:
        out = tuple(self.trajectory.checks.reasons)
        return out + tuple(
            r for r in (self.timed.reasons if self.timed is not None else ()) if r not in out
        )


@dataclass(frozen=True)
class Course:
    """A planned walk: the footholds, each step, and the whole walk as one timed table of both legs
    (``table``, WALK_COLUMNS). ``ok``: every swing safe and within the device limits and every
    hand-over from one swing to the next continuous; ``reasons`` say which step failed and where."""

    terrain: Terrain
    footholds: Footholds
    steps: tuple[CourseStep, ...]
    rate: float
    limits: object
    double_support: float
    method: str
    samples: np.ndarray  # (T, len(WALK_COLUMNS))
    junction_jump: float  # rad, largest joint-angle jump at a hand-over
    reasons: tuple[str, ...]
    plan_seconds: float = 0.0
    notes: tuple[str, ...] = field(default=())
    # The terrain updates applied (TerrainUpdate, their terrain read; in time order)
    updates: tuple = ()

    @property
    def ok(self) -> bool:
        return not self.reasons

    @property
    def duration(self) -> float:
        return float(self.samples[-1, 0]) if len(self.samples) else 0.0

    @property
    def methods(self) -> tuple[str, ...]:
        return tuple(s.method for s in self.steps)

    def table(self) -> np.ndarray:
        return self.samples

    def to_csv(self, path: str | Path | None = None) -> str:
        return write_csv(WALK_COLUMNS, self.samples, path)

    def to_dict(self) -> dict:
        steps = []
        for s in self.steps:
            d = timed_dict(s.timed) if s.timed is not None else s.trajectory.to_dict()
            samples = np.asarray(d["samples"])
            samples[:, 0] += s.start_s  # walk time
            d["samples"] = samples.tolist()
            d.update(
                {
                    "index": s.index,
                    "leg": s.leg,
                    "method": s.method,
                    "start_y": s.start_y,
                    "pivot_y": s.pivot_y,
                    "planned_landing_y": s.goal_y,
                    "landing": {"heel_y": s.landing_y, "heel_z": 0.0},
                    "flat": s.flat,
                    "start_s": s.start_s,
                    "end_s": s.end_s,
                    "ok": s.ok,
                    "reasons": list(s.reasons),
                }
            )
            steps.append(d)
        return {
            "units": units(),
            "ok": self.ok,
            "reasons": list(self.reasons),
            "method": self.method,
            "terrain": {"source": self.terrain.source, "points": self.terrain.points.tolist()},
            "start_y": self.footholds.start_y,
            "footholds": list(self.footholds.landings),
            "rate_hz": self.rate,
            "duration_s": self.duration,
            "limits": self.limits.to_dict(),
            "double_support_s": self.double_support,
            "junction_jump_rad": self.junction_jump,
            "plan_seconds": self.plan_seconds,
            "notes": list(self.notes),
            "updates": [
                {"time_s": u.time, "terrain": u.terrain.source, "points": u.terrain.points.tolist()}
                for u in self.updates
            ],
            "columns": list(WALK_COLUMNS),
            "samples": self.samples.tolist(),
            "steps": steps,
        }

    def to_json(self, path: str | Path | None = None) -> str:
        return write_json(self.to_dict(), path)


def walk_table(timed, places, double_support: float, rate: float):
    """The whole walk as one table (WALK_COLUMNS): each swing's samples in walk time, the swing
    leg's columns on its side; a landing's pose held ``double_support`` s; the first sample of a
    swing (its lift-off, the same instant and pose as the landing before) kept once. Returns the
    table, each step's (start, end) in s, and the largest joint-angle jump at a hand-over (rad).
    ``timed``: the TimedSwings, ``places``: their SwingPlaces."""
    rows, spans = [np.zeros((0, len(WALK_COLUMNS)))], []
    offset, jump = 0.0, 0.0
    last = None
    for t, m in zip(timed, places):
        n = len(t.time)
        side = LEGS.index(m.leg)
        block = np.zeros((n, len(WALK_COLUMNS)))
        block[:, 0] = t.time + offset
        block[:, 1] = m.index + 1
        block[:, 2] = side
        stance = np.zeros_like(t.heel)
        stance[:, 0] = m.pivot_y
        feet = [None, None]
        feet[side], feet[1 - side] = t.heel, stance
        for i, h in enumerate(feet):
            block[:, 3 + 4 * i : 5 + 4 * i] = h
            block[:, 5 + 4 * i] = h[:, 0] + (t.toe[0, 0] - t.heel[0, 0])
            block[:, 6 + 4 * i] = h[:, 1]
        block[:, 11:13] = t.hip
        knees = [None, None]
        knees[side], knees[1 - side] = t.knee_swing, t.knee_stance
        block[:, 13:15], block[:, 15:17] = knees
        for base, arr in ((17, t.joint_angles), (21, t.joint_velocity), (25, t.joint_acceleration)):
            sw, st = arr[:, 0:2], arr[:, 2:4]
            block[:, base + 2 * side : base + 2 * side + 2] = sw
            block[:, base + 2 * (1 - side) : base + 2 * (1 - side) + 2] = st
        if last is not None:
            jump = max(jump, float(np.abs(block[0, 17:21] - last[17:21]).max()))
            block = block[1:]
        if last is not None and double_support > 0.0:
            m = max(1, int(round(double_support * rate)))
            hold = np.repeat(last[None], m, axis=0)
            hold[:, 0] = last[0] + np.arange(1, m + 1) / rate
            hold[:, 2] = -1
            hold[:, 21:] = 0.0
            rows.append(hold)
            offset += m / rate
            block[:, 0] += m / rate
        spans.append((offset, offset + float(t.time[-1])))
        rows.append(block)
        offset += float(t.time[-1])
        last = block[-1]
    return np.concatenate(rows), spans, jump
