"""A timed swing replayed in MuJoCo: kinematically (MuJoCo's own distance query at every pose) and
driven (position actuators within the device's velocity and acceleration limits, the stance heel
held on the ground). Needs the ``sim`` extra (``pip install -e ".[sim]"``: mujoco >= 4.0).

Kinematic replay (``kinematic_replay``): the model's joints are set to the swing's joint angles at
every control sample and at ``substeps`` poses between two samples, the angles there the timed
curve's (``TimedSwing.at``; linear between the samples for a swing without a curve); the pelvis is
placed where the stance leg's angles put it with the stance heel on its pivot, so at a sample the
feet are exactly jaxexo's (the hip of eq 2.42 keeps the stance leg straight on the pivot). At every
pose, MuJoCo's ``mj_geomDistance`` between the swing foot (a capsule around the heel-toe segment;
its radius added back) and each convex obstacle piece gives the foot-obstacle distance, with no
jaxexo geometry involved. The figures: the largest difference between MuJoCo's distance and
jaxexo's (jaxexo.physics.geometry.foot_clearance) at the samples, where both measure the same
pose; and MuJoCo's smallest distance over all poses, which a swing that jaxexo flags ok must keep
at env.min_clearance or more.

Driven replay (``driven_replay``): the physics runs at ``physics_per_sample`` steps per control
period; the swing's joint angles (by default the timed curve itself at every physics step; or its
samples at a rate, interpolated between them as a drive or a ROS 2 joint_trajectory_controller does:
quintic or cubic Hermite, or linear for comparison) are the reference of a setpoint
generator that moves each actuator's command towards it no faster than the device's joint velocity
and with no more than its acceleration (``DeviceLimits``: the [device] section, or scaled); the
position actuators (kp SERVO_KP, critically damped) pull the joints to the command against the
legs' inertia and gravity, and the stance heel is held on its pivot by an equality constraint. The
figures: heel and toe tracking error at the control samples (simulated foot against the swing's),
MuJoCo's smallest foot-obstacle distance over every physics step, contacts of the swing foot with
the obstacle, and whether the setpoint generator had to clip its velocity or acceleration to a limit
(saturation: the swing asks for more than the drive gives).

Not built yet: a walk (a course of swings). The hook: the model already has two identical legs,
and jaxexo.sim.mjcf's SWING_LEG / STANCE_LEG name which one swings; a walk's replay would run its
swings one after another with those roles swapped at each step (the stance heel's equality moved to
the other leg), continuing from the previous swing's final state. It waits for the course feature.

``brute_force_distance`` is the third, independent look: the distance from the flat foot to each
outline edge minimised over the foot by ternary search (the distance from a point moving along a
line to a segment is convex in the point's position), used where the other two disagree.
Units: m, rad, s.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from jaxexo.physics import geometry
from jaxexo.sim.mjcf import (
    ACTUATED,
    DISTMAX,
    FOOT_RADIUS,
    LEGS,
    QPOS_NAMES,
    STANCE_LEG,
    SWING_LEG,
    SimError,
    legs_mjcf,
    pose_qpos,
)

SUBSTEPS = 4  # kinematic poses per control period (the sample and 3 between)
PHYSICS_PER_SAMPLE_MAX_DT = 0.001  # s: the driven replay's physics step is at most this
SETTLE = 0.2  # s the driven replay holds the last setpoint after the swing
SAME_POSE = 1e-6  # m: MuJoCo's heel this close to jaxexo's is the same pose
GROUND_BAND = 1e-3  # m: a heel this close to the floor rests or slides on it
CLIP_TOL = 1e-9  # rad/s: a setpoint speed changed by more than this by a limit counts as saturated


def require_mujoco():
    """The mujoco module, or SimError saying how to install it."""
    try:
        import mujoco
    except ImportError:
        raise SimError(
            'MuJoCo is not installed; install the sim extra: pip install -e ".[sim]" '
            '(or pip install "mujoco>=4.0")'
        ) from None
    return mujoco


class Legs:
    """The MuJoCo model of a config's legs on one scene (the obstacle and the stance heel's pivot)."""

    def __init__(self, config, scene):
        mujoco = self.mujoco = require_mujoco()
        self.config = config
        self.scene = scene
        k = config.kinematics
        self.thigh, self.shin, self.foot_length = (
            float(k.thigh),
            float(k.shin),
            float(k.foot_length),
        )
        self.xml = legs_mjcf(config, scene.outline, scene.pivot_y)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        self.data = mujoco.MjData(self.model)
        gid = lambda n: mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_GEOM, n)  # noqa: E731
        self.foot = gid(f"{SWING_LEG}_foot")
        self.pieces = [
            gid(f"obstacle_{i}") for i in range(int(self.model.numeric("obstacle_pieces").data[0]))
        ]
        adr = [
            int(self.model.jnt_qposadr[mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, n)])
            for n in QPOS_NAMES
        ]
        if adr != list(range(len(QPOS_NAMES))):  # pose_qpos writes the columns in this order
            raise RuntimeError(f"the model's qpos layout {adr} is not QPOS_NAMES")
        self.site = {
            n: mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_SITE, n)
            for n in (f"{leg}_{p}" for leg in LEGS for p in ("heel", "toe"))
        }
        self.stance_eq = mujoco.mj_name2id(
            self.model, mujoco.mjtObj.mjOBJ_EQUALITY, f"{STANCE_LEG}_on_pivot"
        )
        self.actuators = [
            mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in ACTUATED
        ]
        self.actuated_dofs = _dofs(
            self, ACTUATED
        )  # the actuated joints' columns of qvel, ACTUATED order

    def qpos(self, angles) -> np.ndarray:
        """qpos (..., nq) of joint angles (..., 4) in JOINT_NAMES order (jaxexo.sim.mjcf.pose_qpos)."""
        return pose_qpos(angles, self.scene.pivot_y, self.thigh, self.shin)

    def foot_distance(self, distmax: float = DISTMAX) -> float:
        """MuJoCo's smallest distance (m) between the swing foot's heel-toe segment and the obstacle
        at the data's current pose (negative: penetration); ``distmax`` when farther (or no obstacle)."""
        d = distmax
        for g in self.pieces:
            d = min(
                d,
                self.mujoco.mj_geomDistance(self.model, self.data, self.foot, g, distmax, None)
                + FOOT_RADIUS,
            )
        return d

    def set_pose(self, qpos) -> None:
        self.data.qpos[:] = qpos
        self.mujoco.mj_kinematics(self.model, self.data)

    def site_yz(self, name: str) -> np.ndarray:
        """A site's (y, z) in jaxexo's frame (MuJoCo's x, z)."""
        p = self.data.site_xpos[self.site[name]]
        return np.array([p[0], p[2]])


