"""The driven replay: a timed swing's reference (its curve, or its samples interpolated as a drive
does) followed by a setpoint generator within the device's limits, and the legs driven to it in
MuJoCo (PD with inverse-dynamics feed-forward, or stiff servos), the stance heel held on its pivot.
Method and figures: docs/safety.md, "Replayed in a physics engine". Units: m, rad, s."""

from __future__ import annotations

import dataclasses
import math
import time
from typing import TYPE_CHECKING

import numpy as np

from jaxexo.sim.legs import Legs
from jaxexo.sim.mjcf import ACTUATED, DISTMAX, FOOT_RADIUS, LEGS, STANCE_LEG, SWING_LEG, SimError
from jaxexo.summary import Summary

if TYPE_CHECKING:
    from jaxexo.swing.limits import DeviceLimits

PHYSICS_PER_SAMPLE_MAX_DT = 0.001  # s: the driven replay's physics step is at most this
SETTLE = 0.2  # s the driven replay holds the last setpoint after the swing
GROUND_BAND = 1e-3  # m: a heel this close to the floor rests or slides on it
CLIP_TOL = 1e-9  # rad/s: a setpoint speed changed by more than this by a limit counts as saturated


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


def coefficients(kind: str, p, v, a, period) -> np.ndarray:
    """The polynomial pieces in u of ``interpolate``'s ``kind`` through the samples p (n, 4) with
    velocities v and accelerations a (those the kind does not use may be None), ``period`` apart
    (s; a scalar, or (n - 1, 1, 1) for pieces of their own lengths)."""
    if kind == "linear":
        return linear_coefficients(p)
    if kind == "cubic":
        return cubic_coefficients(p, v, period)
    if kind == "quintic":
        return quintic_coefficients(p, v, a, period)
    raise SimError(f"kind: expected linear, cubic or quintic, got {kind!r}")


def interpolate(kind: str, samples, period: float, t) -> tuple[np.ndarray, ...]:
    """Position, velocity and acceleration (len(t), 4 each) at times t (s) of samples ``period``
    apart from t = 0, interpolated as a drive does: "linear" (positions), "cubic" (the cubic
    Hermite of positions and velocities) or "quintic" (the quintic Hermite of positions,
    velocities and accelerations); ``samples``: (positions, velocities, accelerations), (n, 4)
    each (those the kind does not use may be None). Held at the first and last sample outside."""
    p, v, a = (None if x is None else np.asarray(x, np.float64) for x in samples)
    coef = coefficients(kind, p, v, a, period)
    return _polynomial(coef, *_interval(t, period, len(p)), period)


def hermite(ref: np.ndarray, ref_v: np.ndarray, period: float, t: np.ndarray) -> np.ndarray:
    """Joint angles (len(t), 4) at times t: the cubic Hermite through the control samples ``ref``
    (n, 4) with their velocities ``ref_v`` (the swing's chain-rule columns), held after the last."""
    return interpolate("cubic", (ref, ref_v, None), period, t)[0]


REFERENCES = ("curve", "quintic", "cubic", "linear")


def _samples(timed, rate: float | None):
    """The swing's joint samples (positions, velocities, accelerations) at ``rate`` Hz (None: its
    own rate) and their period (s)."""
    sw = timed if rate is None or float(rate) == float(timed.rate) else timed.sample(rate)
    return (sw.joint_angles, sw.joint_velocity, sw.joint_acceleration), 1.0 / float(sw.rate)


def reference_states(timed, t, reference: str = "curve", rate: float | None = None, *, before=None):
    """The driven replay's reference at times t (s): joint angles, velocities and accelerations
    (len(t), 4 each). "curve": the timed swing's curve itself (``timed.at(t)``); "quintic",
    "cubic", "linear": its samples at ``rate`` Hz (``timed.sample(rate)``; None: the swing's own
    rate) interpolated as a drive or a ROS 2 joint_trajectory_controller does (``interpolate``).
    ``before``: the swing ``timed`` was replanned from, followed until the switch
    (``switched_states``)."""
    t = np.asarray(t, np.float64)
    if before is not None:
        return switched_states(before, timed, t, reference, rate)
    if reference == "curve":
        st = timed.at(t)
        return st.joint_angles, st.joint_velocity, st.joint_acceleration
    cols, period = _samples(timed, rate)
    return interpolate(reference, cols, period, t)


