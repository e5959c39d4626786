"""Side-by-side evaluation of trajectory generators (the RL policy and CFFTG) on the same scenarios:
the thesis's metrics (3.3: generation time, hip and knee angles, accuracy eq 3.1) and more, per
obstacle kind and pivot condition, written as report.md, report.json and figures (``jaxexo eval``).

Scenarios (jaxexo.inference.scenarios, NumPy): ``test`` are the five thesis obstacles of Table 3.1
cycled over the three pivot conditions with the policy config's start shifts, step lengths and
offsets, from a fixed seed, like the trainer's eval.json; ``train`` are drawn from the policy's
training distribution (its obstacle mixture and pivot conditions). Everything here is NumPy only
(matplotlib for the figures).

Timing: each generator's ``generate`` is called once per scenario, the two generators alternating
which goes first, in one process, with ``time.perf_counter`` around the call (scene validation,
generation, smoothing and every check included); ``generate_batch`` on 1000 scenarios is timed the
same way (median of ``BATCH_REPEATS``), and per kind and pivot each group's own scenarios in one
``generate_batch`` call, scaled to 1000. Metrics are computed on the trajectories of the single calls.

Per generator, overall, per kind and per pivot: accuracy (eq 3.1: the foot never touches the
obstacle), strict success (goal reached, collision-free, joint limits and leg length respected),
time per trajectory (mean, median, p95, ms), mean hip and knee angle of the swing leg (deg, as
Tables 3.2-3.9), the swing knee's deepest flexion and the swing hip's largest flexion (deg, the
ranges of Table 3.2), minimum clearance (m), heel path length (m) and integrated squared jerk of the
heel (m^2/s^5, finite differences over the trajectory's time stamps); and under ``device`` the
swing timed for the exoskeleton (jaxexo.inference.swing_timing, the policy config's [device]
limits, applied alike to both generators' paths): swing duration (s) and peak joint velocities.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from jaxexo.config import Config
from jaxexo.physics.kinematics import PIVOT_CONDITIONS
from jaxexo.physics import swept
from jaxexo.evaluation.metrics import path_length
from jaxexo.inference.scenarios import sample_scenarios, training_scenarios
from jaxexo.storage.atomic import atomic_write
from jaxexo.storage.rundir import blocking_file

BATCH = 1000
BATCH_REPEATS = 3
SCENARIO_SETS = ("train", "test", "all", "unseen")


def make_scenarios(cfg: Config, which: str, n: int, seed: int = 12345) -> list[dict]:
    """``test``: n scenarios of jaxexo.inference.scenarios.sample_scenarios (the five thesis obstacles
    over the three pivot conditions); ``train``: n of the config's training distribution; ``all``:
    both (2 n); ``unseen``: the fixed held-out benchmark of jaxexo.evaluation.unseen (at least n
    scenes; its seed is fixed, ``seed`` does not apply). Each a dict of ``generate``'s keyword
    arguments plus ``kind``."""
    if which not in SCENARIO_SETS:
        raise ValueError(f"scenarios must be one of {SCENARIO_SETS}, got {which!r}")
    if which == "unseen":
        from jaxexo.physics.scenarios import repeats_for, unseen_scenarios

        return unseen_scenarios(cfg.kinematics.foot_length, repeats_for(n))
    out: list[dict] = []
    if which in ("test", "all"):
        out += sample_scenarios(cfg, n, seed)
    if which in ("train", "all"):
        out += training_scenarios(cfg, n, seed + 1)
    return out


def _kwargs(s: dict) -> dict:
    return {"pivot": s["pivot"], "start_y": s["start_y"], "step_length": s["step_length"]}


# --------------------------------------------------------------------------------------------
# Metrics
# --------------------------------------------------------------------------------------------


def squared_jerk(heel: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Integrated squared jerk of heel paths (..., N, 2) sampled at equally spaced times t (N,):
    sum over the third differences of |d^3 p / dt^3|^2 dt, m^2/s^5."""
    dt = float(t[1] - t[0])
    j = np.diff(heel, n=3, axis=-2) / dt**3
    return (j * j).sum(axis=(-1, -2)) * dt