def fine_angles(angles: np.ndarray, substeps: int) -> np.ndarray:
    """Joint angles (n, 4) at the control samples -> ((n - 1) substeps + 1, 4), linear in between."""
    n = len(angles)
    f = np.arange(substeps) / substeps
    mid = angles[:-1, None, :] + f[None, :, None] * np.diff(angles, axis=0)[:, None, :]
    return np.concatenate([mid.reshape((n - 1) * substeps, angles.shape[1]), angles[-1:]])


def kinematic_replay(timed, config, substeps: int = SUBSTEPS, legs: Legs | None = None) -> dict:
    """The kinematic replay of a TimedSwing (module docstring). ``legs``: a Legs of the same scene to
    reuse. Returns SI figures; ``flagged_ok`` is jaxexo's verdict, ``margin_kept`` MuJoCo's."""
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
    return {
        "method": timed.method,
        "flagged_ok": bool(timed.ok),
        "margin_m": margin,
        "jaxexo_guaranteed_clearance_m": float(timed.checks.min_clearance),
        "mujoco_min_distance_m": float(dist[k]),
        "mujoco_min_time_s": float(k / substeps / timed.rate),
        "mujoco_min_heel": heel[k].tolist(),
        "margin_kept": bool(dist[k] >= margin),
        "flagged_ok_but_within_margin": bool(timed.ok and dist[k] < margin),
        "max_disagreement_m": float(diff[worst]) if worst >= 0 else 0.0,
        "max_disagreement_sample": worst,
        "max_heel_offset_m": float(offset.max()),
        "samples_compared": int(both.sum()),
        "poses": int(len(q)),
        "substeps": substeps,
        "seconds": time.perf_counter() - t0,
    }


def _interval(t, period: float, n: int):
    """The interval k (len(t),) of each time t among n samples ``period`` apart, the position u in
    it ([0, 1], clamped: before the first sample and after the last the reference holds), and
    whether t lies inside the samples (the derivatives are 0 where it does not)."""
    x = np.asarray(t, np.float64) / period
    inside = (x >= 0.0) & (x <= n - 1)
    x = np.clip(x, 0.0, n - 1)
    k = np.minimum(x.astype(int), n - 2)
    return k, (x - k)[:, None], inside[:, None]


