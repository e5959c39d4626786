"""Replanning in flight (NumPy only): a timed swing changed at an instant t when the obstacle turns
out other than estimated. The swing is kept as it is on [0, t]; from t a continuation over the new
obstacle to the same goal is joined to it with the joints' position, velocity and acceleration
continuous, timed within the limits from the moving state, and judged as a whole against the new
obstacle. Method and measurements: docs/replanning.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from jaxexo.config import MAX_SWING_DURATION
from jaxexo.swing import timing
from jaxexo.swing.curve import (
    JointPath,
    SwingCurve,
    TimeLaw,
    check_points,
    chord_knots,
    distinct_samples,
    paths_at,
    speed_nodes,
)
from jaxexo.swing.curve_check import FinalLaw, Plan, lowered_cap, max_samples, with_bounds
from jaxexo.swing.knots import few_knot_paths
from jaxexo.swing.limits import DeviceLimits, GridView, holds, passes_rows, peak_ratio, speed_ratio
from jaxexo.swing.time_law import max_speed_curve, topp


@dataclass(frozen=True)
class FootState:
    """Where a timed swing is at the instant ``time`` (s): the path parameter s, the swing heel (2,)
    m with its velocity (m/s) and acceleration (m/s^2), the joints (4,) rad with theirs (JOINT_NAMES
    order), and the heel's path so far (P, 2) m, from lift-off to the heel at ``time`` (the curve's
    check points on [0, s], spaced within CURVE_TOL of the curve): what a continuation starts from."""

    time: float
    path_parameter: float
    heel: np.ndarray
    heel_velocity: np.ndarray
    heel_acceleration: np.ndarray
    joints: np.ndarray
    joint_velocity: np.ndarray
    joint_acceleration: np.ndarray
    past_heel: np.ndarray


# s: the continuation leaves the old path's direction over the joints' travel in this long at
# the speed they have at the switch (the first knots of the new path within it are dropped, and
# one free knot takes their place): long enough that the turn to the new path asks no more
# acceleration than the passes allow, short enough that the foot is on the new path soon.
BLEND_TIME = 0.08
# The share of the smallest acceleration limit the turn onto the continuation is planned with (the
# rest: the law's deceleration, which the averaging window lags).
TURN_SHARE = 0.5
# The continuation's path parameter speeds from the old path's (at the switch) to its own over
# this fraction of the new path (an exponential approach): the passes' grid is uniform in s.
BLEND_PARAMETER = 0.1
# A switch needs this much of the path still to go at the unfiltered speed profile's position.
MIN_TO_GO = 1e-3
BLEND_TRIES = 3  # turns tried: the estimate and BLEND_TRIES - 1 longer ones (then a shorter one)
START_WINDOWS = 2.0  # law windows after the switch where the start's speed holds the caps up
LIMIT_PASSES = 3  # the passes re-run with caps lowered by a curve's excess, at most this often
OVERSHOOT = 1.002  # ... lowered by the excess squared times this (an excess of 1 + 1e-6 then ends)
# The corrections never lower a cap below the speed the law sheds from its moving start at this
# share of the smallest acceleration limit (``_shed``).
SHED_SHARE = 0.8
# The continuation's first passes keep this fraction of the planned velocity and acceleration
# limits where the start allows (timing.SAFETY: 0.95 for a swing from rest): the averaged law lags
# the passes' by half its window, and a continuation cannot be slowed uniformly afterwards.
START_SAFETY = 0.85


@dataclass(frozen=True)
class _Split:
    """An old time law cut at the switch t0: its speed nodes and speeds up to t0 (the last ones
    t0 and the speed there), the speed v0 (1/s) and the unfiltered position S0 at t0, and the
    path parameter s0 = s(t0) where the old path is cut."""

    nodes: np.ndarray
    speed: np.ndarray
    v0: float
    big_s0: float
    s0: float


def _split_law(law: TimeLaw, t0: float) -> _Split:
    """``law`` cut at t0 (between its first and last speed node)."""
    k = int(np.searchsorted(law.nodes, t0, side="right"))
    d = t0 - float(law.nodes[k - 1])
    a = float(law._acc[k - 1])
    v_prev = float(law.speed[k - 1])
    v0 = v_prev + a * d
    big_s0 = float(law._S[k - 1]) + v_prev * d + a * d * d / 2.0
    nodes, speed = law.nodes[:k], law.speed[:k]
    if d > 0.0:
        nodes, speed = np.append(nodes, t0), np.append(speed, v0)
    s0 = float(law.at(np.array([t0]))[0][0])
    return _Split(nodes, speed, v0, big_s0, s0)


def _cut_path(path: JointPath, s0: float):
    """The old path up to s0: its knots (ending at s0) and pieces, and q, q', q'' there (J,)."""
    m = min(int(np.searchsorted(path.knots, s0, side="right")) - 1, len(path.coef) - 1)
    c0, c1, c2, c3 = path.coef[m]
    d = s0 - float(path.knots[m])
    q = ((c3 * d + c2) * d + c1) * d + c0
    dq = (3.0 * c3 * d + 2.0 * c2) * d + c1
    ddq = 6.0 * c3 * d + 2.0 * c2
    if d > 0.0:
        knots, coef = np.append(path.knots[: m + 1], s0), path.coef[: m + 1]
    else:
        knots, coef = path.knots[: m + 1], path.coef[:m]
    return knots, coef, (q, dq, ddq)