# Backward heel motion counted in the report (m, at the samples): the default env.backward_tolerance.
BACKWARD_REPORT = 0.005


class WithFallback:
    """A TrajectoryGenerator with its ``fallback`` fixed, so that compare can time and score the RL
    swing alone ("rl", fallback None) and the combination ("rl+cfftg") side by side."""

    def __init__(self, gen, fallback):
        self.gen, self.fallback = gen, fallback
        self.config = gen.config

    def generate(self, *a, **kw):
        return self.gen.generate(*a, fallback=self.fallback, **kw)

    def generate_batch(self, *a, **kw):
        return self.gen.generate_batch(*a, fallback=self.fallback, **kw)


def trajectory_metrics(trajs) -> dict[str, np.ndarray]:
    """Per-trajectory figures (arrays over the trajectories)."""
    return {
        "accurate": np.array([t.checks.collision_free for t in trajs]),
        "success": np.array([t.ok for t in trajs]),
        "reached_goal": np.array([t.checks.reached_goal for t in trajs]),
        "hip_mean": np.array([t.joint_angles[:, 0].mean() for t in trajs]),
        "knee_mean": np.array([t.joint_angles[:, 1].mean() for t in trajs]),
        "hip_max": np.array([t.joint_angles[:, 0].max() for t in trajs]),
        "knee_min": np.array([t.joint_angles[:, 1].min() for t in trajs]),
        "min_clearance": np.array([t.checks.min_clearance for t in trajs]),
        "clearance_ok": np.array([t.checks.clearance_ok for t in trajs]),
        "peak_above": np.array([t.heel[:, 1].max() - t.scene.height for t in trajs]),
        "backward": np.array([float(swept.backward_motion(np, t.heel[:, 0])) for t in trajs]),
        "fallback": np.array([t.method == "cfftg-fallback" for t in trajs]),
        "path_length": np.array([path_length(t.heel) for t in trajs]),
        "jerk": np.array([squared_jerk(t.heel, t.time) for t in trajs]),
    }


def device_metrics(trajs, config) -> dict[str, np.ndarray]:
    """Per-trajectory device timing (jaxexo.inference.swing_timing, the config's [device] limits):
    the shortest rest-to-rest swing duration (s), the timed swing's peak hip and knee velocity over
    both legs (rad/s), whether its exported samples stay within the limits, and the peak joint
    velocity of the path at its own uniform time stamps (rad/s), for contrast.

    A generator that stood still (the heel never leaves its start: a policy that learned not to move,
    e.g. the faithful thesis configs) has nothing to time: its swing counts as 0 s at zero velocity,
    within the limits; its success and goal figures already say it failed."""
    from jaxexo.inference.swing_timing import joint_jerk, time_swings, uniform_peaks

    trajs = list(trajs)
    n = len(trajs)
    moves = [i for i, t in enumerate(trajs) if np.any(np.asarray(t.heel) != np.asarray(t.heel)[0])]
    out = {"swing_s": np.zeros(n), "peak_hip_vel": np.zeros(n), "peak_knee_vel": np.zeros(n),
           "within_limits": np.ones(n, bool), "uniform_peak_vel": np.zeros(n), "joint_jerk": np.zeros(n)}
    if moves:
        timed = time_swings([trajs[i] for i in moves], config)
        out["swing_s"][moves] = [t.duration for t in timed]
        out["peak_hip_vel"][moves] = [max(t.peak_velocity[0], t.peak_velocity[2]) for t in timed]
        out["peak_knee_vel"][moves] = [max(t.peak_velocity[1], t.peak_velocity[3]) for t in timed]
        out["within_limits"][moves] = [t.within_limits for t in timed]
        out["joint_jerk"][moves] = [joint_jerk(t) for t in timed]
        out["uniform_peak_vel"][moves] = [uniform_peaks(trajs[i])[0].max() for i in moves]
    return out


