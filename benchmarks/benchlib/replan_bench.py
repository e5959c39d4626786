"""Replanning benchmark: swings planned over an estimate of the obstacle, the true obstacle known
mid-swing, replanned by the RL generator alone, by it with the CFFTG fallback, and by CFFTG side by
side in one process; every replanned swing judged by an independent dense check (the foot against
the true outline at 5 kHz by segment distances written here, the joints at 1 kHz by finite
differences against the full device limits), its latency, and its duration over a swing planned
from the start over the true obstacle. Method: docs/replanning.md."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from jaxexo.summary import table

from benchlib.runner import Record

# The surprises: how the estimate differs from the true obstacle (heights scaled by a factor, the
# width scaled, the obstacle moved in y by metres), each drawn per scene.
SURPRISES = ("lower", "much lower", "farther", "wider", "appeared")
DEFAULT_SEED = 5_917  # no config of ours names it; --seed draws other scenes
DENSE_HZ = 5_000.0  # the clearance check's rate
DIFF_HZ = 1_000.0  # the limits' finite differences
C2_EPS = 1e-7  # s: each side of the switch


@dataclass(frozen=True)
class Surprise(Record):
    """One scene: the obstacle the swing is planned over (``estimate``), the one there is (``true``),
    the scene's pivot, start and step (m), the surprise's kind and the switch as a fraction of the
    swing."""

    kind: str
    estimate: object
    true: object
    pivot: str
    start_y: float
    step_length: float
    at_fraction: float


def _transformed(ob, height: float = 1.0, width: float = 1.0, shift: float = 0.0):
    """An obstacle's outline with heights times ``height``, widths about its centre times
    ``width``, moved by ``shift`` m in y, as a profile obstacle."""
    from jaxexo.physics.geometry import Obstacle

    pts = np.asarray(ob.outline, np.float64).copy()
    pts[:, 0] = ob.center_y + shift + (pts[:, 0] - ob.center_y) * width
    pts[:, 1] *= height
    return Obstacle.profile(pts)


def surprise_scenes(config, n: int, seed: int = DEFAULT_SEED) -> list[Surprise]:
    """``n`` scenes of shapes never trained on (jaxexo.physics.scenarios' unseen shapes, drawn with
    ``seed``), each with a surprise of SURPRISES in turn: the estimate 40-50 % of the true height
    ("lower"), 20-35 % ("much lower"), the true obstacle 3-6 cm farther than estimated ("farther"),
    its width 40-60 % of the true one at 70-90 % of its height ("wider"), or a 1 cm estimate of an
    obstacle that turns out whole ("appeared"); the switch at 15-45 % of the swing."""
    from jaxexo.inference.scenarios import safety_scenarios

    rng = np.random.default_rng(seed)
    out = []
    for i, s in enumerate(safety_scenarios(config, n, seed=seed, unseen=True)):
        kind = SURPRISES[i % len(SURPRISES)]
        true = s.obstacle
        if kind == "lower":
            est = _transformed(true, height=rng.uniform(0.4, 0.5))
        elif kind == "much lower":
            est = _transformed(true, height=rng.uniform(0.2, 0.35))
        elif kind == "farther":
            est = _transformed(true, shift=-rng.uniform(0.03, 0.06))
        elif kind == "wider":
            est = _transformed(true, height=rng.uniform(0.7, 0.9), width=rng.uniform(0.4, 0.6))
        else:
            est = _transformed(true, height=min(1.0, 0.01 / max(true.height, 1e-9)))
        out.append(
            Surprise(
                kind,
                est,
                true,
                s.pivot,
                s.start_y,
                s.step_length,
                float(rng.uniform(0.15, 0.45)),
            )
        )
    return out


# --------------------------------------------------------------------------------------------
# The independent check
# --------------------------------------------------------------------------------------------


def _point_segment(p, a, b):
    """Distances (n, E) from points p (n, 2) to segments a -> b (E, 2)."""
    e = b - a
    len2 = np.maximum((e * e).sum(axis=1), 1e-300)
    t = np.clip(((p[:, None, :] - a[None]) * e[None]).sum(axis=2) / len2, 0.0, 1.0)
    r = p[:, None, :] - (a[None] + t[..., None] * e[None])
    return np.sqrt((r * r).sum(axis=2))


def _crosses(p0, p1, a, b):
    """(n, E): whether segments p0 -> p1 (n, 2) and a -> b (E, 2) cross properly (each one's ends
    strictly on both sides of the other's line); touching and collinear overlaps are the
    end-to-segment distances' zeros."""

    def orient(u, v, w):
        return (v[..., 0] - u[..., 0]) * (w[..., 1] - u[..., 1]) - (v[..., 1] - u[..., 1]) * (
            w[..., 0] - u[..., 0]
        )

    P0, P1, A, B = p0[:, None], p1[:, None], a[None], b[None]
    d1, d2 = orient(A, B, P0), orient(A, B, P1)
    d3, d4 = orient(P0, P1, A), orient(P0, P1, B)
    return (d1 * d2 < 0.0) & (d3 * d4 < 0.0)


def dense_clearance(heel: np.ndarray, foot_length: float, outline: np.ndarray) -> np.ndarray:
    """Signed distance (n,) m of the flat foot [heel, heel + (L, 0)] (heels (n, 2)) from a closed
    ground outline (K, 2) (its vertices from the ground at the left to the ground at the right):
    the least of the four end-to-segment distances, 0 where the foot crosses an edge, negative
    (minus that distance) where the heel is inside (an even-odd ray count). Written here from
    first principles, independent of jaxexo.physics.geometry."""
    o = np.asarray(outline, np.float64)
    poly = np.vstack([o, o[:1]])  # closed along the ground
    a, b = poly[:-1], poly[1:]
    keep = (b - a).any(axis=1)
    a, b = a[keep], b[keep]
    heel = np.asarray(heel, np.float64)
    toe = heel + np.array([foot_length, 0.0])
    d = np.minimum(_point_segment(heel, a, b), _point_segment(toe, a, b)).min(axis=1)
    ends = np.minimum(
        _point_segment(a, heel, toe).T if len(heel) else d, _point_segment(b, heel, toe).T
    ).min(axis=1)
    d = np.minimum(d, ends)
    d = np.where(_crosses(heel, toe, a, b).any(axis=1), 0.0, d)
    # even-odd: a ray from the heel towards +z crossing the edges
    ay, az, by, bz = a[:, 0], a[:, 1], b[:, 0], b[:, 1]
    y, z = heel[:, :1], heel[:, 1:]
    straddle = (ay <= y) != (by <= y)
    with np.errstate(divide="ignore", invalid="ignore"):
        zc = az + (y - ay) * (bz - az) / np.where(by != ay, by - ay, 1.0)
    inside = ((straddle & (zc > z)).sum(axis=1) % 2) == 1
    return np.where(inside, -d, d)


@dataclass(frozen=True)
class Judged(Record):
    """The independent check of one replanned swing: the joints' jump across the switch (rad,
    rad/s, rad/s^2, both sides C2_EPS from it), the largest ratio of a finite difference at DIFF_HZ
    to its full device limit (velocity, acceleration, jerk), the least dense clearance after the
    switch (m), the lowest heel (m), the landing's distance from the goal (m) and its speed, and
    the swing's duration (s) and highest heel (m)."""

    jump: tuple
    limit_ratio: tuple
    clearance: float
    lowest: float
    landing_error: float
    landing_speed: float
    duration: float
    lift: float


def judge(old, new, at: float, outline: np.ndarray, goal_y: float, foot_length: float) -> Judged:
    """``new`` (old replanned at ``at``) judged independently against the true obstacle's
    ``outline`` (K, 2) and the goal ``goal_y`` (m)."""
    a = old.at(np.array([at - C2_EPS]))
    b = new.at(np.array([at + C2_EPS]))
    jump = tuple(
        float(np.abs(getattr(b, k) - getattr(a, k)).max())
        for k in ("joint_angles", "joint_velocity", "joint_acceleration")
    )
    s = new.sample(DIFF_HZ)
    dt = 1.0 / DIFF_HZ
    q = np.asarray(s.joint_angles)
    lim = new.limits
    ratios = [
        float((np.abs(np.diff(q, n=k, axis=0)) / dt**k / np.asarray(m)).max())
        for k, m in ((1, lim.velocity), (2, lim.acceleration), (3, lim.jerk))
        if m is not None
    ]
    t = np.append(np.arange(at, new.duration, 1.0 / DENSE_HZ), new.duration)
    st = new.at(t)
    c = dense_clearance(st.heel, foot_length, outline)
    whole = new.at(np.linspace(0.0, new.duration, 2000))
    end = new.at(np.array([new.duration]))
    return Judged(
        jump,
        tuple(ratios),
        float(c.min()),
        float(whole.heel[:, 1].min()),
        float(abs(end.heel[0, 0] - goal_y)),
        float(np.abs(end.joint_velocity).max()),
        float(new.duration),
        float(whole.heel[:, 1].max()),
    )


def safe_by_check(j: Judged, margin: float) -> bool:
    """The issue's safe replan, by the independent check: C2 at the switch (jumps no larger than
    the curve moves in 2 C2_EPS), within the full limits, more than ``margin`` from the true
    obstacle after the switch, never below the ground, landing at rest within 5 cm of the goal."""
    return (
        j.jump[0] < 1e-5
        and j.jump[1] < 1e-3
        and j.jump[2] < 1e-2
        and max(j.limit_ratio) <= 1.0 + 1e-9
        and j.clearance > margin
        and j.lowest >= -1e-9
        and j.landing_error <= 0.05
        and j.landing_speed < 1e-6
    )


# --------------------------------------------------------------------------------------------
# The run
# --------------------------------------------------------------------------------------------

GENERATORS = ("rl", "rl + cfftg fallback", "cfftg")


@dataclass(frozen=True)
class Row(Record):
    """One scene and generator: whether the switch was feasible (the foot so far clear of the true
    obstacle by the margin), the old swing's least clearance after the switch (left alone), the
    replan's outcome (None: refused, with the reason), its CPU time (s), the independent check,
    its verdict, and the duration and lift of a swing planned from the start over the true
    obstacle (None where that one is not safe)."""

    kind: str
    generator: str
    feasible: bool
    left_alone: float
    refused: str | None
    cpu_s: float
    judged: Judged | None
    flagged_ok: bool
    safe: bool
    method: str
    reasons: tuple
    scratch_duration: float | None
    scratch_lift: float | None


def _kw(s: Surprise) -> dict:
    return {"pivot": s.pivot, "start_y": s.start_y, "step_length": s.step_length}


def _planners(rl, cf):
    """Per generator: (plan a swing over an obstacle, replan a swing: fn(old, true, at))."""
    return {
        "rl": (
            lambda ob, s: rl.generate(ob, fallback=None, **_kw(s)),
            lambda old, ob, at: rl.replan(old, ob, at=at, fallback=None),
        ),
        "rl + cfftg fallback": (
            lambda ob, s: rl.generate(ob, fallback=None, **_kw(s)),
            lambda old, ob, at: rl.replan(old, ob, at=at),
        ),
        "cfftg": (
            lambda ob, s: cf.generate(ob, **_kw(s)),
            lambda old, ob, at: cf.replan(old, ob, at=at),
        ),
    }


def _row(name, plan, re, s: Surprise, cfg, rate, margin, foot) -> Row | None:
    """One scene's Row for one generator (None: the swing over the estimate is not safe)."""
    from jaxexo.swing.timing import time_swing

    try:
        old = time_swing(plan(s.estimate, s), cfg, rate=rate)
    except ValueError:
        return None
    if not old.ok:
        return None
    at = s.at_fraction * old.duration
    outline = np.asarray(s.true.outline, np.float64)
    past = old.at(np.append(np.arange(0.0, at, 1.0 / DENSE_HZ), at))
    feasible = bool(dense_clearance(past.heel, foot, outline).min() > margin)
    after = old.at(np.append(np.arange(at, old.duration, 1.0 / DENSE_HZ), old.duration))
    left = float(dense_clearance(after.heel, foot, outline).min())
    scratch = time_swing(plan(s.true, s), cfg, rate=rate)
    sd = float(scratch.duration) if scratch.ok else None
    sl = float(scratch.heel[:, 1].max()) if scratch.ok else None
    t0 = time.process_time()
    try:
        new = re(old, s.true, at)
    except ValueError as e:
        cpu = time.process_time() - t0
        return Row(s.kind, name, feasible, left, str(e), cpu, None, False, False, "", (), sd, sl)
    cpu = time.process_time() - t0
    j = judge(old, new, at, outline, old.scene.goal_y, foot)
    return Row(
        s.kind,
        name,
        feasible,
        left,
        None,
        cpu,
        j,
        bool(new.ok),
        safe_by_check(j, margin),
        new.method,
        tuple(new.reasons),
        sd,
        sl,
    )


# Replanning's targets (RL alone, feasible scenes): safe by the independent check, at least as
# often as CFFTG; no swing flagged ok that the check finds unsafe; latency; duration over a swing
# planned from the start over the true obstacle (median).
TARGETS = {
    "rl_safe_fraction": 0.98,
    "lies": 0,
    "latency_median_ms": 5.0,
    "latency_p99_ms": 10.0,
    "duration_ratio_median": 1.10,
}
OPTIONS = (
    ("--n", "n", "surprise scenes"),
    ("--seed", "seed", "the scenes' seed"),
    ("--rate", "rate", "control rate, Hz"),
)


@dataclass(frozen=True)
class Figures(Record):
    """A generator's figures over its feasible scenes (rows: its Rows): counts of scenes, feasible
    ones, safe by the independent check and flagged ok (both: ``safe_ok``), swings flagged ok that
    the check finds unsafe (``lies``, all scenes), refusals, CFFTG continuations of the RL
    generator, old swings left alone within 2 cm; the replan's CPU time (ms, median and p99);
    duration and lift over a swing planned from the start (safe ones); safe per surprise."""

    scenes: int
    feasible: int
    safe: int
    safe_ok: int
    lies: int
    refused: int
    fell_back: int
    left_alone_within_margin: int
    latency_median_ms: float | None
    latency_p99_ms: float | None
    duration_ratio_median: float | None
    duration_ratio_max: float | None
    lift_over_scratch_cm_median: float | None
    by_kind: dict

    @property
    def safe_ok_fraction(self) -> float:
        return self.safe_ok / max(self.feasible, 1)


def _figures(rows: list[Row]) -> Figures:
    """A generator's Figures."""
    f = [r for r in rows if r.feasible]
    done = [r for r in f if r.judged is not None]
    cpu = np.array([r.cpu_s for r in f]) * 1e3
    good = [r for r in done if r.safe and r.flagged_ok]
    ratio = [r.judged.duration / r.scratch_duration for r in good if r.scratch_duration]
    lift = [r.judged.lift - r.scratch_lift for r in good if r.scratch_lift is not None]
    return Figures(
        scenes=len(rows),
        feasible=len(f),
        safe=sum(r.safe for r in f),
        safe_ok=len(good),
        lies=sum(r.flagged_ok and not r.safe for r in rows),
        refused=sum(r.refused is not None for r in f),
        fell_back=sum(r.method.startswith("cfftg") for r in done if r.generator != "cfftg"),
        left_alone_within_margin=sum(r.left_alone <= 0.02 for r in f),
        latency_median_ms=float(np.median(cpu)) if len(cpu) else None,
        latency_p99_ms=float(np.percentile(cpu, 99)) if len(cpu) else None,
        duration_ratio_median=float(np.median(ratio)) if ratio else None,
        duration_ratio_max=float(np.max(ratio)) if ratio else None,
        lift_over_scratch_cm_median=float(np.median(lift) * 100) if lift else None,
        by_kind={
            k: [sum(r.safe and r.flagged_ok for r in f if r.kind == k), sum(r.kind == k for r in f)]
            for k in SURPRISES
        },
    )


def _markdown(fig: dict, n: int, seed: int, rate: float) -> str:
    def cell(x, fmt):
        return "-" if x is None else format(x, fmt)

    rows = [
        (
            g,
            f"{f.safe_ok}/{f.feasible} ({100 * f.safe_ok_fraction:.1f} %)",
            str(f.safe),
            str(f.lies),
            str(f.refused),
            str(f.fell_back),
            cell(f.latency_median_ms, ".2f") + " / " + cell(f.latency_p99_ms, ".2f"),
            cell(f.duration_ratio_median, ".3f") + " / " + cell(f.duration_ratio_max, ".3f"),
            cell(f.lift_over_scratch_cm_median, "+.2f"),
            str(f.left_alone_within_margin),
        )
        for g, f in fig.items()
    ]
    head = (
        "generator",
        "safe: flagged ok and by the check",
        "safe by the check",
        "flagged ok, unsafe",
        "refused",
        "CFFTG continuation",
        "CPU ms median / p99",
        "duration / from the start: median / max",
        "lift over from the start, cm",
        "left alone within 2 cm",
    )
    kinds = [
        (g, *(f"{a}/{b}" for a, b in (f.by_kind[k] for k in SURPRISES))) for g, f in fig.items()
    ]
    lines = [
        "# Replanning in flight",
        "",
        f"{n} unseen-shape scenes (seed {seed}), planned over an estimate, replanned at 15-45 % "
        f"of the swing over the true obstacle, {rate:g} Hz; feasible: the foot so far clear of the "
        "true obstacle by the margin. Safe by the check: the independent check (C2 at the switch, "
        "the full limits by finite differences at 1 kHz, more than 2 cm from the true obstacle "
        "after the switch at 5 kHz, above the ground, at rest within 5 cm of the goal). Duration "
        "and lift over a swing planned from the start over the true obstacle, where both are safe.",
        "",
        *table(head, rows, "l" + "r" * (len(head) - 1)),
        "",
        "Safe (flagged ok and by the check) per surprise, feasible scenes:",
        "",
        *table(("generator", *SURPRISES), kinds, "l" + "r" * len(SURPRISES)),
        "",
        "Targets: " + ", ".join(f"{k} {v}" for k, v in TARGETS.items()),
    ]
    return "\n".join(lines)


def run_replan_benchmark(
    policy: str | Path,
    out_dir: str | Path,
    n: int = 300,
    seed: int = DEFAULT_SEED,
    rate: float = 100.0,
) -> dict:
    from tqdm import tqdm

    from jaxexo.baselines import CFFTG
    from jaxexo.evaluation.machine import write_result
    from jaxexo.inference import TrajectoryGenerator

    rl = TrajectoryGenerator.load(policy)
    cfg = rl.config
    cf = CFFTG(cfg)
    margin = float(cfg.env.min_clearance)
    foot = float(cfg.kinematics.foot_length)
    scenes = surprise_scenes(cfg, n, seed)
    planners = _planners(rl, cf)
    rows: dict[str, list[Row]] = {g: [] for g in GENERATORS}
    for s in tqdm(scenes, desc="replan scenes", unit="scene"):
        for g in GENERATORS:  # alternating, in one process
            r = _row(g, *planners[g], s, cfg, rate, margin, foot)
            if r is not None:
                rows[g].append(r)
    fig = {g: _figures(r) for g, r in rows.items()}
    payload = {
        "policy": str(policy),
        "n": n,
        "seed": seed,
        "rate_hz": rate,
        "targets": TARGETS,
        "figures": {g: f.to_dict() for g, f in fig.items()},
        "rows": {g: [r.to_dict() for r in rs] for g, rs in rows.items()},
    }
    write_result(f"replan-seed{seed}", payload, _markdown(fig, n, seed, rate), out_dir)
    return payload
