"""Swing-quality benchmark: what a wearer feels of the RL swing beside CFFTG's (safety, lift, timed
duration, jerk) on scenes outside the training distribution. Run by
benchmarks/bench_swing_quality.py; the model study measures each agent with ``run_set``. Method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from jaxexo.baselines import CFFTG
from jaxexo.evaluation.machine import machine_info, write_result
from jaxexo.inference import TrajectoryGenerator, time_swings
from jaxexo.physics import geometry, swept
from jaxexo.physics.scenarios import batch_options
from jaxexo.storage.atomic import write_figure
from jaxexo.summary import Summary
from jaxexo.swing.timing import joint_jerk

from benchlib.runner import Record
from benchlib.scenes import (
    FAMILIES,
    SHAPES,
    THESIS_FIVE,
    safety_sets,
    set_table,
)

# RL swings whose smoothing a clearing pass corrected carry this module in their notes.
CLEARING = "jaxexo.swing.clearing"


def perturbed(obstacle: geometry.Obstacle, error: float, sign: float) -> geometry.Obstacle:
    """The obstacle a perception error of ``error`` m gives the planner: its outline's heights lowered by
    ``error`` (to 1 mm at least: an obstacle is never seen as nothing), the outline shifted by
    ``sign * error`` along y."""
    o = np.asarray(obstacle.outline, dtype=np.float64).copy()
    o[:, 1] = np.where(o[:, 1] > 0.0, np.maximum(o[:, 1] - error, 0.001), 0.0)
    o[:, 0] += sign * error
    return geometry.Obstacle.profile(o)


def scene_sets(cfg, n: int) -> dict[str, list[dict]]:
    """``n`` scenes per set: held-out families, the thesis five shifted, unseen shapes (seed 2025)."""
    sets = safety_sets(cfg, n, shapes_seed=2025)
    return {k: sets[k] for k in (FAMILIES, THESIS_FIVE, SHAPES)}


def _feasible(trajs, true, seen, cfg, clearance) -> np.ndarray:
    """Scenes where the clearance asked is possible at all: the flat foot at the start and at the goal
    keeps it from the obstacle the planner sees (and the config's margin from the true one)."""
    c_ask = cfg.env.min_clearance if clearance is None else clearance
    feet = lambda y, o: float(  # noqa: E731
        geometry.foot_clearance(
            np, np.array([y, 0.0]), cfg.kinematics.foot_length, np.asarray(o.outline, float)
        )
    )
    return np.array(
        [
            min(feet(t.scene.start_y, o_seen), feet(t.scene.goal_y, o_seen)) >= c_ask - 1e-9
            and min(feet(t.scene.start_y, o), feet(t.scene.goal_y, o))
            >= cfg.env.min_clearance - 1e-9
            for t, o, o_seen in zip(trajs, true, seen)
        ]
    )


@dataclasses.dataclass(frozen=True)
class SetFigures(Record):
    """One generator's figures on one scene set (shares, cm, s); the RL generator's smoothing
    figures and, once both generators ran, those on the scenes both swing safely (else None)."""

    n: int
    safe: float
    feasible: int
    safe_of_feasible: float
    true_contact_of_feasible: float
    reached_goal: float
    lift_cm_median: float
    lift_cm_p95: float
    duration_s_median: float
    duration_s_p95: float
    duration_s_max: float
    jerk_median: float
    jerk_p95: float
    true_contact: float
    true_within_1cm: float
    true_clearance_cm_p5: float
    generate_s: float
    smoothed_once: float | None = None
    corrected: float | None = None
    raw_polyline: float | None = None
    n_all_safe: int | None = None
    lift_cm_median_all_safe: float | None = None
    duration_s_median_all_safe: float | None = None
    duration_s_p95_all_safe: float | None = None

    def to_dict(self) -> dict:
        return {k: v for k, v in super().to_dict().items() if v is not None}


def _figures(
    trajs, timed, true, feasible, cfg, gen_s: float
) -> tuple[SetFigures, np.ndarray, np.ndarray]:
    """One generator's figures on a set (true: the obstacles the judge sees), its lifts (m) and timed
    durations (s)."""
    dur = np.array([t.duration for t in timed])
    jerk = np.array([joint_jerk(t) for t in timed])
    lift = np.array([t.heel[:, 1].max() - o.height for t, o in zip(trajs, true)])
    # clearance from the TRUE obstacle (the judge), exact per sample of the delivered curve and
    # exact between samples (the swept foot)
    true_c = np.array(
        [
            float(
                swept.path_swept_clearance(
                    np, t.heel, cfg.kinematics.foot_length, np.asarray(o.outline)
                ).min()
            )
            for t, o in zip(trajs, true)
        ]
    )
    nan = float("nan")
    lifts, durs, jerks, clear = (
        Summary.of(lift),
        Summary.of(dur),
        Summary.of(jerk),
        Summary.of(true_c),
    )
    return (
        SetFigures(
            n=len(trajs),
            safe=float(np.mean([t.ok for t in trajs])),
            feasible=int(feasible.sum()),
            safe_of_feasible=float(np.mean([t.ok for t, f in zip(trajs, feasible) if f]))
            if feasible.any()
            else nan,
            true_contact_of_feasible=float(np.mean((true_c <= geometry.TOUCH_EPS)[feasible]))
            if feasible.any()
            else nan,
            reached_goal=float(np.mean([t.checks.reached_goal for t in trajs])),
            lift_cm_median=100 * lifts.median,
            lift_cm_p95=100 * lifts.p95,
            duration_s_median=durs.median,
            duration_s_p95=durs.p95,
            duration_s_max=durs.max,
            jerk_median=jerks.median,
            jerk_p95=jerks.p95,
            true_contact=float(np.mean(true_c <= geometry.TOUCH_EPS)),
            true_within_1cm=float(np.mean(true_c < 0.01)),
            true_clearance_cm_p5=100 * clear.p5,
            generate_s=gen_s,
        ),
        lift,
        dur,
    )


def run_set(
    gens: dict, scenes: list[dict], cfg, clearance, error: float, smoothing=None, arrays=None
) -> dict[str, SetFigures]:
    """Both generators' figures on one scene set, by generator name; ``arrays`` (a dict), when given,
    receives each generator's per-scene (safe, lift m, duration s) for the figure."""
    out, per = {}, {}
    true = [s.obstacle for s in scenes]
    seen = (
        true
        if error == 0
        else [perturbed(o, error, 1.0 if i % 2 else -1.0) for i, o in enumerate(true)]
    )
    kw = batch_options(scenes)
    if clearance is not None:
        kw["clearance"] = clearance
    for name, gen in gens.items():
        t0 = time.perf_counter()
        extra = {"fallback": None} if name == "rl" else {}
        if name == "rl" and smoothing is not None:
            extra["smoothing"] = smoothing
        batch = gen.generate_batch(seen, **kw, **extra)
        gen_s = time.perf_counter() - t0
        trajs = list(batch)
        feasible = _feasible(trajs, true, seen, cfg, clearance)
        r, lift, dur = _figures(trajs, time_swings(trajs, cfg), true, feasible, cfg, gen_s)
        if name == "rl":
            smooth = np.array([t.smoothing for t in trajs], dtype=np.float64)
            asked = np.array([(t.method == "rl") for t in trajs])
            asked_s = gen.smoothing if smoothing is None else smoothing
            r = dataclasses.replace(
                r,
                smoothed_once=float(np.mean(asked & (smooth == asked_s))),
                corrected=float(np.mean([any(CLEARING in n for n in t.notes) for t in trajs])),
                raw_polyline=float(np.mean(np.isnan(smooth))),
            )
        out[name] = r
        per[name] = (np.array([t.ok for t in trajs]), lift, dur)
    # The scenes every generator swings safely: lift and duration compared where neither fails.
    both = np.logical_and.reduce([ok for ok, _, _ in per.values()])
    for name, (_, lift, dur) in per.items():
        lifts, durs = Summary.of(lift[both]), Summary.of(dur[both])  # NaN where none is safe
        out[name] = dataclasses.replace(
            out[name],
            n_all_safe=int(both.sum()),
            lift_cm_median_all_safe=100 * lifts.median,
            duration_s_median_all_safe=durs.median,
            duration_s_p95_all_safe=durs.p95,
        )
    if arrays is not None:
        arrays.update(per)
    return out


def figure(arrays: dict, title: str, path: Path) -> None:
    """Per scene set: the distribution (share of swings at or below) of the lift and of the timed swing,
    RL against CFFTG, each generator's unsafe swings marked on the lift panel."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(2, len(arrays), figsize=(4.2 * len(arrays), 6.4), squeeze=False)
    colours = {"rl": "tab:green", "cfftg": "tab:red"}
    for col, (set_name, per) in enumerate(arrays.items()):
        for name, (ok, lift, dur) in per.items():
            label = "RL" if name == "rl" else "CFFTG"
            for row, (values, scale) in enumerate(((lift, 100.0), (dur, 1.0))):
                v = np.sort(values * scale)
                axs[row, col].step(
                    v,
                    np.arange(1, len(v) + 1) / len(v),
                    where="post",
                    color=colours[name],
                    label=f"{label} (unsafe {100 * np.mean(~ok):.1f} %)" if row == 0 else label,
                )
            bad = np.sort(lift[~ok] * 100.0)
            if bad.size:
                axs[0, col].plot(bad, np.zeros_like(bad), "|", color=colours[name], ms=10)
        axs[0, col].set_title(set_name)
        axs[0, col].set_xlabel("lift: heel peak above the obstacle's top (cm)")
        axs[0, col].set_xlim(-6.0, 12.0)  # below 0: a plan whose peak is under the top (it hits)
        axs[1, col].set_xlabel("timed swing at the [device] limits (s)")
        axs[1, col].set_xlim(0.3, 2.5)
        for row in range(2):
            axs[row, col].set_ylabel("share of swings at or below")
            axs[row, col].grid(alpha=0.3)
            axs[row, col].legend(fontsize=8, loc="lower right")
    fig.suptitle(title + " (ticks on the lift axis: unsafe swings)")
    fig.tight_layout()
    write_figure(path, fig, dpi=90)
    plt.close(fig)


def markdown(res: dict, title: str) -> str:
    lines = [
        f"# {title}",
        "",
        "RL alone (fallback none) and CFFTG on the same scenes. Lift = heel peak above the obstacle's "
        "highest point; duration = time-optimal swing within the default [device] limits; jerk = "
        "integrated squared jerk of the timed joint angles (rad^2/s^5). Feasible: scenes whose flat foot at "
        "the start and at the goal keeps the clearance asked from the obstacle the planner sees (and the "
        "margin from the true one); no generator can do better on the others. True contact and < 1 cm: "
        "the delivered curve against the true obstacle (exact swept clearance).",
        "",
    ]

    def cells(r):
        once = f"{100 * r['smoothed_once']:.1f}" if "smoothed_once" in r else ""
        raw = f"{100 * r['raw_polyline']:.1f}" if "raw_polyline" in r else ""
        return (
            f"{r['n']} | {100 * r['safe']:.1f} | {r['feasible']} | "
            f"{100 * r['safe_of_feasible']:.1f} | {100 * r['reached_goal']:.1f} | "
            f"{r['lift_cm_median']:.2f} | {r['lift_cm_p95']:.2f} | {r['duration_s_median']:.3f} | "
            f"{r['duration_s_p95']:.3f} | {r['duration_s_max']:.2f} | {r['jerk_median']:.3g} | "
            f"{r['jerk_p95']:.3g} | {once} | {raw} | {100 * r['true_contact']:.1f} | "
            f"{100 * r['true_within_1cm']:.1f}"
        )

    columns = (
        "n, safe %, feasible n, safe % of feasible, goal %, lift median cm, lift p95 cm, "
        "duration median s, p95 s, max s, jerk median, jerk p95, smoothed once %, raw polyline %, "
        "true contact %, true < 1 cm %"
    )
    lines += set_table(columns.split(", "), res["sets"], cells)
    lines += ["", "On the scenes that every generator swings safely:", ""]
    lines += set_table(
        ("n", "lift median cm", "duration median s", "duration p95 s"),
        res["sets"],
        lambda r: (
            f"{r['n_all_safe']} | {r['lift_cm_median_all_safe']:.2f} | "
            f"{r['duration_s_median_all_safe']:.3f} | {r['duration_s_p95_all_safe']:.3f}"
        ),
    )
    return "\n".join(lines)


def run_swing_quality_benchmark(
    policy,
    out_dir,
    n: int = 600,
    clearance: float | None = None,
    perception_error: float = 0.0,
    smoothing: float | None = None,
    tag: str = "",
) -> dict:
    """Both generators on the three sets, printed and (when ``out_dir``) written with the figure as
    swing_quality[_tag]_<date>_<machine>.{json,md,png}. The clearance asked defaults to the config's
    margin plus the perception error."""
    gen = TrajectoryGenerator.load(policy)
    cfg = gen.config
    if clearance is None and perception_error > 0:
        clearance = cfg.env.min_clearance + perception_error
    gens = {"rl": gen, "cfftg": CFFTG(cfg)}
    res = {
        "policy": str(policy),
        "clearance": clearance,
        "perception_error": perception_error,
        "smoothing": smoothing,
        "sets": {},
        "machine": machine_info(),
    }
    arrays = {}
    for name, scenes in scene_sets(cfg, n).items():
        arrays[name] = {}
        figures = run_set(gens, scenes, cfg, clearance, perception_error, smoothing, arrays[name])
        res["sets"][name] = {g: f.to_dict() for g, f in figures.items()}
        print(
            name,
            {g: {k: round(v, 4) for k, v in r.items()} for g, r in res["sets"][name].items()},
            flush=True,
        )
    title = (
        "Swing quality"
        + (f" at clearance {100 * clearance:.1f} cm" if clearance else "")
        + (f", perception error {100 * perception_error:.1f} cm" if perception_error else "")
    )
    md = markdown(res, title)
    print(md)
    if out_dir:
        paths = write_result("swing_quality" + (f"_{tag}" if tag else ""), res, md, out_dir)
        figure(arrays, title, paths[1].with_suffix(".png"))
        print(*paths, paths[1].with_suffix(".png"))
    return res