def _polynomial(coef: np.ndarray, k, u, inside, period: float):
    """Position, velocity and acceleration (len(u), 4) of the piecewise polynomials ``coef``
    (n - 1, degree + 1, 4) in u = (t - t_k) / period on interval k."""
    c = coef[k]  # (m, degree + 1, 4)
    deg = c.shape[1] - 1
    q, d1, d2 = c[:, deg], np.zeros_like(c[:, 0]), np.zeros_like(c[:, 0])
    for i in range(deg - 1, -1, -1):  # Horner, with the first two derivatives alongside
        d2 = d2 * u + 2.0 * d1
        d1 = d1 * u + q
        q = q * u + c[:, i]
    return q, np.where(inside, d1 / period, 0.0), np.where(inside, d2 / period**2, 0.0)


def linear_coefficients(p: np.ndarray) -> np.ndarray:
    """(n - 1, 2, 4): the straight lines between the samples p (n, 4)."""
    return np.stack([p[:-1], np.diff(p, axis=0)], axis=1)


def cubic_coefficients(p: np.ndarray, v: np.ndarray, period: float) -> np.ndarray:
    """(n - 1, 4, 4): the cubic Hermite in u through the samples p (n, 4) with velocities v."""
    p0, p1, m0, m1 = p[:-1], p[1:], period * v[:-1], period * v[1:]
    return np.stack([p0, m0, 3.0 * (p1 - p0) - 2.0 * m0 - m1, 2.0 * (p0 - p1) + m0 + m1], axis=1)


def quintic_coefficients(p: np.ndarray, v: np.ndarray, a: np.ndarray, period: float) -> np.ndarray:
    """(n - 1, 6, 4): the quintic Hermite in u through the samples p (n, 4) with velocities v and
    accelerations a (what a ROS 2 joint_trajectory_controller makes of positions, velocities and
    accelerations): c0..c2 from the start of each interval, c3..c5 so that the position, velocity
    and acceleration at its end are the next sample's."""
    c0, c1, c2 = p[:-1], period * v[:-1], 0.5 * period**2 * a[:-1]
    rp = p[1:] - (c0 + c1 + c2)  # what c3 + c4 + c5 must add to the position at u = 1
    rv = period * v[1:] - (c1 + 2.0 * c2)  # ... 3 c3 + 4 c4 + 5 c5 to the velocity
    ra = period**2 * a[1:] - 2.0 * c2  # ... 6 c3 + 12 c4 + 20 c5 to the acceleration
    c3 = 10.0 * rp - 4.0 * rv + 0.5 * ra
    c4 = -15.0 * rp + 7.0 * rv - ra
    c5 = 6.0 * rp - 3.0 * rv + 0.5 * ra
    return np.stack([c0, c1, c2, c3, c4, c5], axis=1)


def interpolate(kind: str, samples, period: float, t) -> tuple[np.ndarray, ...]:
    """Position, velocity and acceleration (len(t), 4 each) at times t (s) of samples ``period``
    apart from t = 0, interpolated as a drive does: "linear" (positions), "cubic" (the cubic
    Hermite of positions and velocities) or "quintic" (the quintic Hermite of positions,
    velocities and accelerations); ``samples``: (positions, velocities, accelerations), (n, 4)
    each (those the kind does not use may be None). Held at the first and last sample outside."""
    p, v, a = (None if x is None else np.asarray(x, np.float64) for x in samples)
    if kind == "linear":
        coef = linear_coefficients(p)
    elif kind == "cubic":
        coef = cubic_coefficients(p, v, period)
    elif kind == "quintic":
        coef = quintic_coefficients(p, v, a, period)
    else:
        raise SimError(f"kind: expected linear, cubic or quintic, got {kind!r}")
    return _polynomial(coef, *_interval(t, period, len(p)), period)


def hermite(ref: np.ndarray, ref_v: np.ndarray, period: float, t: np.ndarray) -> np.ndarray:
    """Joint angles (len(t), 4) at times t: the cubic Hermite through the control samples ``ref``
    (n, 4) with their velocities ``ref_v`` (the swing's chain-rule columns), held after the last."""
    return interpolate("cubic", (ref, ref_v, None), period, t)[0]


REFERENCES = ("curve", "quintic", "cubic", "linear")


