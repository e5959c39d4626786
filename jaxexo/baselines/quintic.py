"""The quintic pieces of CFFTG's continuation from a moving start (NumPy only): the boundary basis
that matches the heel's position, velocity and acceleration at u = 0 and lands at rest at u = 1,
the continuation's duration T_c that scales those derivatives, the apex term's monotone range and
the curve's deviation bound. The plan itself: jaxexo.baselines.cfftg (CFFTG.continuation). Method:
docs/replanning.md (Continuation paths).
"""

from __future__ import annotations

import functools

import numpy as np

_P = np.polynomial.polynomial
# The quintic boundary basis on u in [0, 1] (monomial coefficients, lowest first): the value, first
# and second derivative at u = 0, the value at u = 1; every other end condition is zero, so the swing
# lands at rest.
H0 = (1.0, 0.0, 0.0, -10.0, 15.0, -6.0)
H1 = (0.0, 1.0, 0.0, -6.0, 8.0, -3.0)
H2 = (0.0, 0.0, 0.5, -1.5, 1.5, -0.5)
H3 = (0.0, 0.0, 0.0, 10.0, -15.0, 6.0)
# g = u^3 (1-u)^3 vanishes with its first two derivatives at both ends: CFFTG's apex-moving term, and
# the factor of its height shapes phi_k = 64 g (1 + k (1 - 2u)^2) (peak 1 at u = 1/2).
G = (0.0, 0.0, 0.0, 1.0, -3.0, 3.0, -1.0)
BASE = 5  # H0, H1, H2, H3, g; then one phi_k per flatness
DEGREE = 8  # phi_k's
# The quintic basis H0..H3 at u = 1/2, where the height shapes peak (the apex's y); g(1/2) = 1/64.
HALF = np.array([0.5, 0.15625, 0.015625, 0.5])
# Points of the fine grid on which y' (monotonicity, the apex's range) and |c''| are evaluated.
FINE = 1001
# T_c's candidates: the estimate, then halved until y is monotone on the fine grid (the start's
# direction and curvature are matched whatever T_c: it sets only how far the old velocity carries).
HALVINGS = 6
# s: the longest T_c. T_c only sets how far the old velocity carries the path before its own plan
# takes over; on 36 mid-swing states under taller obstacles (docs/replanning.md) CFFTG's continuation
# passed its checks in 56 % with a 2 s cap, 64 % with 1 s and 86 % with 0.6, 0.45 and 0.3 s.
TC_MAX = 0.5
# |g'| below which the fine grid's points do not bound the apex term (u near 0, 1/2, 1).
_G_EPS = 1e-9


def _coef(c) -> np.ndarray:
    out = np.zeros(DEGREE + 1)
    out[: len(c)] = c
    return out


@functools.lru_cache(maxsize=16)
def continuation_basis(n_points: int, flatness: tuple[float, ...]):
    """The basis (H0, H1, H2, H3, g, then phi_k for each k of ``flatness``): values at the samples
    u = i / (N - 1) (basis, N), first derivatives on the fine grid (basis, FINE), and (second, third
    derivatives on the fine grid, the fourth derivatives' monomial coefficients (basis, DEGREE + 1))
    (read-only)."""
    one_minus_2u_sq = _P.polypow((1.0, -2.0), 2)
    phis = [64.0 * _P.polymul(G, _P.polyadd((1.0,), k * one_minus_2u_sq)) for k in flatness]
    coef = [_coef(c) for c in (H0, H1, H2, H3, G, *phis)]
    u = np.linspace(0.0, 1.0, n_points)
    f = np.linspace(0.0, 1.0, FINE)
    values = np.stack([_P.polyval(u, c) for c in coef])
    d1 = np.stack([_P.polyval(f, _P.polyder(c, 1)) for c in coef])
    d2 = np.stack([_P.polyval(f, _P.polyder(c, 2)) for c in coef])
    d3 = np.stack([_P.polyval(f, _P.polyder(c, 3)) for c in coef])
    d4 = np.stack([_coef(_P.polyder(c, 4)) for c in coef])
    for a in (values, d1, d2, d3, d4):
        a.flags.writeable = False
    return values, d1, (d2, d3, d4)