def summarize_device(m: dict[str, np.ndarray], mask: np.ndarray) -> dict:
    """Device-timing figures of one group (seconds; velocities in deg/s)."""
    d = np.degrees
    return {
        "swing_s_mean": float(m["swing_s"][mask].mean()),
        "swing_s_median": float(np.median(m["swing_s"][mask])),
        "swing_s_p95": float(np.percentile(m["swing_s"][mask], 95)),
        "swing_s_max": float(m["swing_s"][mask].max()),
        "joint_jerk_median": float(np.median(m["joint_jerk"][mask])),
        "joint_jerk_p95": float(np.percentile(m["joint_jerk"][mask], 95)),
        "peak_hip_vel_deg_s_mean": float(d(m["peak_hip_vel"][mask].mean())),
        "peak_knee_vel_deg_s_mean": float(d(m["peak_knee_vel"][mask].mean())),
        "device_within_limits": float(m["within_limits"][mask].mean()),
        "uniform_peak_joint_vel_deg_s_median": float(d(np.median(m["uniform_peak_vel"][mask]))),
    }


def summarize(m: dict[str, np.ndarray], times_s: np.ndarray, mask: np.ndarray) -> dict:
    """Figures of one group of trajectories (angles in degrees, lengths in metres, times in ms)."""
    t = times_s[mask] * 1e3
    d = np.degrees
    return {
        "n": int(mask.sum()),
        "accuracy": float(m["accurate"][mask].mean()),
        "success": float(m["success"][mask].mean()),
        "reached_goal": float(m["reached_goal"][mask].mean()),
        "time_ms_mean": float(t.mean()),
        "time_ms_median": float(np.median(t)),
        "time_ms_p95": float(np.percentile(t, 95)),
        "hip_swing_mean_deg": float(d(m["hip_mean"][mask].mean())),
        "knee_swing_mean_deg": float(d(m["knee_mean"][mask].mean())),
        "hip_swing_max_deg": float(d(m["hip_max"][mask].mean())),
        "knee_swing_min_deg": float(d(m["knee_min"][mask].mean())),
        "min_clearance_m_mean": float(m["min_clearance"][mask].mean()),
        "min_clearance_m_median": float(np.median(m["min_clearance"][mask])),
        "min_clearance_m_worst": float(m["min_clearance"][mask].min()),
        "clearance_ok": float(m["clearance_ok"][mask].mean()),
        "peak_above_obstacle_m_median": float(np.median(m["peak_above"][mask])),
        "peak_above_obstacle_m_p95": float(np.percentile(m["peak_above"][mask], 95)),
        "heel_backward_rate": float((m["backward"][mask] > BACKWARD_REPORT).mean()),
        "fallback_rate": float(m["fallback"][mask].mean()),
        "path_length_m_mean": float(m["path_length"][mask].mean()),
        "squared_jerk_mean": float(m["jerk"][mask].mean()),
    }


def batch_time(gen, scenarios: list[dict], size: int = BATCH, repeats: int = BATCH_REPEATS) -> float:
    """Median wall time (ms) of ``generate_batch`` on ``size`` scenarios (cycled if fewer), timed by
    the generator benchmark's own function, scaled to a batch of 1000 (exact when size = 1000)."""
    from jaxexo.evaluation.timing import time_batch

    t = np.median(time_batch(gen, [scenarios[i % len(scenarios)] for i in range(size)], repeats)[0])
    return float(t) * 1e3 * BATCH / size


