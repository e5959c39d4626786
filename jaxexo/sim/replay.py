"""A timed swing replayed in MuJoCo (the ``sim`` extra: ``pip install -e ".[sim]"``): kinematically
here (MuJoCo's own distance query at every pose, against jaxexo's at the samples), driven at the
device's limits in jaxexo.sim.driven, and many swings summarised for ``jaxexo eval --replay`` and
the benchmarks; ``brute_force_distance`` is a third, independent look at the foot-obstacle distance.
Method and figures: docs/safety.md, "Replayed in a physics engine". Units: m, rad, s."""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from jaxexo.physics import geometry
from jaxexo.sim.driven import DrivenReplay, driven_replay
from jaxexo.sim.driven import feed_forward as feed_forward  # the replay's face re-exports
from jaxexo.sim.driven import hermite as hermite
from jaxexo.sim.driven import interpolate as interpolate
from jaxexo.sim.driven import reference_states as reference_states
from jaxexo.sim.legs import Legs, require_mujoco
from jaxexo.sim.mjcf import DISTMAX, SWING_LEG, SimError
from jaxexo.summary import Summary

SUBSTEPS = 4  # kinematic poses per control period (the sample and 3 between)
SAME_POSE = 1e-6  # m: MuJoCo's heel this close to jaxexo's is the same pose


def fine_angles(angles: np.ndarray, substeps: int) -> np.ndarray:
    """Joint angles (n, 4) at the control samples -> ((n - 1) substeps + 1, 4), linear in between."""
    n = len(angles)
    f = np.arange(substeps) / substeps
    mid = angles[:-1, None, :] + f[None, :, None] * np.diff(angles, axis=0)[:, None, :]
    return np.concatenate([mid.reshape((n - 1) * substeps, angles.shape[1]), angles[-1:]])


@dataclass(frozen=True)
class KinematicReplay:
    """A kinematic replay (``kinematic_replay``), SI units: the swing's method, jaxexo's verdict
    (``flagged_ok``), the margin and jaxexo's guaranteed clearance; MuJoCo's smallest distance, when
    and the heel [2] there, whether it kept the margin (and so a swing flagged ok that did not);
    the two geometries' largest disagreement at the samples (and which sample, -1 for none) and the
    largest heel offset; the samples compared, the poses, the substeps and the wall time (s)."""

    method: str
    flagged_ok: bool
    margin_m: float
    jaxexo_guaranteed_clearance_m: float
    mujoco_min_distance_m: float
    mujoco_min_time_s: float
    mujoco_min_heel: list
    margin_kept: bool
    flagged_ok_but_within_margin: bool
    max_disagreement_m: float
    max_disagreement_sample: int
    max_heel_offset_m: float
    samples_compared: int
    poses: int
    substeps: int
    seconds: float

    def to_dict(self) -> dict:
        return asdict(self)