def switched_states(before, timed, t, reference: str = "curve", rate: float | None = None):
    """The reference of a swing replanned in flight as a drive follows it (``reference_states``'
    three arrays): ``before`` (the swing as planned) until the switch (``timed``'s last switch
    time), ``timed`` (the replanned swing) from it. "curve": each swing's curve on its side. The
    sampled references: ``before``'s samples until the switch; then, as a drive that receives new
    samples interpolates from its own desired state (a ROS 2 joint_trajectory_controller's
    interpolate_from_desired_state), one piece of the same kind from the old reference's position,
    velocity and acceleration at the switch to the first of ``timed``'s samples at least half a
    period after it (a shorter piece would ask for more acceleration than a period does); then
    ``timed``'s samples."""
    t = np.asarray(t, np.float64)
    at = float(timed.switch_times[-1])
    after = t >= at
    out = tuple(x.copy() for x in reference_states(before, t, reference, rate))
    for o, x in zip(out, reference_states(timed, t[after], reference, rate)):
        o[after] = x
    if reference == "curve":
        return out
    cols, period = _samples(timed, rate)
    k = min(math.ceil(at / period + 0.5 - 1e-9), len(cols[0]) - 1)
    h = k * period - at
    span = after & (t < k * period)
    if h <= 0.0 or not span.any():  # no new sample after the switch: the new swing's hold
        return out
    start = reference_states(before, np.array([at]), reference, rate)
    pts = [np.vstack([s0[:1], np.asarray(c[k : k + 1], np.float64)]) for s0, c in zip(start, cols)]
    m = int(span.sum())
    piece = _polynomial(
        coefficients(reference, *pts, h),
        np.zeros(m, dtype=int),
        ((t[span] - at) / h)[:, None],
        np.ones((m, 1), dtype=bool),
        h,
    )
    for o, x in zip(out, piece):
        o[span] = x
    return out


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
        tendon[r, legs.dofs([f"{leg}_{j}" for j in ("hip", "knee", "ankle")])] = 1.0
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
    rollout = legs.rollout
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


def check_before(timed, before, reference: str) -> None:
    """``before`` checked as the swing that ``timed`` was replanned from (SimError naming it): a
    TimedSwing with ``timed``'s switch times but the last, which falls before it lands; carrying
    its curve for the "curve" reference."""
    from jaxexo.swing.timing import TimedSwing

    if not isinstance(before, TimedSwing):
        raise SimError(
            f"before: expected the TimedSwing that was replanned, got {type(before).__name__}"
        )
    sw = tuple(getattr(timed, "switch_times", ()))
    if not sw:
        raise SimError("before: the swing replayed was not replanned (it has no switch time)")
    if tuple(before.switch_times) != sw[:-1]:
        raise SimError(
            f"before: expected the swing replanned at {sw[-1]:.4f} s (switch times {list(sw[:-1])}), "
            f"got one with switch times {list(before.switch_times)}"
        )
    if not sw[-1] < before.duration:
        raise SimError(
            f"before: lands at {before.duration:.4f} s, before the switch at {sw[-1]:.4f} s"
        )
    if reference == "curve" and before.curve is None:
        raise SimError("before: the 'curve' reference needs a TimedSwing that carries its curve")