def reference_states(timed, t, reference: str = "curve", rate: float | None = None):
    """The driven replay's reference at times t (s): joint angles, velocities and accelerations
    (len(t), 4 each). "curve": the timed swing's curve itself (``timed.at(t)``); "quintic",
    "cubic", "linear": its samples at ``rate`` Hz (``timed.sample(rate)``; None: the swing's own
    rate) interpolated as a drive or a ROS 2 joint_trajectory_controller does (``interpolate``)."""
    t = np.asarray(t, np.float64)
    if reference == "curve":
        st = timed.at(t)
        return st.joint_angles, st.joint_velocity, st.joint_acceleration
    sw = timed if rate is None or float(rate) == float(timed.rate) else timed.sample(rate)
    cols = (sw.joint_angles, sw.joint_velocity, sw.joint_acceleration)
    return interpolate(reference, cols, 1.0 / float(sw.rate), t)


def setpoints(ref: np.ndarray, dt: float, vmax, amax):
    """The drives' commands (steps, 4) following the reference ``ref`` (steps + 1, 4) sampled every
    ``dt``: each step feeds the reference's own step forward and catches up on the error no faster
    than the drive can stop (v^2 = 2 a |e|), then clips to the acceleration and velocity limits.
    Returns the commands and, per step, whether an acceleration or a velocity limit clipped."""
    steps = len(ref) - 1
    out = np.empty((steps, ref.shape[1]))
    clip_a = np.zeros(steps, dtype=bool)
    clip_v = np.zeros(steps, dtype=bool)
    cmd = ref[0].tolist()
    vel = [0.0] * ref.shape[1]
    vmax, amax = [float(x) for x in vmax], [float(x) for x in amax]
    rows = ref.tolist()
    for i in range(steps):
        r, r_next = rows[i], rows[i + 1]
        for j in range(len(cmd)):
            e = r[j] - cmd[j]
            want = (r_next[j] - r[j]) / dt + math.copysign(
                min(abs(e) / dt, math.sqrt(2.0 * amax[j] * abs(e))), e
            )
            v = min(max(want, vel[j] - amax[j] * dt), vel[j] + amax[j] * dt)
            if abs(v - want) > CLIP_TOL:
                clip_a[i] = True
            w = min(max(v, -vmax[j]), vmax[j])
            if abs(w - v) > CLIP_TOL:
                clip_v[i] = True
            vel[j] = w
            cmd[j] += w * dt
        out[i] = cmd
    return out, clip_a, clip_v


CONTROLLERS = ("pd_ff", "servo")
PD_BANDWIDTH_HZ = (
    8.0  # Hz: the PD loop's natural frequency per joint (critically damped) under feed-forward
)


def _equalities_on(legs: Legs) -> None:
    """The stance heel held on its pivot and both feet level (the driven replay's constraints)."""
    mujoco, m = legs.mujoco, legs.model
    m.eq_active0[:] = 0
    m.eq_active0[legs.stance_eq] = 1
    for name in (f"{leg}_level" for leg in LEGS):
        m.eq_active0[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_EQUALITY, name)] = 1


def _dofs(legs: Legs, names) -> list[int]:
    """The qvel columns of the named joints."""
    mujoco, m = legs.mujoco, legs.model
    return [int(m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)]) for n in names]


def feed_forward(legs: Legs, qpos: np.ndarray, qvel: np.ndarray, qacc: np.ndarray) -> np.ndarray:
    """Joint torques (steps, 4), ACTUATED order, that move the legs along (qpos, qvel, qacc) (steps,
    nv each) with the stance heel on its pivot and the feet level: MuJoCo's rigid-body inverse
    dynamics (mj_inverse, constraints off: M qacc + bias), less the constraint forces that make the
    unactuated coordinates (pelvis, ankles) balance. The constraint rows (the stance heel's
    horizontal and vertical position, each foot's level tendon) are as many as those coordinates,
    so the split is exact; mj_inverse's own soft-constraint forces are not used (they follow the
    reference's small inconsistencies, not the rigid constraint)."""
    mujoco, m, d = legs.mujoco, legs.model, legs.data
    act = legs.actuated_dofs
    free = [i for i in range(m.nv) if i not in act]
    tendon = np.zeros((len(LEGS), m.nv))
    for r, leg in enumerate(LEGS):
        tendon[r, _dofs(legs, [f"{leg}_{j}" for j in ("hip", "knee", "ankle")])] = 1.0
    site = legs.site[f"{STANCE_LEG}_heel"]
    jac = np.zeros((3, m.nv))
    tau = np.empty((len(qpos), len(act)))
    flags = m.opt.disableflags
    m.opt.disableflags = flags | int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    try:
        for k in range(len(qpos)):
            d.qpos[:], d.qvel[:], d.qacc[:] = qpos[k], qvel[k], qacc[k]
            mujoco.mj_inverse(m, d)
            mujoco.mj_jacSite(m, d, jac, None, site)
            rows = np.vstack([jac[[0, 2]], tendon])  # the planar rows of the constraints
            f = d.qfrc_inverse
            lam = np.linalg.solve(rows[:, free].T, f[free])
            tau[k] = (f - rows.T @ lam)[act]
    finally:
        m.opt.disableflags = flags
    return tau