def _parameter_map(frac: np.ndarray, rho: float) -> np.ndarray:
    """phi (n,) of chord fractions frac in [0, 1]: phi(0) = 0, phi(1) = 1, phi'(0) = rho, phi'
    approaching a constant c over BLEND_PARAMETER (phi' = c + (rho - c) exp(-x / beta)),
    increasing for any rho > 0."""
    beta = min(BLEND_PARAMETER, 0.9 / rho)
    e = beta * -np.expm1(-1.0 / beta)
    c = (1.0 - rho * e) / (1.0 - e)
    phi = c * frac + (rho - c) * beta * -np.expm1(-frac / beta)
    phi[-1] = 1.0
    return phi


def start_conditioned_spline(
    knots: np.ndarray, values: np.ndarray, dq0: np.ndarray, ddq0: np.ndarray
) -> JointPath:
    """The C2 cubic spline on ``knots`` (N + 1,) whose value, first and second derivative at
    knots[0] are values[0] (J,), dq0, ddq0, through values[2:] at knots[2:], free at knots[1] (its
    value solved for: the three start conditions need one more unknown), not-a-knot at the end.
    Unknowns: the slopes m_0..m_N and the value y_1, one dense solve for every joint."""
    n = len(knots) - 1
    h = np.diff(knots)
    nj = values.shape[1]
    a = np.zeros((n + 2, n + 2))  # columns: m_0..m_N, y_1
    rhs = np.zeros((n + 2, nj))
    y1 = n + 1
    # delta_i = (y_{i+1} - y_i) / h_i as (coefficient on y_1, known part).
    known = values.copy()
    known[1] = 0.0
    dk = np.diff(known, axis=0) / h[:, None]
    dy = np.zeros(n)
    dy[0], dy[1] = 1.0 / h[0], -1.0 / h[1]
    a[0, 0] = 1.0
    rhs[0] = dq0
    # c2 of piece 0 = (3 delta_0 - 2 m_0 - m_1) / h_0 = q''(0) / 2
    a[1, 0], a[1, 1], a[1, y1] = -2.0 / h[0], -1.0 / h[0], 3.0 * dy[0] / h[0]
    rhs[1] = ddq0 / 2.0 - 3.0 * dk[0] / h[0]
    for i in range(1, n):  # C2 at knot i
        r = i + 1
        a[r, i - 1], a[r, i], a[r, i + 1] = h[i], 2.0 * (h[i - 1] + h[i]), h[i - 1]
        a[r, y1] = -3.0 * (h[i] * dy[i - 1] + h[i - 1] * dy[i])
        rhs[r] = 3.0 * (h[i] * dk[i - 1] + h[i - 1] * dk[i])
    # not-a-knot at knot N-1: c3 equal on the last two pieces, c3_i = (m_i + m_{i+1} - 2 d_i)/h_i^2
    wa, wb = 1.0 / h[n - 2] ** 2, 1.0 / h[n - 1] ** 2
    a[n + 1, n - 2], a[n + 1, n - 1], a[n + 1, n] = wa, wa - wb, -wb
    a[n + 1, y1] = -2.0 * (wa * dy[n - 2] - wb * dy[n - 1])
    rhs[n + 1] = 2.0 * (wa * dk[n - 2] - wb * dk[n - 1])
    sol = np.linalg.solve(a, rhs)
    m = sol[: n + 1]
    q = values.copy()
    q[1] = sol[y1]
    delta = np.diff(q, axis=0) / h[:, None]
    hh = h[:, None]
    c2 = (3.0 * delta - 2.0 * m[:-1] - m[1:]) / hh
    c3 = (m[:-1] + m[1:] - 2.0 * delta) / (hh * hh)
    m[0], c2[0] = dq0, ddq0 / 2.0  # the start's own values (the solve gives them to rounding)
    return JointPath(np.asarray(knots, np.float64), np.stack([q[:-1], m[:-1], c2, c3], axis=1))