def run_generators(generators: dict, scenarios: list[dict], warmup: int = 20):
    """Generate every scenario with every generator, alternating their order per scenario.
    Returns {name: (trajectories, per-call seconds)}."""
    names = list(generators)
    for s in scenarios[:warmup]:
        for g in generators.values():
            g.generate(s["obstacle"], **_kwargs(s))
    trajs = {n: [] for n in names}
    times = {n: np.empty(len(scenarios)) for n in names}
    for i, s in enumerate(scenarios):
        order = names if i % 2 == 0 else names[::-1]
        for n in order:
            g = generators[n]
            t0 = time.perf_counter()
            tr = g.generate(s["obstacle"], **_kwargs(s))
            times[n][i] = time.perf_counter() - t0
            trajs[n].append(tr)
    return {n: (trajs[n], times[n]) for n in names}


def evaluate_generators(generators: dict, scenarios: list[dict], batch_size: int = BATCH,
                        batch_repeats: int = BATCH_REPEATS) -> tuple[dict, dict]:
    """The report's figures per generator, and the trajectories (for figures)."""
    runs = run_generators(generators, scenarios)
    kinds = np.array([s["kind"] for s in scenarios])
    pivots = np.array([s["pivot"] for s in scenarios])
    report, trajs = {}, {}
    groups = {
        "by_kind": {k: kinds == k for k in dict.fromkeys(kinds)},
        "by_pivot": {p: pivots == p for p in PIVOT_CONDITIONS if (pivots == p).any()},
        "by_kind_pivot": {f"{k}/{p}": (kinds == k) & (pivots == p) for k in dict.fromkeys(kinds)
                          for p in PIVOT_CONDITIONS if ((kinds == k) & (pivots == p)).any()},
    }
    for name, (tr, times) in runs.items():
        gen = generators[name]
        m = trajectory_metrics(tr)
        dm = device_metrics(tr, gen.config)
        entry = summarize(m, times, np.ones(len(tr), bool))
        entry["device"] = summarize_device(dm, np.ones(len(tr), bool))
        entry["batch_1000_ms"] = batch_time(gen, scenarios, batch_size, batch_repeats) if batch_size else None
        entry["batch_size"] = batch_size
        for key, masks in groups.items():
            entry[key] = {}
            for g, mask in masks.items():
                entry[key][g] = summarize(m, times, mask)
                entry[key][g]["device"] = summarize_device(dm, mask)
                # The group's own scenarios in one generate_batch call, scaled to 1000.
                sub = [scenarios[i] for i in np.flatnonzero(mask)]
                entry[key][g]["batch_1000_ms"] = batch_time(gen, sub, len(sub), 1) if batch_size else None
        entry["failures"] = [{"scenario": i, "kind": str(kinds[i]), "pivot": str(pivots[i]),
                              "reasons": list(t.checks.reasons)} for i, t in enumerate(tr) if not t.ok][:20]
        report[name] = entry
        trajs[name] = tr
    return report, trajs


# --------------------------------------------------------------------------------------------
# Report files
# --------------------------------------------------------------------------------------------


def _row(name: str, r: dict) -> str:
    b = r.get("batch_1000_ms")
    return (f"| {name} | {r['n']} | {100 * r['accuracy']:.1f} | {100 * r['success']:.1f} | "
            f"{100 * r['min_clearance_m_median']:.2f} | {100 * r['peak_above_obstacle_m_median']:.1f} | "
            f"{100 * r['heel_backward_rate']:.1f} | {100 * r['fallback_rate']:.1f} | {r['time_ms_mean']:.3f} | "
            f"{r['time_ms_median']:.3f} | {r['time_ms_p95']:.3f} | {r['hip_swing_mean_deg']:.1f} | "
            f"{r['knee_swing_mean_deg']:.1f} | {r['hip_swing_max_deg']:.1f} | {r['knee_swing_min_deg']:.1f} | "
            f"{100 * r['min_clearance_m_mean']:.2f} | {100 * r['path_length_m_mean']:.1f} | {r['squared_jerk_mean']:.3g} | "
            f"{'-' if b is None else f'{b:.1f}'} |")


