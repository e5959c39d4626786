"""The files of ``jaxexo eval``: report.json, report.md (the RL-vs-CFFTG summary, then a table per
concern: safety and clearance, the wearer's figures, generation time, joint angles; each over all
scenes, by obstacle kind and by pivot condition) and the figures (heel paths over each obstacle as
thesis Fig. 3.29, joint angles as Figs. 3.11-3.28)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from jaxexo.evaluation.metrics import BACKWARD_REPORT
from jaxexo.evaluation.timing import BATCH
from jaxexo.storage.atomic import atomic_write, write_figure
from jaxexo.storage.rundir import blocking_file
from jaxexo.summary import table


# Each table of report.md answers one question and fits a screen (at most 8 columns); report.json holds
# every figure. A column: (header, cell of a group's entry).
def _pct(key):
    return lambda r: f"{100 * r[key]:.1f}"


def _cm(key, digits=2):
    return lambda r: f"{100 * r[key]:.{digits}f}"


def _val(key, fmt, device=False):
    return lambda r: format((r["device"] if device else r)[key], fmt)


def _batch(r):
    b = r.get("batch_1000_ms")
    size = r.get("batch_size", BATCH)
    return (
        "-"
        if b is None
        else f"{b:.1f}" + ("" if size in (BATCH, 0) else f" (timed on {size}, scaled)")
    )


SUMMARY = (
    ("n", _val("n", "d")),
    ("safe swing %", _pct("success")),
    ("accuracy % (eq 3.1)", _pct("accuracy")),
    ("CFFTG fallback %", _pct("fallback_rate")),
    ("median guaranteed clearance cm", _cm("min_clearance_m_median")),
    ("median lift cm", _cm("peak_above_obstacle_m_median", 1)),
    ("median ms per trajectory", _val("time_ms_median", ".3f")),
)

# (section, columns, groups besides all scenes, note)
SECTIONS = (
    (
        "Safety and clearance",
        (
            ("n", _val("n", "d")),
            ("accuracy %", _pct("accuracy")),
            ("safe swing %", _pct("success")),
            (f"heel backward > {1000 * BACKWARD_REPORT:g} mm %", _pct("heel_backward_rate")),
            ("CFFTG fallback %", _pct("fallback_rate")),
            ("median guaranteed clearance cm", _cm("min_clearance_m_median")),
            ("worst clearance cm", _cm("min_clearance_m_worst")),
        ),
        ("by_kind", "by_pivot", "by_kind_pivot"),
        "Accuracy counts trajectories whose foot never touches the obstacle (thesis eq 3.1); a safe swing also "
        "keeps env.min_clearance over the whole motion (exact between samples, less the curve's deviation "
        "bound), reaches the goal, keeps the heel from moving backward by more than env.backward_tolerance, and "
        "respects the joint limits and the leg length. Clearance: the guaranteed minimum distance to the obstacle.",
    ),
    (
        "Wearer: lift and heel path",
        (
            ("lift median cm", _cm("peak_above_obstacle_m_median")),
            ("lift p95 cm", _cm("peak_above_obstacle_m_p95")),
            ("heel path length cm", _cm("path_length_m_mean", 1)),
            ("heel sq. jerk m²/s⁵", _val("squared_jerk_mean", ".3g")),
        ),
        ("by_kind", "by_pivot"),
        "Lift: the heel's peak height above the obstacle's highest point. Path length and squared jerk: means "
        "over the scenes, of the heel path at its uniform time stamps.",
    ),
    (
        "Wearer: device timing and smoothness",
        (
            ("swing s mean", _val("swing_s_mean", ".3f", True)),
            ("median", _val("swing_s_median", ".3f", True)),
            ("p95", _val("swing_s_p95", ".3f", True)),
            ("max", _val("swing_s_max", ".3f", True)),
            ("joint jerk median rad²/s⁵", _val("joint_jerk_median", ".3g", True)),
            ("p95", _val("joint_jerk_p95", ".3g", True)),
            ("within limits %", lambda r: f"{100 * r['device']['device_within_limits']:.1f}"),
        ),
        ("by_kind", "by_pivot"),
        "The shortest rest-to-rest swing within the [device] joint limits (jaxexo.swing.timing). "
        "Joint jerk: integrated squared third derivative of the four timed joint angles.",
    ),
    (
        "Generation time",
        (
            ("n", _val("n", "d")),
            ("mean ms", _val("time_ms_mean", ".3f")),
            ("median ms", _val("time_ms_median", ".3f")),
            ("p95 ms", _val("time_ms_p95", ".3f")),
            ("batch of 1000 ms", _batch),
        ),
        ("by_kind", "by_pivot"),
        "Per trajectory: one `generate` call (validation, generation, smoothing and every check). Batch of "
        "1000: one `generate_batch` call (overall: the median of its repeats; a group: its own scenarios "
        "in one call), scaled to 1000 scenarios where timed on fewer.",
    ),
    (
        "Joint angles",
        (
            ("hip swing mean deg", _val("hip_swing_mean_deg", ".1f")),
            ("knee swing mean deg", _val("knee_swing_mean_deg", ".1f")),
            ("hip swing max deg", _val("hip_swing_max_deg", ".1f")),
            ("knee swing min deg", _val("knee_swing_min_deg", ".1f")),
            ("peak hip vel deg/s", _val("peak_hip_vel_deg_s_mean", ".0f", True)),
            ("peak knee vel deg/s", _val("peak_knee_vel_deg_s_mean", ".0f", True)),
            (
                "uniform-time peak deg/s (median)",
                _val("uniform_peak_joint_vel_deg_s_median", ".0f", True),
            ),
        ),
        ("by_kind", "by_pivot"),
        "Swing-leg angles (hip flexion +, knee flexion -); max and min: means over the scenes of each swing's "
        "extreme. Peak velocities: those of the timed swing (both legs, mean over the scenes); the last column "
        "is the same path at its uniform time stamps (1 s), which no joint drive follows.",
    ),
)
GROUP_LABEL = {"by_kind": "{g}", "by_pivot": "pivot {g}", "by_kind_pivot": "{g}"}


def _table(first: str, columns, rows: list[tuple[str, dict]]) -> list[str]:
    cells = [(label, *(cell(r) for _, cell in columns)) for label, r in rows]
    return table((first, *(h for h, _ in columns)), cells)


def _section_rows(report: dict, groups) -> list[tuple[str, dict]]:
    """Every generator overall, then each group's (kind, pivot, ...) generators in turn."""
    rows = [(f"all ({name})", r) for name, r in report.items()]
    first = next(iter(report.values()))
    for key in groups:
        for g in first.get(key, {}):
            rows += [
                (GROUP_LABEL[key].format(g=g) + f" ({name})", r[key][g])
                for name, r in report.items()
                if g in r[key]
            ]
    return rows