def _pd_gains(legs: Legs, qpos0: np.ndarray):
    """Per actuated joint, kp (N m / rad) and kd (N m s / rad) of a critically damped loop of
    PD_BANDWIDTH_HZ on the joint's own inertia (the mass matrix's diagonal at the start pose)."""
    mujoco, m, d = legs.mujoco, legs.model, legs.data
    d.qpos[:] = qpos0
    mujoco.mj_forward(m, d)
    full = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, full)
    inertia = np.diag(full)[legs.actuated_dofs]
    w = 2.0 * math.pi * PD_BANDWIDTH_HZ
    return inertia * w * w, 2.0 * inertia * w


def _rollout(legs: Legs, qpos0: np.ndarray, control: np.ndarray, gains=None) -> np.ndarray:
    """MuJoCo's rollout from rest at qpos0 with the actuators' commands ``control`` (steps, 4);
    ``gains``: (kp, kd) for the PD with feed-forward (the position actuators re-gained for the
    call, their command range off: the command carries the velocity and torque terms too).
    Returns the sensor data after each step, the start's first (steps + 1, nsensordata)."""
    mujoco, m, d = legs.mujoco, legs.model, legs.data
    from mujoco import rollout

    saved = (m.actuator_gainprm.copy(), m.actuator_biasprm.copy(), m.actuator_ctrllimited.copy())
    try:
        if gains is not None:
            for j, a in enumerate(legs.actuators):
                m.actuator_gainprm[a, 0] = gains[0][j]
                m.actuator_biasprm[a, 1:3] = (-gains[0][j], -gains[1][j])
                m.actuator_ctrllimited[a] = 0
        mujoco.mj_resetData(m, d)
        d.qpos[:] = qpos0
        mujoco.mj_forward(m, d)
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        state0 = np.empty(mujoco.mj_stateSize(m, spec))
        mujoco.mj_getState(m, d, state0, spec)
        first = d.sensordata.copy()
        full = np.zeros((1, len(control), m.nu))
        full[0][:, legs.actuators] = control
        _, sensors = rollout.rollout(m, d, state0[None], full)
    finally:
        m.actuator_gainprm[:], m.actuator_biasprm[:], m.actuator_ctrllimited[:] = saved
    return np.concatenate([first[None], sensors[0]])


def _check_driven(config, limits, settle, controller):
    """The driven replay's limits (default: the config's [device]), its other inputs checked
    (SimError)."""
    from jaxexo.swing.timing import DeviceLimits

    limits = DeviceLimits.from_config(config) if limits is None else limits
    if not isinstance(limits, DeviceLimits):
        raise SimError(f"limits: expected a DeviceLimits, got {type(limits).__name__}")
    if isinstance(settle, bool) or not (
        isinstance(settle, (int, float)) and math.isfinite(settle) and settle >= 0
    ):
        raise SimError(f"settle: must be a finite number >= 0 (s), got {settle!r}")
    if controller not in CONTROLLERS:
        raise SimError(f"controller: expected one of {', '.join(CONTROLLERS)}, got {controller!r}")
    return limits


def check_reference(timed, reference, reference_rate) -> float | None:
    """The driven replay's ``reference`` and ``reference_rate`` checked (SimError naming the
    argument); returns the rate in Hz of a sampled reference (None: the curve)."""
    from jaxexo.swing.timing import check_rate

    if not isinstance(reference, str) or reference not in REFERENCES:
        raise SimError(f"reference: expected one of {', '.join(REFERENCES)}, got {reference!r}")
    if reference == "curve":
        if reference_rate is not None:
            raise SimError(
                "reference_rate: only for the sampled references (quintic, cubic, linear); "
                f"reference='curve' follows the curve at every physics step, got {reference_rate!r}"
            )
        if getattr(timed, "curve", None) is None:
            raise SimError("reference: 'curve' needs a TimedSwing that carries its curve")
        return None
    if reference_rate is None:
        return float(timed.rate)
    try:
        return check_rate(reference_rate, "reference_rate")
    except (TypeError, ValueError) as e:
        raise SimError(str(e)) from None