def _continuation_path(
    old: JointPath, s0: float, q_c: np.ndarray, lengths, blend: float
) -> JointPath:
    """The joint path of the replanned swing: ``old`` up to s0, then a C2 spline from the old
    path's q, q', q'' at s0 through the continuation's joint samples q_c (M, J) (its first sample
    replaced by the old path's value at s0), over s in [s0, 1]; the samples within ``blend`` (rad,
    joint-space chord) of the start are left to the spline's turn onto the new path."""
    knots, coef, (q0, dq0, ddq0) = _cut_path(old, s0)
    q_c = q_c + 2.0 * np.pi * np.round((q0 - q_c[0]) / (2.0 * np.pi))  # the old path's branch
    frac = chord_knots(q_c)
    chord = float(np.sqrt((np.diff(q_c, axis=0) ** 2).sum(axis=1)).sum())
    picked = few_knot_paths([q_c], [frac], lengths)[0].knots
    idx = np.searchsorted(frac, picked)
    # The new path's first knots within the blend are dropped (the free knot replaces them).
    speed0 = float(np.sqrt(dq0 @ dq0))  # |dq/ds| at s0
    keep = np.r_[0, idx[1:][(frac[idx[1:]] * chord >= blend) | (idx[1:] == idx[-1])]]
    if len(keep) < 4:
        keep = np.r_[0, idx[-3:]] if len(idx) >= 4 else idx
    rho = chord / max((1.0 - s0) * speed0, 1e-12)
    sk = s0 + (1.0 - s0) * _parameter_map(frac[keep], rho)
    sk[0], sk[-1] = s0, 1.0
    values = q_c[keep].copy()
    values[0] = q0
    sk = np.insert(sk, 1, 0.5 * (sk[0] + sk[1]))
    values = np.insert(values, 1, values[0], axis=0)  # solved for
    new = start_conditioned_spline(sk, values, dq0, ddq0)
    return JointPath(np.concatenate([knots, sk[1:]]), np.concatenate([coef, new.coef]))


def _blend(qdot: np.ndarray, q_c: np.ndarray, accel: float) -> float:
    """The joint-space chord (rad) over which the continuation turns from the old swing's
    direction onto its own: the joints' travel at their speed |qdot| (rad/s) at the switch in the
    time that turning their velocity (the change |qdot| |u_old - u_new| of the unit directions, the
    new one towards the continuation's sample at that chord) takes at TURN_SHARE of ``accel``
    (rad/s^2, the smallest acceleration limit), and at least BLEND_TIME; two fixed-point rounds."""
    speed = float(np.sqrt(qdot @ qdot))
    if speed <= 0.0:
        return 0.0
    u_old = qdot / speed
    d = q_c - q_c[0]
    chord = np.concatenate([[0.0], np.cumsum(np.sqrt((np.diff(q_c, axis=0) ** 2).sum(axis=1)))])
    blend = BLEND_TIME * speed
    for _ in range(2):
        i = min(int(np.searchsorted(chord, blend)), len(q_c) - 1)
        norm = float(np.sqrt(d[i] @ d[i]))
        turn = speed * float(np.sqrt(((u_old - d[i] / norm) ** 2).sum())) if norm > 0 else 0.0
        blend = speed * max(BLEND_TIME, turn / (TURN_SHARE * accel))
    return min(blend, 0.5 * float(chord[-1]))