TABLE_HEAD = ("| {what} | n | accuracy % (eq 3.1) | safe swing % | median guaranteed clearance cm | "
              "median peak above obstacle cm | heel backward > 5 mm % | CFFTG fallback % | time mean ms | median ms | p95 ms | "
              "hip swing mean deg | knee swing mean deg | hip swing max deg | knee swing min deg | "
              "min clearance cm | path length cm | sq. jerk m²/s⁵ | batch of 1000 ms |\n"
              "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")


def markdown(report: dict, title: str, context: list[str]) -> str:
    lines = [f"# {title}", "", *context, "", "## Overall", "", TABLE_HEAD.format(what="generator")]
    for name, r in report.items():
        lines.append(_row(name, r))
    lines += ["", "| generator | batch of 1000 (ms, median) |", "|---|---:|"]
    for name, r in report.items():
        b = r["batch_1000_ms"]
        scaled = "" if r["batch_size"] in (BATCH, 0) else f" (timed on {r['batch_size']}, scaled)"
        lines.append(f"| {name} | {'-' if b is None else f'{b:.1f}'}{scaled} |")
    for key, label in (("by_kind", "obstacle kind"), ("by_pivot", "pivot condition"),
                       ("by_kind_pivot", "kind / pivot")):
        lines += ["", f"## By {label}", "", TABLE_HEAD.format(what=f"{label} (generator)")]
        groups = list(next(iter(report.values()))[key])
        for g in groups:
            for name, r in report.items():
                if g in r[key]:
                    lines.append(_row(f"{g} ({name})", r[key][g]))
    lines += device_markdown(report)
    for name, r in report.items():
        if r["failures"]:
            lines += ["", f"## First failures of {name}", ""]
            lines += [f"- scenario {f['scenario']} ({f['kind']}, pivot {f['pivot']}): {'; '.join(f['reasons'])}"
                      for f in r["failures"]]
    lines += ["", "Units: angles in degrees (hip flexion +, knee flexion -), clearance and path length in cm, "
              "times in ms; accuracy counts trajectories whose foot never touches the obstacle (thesis eq 3.1); "
              "a safe swing (issue 11) also keeps env.min_clearance over the whole motion (exact between "
              "samples, less the curve's deviation bound), reaches the goal, keeps the heel from moving "
              "backward by more than env.backward_tolerance, and respects the joint limits and the leg length. "
              "`rl` is the RL swing alone, `rl+cfftg` the generator's default (CFFTG's plan when the RL swing "
              "is not safe)."]
    return "\n".join(lines) + "\n"


DEVICE_HEAD = ("| {what} | lift median cm | lift p95 cm | swing s mean | median | p95 | max | "
               "joint jerk median rad²/s⁵ | p95 | peak hip vel deg/s | peak knee vel deg/s | "
               "within limits % | uniform-time peak deg/s (median) |\n"
               "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")


def _device_row(name: str, r: dict) -> str:
    d = r["device"]
    return (f"| {name} | {100 * r['peak_above_obstacle_m_median']:.2f} | {100 * r['peak_above_obstacle_m_p95']:.2f} | "
            f"{d['swing_s_mean']:.3f} | {d['swing_s_median']:.3f} | {d['swing_s_p95']:.3f} | {d['swing_s_max']:.3f} | "
            f"{d['joint_jerk_median']:.3g} | {d['joint_jerk_p95']:.3g} | "
            f"{d['peak_hip_vel_deg_s_mean']:.0f} | {d['peak_knee_vel_deg_s_mean']:.0f} | "
            f"{100 * d['device_within_limits']:.1f} | {d['uniform_peak_joint_vel_deg_s_median']:.0f} |")