@dataclasses.dataclass(frozen=True)
class DrivenRun:
    """A driven replay's simulation: MuJoCo's sensor data after each physics step (the start's
    first), the physics step ``dt``, ``sub`` physics steps per control sample, the ``steps``
    simulated, where the setpoint generator clipped the acceleration and the velocity (per step),
    the feed-forward torque's peak per actuated joint (pd_ff; None for the servo), and the
    reference's joint angles at every physics step (``reference_states``)."""

    sens: np.ndarray
    dt: float
    sub: int
    steps: int
    clip_a: np.ndarray
    clip_v: np.ndarray
    torque_peak: list | None
    reference: np.ndarray | None = None  # (steps + 2, 4) rad: the reference's joint angles

    def sensor(self, legs: Legs, name: str) -> np.ndarray:
        """The first three columns of sensor ``name`` at every physics step."""
        mujoco, m = legs.mujoco, legs.model
        return self.sens[:, m.sensor_adr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, name)] :][
            :, :3
        ]


def qpos_derivatives(legs: Legs, q, qd, qdd, h: float = 1e-4):
    """The model's qpos, qvel and qacc (steps, nq each) of joint angles q (steps, 4) moving at qd
    with acceleration qdd: pose_qpos along its second-order Taylor step q +- h qd + h^2/2 qdd
    (central differences in the direction of motion: the pelvis and ankles follow the joints)."""
    p0 = legs.qpos(q)
    pp = legs.qpos(q + h * qd + 0.5 * h * h * qdd)
    pm = legs.qpos(q - h * qd + 0.5 * h * h * qdd)
    return p0, (pp - pm) / (2.0 * h), (pp - 2.0 * p0 + pm) / (h * h)


def _simulate(
    timed, legs: Legs, limits, settle: float, controller: str, reference="curve", ref_rate=None
) -> DrivenRun:
    """The commands of a driven replay (they do not depend on the simulation), then MuJoCo's
    rollout of the model under them (``driven_replay``)."""
    m = legs.model
    rate = float(timed.rate)
    sub = max(1, math.ceil(1.0 / (rate * PHYSICS_PER_SAMPLE_MAX_DT) - 1e-9))
    dt = 1.0 / (rate * sub)
    m.opt.timestep = dt
    n = len(timed.joint_angles)
    steps = (n - 1) * sub + int(round(settle / dt))
    # The reference at every physics step, and one step beyond for the velocity at each step's end.
    q, qd, qdd = reference_states(timed, np.arange(steps + 2) * dt, reference, ref_rate)
    if reference == "linear":  # its velocity jumps at the samples: the derivatives of its steps
        qd = np.gradient(q, dt, axis=0, edge_order=2)
        qdd = np.gradient(qd, dt, axis=0, edge_order=2)
    _equalities_on(legs)
    qpos0 = legs.qpos(q[0])
    # Both controllers follow the reference through the setpoint generator: the drive is never
    # asked beyond its limits (where it would be, the generator clips: saturation).
    cmd, clip_a, clip_v = setpoints(q, dt, limits.velocity, limits.acceleration)
    torque_peak = None
    if controller == "servo":
        sens = _rollout(legs, qpos0, cmd[:steps])
    else:
        # The commanded motion: the reference's own velocity and acceleration, plus those of the
        # generator's departure from it (zero unless a limit clipped).
        dev = np.concatenate([q[:1], cmd]) - q
        dv = np.gradient(dev, dt, axis=0, edge_order=2)
        qpos, qvel, qacc = qpos_derivatives(
            legs, q + dev, qd + dv, qdd + np.gradient(dv, dt, axis=0, edge_order=2)
        )
        tau = feed_forward(legs, qpos[:steps], qvel[:steps], qacc[:steps])
        kp, kd = _pd_gains(legs, qpos0)
        # The command of the step ending at t_{k+1}: force = kp (q_ref - q) + kd (q_ref' - q') + tau.
        qvel_ref = qvel[1 : steps + 1][:, legs.actuated_dofs]
        sens = _rollout(legs, qpos0, cmd[:steps] + (kd / kp) * qvel_ref + tau / kp, (kp, kd))
        torque_peak = np.abs(tau).max(axis=0).tolist()
    return DrivenRun(sens, dt, sub, steps, clip_a[:steps], clip_v[:steps], torque_peak, q)