@dataclasses.dataclass(frozen=True)
class DrivenRun:
    """A driven replay's simulation: MuJoCo's sensor data after each physics step (the start's
    first), the physics step ``dt``, ``sub`` physics steps per control sample, the ``steps``
    simulated, where the setpoint generator clipped the acceleration and the velocity (per step),
    the feed-forward torque's peak per actuated joint (pd_ff; None for the servo), the
    reference's joint angles at every physics step (``reference_states``) and the setpoints
    (``setpoints``; the command of each step, at its end)."""

    sens: np.ndarray
    dt: float
    sub: int
    steps: int
    clip_a: np.ndarray
    clip_v: np.ndarray
    torque_peak: list | None
    reference: np.ndarray | None = None  # (steps + 2, 4) rad: the reference's joint angles
    command: np.ndarray | None = None  # (steps, 4) rad: the setpoints

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
    timed,
    legs: Legs,
    limits,
    settle: float,
    controller: str,
    reference="curve",
    ref_rate=None,
    *,
    before=None,
) -> DrivenRun:
    """The commands of a driven replay (they do not depend on the simulation), then MuJoCo's
    rollout of the model under them (``driven_replay``; ``before``: the swing followed until
    the switch, ``switched_states``)."""
    m = legs.model
    rate = float(timed.rate)
    sub = max(1, math.ceil(1.0 / (rate * PHYSICS_PER_SAMPLE_MAX_DT) - 1e-9))
    dt = 1.0 / (rate * sub)
    m.opt.timestep = dt
    n = len(timed.joint_angles)
    steps = (n - 1) * sub + int(round(settle / dt))
    # The reference at every physics step, and one step beyond for the velocity at each step's end.
    q, qd, qdd = reference_states(
        timed, np.arange(steps + 2) * dt, reference, ref_rate, before=before
    )
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
    return DrivenRun(
        sens, dt, sub, steps, clip_a[:steps], clip_v[:steps], torque_peak, q, cmd[:steps]
    )


@dataclasses.dataclass(frozen=True)
class DrivenFigures:
    """What MuJoCo measured of a driven replay (``_driven_figures``), SI units: the swing heel's and
    toe's tracking error at the samples (largest; the heel's off the floor, at p95 and after the
    settle too), MuJoCo's smallest foot-obstacle distance and when, whether it kept the margin and
    touched (steps in contact), the setpoint generator's clipped steps, the steps simulated, the
    largest joint speed [4], the stance heel's largest slip and the feed-forward torque's peak [4]
    (None for the servo)."""

    heel_error_max_m: float
    toe_error_max_m: float
    heel_error_airborne_max_m: float
    heel_error_p95_m: float
    toe_error_p95_m: float
    final_heel_error_m: float
    mujoco_min_distance_m: float
    mujoco_min_time_s: float
    margin_kept: bool
    contact_steps: int
    contact: bool
    saturated_velocity_steps: int
    saturated_acceleration_steps: int
    saturated: bool
    steps: int
    peak_joint_velocity_rad_s: list
    stance_heel_slip_max_m: float
    feed_forward_torque_peak_nm: list | None


@dataclasses.dataclass(frozen=True)
class SwitchFigures:
    """A driven replay through a switch (``switch_figures``), any joint: the switch time (s); the
    reference's jumps there in position (rad), velocity (rad/s) and acceleration (rad/s^2), its
    two sides read SWITCH_EPS either side of it (0 for a C2 join, to the next derivative times
    2 SWITCH_EPS); the
    commanded acceleration (the setpoints' second difference over the physics step, rad/s^2):
    its largest step between two physics steps whose differences reach across the switch (the
    jerk there times the step), the largest step elsewhere in the replay, the first over the
    second (at most 1: no worse than an ordinary step); its largest change over a control period
    (the swing's sample period) across the switch, elsewhere, and the first over the second."""

    switch_time_s: float
    position_jump_rad: float
    velocity_jump_rad_s: float
    acceleration_jump_rad_s2: float
    switch_step_rad_s2: float
    step_elsewhere_rad_s2: float
    step_ratio: float
    period_change_rad_s2: float
    period_change_elsewhere_rad_s2: float
    period_ratio: float


SWITCH_EPS = 1e-7  # s: each side of a switch where the reference's jumps are read


def reference_jumps(timed, before, reference: str = "curve", rate: float | None = None):
    """The largest jump (any joint) of the switched reference (``switched_states``) in position,
    velocity and acceleration at ``timed``'s last switch: its values SWITCH_EPS after it less
    ``before``'s SWITCH_EPS before it."""
    at = float(timed.switch_times[-1])
    left = reference_states(before, np.array([at - SWITCH_EPS]), reference, rate)
    right = reference_states(timed, np.array([at + SWITCH_EPS]), reference, rate, before=before)
    return tuple(float(np.abs(r - x).max()) for r, x in zip(right, left))


