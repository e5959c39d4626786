"""Replanned swings driven through the switch in MuJoCo: surprise scenes of shapes the default
policy never trained on (an obstacle estimated lower than it is, or where it is not), a swing
planned and timed over the estimate, replanned over the true obstacle at 15-40 % of the swing by
the policy (alone) and by CFFTG, and driven in the true scene from the start, following the old
swing until the switch and the new one after (jaxexo.sim.driven, ``before``). Run by
benchmarks/bench_replan_replay.py; method: docs/replanning.md#replayed-through-the-switch."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from jaxexo.baselines import CFFTG
from jaxexo.evaluation.machine import write_result
from jaxexo.inference import TrajectoryGenerator
from jaxexo.physics.geometry import Obstacle
from jaxexo.physics.scene import PIVOT_CONDITIONS
from jaxexo.physics.terrain import FAR_MARGIN, NEAR_MARGIN
from jaxexo.sim.replay import Legs, driven_replay, summarize_driven
from jaxexo.summary import Summary, table
from jaxexo.swing.timing import time_swing

from benchlib.runner import Record

# Shapes of the held-out families (none is a training family: jaxexo.physics.terrain), drawn
# wider and taller than those: a pole, stairs up or down, two or three bumps, a smooth bump.
SHAPES = ("pole", "stairs", "bumps", "smooth_bump")
TRUE_HEIGHT = (0.06, 0.22)  # m, the true obstacle's
TALLER = (1.3, 1.6)  # the true obstacle over the estimate, in height
MOVED = (0.03, 0.05)  # m the true obstacle lies from the estimate, farther or nearer
AT = (0.15, 0.40)  # the switch, as a fraction of the old swing's duration
START, STEP = (0.0, 0.10), (0.55, 0.85)  # m: the start and the step length
REFERENCES = (("curve", None), ("quintic", None))  # the drive's reference: (kind, rate)


def _profile(rng, shape: str, height: float) -> np.ndarray:
    """A height profile (P, 2) m of ``shape`` centred on y = 0, ``height`` high."""
    if shape == "pole":
        w = rng.uniform(0.01, 0.04)
        return np.array([[-w / 2, 0.0], [-w / 2, height], [w / 2, height], [w / 2, 0.0]])
    w = rng.uniform(0.10, 0.30)
    if shape == "stairs":
        k = int(rng.integers(2, 4))
        z = height * np.arange(1, k + 1) / k
        z = z if rng.uniform() < 0.5 else z[::-1]
        y = np.linspace(-w / 2, w / 2, k + 1)
        pts = [[y[0], 0.0]]
        for i in range(k):
            pts += [[y[i], z[i]], [y[i + 1], z[i]]]
        return np.array(pts + [[y[-1], 0.0]])
    if shape == "bumps":
        k = int(rng.integers(2, 4))
        y = np.linspace(-w / 2, w / 2, 2 * k + 1)
        z = np.zeros(2 * k + 1)
        z[1::2] = height * rng.uniform(0.6, 1.0, k)
        z[1 + 2 * int(rng.integers(k))] = height
        z[2:-1:2] = height * rng.uniform(0.0, 0.4, k - 1)
        return np.column_stack([y, z])
    y = np.linspace(-w / 2, w / 2, 11)
    return np.column_stack([y, height * 0.5 * (1.0 + np.cos(2.0 * np.pi * y / w))])


@dataclasses.dataclass(frozen=True)
class Surprise(Record):
    """A surprise scene: the shape, the change ("taller" or "moved"), the estimated and the true
    obstacle, the pivot, start and step length (m), and the switch as a fraction of the swing."""

    shape: str
    change: str
    estimate: Obstacle
    true: Obstacle
    pivot: str
    start_y: float
    step_length: float
    at_fraction: float

    def scene_kwargs(self) -> dict:
        return {"pivot": self.pivot, "start_y": self.start_y, "step_length": self.step_length}


def surprise_scenes(foot_length: float, n: int, seed: int = 59) -> list[Surprise]:
    """``n`` surprise scenes (SHAPES in turn, the changes alternating, the pivots in turn): the
    true obstacle in the gap with procedural terrain's margins (and, where it moved, the estimate
    too), the estimate lower by TALLER or moved by MOVED, the switch at AT of the swing."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        shape, change = SHAPES[i % len(SHAPES)], ("taller", "moved")[(i // len(SHAPES)) % 2]
        prof = _profile(rng, shape, rng.uniform(*TRUE_HEIGHT))
        half = float(prof[-1, 0])
        shift = rng.uniform(*MOVED) * rng.choice([-1.0, 1.0]) if change == "moved" else 0.0
        lo = hi = 0.0
        while hi <= lo:  # a step long enough for both obstacles in the gap
            start, step = rng.uniform(*START), rng.uniform(*STEP)
            # the estimate lies -shift from the true obstacle: both within the margins
            lo = start + foot_length + NEAR_MARGIN + half + max(0.0, shift)
            hi = start + step - FAR_MARGIN - half - max(0.0, -shift)
        center = rng.uniform(lo, hi)
        true = prof + [center, 0.0]
        est = true - [shift, 0.0] if change == "moved" else true / [1.0, rng.uniform(*TALLER)]
        out.append(
            Surprise(
                shape=shape,
                change=change,
                estimate=Obstacle.profile(est),
                true=Obstacle.profile(true),
                pivot=PIVOT_CONDITIONS[(i // (2 * len(SHAPES))) % len(PIVOT_CONDITIONS)],
                start_y=float(start),
                step_length=float(step),
                at_fraction=float(rng.uniform(*AT)),
            )
        )
    return out


@dataclasses.dataclass(frozen=True)
class ReplayRow(Record):
    """One driven replay's figures kept per scene: MuJoCo's smallest distance (m) and when (s),
    whether it touched and a setpoint clipped, the heel error (largest and p95, m) and the
    switch's figures (SwitchFigures as a dict)."""

    min_distance_m: float
    min_time_s: float
    contact: bool
    clipped: bool
    heel_error_max_m: float
    heel_error_p95_m: float
    switch: dict

    @classmethod
    def of(cls, d) -> ReplayRow:
        """The ReplayRow of a DrivenReplay ``d`` (replayed through a switch)."""
        f = d.figures
        return cls(
            min_distance_m=f.mujoco_min_distance_m,
            min_time_s=f.mujoco_min_time_s,
            contact=f.contact,
            clipped=f.saturated,
            heel_error_max_m=f.heel_error_max_m,
            heel_error_p95_m=f.heel_error_p95_m,
            switch=dataclasses.asdict(d.switch),
        )


@dataclasses.dataclass(frozen=True)
class SwingRow(Record):
    """One generator on one surprise scene: the scene's index, shape and change; what became of it
    ("old not ok": the swing over the estimate was not safe; "refused": replan raised, with its
    message; "not ok": the replanned swing is flagged not safe; "ok": replayed); the switch (s),
    the replan's CPU time (s); the old swing left alone in the true scene (MuJoCo's smallest
    distance, m, and whether it touched); the replanned swing's largest proven jerk peak times
    the physics step (rad/s^2: what a 1 ms step of its acceleration may reach); the driven
    replays through the switch (ReplayRow dicts, by reference)."""

    scene: int
    shape: str
    change: str
    status: str
    message: str = ""
    at_s: float | None = None
    replan_cpu_s: float | None = None
    alone_min_distance_m: float | None = None
    alone_contact: bool | None = None
    jerk_step_bound_rad_s2: float | None = None
    replays: dict = dataclasses.field(default_factory=dict)


def replay_scene(i: int, sc: Surprise, name: str, gen, config, clearance=None):
    """Generator ``name`` (``gen``) on scene ``sc``, replanning with ``clearance`` (m; None: the
    config's margin): the row, the DrivenReplays by reference and (old, replanned) where
    replayed (None elsewhere)."""
    base = {"scene": i, "shape": sc.shape, "change": sc.change}
    kw = sc.scene_kwargs() | ({"fallback": None} if name == "rl" else {})
    old = time_swing(gen.generate(sc.estimate, **kw), config)
    if not old.ok:
        return SwingRow(**base, status="old not ok"), {}, None
    at = sc.at_fraction * old.duration
    t0 = time.process_time()
    try:
        opts = ({"fallback": None} if name == "rl" else {}) | {"clearance": clearance}
        new = gen.replan(old, sc.true, at=at, **opts)
    except ValueError as e:
        return SwingRow(**base, status="refused", message=str(e), at_s=at), {}, None
    cpu = time.process_time() - t0
    legs = Legs(config, new.scene)
    alone = driven_replay(old, config, legs=legs).figures
    row = dict(base, at_s=at, replan_cpu_s=cpu, alone_min_distance_m=alone.mujoco_min_distance_m)
    row["alone_contact"] = alone.contact
    if not new.ok:
        return SwingRow(**row, status="not ok", message="; ".join(new.reasons)), {}, None
    drv = {
        kind: driven_replay(new, config, legs=legs, before=old, reference=kind, reference_rate=r)
        for kind, r in REFERENCES
    }
    row["jerk_step_bound_rad_s2"] = float(np.max(new.peak_jerk)) * drv["curve"].physics_dt_s
    out = SwingRow(
        **row, status="ok", replays={k: ReplayRow.of(d).to_dict() for k, d in drv.items()}
    )
    return out, drv, (old, new)


@dataclasses.dataclass(frozen=True)
class Ratios(Record):
    """Ratios of the replays (of a figure at the switch over its largest elsewhere): median, max
    and how many are above 1."""

    median: float
    max: float
    above_1: int

    @classmethod
    def of(cls, x) -> Ratios:
        s = Summary.of(x)
        return cls(s.median, s.max, int(np.sum(np.asarray(x) > 1.0)))

    def cell(self) -> str:
        return f"median {self.median:.2f}, max {self.max:.2f} ({self.above_1} above 1)"


@dataclasses.dataclass(frozen=True)
class ReplayFigures(Record):
    """The driven replays of one generator's replanned swings through the switch, one reference:
    the replays (n), within the margin and in contact (MuJoCo), the swings where a setpoint clipped
    (count and share), the heel error (p95 over the swings of each one's largest, and its max, m),
    MuJoCo's smallest distance (m); at the switch (SwitchFigures): the reference's largest jumps
    in position (rad), velocity (rad/s) and acceleration (rad/s^2), the replays whose commanded
    acceleration's 1 ms step across the switch is within the swing's proven jerk peak times 1 ms,
    that step over the largest 1 ms step elsewhere, and its change over a control period across
    the switch over the largest elsewhere."""

    n: int
    within_margin: int
    contacts: int
    clipped: int
    clipped_share: float
    heel_error_p95_m: float
    heel_error_max_m: float
    min_distance_m: float
    position_jump_max_rad: float
    velocity_jump_max_rad_s: float
    acceleration_jump_max_rad_s2: float
    step_within_jerk_bound: int
    step: Ratios
    period: Ratios


def replay_figures(rows, bounds) -> ReplayFigures | None:
    """The ReplayFigures of DrivenReplays ``rows`` (None for none), ``bounds`` their swings'
    SwingRow.jerk_step_bound_rad_s2."""
    if not rows:
        return None
    s = summarize_driven(rows)
    sw = [d.switch for d in rows]
    return ReplayFigures(
        n=s.n,
        within_margin=s.within_margin,
        contacts=s.contacts,
        clipped=s.saturated,
        clipped_share=s.saturated / s.n,
        heel_error_p95_m=s.heel_error_p95_m,
        heel_error_max_m=s.heel_error_max_m,
        min_distance_m=s.min_distance_m,
        position_jump_max_rad=max(x.position_jump_rad for x in sw),
        velocity_jump_max_rad_s=max(x.velocity_jump_rad_s for x in sw),
        acceleration_jump_max_rad_s2=max(x.acceleration_jump_rad_s2 for x in sw),
        step_within_jerk_bound=sum(x.switch_step_rad_s2 <= b for x, b in zip(sw, bounds)),
        step=Ratios.of([x.step_ratio for x in sw]),
        period=Ratios.of([x.period_ratio for x in sw]),
    )


@dataclasses.dataclass(frozen=True)
class GeneratorFigures(Record):
    """One generator over the surprise scenes: the scenes, how many ended in each status, the old
    swings left alone within the margin and in contact (of those replanned), the replan's CPU time
    (median and p99, s) and the replays' figures by reference."""

    scenes: int
    status: dict
    alone_within_margin: int
    alone_contacts: int
    replan_cpu_s_median: float | None
    replan_cpu_s_p99: float | None
    replays: dict


def generator_figures(rows: list[SwingRow], drv: list[dict], margin: float) -> GeneratorFigures:
    """The GeneratorFigures of one generator's rows and replays."""
    planned = [r for r in rows if r.alone_min_distance_m is not None]
    cpu = np.array([r.replan_cpu_s for r in planned])
    bounds = [r.jerk_step_bound_rad_s2 for r in rows if r.status == "ok"]
    return GeneratorFigures(
        scenes=len(rows),
        status={
            s: sum(r.status == s for r in rows) for s in ("ok", "not ok", "refused", "old not ok")
        },
        alone_within_margin=sum(r.alone_min_distance_m < margin for r in planned),
        alone_contacts=sum(bool(r.alone_contact) for r in planned),
        replan_cpu_s_median=float(np.median(cpu)) if len(cpu) else None,
        replan_cpu_s_p99=float(np.percentile(cpu, 99)) if len(cpu) else None,
        replays={
            k: (f.to_dict() if (f := replay_figures([d[k] for d in drv if d], bounds)) else None)
            for k, _ in REFERENCES
        },
    )


def _mm(x) -> str:
    return "-" if x is None else f"{1000 * x:.2f}"


HEADER = (
    *("generator", "reference", "replayed", "within 2 cm", "contacts", "clipped swings"),
    *("heel error p95 / max, mm", "smallest distance, mm"),
    "reference's largest jump: position rad, velocity rad/s, acceleration rad/s^2",
    "1 ms step across within the proven jerk",
    "1 ms step across / largest elsewhere",
    "change over a control period across / largest elsewhere",
)


def markdown(res: dict) -> str:
    """The report: the scenes, what became of them, and the replays' table."""
    rows, fate = [], []
    for g, f in res["generators"].items():
        st = f["status"]
        fate.append(
            (
                g,
                str(f["scenes"]),
                *(str(st[k]) for k in ("old not ok", "refused", "not ok", "ok")),
                f"{f['alone_within_margin']} / {f['alone_contacts']}",
                f"{1e3 * f['replan_cpu_s_median']:.1f} / {1e3 * f['replan_cpu_s_p99']:.1f}",
            )
        )
        for k, r in f["replays"].items():
            if r is None:
                continue
            rows.append(
                (
                    *(g, k, str(r["n"]), str(r["within_margin"]), str(r["contacts"])),
                    f"{r['clipped']} ({100 * r['clipped_share']:.1f} %)",
                    f"{_mm(r['heel_error_p95_m'])} / {_mm(r['heel_error_max_m'])}",
                    _mm(r["min_distance_m"]),
                    f"{r['position_jump_max_rad']:.1e}, {r['velocity_jump_max_rad_s']:.1e}, "
                    f"{r['acceleration_jump_max_rad_s2']:.1e}",
                    f"{r['step_within_jerk_bound']} of {r['n']}",
                    *(Ratios(**r[x]).cell() for x in ("step", "period")),
                )
            )
    fate_header = (
        *("generator", "scenes", "old swing not ok", "replan refused", "replanned, not ok"),
        *("replanned ok", "old left alone: within 2 cm / contacts", "replan CPU ms median / p99"),
    )
    return "\n".join(
        [
            "# Replanned swings driven through the switch (MuJoCo)",
            "",
            f"Policy `{res['policy']}`; {res['n']} surprise scenes (seed {res['seed']}: "
            f"{', '.join(SHAPES)}; the true obstacle {TALLER[0]:g}-{TALLER[1]:g}x the estimate's "
            f"height or {100 * MOVED[0]:g}-{100 * MOVED[1]:g} cm from it; switch at "
            f"{100 * AT[0]:g}-{100 * AT[1]:g} % of the swing); {res['rate_hz']:g} Hz; margin "
            f"{100 * res['margin_m']:g} cm; replanned with clearance "
            f"{res['replan_clearance_m'] or 'the margin'}; RL alone (fallback=None) and CFFTG; pd_ff; "
            f"{res['seconds']:.0f} s in all.",
            "",
            *table(fate_header, fate, "l" + "r" * 7),
            "",
            "Driven replays of the replanned swings flagged ok, in the true scene from the start, "
            "following the old swing until the switch and the replanned one after (`curve`: the "
            "curves at every 1 ms physics step; `quintic`: the 100 Hz samples as a drive "
            "interpolates them, joined from the drive's own state at the switch):",
            "",
            *table(HEADER, rows, "ll" + "r" * (len(HEADER) - 2)),
        ]
    )


def commanded(timed, before, at: float, limits, span: float = 0.15):
    """Times (s) and the setpoints' acceleration (rad/s^2, 4 joints) of ``timed``'s reference at
    1 ms within ``span`` of ``at``, followed through its last switch from ``before`` (None:
    ``timed`` alone), as the driven replay commands it (``setpoints`` from lift-off, 1 ms)."""
    from jaxexo.sim.driven import reference_states, setpoints

    dt = 1e-3
    t = np.arange(0.0, at + span, dt)
    q = reference_states(timed, t, before=before)[0]
    cmd = setpoints(q, dt, limits.velocity, limits.acceleration)[0]
    acc = np.diff(np.concatenate([q[:1], cmd]), n=2, axis=0) / dt**2
    keep = t[1:-1] >= at - span
    return t[1:-1][keep], acc[keep]


def figure(res: dict, example, path) -> None:
    """Left: a replanned swing's commanded acceleration (swing hip and knee) through the switch,
    beside the old swing's own; right: the 1 ms step and the change over a control period of the
    commanded acceleration across the switch over the largest elsewhere, every replay of the
    curve, by generator."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    old, new = example
    at = new.switch_times[-1]
    for j, name, color in ((0, "swing hip", "C0"), (1, "swing knee", "C1")):
        t, acc = commanded(new, old, at, new.limits)
        a.plot(t, acc[:, j], color=color, label=f"{name}, through the switch")
        t, acc = commanded(old, None, at, new.limits)
        a.plot(t, acc[:, j], color=color, ls="--", alpha=0.6, label=f"{name}, old swing")
    a.axvline(at, color="k", lw=0.8)
    a.set(
        xlabel="t (s)",
        ylabel="commanded acceleration (rad/s$^2$)",
        title="The replan with the largest 1 ms step across the switch",
    )
    a.legend(fontsize=7)
    bins = np.linspace(0.0, 1.5, 31)
    keys = (("step_ratio", "1 ms step"), ("period_ratio", "change over a period"))
    for g, rows in res["per_scene"].items():
        for key, what in keys:
            x = [r["replays"]["curve"]["switch"][key] for r in rows if r["replays"]]
            b.hist(x, bins=bins, histtype="step", label=f"{g}, {what} (n = {len(x)})")
    b.axvline(1.0, color="k", lw=0.8)
    b.set(
        xlabel="at the switch / largest elsewhere (curve reference)",
        ylabel="replays",
        title="Commanded acceleration across the switch",
    )
    b.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run_replan_replay_benchmark(
    policy, out_dir, n: int = 200, seed: int = 59, name="replan-replay", clearance: float = 0.0
):
    """Both generators over ``n`` surprise scenes, replanning with ``clearance`` (m; 0: the
    config's margin), printed and written as <name>_<date>_<machine>.{json,md,png}."""
    rl = TrajectoryGenerator.load(policy)
    config = rl.config
    gens = {"rl": rl, "cfftg": CFFTG(config)}
    scenes = surprise_scenes(config.kinematics.foot_length, n, seed)
    t0 = time.perf_counter()
    res = {"policy": str(policy), "n": n, "seed": seed, "rate_hz": config.device.control_rate}
    res["margin_m"] = float(config.env.min_clearance)
    res["replan_clearance_m"] = clearance or None
    per, figs, example, worst = {}, {}, None, -1.0
    for g, gen in gens.items():
        rows, drv = [], []
        for i, sc in enumerate(scenes):
            row, d, pair = replay_scene(i, sc, g, gen, config, clearance or None)
            rows.append(row)
            drv.append(d)
            if pair and d["curve"].switch.step_ratio > worst:  # the figure's: the largest step
                worst, example = d["curve"].switch.step_ratio, pair
        figs[g] = generator_figures(rows, drv, res["margin_m"]).to_dict()
        per[g] = [r.to_dict() for r in rows]
        print(f"[{time.strftime('%H:%M:%S')}]", g, figs[g], flush=True)
    res |= {"seconds": time.perf_counter() - t0, "generators": figs, "per_scene": per}
    md = markdown(res)
    paths = write_result(name, res, md, out_dir)
    if example is not None:
        figure(res, example, paths[1].with_suffix(".png"))
    print(md)
    print("wrote", *paths)
    return res