def _driven_figures(timed, config, legs: Legs, run: DrivenRun) -> dict:
    """Tracking, clearance, contact, saturation and slip figures of a driven replay's simulation."""
    col = lambda name: run.sensor(legs, name)  # noqa: E731
    n = len(timed.joint_angles)
    heel = col(f"{SWING_LEG}_heel")[:: run.sub][:n][:, [0, 2]]
    toe = col(f"{SWING_LEG}_toe")[:: run.sub][:n][:, [0, 2]]
    heel_err = np.linalg.norm(heel - timed.heel, axis=1)
    toe_err = np.linalg.norm(toe - timed.toe, axis=1)
    pivot = np.array([timed.scene.pivot_y, 0.0])
    slip = np.linalg.norm(col(f"{STANCE_LEG}_heel")[:, [0, 2]] - pivot, axis=1).max()
    dist = np.full(len(run.sens), DISTMAX)
    for i in range(len(legs.pieces)):
        dist = np.minimum(dist, col(f"foot_obstacle_{i}")[:, 0] + FOOT_RADIUS)
    qv = np.stack([col(j)[:, 0] for j in ACTUATED], axis=1)
    k = int(np.argmin(dist))
    margin = float(config.env.min_clearance)
    return {
        "heel_error_max_m": float(heel_err.max()),
        "toe_error_max_m": float(toe_err.max()),
        # Where the swing's heel is off the floor: a heel moved along the floor is held back by friction.
        "heel_error_airborne_max_m": float(
            np.max(heel_err[timed.heel[:, 1] > GROUND_BAND], initial=0.0)
        ),
        "heel_error_p95_m": float(np.percentile(heel_err, 95)),
        "toe_error_p95_m": float(np.percentile(toe_err, 95)),
        "final_heel_error_m": float(
            np.linalg.norm(col(f"{SWING_LEG}_heel")[-1, [0, 2]] - timed.heel[-1])
        ),
        "mujoco_min_distance_m": float(dist[k]),
        "mujoco_min_time_s": float(k * run.dt),
        "margin_kept": bool(dist[k] >= margin),
        # The foot's capsule touches a piece where the segment comes within its radius: MuJoCo makes a contact.
        "contact_steps": int(np.sum(dist <= FOOT_RADIUS)),
        "contact": bool(dist[k] <= FOOT_RADIUS),
        "saturated_velocity_steps": int(run.clip_v.sum()),
        "saturated_acceleration_steps": int(run.clip_a.sum()),
        "saturated": bool(run.clip_v.any() or run.clip_a.any()),
        "steps": run.steps,
        "peak_joint_velocity_rad_s": np.abs(qv).max(axis=0).tolist(),
        "stance_heel_slip_max_m": float(slip),
        "feed_forward_torque_peak_nm": run.torque_peak,
    }


def driven_replay(
    timed,
    config,
    limits=None,
    legs: Legs | None = None,
    settle: float = SETTLE,
    controller: str = "pd_ff",
    *,
    reference: str = "curve",
    reference_rate: float | None = None,
) -> dict:
    """The driven replay of a TimedSwing (module docstring) with the drives' ``limits`` (a
    DeviceLimits; default: the config's [device]) and a ``controller``:

    - "pd_ff": what an exoskeleton's joint controller does: the inverse-dynamics torque of the
      reference (``feed_forward``) plus a PD loop on the position and velocity error
      (``_pd_gains``), on the setpoints' positions, velocities and accelerations.
    - "servo": stiff position servos (SERVO_KP, critically damped) on the setpoints' positions
      alone: with no velocity term a servo lags a moving reference by 2 / omega times its speed.

    The ``reference`` the setpoints follow, for both (``reference_states``):

    - "curve" (default): the timed swing's curve, its position, velocity and acceleration at every
      physics step (``timed.at``).
    - "quintic", "cubic", "linear": the swing sampled at ``reference_rate`` Hz (default: its own
      rate; ``timed.sample``) and interpolated between the samples as a drive or a ROS 2
      joint_trajectory_controller does: the quintic Hermite of positions, velocities and
      accelerations, the cubic Hermite of positions and velocities, or straight lines between the
      positions (for comparison only: its velocity jumps at every sample).

    A setpoint generator then moves each command towards the reference within the velocity and
    acceleration limits (``setpoints``); saturated where it clips.

    The commands are computed first (they do not depend on the simulation), then MuJoCo rolls the
    model out in one call (mujoco.rollout) and its sensors give the sites and the foot-obstacle
    distances. Returns SI figures."""
    limits = _check_driven(config, limits, settle, controller)
    ref_rate = check_reference(timed, reference, reference_rate)
    t0 = time.perf_counter()
    legs = Legs(config, timed.scene) if legs is None else legs
    run = _simulate(timed, legs, limits, settle, controller, reference, ref_rate)
    return {
        "method": timed.method,
        "flagged_ok": bool(timed.ok),
        "margin_m": float(config.env.min_clearance),
        "controller": controller,
        "reference": reference,
        "reference_rate_hz": ref_rate,
        "limits": limits.to_dict(),
        "physics_dt_s": run.dt,
        "settle_s": float(settle),
        **_driven_figures(timed, config, legs, run),
        "seconds": time.perf_counter() - t0,
    }