def summary_lines(report: dict) -> list[str]:
    """The comparison a reader looks for first: how often each generator swings safely, how close it
    passes and how fast it is, and what the CFFTG fallback adds to the RL swing."""
    lines = [
        "## RL vs CFFTG" if "cfftg" in report else "## Summary",
        "",
        *_table("generator", SUMMARY, list(report.items())),
    ]
    rl, both, cf = report.get("rl"), report.get("rl+cfftg"), report.get("cfftg")
    if rl is not None:
        said = [
            f"The RL swing alone is safe on {100 * rl['success']:.1f} % of the {rl['n']} scenes"
        ]
        if both is not None:
            said.append(
                f"the generator's default (`rl+cfftg`) on {100 * both['success']:.1f} %, taking CFFTG's "
                f"plan on {100 * both['fallback_rate']:.1f} %"
            )
        if cf is not None:
            said.append(
                f"CFFTG alone on {100 * cf['success']:.1f} %, at {cf['time_ms_median']:.3f} ms per "
                f"trajectory against the RL swing's {rl['time_ms_median']:.3f} ms (medians)"
            )
        lines += ["", "; ".join(said) + "."]
    return lines


def markdown(report: dict, title: str, context: list[str], sections: list[str] = ()) -> str:
    """report.md: the title and ``context``, the summary, ``sections`` (more Markdown lines), then one
    table per concern, each over all scenes, per obstacle kind and per pivot condition."""
    lines = [f"# {title}", "", *context, "", *summary_lines(report)]
    if sections:
        lines += ["", *sections]
    for head, columns, groups, note in SECTIONS:
        lines += [
            "",
            f"## {head}",
            "",
            note,
            "",
            *_table("scenes (generator)", columns, _section_rows(report, groups)),
        ]
    for name, r in report.items():
        if r["failures"]:
            lines += ["", f"## First failures of {name}", ""]
            lines += [
                f"- scenario {f['scenario']} ({f['kind']}, pivot {f['pivot']}): {'; '.join(f['reasons'])}"
                for f in r["failures"]
            ]
    lines += [
        "",
        "Units: angles in degrees, lengths in cm, times in ms unless labelled. `rl` is the RL swing "
        "alone, `rl+cfftg` the generator's default (CFFTG's plan when the RL swing is not safe).",
    ]
    return "\n".join(lines) + "\n"