def _passes(view: GridView, cap: np.ndarray, x0: float, constraints):
    """The passes on the continuation's grid (``view``: its s (K,) and the path's derivatives
    there) from a moving start (s'^2 = x0 at s[0]): s'^2 (K,) and the cells' floors (K - 1,)."""
    cap, rows = passes_rows(constraints, view, cap[None])
    grid = view.s
    ds = (grid[-1] - grid[0]) / (len(grid) - 1)
    x, floor = topp(rows, ds, cap, both_ends=True, start=np.array([x0]))
    return x[0], floor[0]


def _law(split: _Split, grid, x, floor, window: float) -> TimeLaw:
    """The replanned swing's time law: the old speed nodes up to the switch, then the passes'."""
    nodes, speed = speed_nodes(grid, x, floor, start=split.v0)
    t0 = float(split.nodes[-1])
    return TimeLaw(
        np.concatenate([split.nodes, t0 + nodes[1:]]),
        np.concatenate([split.speed, speed[1:]]),
        window,
    )


def _timed_law(split: _Split, path: JointPath, window: float, device: DeviceLimits) -> Plan:
    """The continuation's passes from the moving start, then local corrections where the proven
    bounds exceed a limit (``curve_check.lowered_cap``) and, while still over, every cap lowered
    by the excess (a swing cannot be slowed uniformly: its start is fixed): a Plan with the
    curve's bounds."""
    planned, _, passes, check = timing._planned(device)
    k = timing.grid_size(int(np.count_nonzero(path.knots > split.s0)))
    grid = np.linspace(split.big_s0, 1.0, k)
    x0 = split.v0 * split.v0
    reach = split.v0 * START_WINDOWS * window
    cap, view, least = _first_caps(path, grid, x0, planned, reach)
    plan, last = None, np.inf
    for attempt in range(timing.LOCAL_PASSES + LIMIT_PASSES + 1):
        x, floor = _passes(view, cap, x0, passes)
        law = _law(split, grid, x, floor, window)
        # The curve before the switch is the old swing's (its peaks bound it): bounded from there.
        plan = with_bounds([Plan(path, view, cap, x, law)], [0], [float(split.nodes[-1])])[0]
        ratio = peak_ratio(check, plan.check.peaks)
        if ratio <= 1.0 or law.duration > MAX_SWING_DURATION or ratio >= last * (1.0 - 1e-6):
            break  # within; or the caps no longer help (the excess where the start holds them)
        last = ratio
        if attempt < timing.LOCAL_PASSES and ratio > timing.LOCAL_FROM:
            lower = lowered_cap(plan, speed_ratio(check, plan.check.bound))
        else:
            lower = np.where(x > 0.0, x / (ratio * ratio * OVERSHOOT), cap)
        # Never below what the law can shed from its moving start: a cap under it makes the
        # passes drop the speed in one cell, the curve's acceleration at the switch far over.
        cap = np.minimum(cap, np.maximum(lower, least))
    return plan


def _first_caps(path: JointPath, grid: np.ndarray, x0: float, planned: DeviceLimits, reach):
    """The first passes' caps on s'^2 (K,): the largest speeds within START_SAFETY of the planned
    velocity and acceleration limits (the passes' own are within timing.SAFETY), but never below
    what the law sheds from its moving start (``_shed``, over ``reach`` of s); the grid's view,
    and that floor."""
    q, dq, ddq = paths_at([path], [grid], 2)[0]
    view = GridView(grid, q[None], dq[None], ddq[None])
    cap, rows = passes_rows(
        planned.constraints(START_SAFETY), view, np.full((1, len(grid)), np.inf)
    )
    x = np.minimum(max_speed_curve(rows), cap)[0]
    least = _shed(view, x0, min(planned.acceleration), reach)
    return np.maximum(x, least), view, least


def _shed(view: GridView, x0: float, accel: float, reach: float) -> np.ndarray:
    """(K,) the least cap on s'^2 the corrections set: s'^2 falling from x0 at the start at
    SHED_SHARE of ``accel`` (rad/s^2, the smallest limit) over each cell's largest |q'| (s'^2
    falls by 2 u ds over a cell at s'' = -u), over the first ``reach`` of s (what the law covers
    in START_WINDOWS of its window at the start's speed); 0 past it."""
    u = SHED_SHARE * accel / np.maximum(np.abs(view.dq[0]).max(axis=1), 1e-12)
    ds = np.diff(view.s)
    drop = np.concatenate([[0.0], np.cumsum(2.0 * u[:-1] * ds)])
    return np.where(view.s <= view.s[0] + reach, np.maximum(x0 - drop, 0.0), 0.0)