def kinematic_replay(
    timed, config, substeps: int = SUBSTEPS, legs: Legs | None = None
) -> KinematicReplay:
    """The kinematic replay of a TimedSwing: the joints set to its angles at every control sample
    and ``substeps`` poses between (the timed curve's there; linear for a swing without a curve), the
    pelvis where the stance leg puts it on its pivot, and MuJoCo's distance from the swing foot to
    each obstacle piece at every pose; compared with jaxexo's (geometry.foot_clearance) at the
    samples, where both measure the same pose. ``legs``: a Legs of the same scene to reuse."""
    if not isinstance(substeps, int) or isinstance(substeps, bool) or substeps < 1:
        raise SimError(f"substeps: must be an integer >= 1, got {substeps!r}")
    t0 = time.perf_counter()
    legs = Legs(config, timed.scene) if legs is None else legs
    angles = np.asarray(timed.joint_angles, dtype=np.float64)
    if getattr(timed, "curve", None) is not None:
        # Between the samples the drives follow the curve, not a straight line in joint space.
        t = np.arange((len(angles) - 1) * substeps + 1) / (substeps * timed.rate)
        fine = timed.at(np.minimum(t, timed.duration)).joint_angles
        fine[::substeps] = angles
    else:
        fine = fine_angles(angles, substeps)
    q = legs.qpos(fine)
    dist = np.empty(len(q))
    heel = np.empty((len(q), 2))
    for i, qi in enumerate(q):
        legs.set_pose(qi)
        dist[i] = legs.foot_distance()
        heel[i] = legs.site_yz(f"{SWING_LEG}_heel")
    at_samples = dist[::substeps]
    jx = geometry.foot_clearance(np, np.asarray(timed.heel), legs.foot_length, timed.scene.outline)
    offset = np.linalg.norm(heel[::substeps] - np.asarray(timed.heel), axis=1)
    # Compared where both measure a distance of one pose: MuJoCo caps at DISTMAX, the foot is outside,
    # and the angles put MuJoCo's heel on jaxexo's (not so where a failed swing's heel is out of reach).
    both = (at_samples < DISTMAX) & (jx > 0.0) & (offset < SAME_POSE)
    diff = np.abs(at_samples - jx)
    worst = int(np.argmax(np.where(both, diff, -1.0))) if both.any() else -1
    margin = float(config.env.min_clearance)
    k = int(np.argmin(dist))
    return KinematicReplay(
        method=timed.method,
        flagged_ok=bool(timed.ok),
        margin_m=margin,
        jaxexo_guaranteed_clearance_m=float(timed.checks.min_clearance),
        mujoco_min_distance_m=float(dist[k]),
        mujoco_min_time_s=float(k / substeps / timed.rate),
        mujoco_min_heel=heel[k].tolist(),
        margin_kept=bool(dist[k] >= margin),
        flagged_ok_but_within_margin=bool(timed.ok and dist[k] < margin),
        max_disagreement_m=float(diff[worst]) if worst >= 0 else 0.0,
        max_disagreement_sample=worst,
        max_heel_offset_m=float(offset.max()),
        samples_compared=int(both.sum()),
        poses=int(len(q)),
        substeps=substeps,
        seconds=time.perf_counter() - t0,
    )


@dataclass(frozen=True)
class KinematicSummary:
    """Many kinematic replays (``summarize_kinematic``), SI units: how many, how many jaxexo flags ok
    and of those how many come within the margin in MuJoCo (the target is 0); MuJoCo's smallest
    distance among the ok swings and its smallest excess over jaxexo's guaranteed clearance; the
    largest disagreement between the two geometries at the samples and the largest heel offset of an
    ok swing; the replay's median wall time (s) and poses. None where no swing gives a figure."""

    n: int
    flagged_ok: int
    flagged_ok_within_margin: int
    min_mujoco_distance_of_ok_m: float | None
    min_mujoco_minus_guaranteed_of_ok_m: float | None
    max_disagreement_m: float | None
    max_heel_offset_of_ok_m: float | None
    seconds_median: float | None
    poses_median: float | None

    def to_dict(self) -> dict:
        return asdict(self)


def summarize_kinematic(rows: list[KinematicReplay]) -> KinematicSummary:
    """The figures of many kinematic replays (a KinematicSummary)."""
    ok = [r for r in rows if r.flagged_ok]
    return KinematicSummary(
        n=len(rows),
        flagged_ok=len(ok),
        flagged_ok_within_margin=int(sum(r.flagged_ok_but_within_margin for r in rows)),
        min_mujoco_distance_of_ok_m=min((r.mujoco_min_distance_m for r in ok), default=None),
        min_mujoco_minus_guaranteed_of_ok_m=min(
            (r.mujoco_min_distance_m - r.jaxexo_guaranteed_clearance_m for r in ok), default=None
        ),
        max_disagreement_m=max((r.max_disagreement_m for r in rows), default=None),
        # Over the swings flagged ok: a failed swing may ask for a heel out of the leg's reach.
        max_heel_offset_of_ok_m=max((r.max_heel_offset_m for r in ok), default=None),
        seconds_median=Summary.of([r.seconds for r in rows]).median if rows else None,
        poses_median=Summary.of([r.poses for r in rows]).median if rows else None,
    )