def plot_overlays(path: Path, trajs: dict, scenarios: list, per_kind: int = 25) -> None:
    """Heel paths over the obstacle, one panel per kind, each generator in its colour (Fig. 3.29).
    ``rl+cfftg`` is, scene by scene, either the RL swing or CFFTG's plan, so its own lines would hide
    under (or over) identical ones: with ``rl`` beside it, the RL paths it replaced are drawn dotted
    instead, and it gets no lines of its own."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    kinds = list(dict.fromkeys(s.kind for s in scenarios))
    cols = min(3, len(kinds))
    rows = -(-len(kinds) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.0 * cols, 3.4 * rows + 0.8), squeeze=False)
    colours = dict(zip(trajs, ("tab:blue", "tab:orange", "tab:green", "tab:red")))
    merged = "rl" in trajs and "rl+cfftg" in trajs
    drawn = [n for n in trajs if not (merged and n == "rl+cfftg")]
    style = {n: dict(color=colours[n], lw=0.8, alpha=0.6) for n in drawn}
    legend = [(Line2D([], [], **{**style[n], "alpha": 1.0}), n) for n in drawn]
    if merged:
        replaced = dict(color=colours["rl"], lw=0.8, alpha=0.6, ls=":")
        legend[drawn.index("rl")] = (
            Line2D([], [], color=colours["rl"], lw=0.8),
            "rl (kept by rl+cfftg)",
        )
        legend.insert(
            drawn.index("rl") + 1,
            (
                Line2D([], [], **{**replaced, "alpha": 1.0}),
                "rl, not safe (rl+cfftg takes cfftg's plan)",
            ),
        )
    for ax, k in zip(axes.flat, kinds):
        idx = [i for i, s in enumerate(scenarios) if s.kind == k][:per_kind]
        for i in idx:
            o = scenarios[i].obstacle.outline
            ax.fill(o[:, 0] * 100, o[:, 1] * 100, color="0.85", zorder=0)
        for name in drawn:
            for i in idx:
                h = trajs[name][i].heel * 100
                swapped = (
                    merged and name == "rl" and trajs["rl+cfftg"][i].method == "cfftg-fallback"
                )
                ax.plot(h[:, 0], h[:, 1], **(replaced if swapped else style[name]))
        ax.set_title(k)
        ax.set_xlabel("y (cm)")
        ax.set_ylabel("heel z (cm)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(kinds) :]:
        ax.set_visible(False)
    # One legend for the figure, above the panels, with every generator even where a panel lacks its lines.
    fig.legend(
        *zip(*legend),
        loc="upper center",
        ncol=len(legend),
        fontsize=8,
        frameon=False,
        bbox_to_anchor=(0.5, 1.0 - 0.45 / fig.get_figheight()),
    )
    fig.suptitle("Heel paths over each obstacle (thesis Fig. 3.29); obstacles grey")
    fig.tight_layout(rect=(0, 0, 1, 1.0 - 0.75 / fig.get_figheight()))
    write_figure(path, fig, dpi=110)
    plt.close(fig)


def plot_joint_profiles(path: Path, trajs: dict, scenarios: list, per_kind: int = 10) -> None:
    """Swing hip and knee angles over the swing, per generator and kind (thesis Fig. 3.11-3.28)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kinds = list(dict.fromkeys(s.kind for s in scenarios))
    names = list(trajs)
    fig, axes = plt.subplots(
        2 * len(names),
        len(kinds),
        figsize=(3.6 * len(kinds), 2.6 * 2 * len(names)),
        squeeze=False,
        sharex=True,
    )
    for c, k in enumerate(kinds):
        idx = [i for i, s in enumerate(scenarios) if s.kind == k][:per_kind]
        for r, name in enumerate(names):
            for j, (col, label) in enumerate(((0, "hip swing"), (1, "knee swing"))):
                ax = axes[2 * r + j, c]
                for i in idx:
                    t = trajs[name][i]
                    ax.plot(
                        t.time / t.time[-1], np.degrees(t.joint_angles[:, col]), lw=0.8, alpha=0.7
                    )
                ax.set_title(f"{name}: {label}, {k}", fontsize=9)
                ax.grid(alpha=0.3)
                if c == 0:
                    ax.set_ylabel("angle (deg)")
    for ax in axes[-1]:
        ax.set_xlabel("swing phase (t / duration)")
    fig.suptitle("Swing-leg joint angles (thesis Fig. 3.11-3.28): hip flexion +, knee flexion -")
    fig.tight_layout(rect=(0, 0, 1, 1.0 - 0.4 / fig.get_figheight()))  # room for the title
    write_figure(path, fig, dpi=100)
    plt.close(fig)


REPORT_FILES = ("report.json", "report.md", "trajectories.png", "joint_angles.png")


def check_report_folder(
    out: str | Path, policy: str | Path | None = None, force: bool = False
) -> None:
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
        if policy is not None and (
            os.path.realpath(f) == os.path.realpath(policy)
            or (f.exists() and os.path.samefile(f, policy))
        ):
            raise ValueError(
                f"--out: the report would replace its input {policy} ({name}); pick another --out"
            )
        if f.is_symlink():
            raise ValueError(
                f"--out: {f} is a symbolic link; jaxexo writes no file through a link it did not make"
            )
    earlier = [name for name in REPORT_FILES if (out / name).exists()]
    if earlier and not force:
        raise ValueError(
            f"--out: {out} already holds a report ({', '.join(earlier)}); pass --force to replace "
            "it, or pick another folder"
        )


def write_report(
    out: str | Path,
    report: dict,
    trajs: dict,
    scenarios: list,
    title: str,
    context: list[str],
    figures: bool = True,
    sections: list[str] = (),
) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / "report.json", json.dumps(report, indent=1, allow_nan=False) + "\n")
    atomic_write(out / "report.md", markdown(report, title, context, sections))
    if figures:
        plot_overlays(out / "trajectories.png", trajs, scenarios)
        plot_joint_profiles(out / "joint_angles.png", trajs, scenarios)
    return report