def commanded_acceleration(run: DrivenRun) -> np.ndarray:
    """The setpoints' acceleration (steps - 1, 4) rad/s^2 at t = dt, 2 dt, ...: their second
    difference over the physics step, the reference's start as the setpoint at t = 0."""
    c = np.concatenate([run.reference[:1], run.command])
    return np.diff(c, n=2, axis=0) / run.dt**2


def _changes(acc: np.ndarray, dt: float, at: float, w: int) -> tuple[float, float]:
    """The largest change of ``acc`` (at t = dt, 2 dt, ...) over ``w`` physics steps across t =
    ``at`` and elsewhere. Change i, from the acceleration at (i + 1) dt to (i + 1 + w) dt, takes
    the setpoints at i dt to (i + w + 2) dt: it reaches across ``at`` where those span it."""
    change = np.abs(acc[w:] - acc[:-w]).max(axis=1)
    i = np.arange(len(change))
    across = (i * dt <= at) & (at <= (i + w + 2) * dt)
    return float(change[across].max(initial=0.0)), float(change[~across].max(initial=0.0))


def switch_figures(run: DrivenRun, at: float, jumps=(0.0, 0.0, 0.0)) -> SwitchFigures:
    """A SwitchFigures of the replay ``run`` through the switch at t = ``at`` (s): the reference's
    ``jumps`` there (``reference_jumps``), and the commanded acceleration's largest change across
    it and elsewhere over a physics step and over a control period (``run.sub`` steps)."""
    acc = commanded_acceleration(run)
    ratio = lambda a, b: a / b if b > 0.0 else math.inf  # noqa: E731
    step, other = _changes(acc, run.dt, at, 1)
    period, period_other = _changes(acc, run.dt, at, run.sub)
    return SwitchFigures(
        switch_time_s=float(at),
        position_jump_rad=jumps[0],
        velocity_jump_rad_s=jumps[1],
        acceleration_jump_rad_s2=jumps[2],
        switch_step_rad_s2=step,
        step_elsewhere_rad_s2=other,
        step_ratio=ratio(step, other),
        period_change_rad_s2=period,
        period_change_elsewhere_rad_s2=period_other,
        period_ratio=ratio(period, period_other),
    )