@dataclass(frozen=True)
class DrivenSummary:
    """Many driven replays (``summarize_driven``), SI units: how many; the heel's and toe's tracking
    error (p95 and max over the swings of each swing's largest; the heel's off the floor at p95);
    the swings in contact and within the margin; MuJoCo's smallest distance (least and median);
    the saturated swings, the stance heel's largest slip and the replay's median wall time (s).
    Only ``n`` (0) for no replays."""

    n: int
    heel_error_p95_m: float | None = None
    heel_error_max_m: float | None = None
    heel_error_airborne_p95_m: float | None = None
    toe_error_p95_m: float | None = None
    toe_error_max_m: float | None = None
    contacts: int | None = None
    within_margin: int | None = None
    min_distance_m: float | None = None
    median_min_distance_m: float | None = None
    saturated: int | None = None
    stance_heel_slip_max_m: float | None = None
    seconds_median: float | None = None

    def to_dict(self) -> dict:
        """The JSON entry: ``{"n": 0}`` alone for no replays."""
        return asdict(self) if self.n else {"n": 0}


def summarize_driven(rows: list[DrivenReplay]) -> DrivenSummary:
    """The figures of many driven replays (a DrivenSummary)."""
    if not rows:
        return DrivenSummary(n=0)
    fig = [d.figures for d in rows]
    he = Summary.of([f.heel_error_max_m for f in fig])
    te = Summary.of([f.toe_error_max_m for f in fig])
    md = np.array([f.mujoco_min_distance_m for f in fig])
    return DrivenSummary(
        n=len(rows),
        heel_error_p95_m=he.p95,
        heel_error_max_m=he.max,
        heel_error_airborne_p95_m=Summary.of([f.heel_error_airborne_max_m for f in fig]).p95,
        toe_error_p95_m=te.p95,
        toe_error_max_m=te.max,
        contacts=int(sum(f.contact for f in fig)),
        within_margin=int(np.sum(md < rows[0].margin_m)),
        min_distance_m=float(md.min()),
        median_min_distance_m=Summary.of(md).median,
        saturated=int(sum(f.saturated for f in fig)),
        stance_heel_slip_max_m=float(max(f.stance_heel_slip_max_m for f in fig)),
        seconds_median=Summary.of([d.seconds for d in rows]).median,
    )


def replay_trajectories(trajs, config, rate: float | None = None, driven: bool = True) -> dict:
    """Trajectories (one generator's) timed for the device at ``rate`` and replayed in MuJoCo:
    ``summarize_kinematic`` of all of them and ``summarize_driven`` of those flagged ok, at the
    config's [device] limits (``jaxexo eval --replay``), as the report's JSON entry."""
    from jaxexo.swing.timing import time_swings

    require_mujoco()
    kin, drv = [], []
    for ts in time_swings(list(trajs), config, rate=rate):
        legs = Legs(config, ts.scene)
        kin.append(kinematic_replay(ts, config, legs=legs))
        if driven and ts.ok:
            drv.append(driven_replay(ts, config, legs=legs))
    out = {"kinematic": summarize_kinematic(kin).to_dict()}
    if driven:
        out["driven"] = summarize_driven(drv).to_dict()
    return out


def brute_force_distance(heel, foot_length: float, outline, iterations: int = 200) -> float:
    """Distance (m) from the flat foot [heel, heel + (foot_length, 0)] to the outline's edges (the
    boundary, unsigned), by ternary search of the foot position on each edge (the distance from a
    point moving along a line to a segment is convex in its position): independent of jaxexo.physics.geometry's closed form and of MuJoCo. 0 where they cross."""
    o = np.asarray(outline, dtype=np.float64)
    a, b = o[:-1], o[1:]
    e = b - a
    len2 = np.maximum((e * e).sum(axis=1), 1e-300)
    heel = np.asarray(heel, dtype=np.float64)

    def dist(u):  # u (E,): the foot point at heel + u (L, 0) to each edge
        p = heel[None, :] + np.stack([u * foot_length, np.zeros_like(u)], axis=1)
        t = np.clip(((p - a) * e).sum(axis=1) / len2, 0.0, 1.0)
        r = p - (a + t[:, None] * e)
        return np.sqrt((r * r).sum(axis=1))

    lo = np.zeros(len(a))
    hi = np.ones(len(a))
    for _ in range(iterations):
        m1 = lo + (hi - lo) / 3.0
        m2 = hi - (hi - lo) / 3.0
        left = dist(m1) <= dist(m2)
        hi = np.where(left, m2, hi)
        lo = np.where(left, lo, m1)
    return float(min(dist(lo).min(), dist(np.zeros(len(a))).min(), dist(np.ones(len(a))).min()))