def _final(plan: Plan, old, rate: float) -> FinalLaw:
    """The continuation's law as it is (no uniform slow-down: the start is fixed), the swing's
    peaks (the old swing's before the switch, the continuation's proven ones after) and whether
    they are within the planned limits."""
    planned = old.limits.planned()
    law = plan.law
    notes = []
    before = (old.peak_velocity, old.peak_acceleration, old.peak_jerk)
    peaks = tuple(
        after if b is None else np.maximum(b, after) for b, after in zip(before, plan.check.peaks)
    )
    ok = holds(planned.constraints(1.0), peaks)
    if law.duration > MAX_SWING_DURATION:
        notes.append(
            f"the continuation needs {law.duration:.4g} s, longer than the longest swing "
            f"({MAX_SWING_DURATION:g} s)"
        )
        ok = False
    n = law.duration * rate
    if not n < max_samples():
        raise ValueError(
            f"rate: a {law.duration:.4g} s swing at {rate:g} Hz needs {math.ceil(n)} samples, more "
            "than half the memory this process may use holds; lower the rate"
        )
    return FinalLaw(law, 1.0, 1.0, peaks, ok, tuple(notes))


def _candidates(blend: float, chord: float) -> list[float]:
    """The turns tried, in order: ``blend``, then longer ones (a turn too fast for the limits where
    the switch fixes the speed) and a shorter one (a turn that cuts into the margin)."""
    longer = [min(blend * 2.0**k, 0.5 * chord) for k in range(1, BLEND_TRIES)]
    return [blend, *dict.fromkeys(b for b in longer if b > blend), 0.5 * blend]


def _joined(curve: SwingCurve, split: _Split, q_c: np.ndarray, qdot, device, judge, retry: bool):
    """The joined path, its timed law (a Plan) and its verdict (``judge(plan)``: TrajectoryChecks):
    the first of ``_candidates``' turns onto the continuation whose swing is within the limits and
    passes, else the first one's (only the first with ``retry`` False: a continuation that fails
    its own checks, whose joined swing cannot pass)."""
    accel = min(device.planned().acceleration)
    blend = _blend(qdot, q_c, accel)
    chord = float(np.sqrt((np.diff(q_c, axis=0) ** 2).sum(axis=1)).sum())
    planned = device.planned()
    first = None
    for b in _candidates(blend, chord)[: None if retry else 1]:
        path = _continuation_path(curve.path, split.s0, q_c, curve.lengths, b)
        plan = _timed_law(split, path, curve.law.window, device)
        within = peak_ratio(planned.constraints(1.0), plan.check.peaks) <= 1.0
        checks = judge(plan) if within or first is None else None
        if first is None:
            first = (plan, checks)
        if within and checks.ok:
            return plan, checks
    return first


def continue_swing(swing, traj, *, at: float, sp, rate: float | None = None):
    """The swing ``swing`` (a TimedSwing) replanned at t = ``at`` (s, validated by the caller) onto
    the continuation ``traj`` (a Trajectory from the foot's state at ``at`` over the new scene to
    the same goal): identical to ``swing`` on [0, at], C2 there, the continuation timed from the
    moving state within ``swing.limits``, the whole swing judged against ``traj.scene``, sampled at
    ``rate`` (default: the swing's)."""
    rate = timing.check_rate(swing.rate if rate is None else rate)
    curve, device = swing.curve, swing.limits
    split = None if at >= curve.law.nodes[-1] else _split_law(curve.law, float(at))
    if split is None or split.big_s0 > 1.0 - MIN_TO_GO:
        raise ValueError(
            f"at: the swing is landing by t={at:g} s (it lands at {swing.duration:.4f} s, its "
            f"speed profile ends at {curve.law.nodes[-1]:.4f} s); too late to replan it"
        )
    q_c = timing._joint_samples(sp, traj)
    q_c = np.take(q_c, distinct_samples(q_c), axis=0)
    s_dot = float(curve.law.at(np.array([at]))[1][0])
    _, _, (_, dq0, _) = _cut_path(curve.path, split.s0)

    def judge(plan):
        return timing._curve_verdict(
            traj, plan, timing._path_checks([traj], [plan], sp), 0, 1.0, sp
        )

    plan, checks = _joined(curve, split, q_c, dq0 * s_dot, device, judge, bool(traj.ok))
    final = _final(plan, swing, rate)
    new_curve = SwingCurve(plan.path, final.law, curve.pivot_y, curve.lengths, curve.foot_length)
    samples = timing._samples([new_curve], rate)[0]
    note = f"replanned at t={at:.4f} s ({traj.method} continuation)"
    out = timing._timed(traj, checks, final, new_curve, samples, device, rate)
    return replace(
        out,
        notes=swing.notes + (note,) + out.notes,
        switch_times=swing.switch_times + (float(at),),
    )


