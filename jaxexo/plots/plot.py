"""Figures of a trajectory (needs matplotlib, imported here only): the exoskeleton's legs over the
obstacle with the foot path and its arrows (thesis Fig. 2.3), beside the hip and knee angle
profiles of both legs (thesis Fig. 3.11-3.30). Lengths in centimetres, angles in degrees."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from jaxexo.storage.atomic import write_figure
from jaxexo.swing.trajectory import Trajectory

CM = 100.0


def plot_trajectory(
    traj: Trajectory, path: str | Path | None = None, n_poses: int = 6, title: str | None = None
):
    """Draw one trajectory; saves to ``path`` when given and returns the figure."""
    import matplotlib

    if path is not None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax_h, ax_k) = plt.subplots(
        1, 3, figsize=(15, 4.8), gridspec_kw={"width_ratios": [1.6, 1, 1]}
    )
    sc = traj.scene
    o = sc.obstacle.outline * CM
    ax.fill(o[:, 0], o[:, 1], color="0.55", alpha=0.8, label=f"obstacle ({sc.obstacle.kind})")
    ax.axhline(0.0, color="k", lw=0.8)
    for j in np.linspace(0, len(traj.heel) - 1, n_poses).round().astype(int):
        a = 0.25 + 0.75 * j / (len(traj.heel) - 1)
        hip, ks, kt = traj.hip[j] * CM, traj.knee_swing[j] * CM, traj.knee_stance[j] * CM
        heel, toe = traj.heel[j] * CM, traj.toe[j] * CM
        ax.plot(
            [hip[0], ks[0], heel[0]],
            [hip[1], ks[1], heel[1]],
            "-o",
            color="tab:blue",
            alpha=a,
            ms=3,
        )
        ax.plot(
            [hip[0], kt[0], sc.pivot_y * CM],
            [hip[1], kt[1], 0.0],
            "-o",
            color="tab:gray",
            alpha=a,
            ms=3,
        )
        ax.plot([heel[0], toe[0]], [heel[1], toe[1]], "-", color="tab:blue", alpha=a, lw=2.5)
    raw = traj.raw * CM
    rl = traj.method == "rl"
    if rl:
        d = np.diff(raw, axis=0)
        ax.quiver(
            raw[:-1, 0],
            raw[:-1, 1],
            d[:, 0],
            d[:, 1],
            angles="xy",
            scale_units="xy",
            scale=1.0,
            color="tab:orange",
            width=0.003,
            label="agent moves",
        )
    else:
        ax.plot(
            raw[:, 0], raw[:, 1], "o", color="tab:orange", ms=4, label=f"{traj.method} plan points"
        )
    ax.plot(
        traj.heel[:, 0] * CM,
        traj.heel[:, 1] * CM,
        color="tab:red",
        lw=1.5,
        label="heel (smoothed)" if rl else "heel",
    )
    ax.plot(traj.toe[:, 0] * CM, traj.toe[:, 1] * CM, color="tab:red", lw=0.8, ls="--", label="toe")
    ax.plot([sc.goal_y * CM], [0.0], "g*", ms=12, label="goal")
    ax.set_aspect("equal")
    ax.set_xlabel("y, forward (cm)")
    ax.set_ylabel("z, up (cm)")
    status = "ok" if traj.ok else "FAILED: " + "; ".join(traj.checks.reasons)
    ax.set_title(
        title or f"{traj.method}: {sc.obstacle.kind}, pivot {sc.pivot} ({status})", fontsize=9
    )
    ax.legend(fontsize=7, loc="upper left")
    ang = np.degrees(traj.joint_angles)
    for axis, col, name in ((ax_h, 0, "hip"), (ax_k, 1, "knee")):
        axis.plot(traj.time, ang[:, col], color="tab:blue", label=f"swing {name}")
        axis.plot(traj.time, ang[:, col + 2], color="tab:gray", label=f"stance {name}")
        axis.set_xlabel("time (s)")
        axis.set_ylabel(f"{name} angle (deg, flexion {'+' if name == 'hip' else '-'})")
        axis.grid(alpha=0.3)
        axis.legend(fontsize=8)
    ax_h.set_title("Hip angles (thesis Fig. 3.11-3.30)", fontsize=9)
    ax_k.set_title("Knee angles", fontsize=9)
    return _save(fig, path, 110)


LEG_COLORS = {"left": "tab:blue", "right": "tab:orange"}


def plot_course(course, path: str | Path | None = None):
    """Draw a walk (jaxexo.course.Course): the terrain, each swing's heel path and the
    footholds, coloured by leg; below, both legs' joint angles over the walk. Saves to ``path``
    when given and returns the figure."""
    import matplotlib

    if path is not None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ter = course.terrain
    length = float(ter.y[-1] - ter.y[0])
    fig, (ax, axq) = plt.subplots(
        2, 1, figsize=(min(4.0 + 2.2 * length, 22.0), 6.4), gridspec_kw={"height_ratios": [1.2, 1]}
    )
    ax.fill_between(ter.y * CM, 0.0, ter.z * CM, color="0.55", lw=0, label="terrain")
    ax.axhline(0.0, color="k", lw=0.8)
    foot = (
        course.steps[0].trajectory.toe[0, 0] - course.steps[0].trajectory.heel[0, 0]
        if course.steps
        else 0.2
    )
    ax.plot([course.footholds.start_y * CM] * 2, [0.0, 0.0], "ks", ms=6, label="start (both feet)")
    for st in course.steps:
        c = LEG_COLORS[st.leg]
        h = st.trajectory.heel * CM
        ax.plot(h[:, 0], h[:, 1], color=c, lw=1.2, ls="-" if st.method == "rl" else "--")
        y = st.landing_y * CM
        ax.plot([y, y + foot * CM], [0.0, 0.0], color=c, lw=4, solid_capstyle="butt")
        ax.annotate(
            str(st.index + 1),
            (y, 0.0),
            xytext=(0, -11),
            textcoords="offset points",
            fontsize=7,
            ha="left",
            color=c,
        )
    for leg, c in LEG_COLORS.items():
        ax.plot([], [], color=c, lw=3, label=f"{leg} foot: heel path, foothold")
    _course_updates(ax, course)
    ax.set_aspect("equal")
    ax.set_ylim(-15, max(float(ter.z.max()) * CM + 25, 30))
    ax.set_xlabel("y, along the course (cm)")
    ax.set_ylabel("z (cm)")
    fb = sum(s.method == "cfftg-fallback" for s in course.steps)
    ax.set_title(
        f"{course.method}: {len(course.steps)} swings, {course.duration:.1f} s at the device limits"
        + (f", {fb} CFFTG fallbacks (dashed)" if fb else "")
        + f" ({'ok' if course.ok else 'FAILED'})",
        fontsize=9,
    )
    ax.legend(fontsize=7, loc="upper right", ncol=3)
    t = course.samples[:, 0]
    ang = np.degrees(course.samples[:, 17:21])
    for col, name, c, ls in (
        (0, "left hip", "tab:blue", "-"),
        (1, "left knee", "tab:blue", ":"),
        (2, "right hip", "tab:orange", "-"),
        (3, "right knee", "tab:orange", ":"),
    ):
        axq.plot(t, ang[:, col], color=c, ls=ls, label=name)
    for st in course.steps:
        axq.axvline(st.start_s, color="0.8", lw=0.6)
    axq.set_xlabel("time (s)")
    axq.set_ylabel("joint angle (deg)")
    axq.legend(fontsize=7, ncol=4)
    axq.grid(alpha=0.3)
    return _save(fig, path, 100)


def _course_updates(ax, course) -> None:
    """A walk's terrain updates on its figure: each new terrain (dashed), and for each swing
    replanned in flight its old plan (dotted) and where it switched."""
    for u in course.updates:
        ax.plot(
            u.terrain.y * CM,
            u.terrain.z * CM,
            color="tab:red",
            ls="--",
            lw=1.0,
            label=f"terrain from t = {u.time:.2f} s",
        )
    for st in course.steps:
        if st.replanned_from is None:
            continue
        h = st.replanned_from.heel * CM
        ax.plot(h[:, 0], h[:, 1], color="0.3", ls=":", lw=1.0)
        hs = st.timed.at(np.asarray(st.timed.switch_times)).heel * CM
        ax.plot(hs[:, 0], hs[:, 1], "o", mfc="none", mec="tab:red", ms=7, mew=1.5)
    if any(st.replanned_from is not None for st in course.steps):
        ax.plot([], [], color="0.3", ls=":", label="old plan (replanned at the circle)")


def _save(fig, path, dpi: int):
    """Lay ``fig`` out and, when ``path`` is given, write it there and close it; returns the figure."""
    fig.tight_layout()
    if path is not None:
        import matplotlib.pyplot as plt

        write_figure(path, fig, dpi=dpi)
        plt.close(fig)
    return fig


def plot_replan(
    old, new, path: str | Path | None = None, n_poses: int = 6, title: str | None = None
):
    """Draw a swing replanned in flight (jaxexo.swing.replan): ``old`` (the TimedSwing it continues)
    dashed over its own obstacle, ``new`` (the replanned TimedSwing) solid over the new one, the
    moment of the update (its last switch) as a marker on the heel path and a vertical line in the
    joint-angle panels. Saves to ``path`` when given and returns the figure."""
    import matplotlib

    if path is not None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax_h, ax_k) = plt.subplots(
        1, 3, figsize=(15, 4.8), gridspec_kw={"width_ratios": [1.6, 1, 1]}
    )
    at = new.switch_times[-1]
    _replan_scene(ax, old, new, at, n_poses)
    ax.set_title(title or _replan_title(old, new, at), fontsize=9)
    t_old, q_old = old.time, np.degrees(old.joint_angles)
    t_new, q_new = new.time, np.degrees(new.joint_angles)
    for axis, col, name in ((ax_h, 0, "hip"), (ax_k, 1, "knee")):
        for off, leg, c in ((0, "swing", "tab:blue"), (2, "stance", "tab:gray")):
            axis.plot(t_old, q_old[:, col + off], color=c, ls="--", lw=1.0, alpha=0.7)
            axis.plot(t_new, q_new[:, col + off], color=c, label=f"{leg} {name}")
        for t in new.switch_times:
            axis.axvline(t, color="tab:red", lw=0.9, ls=":")
        axis.plot([], [], color="0.3", ls="--", label="old plan")
        axis.plot([], [], color="tab:red", ls=":", label="update")
        axis.set_xlabel("time (s)")
        axis.set_ylabel(f"{name} angle (deg, flexion {'+' if name == 'hip' else '-'})")
        axis.grid(alpha=0.3)
        axis.legend(fontsize=7)
    ax_h.set_title("Hip angles: old plan dashed, replanned solid", fontsize=9)
    ax_k.set_title("Knee angles", fontsize=9)
    return _save(fig, path, 110)


def _replan_title(old, new, at: float) -> str:
    """The title: where it switched, both durations and the verdict (its reasons wrapped)."""
    import textwrap

    head = (
        f"replanned at t = {at:.3f} s ({new.method} continuation): {old.duration:.2f} s swing "
        f"-> {new.duration:.2f} s, {'ok' if new.ok else 'FAILED'}"
    )
    why = "; ".join(new.reasons)
    return head if new.ok else head + "\n" + textwrap.shorten(why, 90, placeholder=" ...")


def _replan_scene(ax, old, new, at: float, n_poses: int) -> None:
    """The legs' panel of ``plot_replan``: both obstacles, both heel paths, the switch, poses of
    the replanned swing."""
    for sw, style in ((old, dict(fill=False, ec="tab:purple", ls="--", lw=1.5)), (new, {})):
        o = sw.scene.obstacle.outline * CM
        label = f"{'old' if sw is old else 'new'} obstacle ({sw.scene.obstacle.kind})"
        if sw is old:
            ax.fill(o[:, 0], o[:, 1], label=label, **style)
        else:
            ax.fill(o[:, 0], o[:, 1], color="0.55", alpha=0.6, label=label, zorder=0)
    ax.axhline(0.0, color="k", lw=0.8)
    for j in np.linspace(0, len(new.heel) - 1, n_poses).round().astype(int):
        a = 0.25 + 0.75 * j / (len(new.heel) - 1)
        hip, ks, kt, heel, toe = (
            x[j] * CM for x in (new.hip, new.knee_swing, new.knee_stance, new.heel, new.toe)
        )
        p = new.scene.pivot_y * CM
        ax.plot(
            [hip[0], ks[0], heel[0], toe[0]],
            [hip[1], ks[1], heel[1], toe[1]],
            "-o",
            color="tab:blue",
            alpha=a,
            ms=3,
        )
        ax.plot([hip[0], kt[0], p], [hip[1], kt[1], 0.0], "-o", color="tab:gray", alpha=a, ms=3)
    oh, nh = old.heel * CM, new.heel * CM
    ax.plot(oh[:, 0], oh[:, 1], color="0.3", ls="--", lw=1.2, label="old plan (heel)")
    ax.plot(nh[:, 0], nh[:, 1], color="tab:red", lw=1.5, label="replanned (heel)")
    ax.plot(new.toe[:, 0] * CM, new.toe[:, 1] * CM, color="tab:red", lw=0.8, ls=":", label="toe")
    hs = new.at(np.asarray(new.switch_times)).heel * CM
    ax.plot(
        hs[:, 0],
        hs[:, 1],
        "o",
        mfc="none",
        mec="tab:red",
        ms=9,
        mew=1.8,
        label=f"update at t = {at:.3f} s",
    )
    ax.plot([new.scene.goal_y * CM], [0.0], "g*", ms=12, label="goal")
    ax.set_aspect("equal")
    ax.set_xlabel("y, forward (cm)")
    ax.set_ylabel("z, up (cm)")
    ax.legend(fontsize=7, loc="upper left")