def device_markdown(report: dict) -> list[str]:
    """What a wearer feels, per generator, overall, by obstacle kind (or family) and by pivot: the lift
    (heel peak above the obstacle's highest point), the device timing (jaxexo.inference.swing_timing)
    and the smoothness of the timed joint trajectories."""
    lines = ["", "## Lift, device timing and smoothness (shortest rest-to-rest swing within the [device] "
             "joint limits)", "", DEVICE_HEAD.format(what="generator")]
    lines += [_device_row(name, r) for name, r in report.items() if "device" in r]
    for key in ("by_kind", "by_pivot"):
        for g in list(next(iter(report.values()))[key]):
            for name, r in report.items():
                if "device" in r[key].get(g, {}):
                    lines.append(_device_row(f"{g} ({name})", r[key][g]))
    lines += ["", "Lift: the heel's peak height above the obstacle's highest point. Joint jerk: integrated "
              "squared third derivative of the four timed joint angles. Peak velocities are those of the "
              "timed swing (both legs); the last column is the same path at its uniform time stamps (1 s), "
              "which no joint drive follows."]
    return lines


def plot_overlays(path: Path, trajs: dict, scenarios: list[dict], per_kind: int = 25) -> None:
    """Heel paths over the obstacle, one panel per kind, each generator in its colour (Fig. 3.29)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kinds = list(dict.fromkeys(s["kind"] for s in scenarios))
    fig, axes = plt.subplots(1, len(kinds), figsize=(4.2 * len(kinds), 3.6), squeeze=False)
    colours = dict(zip(trajs, ("tab:blue", "tab:orange", "tab:green", "tab:red")))
    for ax, k in zip(axes[0], kinds):
        idx = [i for i, s in enumerate(scenarios) if s["kind"] == k][:per_kind]
        for i in idx:
            o = scenarios[i]["obstacle"].outline
            ax.fill(o[:, 0] * 100, o[:, 1] * 100, color="0.85", zorder=0)
        for name, tr in trajs.items():
            for j, i in enumerate(idx):
                h = tr[i].heel * 100
                ax.plot(h[:, 0], h[:, 1], color=colours[name], lw=0.8, alpha=0.6,
                        label=name if j == 0 else None)
        ax.set_title(k)
        ax.set_xlabel("y (cm)")
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("heel z (cm)")
    axes[0, 0].legend(loc="upper left", fontsize=8)
    fig.suptitle("Heel paths over each obstacle (thesis Fig. 3.29); obstacles grey")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_joint_profiles(path: Path, trajs: dict, scenarios: list[dict], per_kind: int = 10) -> None:
    """Swing hip and knee angles over the swing, per generator and kind (thesis Fig. 3.11-3.28)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kinds = list(dict.fromkeys(s["kind"] for s in scenarios))
    names = list(trajs)
    fig, axes = plt.subplots(2 * len(names), len(kinds), figsize=(3.6 * len(kinds), 2.6 * 2 * len(names)),
                             squeeze=False, sharex=True)
    for c, k in enumerate(kinds):
        idx = [i for i, s in enumerate(scenarios) if s["kind"] == k][:per_kind]
        for r, name in enumerate(names):
            for j, (col, label) in enumerate(((0, "hip swing"), (1, "knee swing"))):
                ax = axes[2 * r + j, c]
                for i in idx:
                    t = trajs[name][i]
                    ax.plot(t.time / t.time[-1], np.degrees(t.joint_angles[:, col]), lw=0.8, alpha=0.7)
                ax.set_title(f"{name}: {label}, {k}", fontsize=9)
                ax.grid(alpha=0.3)
                if c == 0:
                    ax.set_ylabel("angle (deg)")
    for ax in axes[-1]:
        ax.set_xlabel("swing phase (t / duration)")
    fig.suptitle("Swing-leg joint angles (thesis Fig. 3.11-3.28): hip flexion +, knee flexion -")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


REPORT_FILES = ("report.json", "report.md", "trajectories.png", "joint_angles.png")