# --------------------------------------------------------------------------------------------
# The public replanning's pieces: inputs checked, the foot's state (jaxexo.swing.generator's
# ``replan`` joins a generator's continuation)
# --------------------------------------------------------------------------------------------


def foot_state(swing, at: float) -> FootState:
    """The swing's FootState at t = ``at`` (s, within the swing; ``checked_switch``)."""
    curve = swing.curve
    st = curve.at(np.array([at]))
    s0 = float(st.path_parameter[0])
    s, _, heel = check_points(curve.lengths, curve.pivot_y, curve.path, timing.CURVE_TOL)
    return FootState(
        time=float(at),
        path_parameter=s0,
        heel=st.heel[0],
        heel_velocity=st.heel_velocity[0],
        heel_acceleration=st.heel_acceleration[0],
        joints=st.joint_angles[0],
        joint_velocity=st.joint_velocity[0],
        joint_acceleration=st.joint_acceleration[0],
        past_heel=np.vstack([heel[s < s0], st.heel[:1]]),
    )


def checked_switch(swing, at, config) -> float:
    """``at`` as a switch time of ``swing`` made with ``config``'s legs: TypeError or ValueError
    naming ``swing`` or ``at`` (a time within the swing, after its last switch, before it
    lands)."""
    from jaxexo.physics.geometry import as_given

    if not isinstance(swing, timing.TimedSwing) or swing.curve is None:
        raise TypeError(
            f"swing: expected a TimedSwing (from time_swing or replan), got {type(swing).__name__}"
        )
    curve = swing.curve
    config.kinematics.check_legs(
        {"thigh": curve.lengths[0], "shin": curve.lengths[1], "foot_length": curve.foot_length},
        "the swing was timed for",
        "replan a swing with the generator that made it",
    )
    if isinstance(at, (bool, np.bool_)) or not isinstance(
        at, (int, float, np.integer, np.floating)
    ):
        raise TypeError(f"at: expected a time in seconds, got {at!r}")
    t = float(at)
    last = swing.switch_times[-1] if swing.switch_times else 0.0
    if not (math.isfinite(t) and last < t < swing.duration):
        after = f"after its last switch at {last:.4f} s" if swing.switch_times else "after 0"
        raise ValueError(
            f"at: expected a time in s within the swing ({after} and before it lands at "
            f"{swing.duration:.4f} s), got {as_given(at)}"
        )
    return t


def checked_obstacle_scene(gen, swing, obstacle, state: FootState):
    """The new obstacle's scene, with the swing's pivot, start and goal; ValueError naming
    ``obstacle`` when the foot is already within the margin of it at the switch (no continuation
    from there keeps the margin)."""
    from jaxexo.physics.geometry import foot_clearance

    sc = swing.scene
    scene = gen.scene(
        obstacle, pivot_y=sc.pivot_y, start_y=sc.start_y, step_length=sc.goal_y - sc.start_y
    )
    scene = scene._replace(goal_y=sc.goal_y, pivot_kind=sc.pivot_kind)
    c = float(foot_clearance(np, state.heel[None], gen.sp.foot_length, scene.outline[None])[0])
    if c < gen.sp.min_clearance:
        where = "inside (or touching)" if c <= 0.0 else f"{c:.4f} m from"
        raise ValueError(
            f"obstacle: at t={state.time:.4f} s the foot (heel y={state.heel[0]:.4f} m, "
            f"z={state.heel[1]:.4f} m) is already {where} the new obstacle, within the margin "
            f"{gen.sp.min_clearance:g} m: no continuation from there keeps it"
        )
    return scene
