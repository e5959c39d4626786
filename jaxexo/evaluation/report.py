"""The files of ``jaxexo eval``: report.json, report.md (tables overall, by obstacle kind and by
pivot condition, device timing) and the figures (heel paths over each obstacle as thesis Fig. 3.29,
joint angles as Figs. 3.11-3.28)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from jaxexo.evaluation.metrics import BACKWARD_REPORT
from jaxexo.evaluation.timing import BATCH
from jaxexo.storage.atomic import atomic_write, write_figure
from jaxexo.storage.rundir import blocking_file


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
              "median peak above obstacle cm | heel backward > " + f"{1000 * BACKWARD_REPORT:g}" + " mm % | "
              "CFFTG fallback % | time mean ms | median ms | p95 ms | "
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
              "a safe swing also keeps env.min_clearance over the whole motion (exact between "
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
    write_figure(path, fig, dpi=110)
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
    write_figure(path, fig, dpi=100)
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