def estimate_tc(heel, velocity, goal_y, top) -> np.ndarray:
    """T_c (B,) s before the monotone check: the continuation's length estimate over the heel's
    speed (the time it takes at the speed it has), at most TC_MAX. The length: forward to the goal, up (or down) to ``top`` (the obstacle's
    height plus the margin) and down from there to the floor."""
    length = (goal_y - heel[:, 0]) + np.abs(top - heel[:, 1]) + top
    speed = np.sqrt((velocity * velocity).sum(axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.minimum(np.where(speed > 0.0, length / speed, TC_MAX), TC_MAX)


def y_weights(heel, velocity, acceleration, goal_y, tc, c) -> np.ndarray:
    """(B, BASE) y's weights on H0, H1, H2, H3 and g (c times the distance to the goal)."""
    d = goal_y - heel[:, 0]
    return np.stack(
        [heel[:, 0], tc * velocity[:, 0], tc * tc * acceleration[:, 0], goal_y, c * d], -1
    )


def z_weights(heel, velocity, acceleration, tc) -> np.ndarray:
    """(B, 4) z's weights on H0, H1, H2, H3 (the floor at u = 1)."""
    zero = np.zeros(len(tc))
    return np.stack([heel[:, 1], tc * velocity[:, 1], tc * tc * acceleration[:, 1], zero], -1)


def monotone_tc(heel, velocity, acceleration, goal_y, tc0) -> np.ndarray:
    """(B,) the largest of tc0, tc0 / 2, ... (HALVINGS halvings) for which the plain quintic y (no apex
    term) never decreases on the fine grid; the smallest where none does (a heel moving backward at
    the state: the checks then judge how far)."""
    _, d1, _ = continuation_basis(2, ())
    tc = tc0[:, None] * 0.5 ** np.arange(HALVINGS + 1)  # (B, K)
    w = np.stack(
        [
            np.broadcast_to(heel[:, :1], tc.shape),
            tc * velocity[:, :1],
            tc * tc * acceleration[:, :1],
            np.broadcast_to(goal_y[:, None], tc.shape),
        ],
        -1,
    )  # (B, K, 4)
    ok = (w @ d1[:4]).min(axis=-1) >= 0.0  # (B, K)
    pick = np.where(ok.any(axis=1), np.argmax(ok, axis=1), HALVINGS)
    return tc[np.arange(len(tc)), pick]


def apex_range(heel, velocity, acceleration, goal_y, tc) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (B,): the apex-moving coefficients c for which y' = base' + c D g' >= 0 on the fine
    grid (D the distance to the goal): g' > 0 before u = 1/2 bounds c from below, g' < 0 after it
    from above; (0, 0) where no c keeps y monotone."""
    _, d1, _ = continuation_basis(2, ())
    w = y_weights(heel, velocity, acceleration, goal_y, tc, np.zeros(len(tc)))
    base = w[:, :4] @ d1[:4]  # (B, FINE)
    gd = d1[4]
    dd = np.maximum(goal_y - heel[:, 0], 1e-9)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        lo = np.where(gd > _G_EPS, -base / (dd * gd), -np.inf).max(axis=1)
        hi = np.where(gd < -_G_EPS, base / (dd * -gd), np.inf).min(axis=1)
    bad = ~(lo <= hi)
    return np.where(bad, 0.0, lo), np.where(bad, 0.0, hi)


def curve_deviation(wy, wz, high, n_points: int) -> np.ndarray:
    """(B,) m: the bound on each curve's distance from the polyline through its N samples, for y's
    and z's weights ``wy``, ``wz`` (B, basis; fewer columns: the first ones) on a basis whose second
    and third derivatives on the fine grid and fourth derivatives' coefficients are ``high``
    (``continuation_basis``): (1 / (N-1))^2 / 8 max |c''|. Between grid points |c''| exceeds its
    grid value by at most half the step times max |c'''|, itself at most its grid maximum plus half
    the step times a bound on |c''''| (its monomial coefficients' magnitudes summed: valid on
    [0, 1]); one level alone would be loose (phi_3's third derivative's sum is ~2e6 h)."""
    d2, d3, d4 = high
    slack = 0.5 / (FINE - 1)

    def most(w):
        k = w.shape[1]
        c3 = np.abs(w @ d3[:k]).max(axis=1) + slack * np.abs(w @ d4[:k]).sum(axis=1)
        return np.abs(w @ d2[:k]).max(axis=1) + slack * c3

    ypp, zpp = most(wy), most(wz)
    return (1.0 / (n_points - 1)) ** 2 / 8.0 * np.sqrt(ypp * ypp + zpp * zpp)


@functools.lru_cache(maxsize=16)
def ramp(n_points: int) -> np.ndarray:
    """(N,) at the samples u = i / (N - 1): 64 u^3 (1-u)^3 (phi_0) up to u = 1/2, then 1: the share
    of the margin the continuation's shadow reaches beside the foot (0 at the start, C2 at 1/2)
    (read-only)."""
    u = np.linspace(0.0, 1.0, n_points)
    out = np.where(u < 0.5, 64.0 * u**3 * (1.0 - u) ** 3, 1.0)
    out.flags.writeable = False
    return out