def summarize_kinematic(rows: list[dict]) -> dict:
    """Figures of many kinematic replays (``kinematic_replay``'s dicts): the swings jaxexo flags ok
    that come within the margin in MuJoCo (the target is 0), MuJoCo's smallest distance among the ok
    swings and its smallest excess over jaxexo's guaranteed clearance, the largest disagreement
    between the two geometries at the samples, and the replay's median cost."""
    ok = [r for r in rows if r["flagged_ok"]]
    return {
        "n": len(rows),
        "flagged_ok": len(ok),
        "flagged_ok_within_margin": int(sum(r["flagged_ok_but_within_margin"] for r in rows)),
        "min_mujoco_distance_of_ok_m": min((r["mujoco_min_distance_m"] for r in ok), default=None),
        "min_mujoco_minus_guaranteed_of_ok_m": min(
            (r["mujoco_min_distance_m"] - r["jaxexo_guaranteed_clearance_m"] for r in ok),
            default=None,
        ),
        "max_disagreement_m": max((r["max_disagreement_m"] for r in rows), default=None),
        # Over the swings flagged ok: a failed swing may ask for a heel out of the leg's reach.
        "max_heel_offset_of_ok_m": max((r["max_heel_offset_m"] for r in ok), default=None),
        "seconds_median": float(np.median([r["seconds"] for r in rows])) if rows else None,
        "poses_median": float(np.median([r["poses"] for r in rows])) if rows else None,
    }


def summarize_driven(rows: list[dict]) -> dict:
    """Figures of many driven replays (``driven_replay``'s dicts): heel and toe tracking error (p95
    and max over the swings of each swing's largest), contacts, swings within the margin, MuJoCo's
    smallest distance, saturated swings, the stance heel's largest slip and the median cost."""
    if not rows:
        return {"n": 0}
    he = np.array([d["heel_error_max_m"] for d in rows])
    te = np.array([d["toe_error_max_m"] for d in rows])
    md = np.array([d["mujoco_min_distance_m"] for d in rows])
    ha = np.array([d["heel_error_airborne_max_m"] for d in rows])
    return {
        "n": len(rows),
        "heel_error_p95_m": float(np.percentile(he, 95)),
        "heel_error_max_m": float(he.max()),
        "heel_error_airborne_p95_m": float(np.percentile(ha, 95)),
        "toe_error_p95_m": float(np.percentile(te, 95)),
        "toe_error_max_m": float(te.max()),
        "contacts": int(sum(d["contact"] for d in rows)),
        "within_margin": int(np.sum(md < rows[0]["margin_m"])),
        "min_distance_m": float(md.min()),
        "median_min_distance_m": float(np.median(md)),
        "saturated": int(sum(d["saturated"] for d in rows)),
        "stance_heel_slip_max_m": float(max(d["stance_heel_slip_max_m"] for d in rows)),
        "seconds_median": float(np.median([d["seconds"] for d in rows])),
    }


def replay_trajectories(trajs, config, rate: float | None = None, driven: bool = True) -> dict:
    """Trajectories (one generator's) timed for the device at ``rate`` and replayed in MuJoCo:
    ``summarize_kinematic`` of all of them and ``summarize_driven`` of those flagged ok, at the
    config's [device] limits (``jaxexo eval --replay``)."""
    from jaxexo.swing.timing import time_swings

    require_mujoco()
    kin, drv = [], []
    for ts in time_swings(list(trajs), config, rate=rate):
        legs = Legs(config, ts.scene)
        kin.append(kinematic_replay(ts, config, legs=legs))
        if driven and ts.ok:
            drv.append(driven_replay(ts, config, legs=legs))
    out = {"kinematic": summarize_kinematic(kin)}
    if driven:
        out["driven"] = summarize_driven(drv)
    return out


def brute_force_distance(heel, foot_length: float, outline, iterations: int = 200) -> float:
    """Distance (m) from the flat foot [heel, heel + (foot_length, 0)] to the outline's edges (the
    boundary, unsigned), by ternary search of the foot position on each edge (module docstring):
    independent of jaxexo.physics.geometry's closed form and of MuJoCo. 0 where they cross."""
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