def check_report_folder(out: str | Path, policy: str | Path | None = None, force: bool = False) -> None:
    """Before any work: ``out`` must be a folder (or absent, in an existing folder or not), an earlier
    report there is replaced only with ``force``, the policy is never one of the report's files, and
    no report file is a symbolic link (it would be written through). ValueError naming --out."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out: {out} is a file, not a folder (the report folder)")
    q = blocking_file(out.parent)
    if q is not None:
        raise ValueError(f"--out: {q} is a file, not a folder (for {out})")
    for name in REPORT_FILES:
        f = out / name
        if policy is not None and (os.path.realpath(f) == os.path.realpath(policy)
                                   or (f.exists() and os.path.samefile(f, policy))):
            raise ValueError(f"--out: the report would replace its input {policy} ({name}); pick another --out")
        if f.is_symlink():
            raise ValueError(f"--out: {f} is a symbolic link; jaxexo writes no file through a link it did not make")
    earlier = [name for name in REPORT_FILES if (out / name).exists()]
    if earlier and not force:
        raise ValueError(f"--out: {out} already holds a report ({', '.join(earlier)}); pass --force to replace "
                         "it, or pick another folder")


def write_report(out: str | Path, report: dict, trajs: dict, scenarios: list[dict], title: str,
                 context: list[str], figures: bool = True) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / "report.json", json.dumps(report, indent=1, allow_nan=False) + "\n")
    atomic_write(out / "report.md", markdown(report, title, context))
    if figures:
        plot_overlays(out / "trajectories.png", trajs, scenarios)
        plot_joint_profiles(out / "joint_angles.png", trajs, scenarios)
    return report


def run_eval(policy: str | Path, out: str | Path, against: str | None = "cfftg", scenarios: str = "test",
             n: int = 1000, seed: int = 12345, figures: bool = True, batch_size: int = BATCH,
             force: bool = False) -> dict:
    """``jaxexo eval``: the policy (and CFFTG) on the chosen scenarios; writes the report.
    ``batch_size``: scenarios per timed ``generate_batch`` call (the figure is scaled to 1000);
    ``force``: replace an earlier report in ``out`` (else refused, as is a report over its policy)."""
    check_report_folder(out, policy, force)
    from jaxexo.baselines import CFFTG
    from jaxexo.evaluation.machine import machine_info
    from jaxexo.inference import TrajectoryGenerator

    rl = TrajectoryGenerator.load(policy)
    gens = {"rl": WithFallback(rl, None)}
    if against == "cfftg":
        gens["rl+cfftg"] = WithFallback(rl, "cfftg")
        gens["cfftg"] = CFFTG(rl.config)
    elif against is not None:
        raise ValueError(f"against must be 'cfftg' or None, got {against!r}")
    sc = make_scenarios(rl.config, scenarios, n, seed)
    report, trajs = evaluate_generators(gens, sc, batch_size)
    info = machine_info()
    context = [f"Policy `{policy}`; scenarios `{scenarios}` ({len(sc)}, seed {seed}); both generators in one "
               f"process, alternating; {info['cpu']}, {info['cores']} cores.",
               "Thesis reference (Tables 3.9-3.11): final model accuracy 94.7 %, 2.31 ms per trajectory, "
               "1.764 s per 1000; CFFTG about 2 ms per trajectory."]
    for entry in report.values():
        entry["scenarios"] = scenarios
        entry["policy"] = str(policy)
    if scenarios == "unseen":
        from jaxexo.evaluation.unseen import family_table, markdown_lines
        from jaxexo.physics.scenarios import UNSEEN_SEED

        table = family_table(trajs, sc)
        for name, entry in report.items():
            entry["by_family"] = {fam: gens[name] for fam, gens in table.items()}
        context[0] = context[0].replace(f"seed {seed}", f"fixed seed {UNSEEN_SEED}")
        context += ["", *markdown_lines(table)]
    return write_report(out, report, trajs, sc, "jaxexo eval: RL generator" + (" vs CFFTG" if against else ""),
                        context, figures)