@dataclasses.dataclass(frozen=True)
class DrivenReplay:
    """A driven replay (``driven_replay``): the swing's method and jaxexo's verdict, the margin (m),
    the controller, the reference and its rate (Hz; None for the curve), the drives' limits, the
    physics step and the settle (s), MuJoCo's figures, the replay's wall time (s) and, for a swing
    replayed through its switch (``before``), the commanded acceleration there."""

    method: str
    flagged_ok: bool
    margin_m: float
    controller: str
    reference: str
    reference_rate_hz: float | None
    limits: DeviceLimits
    physics_dt_s: float
    settle_s: float
    figures: DrivenFigures
    seconds: float
    switch: SwitchFigures | None = None

    def to_dict(self) -> dict:
        """The JSON entry: the fields in order, the limits as their dict, the figures spread flat;
        the switch's figures, where replayed through one, as their dict."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)[:-3]}
        out["limits"] = self.limits.to_dict()
        out = {**out, **dataclasses.asdict(self.figures), "seconds": self.seconds}
        if self.switch is not None:
            out["switch"] = dataclasses.asdict(self.switch)
        return out


def _driven_figures(timed, config, legs: Legs, run: DrivenRun) -> DrivenFigures:
    """Tracking, clearance, contact, saturation and slip figures of a driven replay's simulation."""
    col = lambda name: run.sensor(legs, name)  # noqa: E731
    n = len(timed.joint_angles)
    heel = col(f"{SWING_LEG}_heel")[:: run.sub][:n][:, [0, 2]]
    toe = col(f"{SWING_LEG}_toe")[:: run.sub][:n][:, [0, 2]]
    heel_e = np.linalg.norm(heel - timed.heel, axis=1)
    heel_err, toe_err = Summary.of(heel_e), Summary.of(np.linalg.norm(toe - timed.toe, axis=1))
    pivot = np.array([timed.scene.pivot_y, 0.0])
    slip = np.linalg.norm(col(f"{STANCE_LEG}_heel")[:, [0, 2]] - pivot, axis=1).max()
    dist = np.full(len(run.sens), DISTMAX)
    for i in range(len(legs.pieces)):
        dist = np.minimum(dist, col(f"foot_obstacle_{i}")[:, 0] + FOOT_RADIUS)
    qv = np.stack([col(j)[:, 0] for j in ACTUATED], axis=1)
    k = int(np.argmin(dist))
    return DrivenFigures(
        heel_error_max_m=heel_err.max,
        toe_error_max_m=toe_err.max,
        # Where the swing's heel is off the floor: a heel moved along the floor is held back by friction.
        heel_error_airborne_max_m=float(
            np.max(heel_e[timed.heel[:, 1] > GROUND_BAND], initial=0.0)
        ),
        heel_error_p95_m=heel_err.p95,
        toe_error_p95_m=toe_err.p95,
        final_heel_error_m=float(
            np.linalg.norm(col(f"{SWING_LEG}_heel")[-1, [0, 2]] - timed.heel[-1])
        ),
        mujoco_min_distance_m=float(dist[k]),
        mujoco_min_time_s=float(k * run.dt),
        margin_kept=bool(dist[k] >= float(config.env.min_clearance)),
        # The foot's capsule touches a piece where the segment comes within its radius: MuJoCo makes a contact.
        contact_steps=int(np.sum(dist <= FOOT_RADIUS)),
        contact=bool(dist[k] <= FOOT_RADIUS),
        saturated_velocity_steps=int(run.clip_v.sum()),
        saturated_acceleration_steps=int(run.clip_a.sum()),
        saturated=bool(run.clip_v.any() or run.clip_a.any()),
        steps=run.steps,
        peak_joint_velocity_rad_s=np.abs(qv).max(axis=0).tolist(),
        stance_heel_slip_max_m=float(slip),
        feed_forward_torque_peak_nm=run.torque_peak,
    )


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
    before=None,
) -> DrivenReplay:
    """The driven replay of a TimedSwing (docs/safety.md): a setpoint generator (``setpoints``)
    moves each command towards the ``reference`` (``reference_states``: "curve", the timed curve at
    every physics step; "quintic", "cubic" or "linear", its samples at ``reference_rate`` Hz, default
    its own rate, interpolated as a drive does) within the drives' ``limits`` (a DeviceLimits;
    default: the config's [device]), and the ``controller`` drives the legs after it: "pd_ff",
    inverse-dynamics feed-forward (``feed_forward``) plus a PD loop (``_pd_gains``); "servo", stiff
    position servos on the positions alone (they lag a moving reference by 2 / omega times its
    speed). ``before``: for a swing replanned in flight (``timed``), the swing it was replanned
    from; the reference follows it until the switch and ``timed`` after (``switched_states``), in
    ``timed``'s scene from the start, and the replay measures the commanded acceleration across
    the switch (``switch_figures``). The commands are computed first (they do not depend on the
    simulation), then MuJoCo rolls the model out in one call. SI units."""
    limits = _check_driven(config, limits, settle, controller)
    ref_rate = check_reference(timed, reference, reference_rate)
    if before is not None:
        check_before(timed, before, reference)
    t0 = time.perf_counter()
    legs = Legs(config, timed.scene) if legs is None else legs
    run = _simulate(timed, legs, limits, settle, controller, reference, ref_rate, before=before)
    figures = _driven_figures(timed, config, legs, run)
    switch = None
    if before is not None:
        jumps = reference_jumps(timed, before, reference, ref_rate)
        switch = switch_figures(run, float(timed.switch_times[-1]), jumps)
    return DrivenReplay(
        method=timed.method,
        flagged_ok=bool(timed.ok),
        margin_m=float(config.env.min_clearance),
        controller=controller,
        reference=reference,
        reference_rate_hz=ref_rate,
        limits=limits,
        physics_dt_s=run.dt,
        settle_s=float(settle),
        figures=figures,
        seconds=time.perf_counter() - t0,
        switch=switch,
    )
