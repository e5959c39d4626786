"""Animation of a timed swing (matplotlib and Pillow, imported here only): both legs in real time
at the computed timing, the heel's path traced, the swing knee's velocity against its limit.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from jaxexo.storage.atomic import atomic_write

CM = 100.0


def animate_swing(
    swing, path: str | Path, fps: float = 25.0, hold_s: float = 0.4, dpi: int = 64
) -> Path:
    """Write a GIF of ``swing`` (a TimedSwing) to ``path``: one frame every 1/fps s of swing time
    (the GIF plays in real time), the last pose held ``hold_s``. Returns the path."""
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps: must be > 0, got {fps!r}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sc = swing.scene
    idx = _frames(swing.time, fps, hold_s)
    fig, (ax, axv) = plt.subplots(1, 2, figsize=(9, 3.6), gridspec_kw={"width_ratios": [1.7, 1]})
    o = sc.obstacle.outline * CM
    ax.fill(o[:, 0], o[:, 1], color="0.6")
    ax.axhline(0.0, color="k", lw=0.8)
    heel = swing.heel * CM
    ax.plot(heel[:, 0], heel[:, 1], color="tab:red", lw=0.6, alpha=0.35)
    (trace,) = ax.plot([], [], color="tab:red", lw=1.4)
    (swing_leg,) = ax.plot([], [], "-o", color="tab:blue", ms=3, lw=2.5)
    (stance_leg,) = ax.plot([], [], "-o", color="0.35", ms=3, lw=2.5)
    label = ax.text(0.02, 0.95, "", transform=ax.transAxes, fontsize=8, va="top")
    ys = np.concatenate([swing.hip[:, 0], swing.toe[:, 0], [sc.pivot_y + 0.2]]) * CM
    ax.set_xlim(ys.min() - 10, ys.max() + 10)
    ax.set_ylim(-3, max(swing.hip[:, 1].max() * CM + 5, 30))
    ax.set_aspect("equal")
    ax.set_xlabel("y, forward (cm)")
    ax.set_ylabel("z, up (cm)")
    ax.set_title(
        f"{swing.method}: {sc.obstacle.kind}, pivot {sc.pivot}, {swing.duration:.2f} s swing",
        fontsize=9,
    )
    vel = np.degrees(swing.joint_velocity)
    lim = np.degrees(swing.limits.velocity)
    for col, name, c in ((0, "hip", "tab:green"), (1, "knee", "tab:blue")):
        axv.plot(swing.time, vel[:, col], color=c, label=f"swing {name}")
        axv.axhline(lim[col], color=c, ls=":", lw=0.8)
        axv.axhline(-lim[col], color=c, ls=":", lw=0.8)
    cursor = axv.axvline(0.0, color="k", lw=0.8)
    axv.set_xlabel("time (s)")
    axv.set_ylabel("joint velocity (deg/s); dotted: limits")
    axv.legend(fontsize=7, loc="lower left")
    axv.grid(alpha=0.3)
    fig.tight_layout()

    def draw(k):
        j = idx[k]
        hip, ks, kt = swing.hip[j] * CM, swing.knee_swing[j] * CM, swing.knee_stance[j] * CM
        h, toe = heel[j], swing.toe[j] * CM
        swing_leg.set_data([hip[0], ks[0], h[0], toe[0]], [hip[1], ks[1], h[1], toe[1]])
        p = sc.pivot_y * CM
        stance_leg.set_data(
            [hip[0], kt[0], p, p + swing.toe[0, 0] * CM - heel[0, 0]], [hip[1], kt[1], 0.0, 0.0]
        )
        trace.set_data(heel[: j + 1, 0], heel[: j + 1, 1])
        cursor.set_xdata([swing.time[j], swing.time[j]])
        label.set_text(f"t = {swing.time[j]:.2f} s")
        return swing_leg, stance_leg, trace, cursor, label

    return _save(fig, draw, len(idx), path, fps, dpi)


def animate_course(
    course, path: str | Path, fps: float = 20.0, hold_s: float = 0.5, dpi: int = 60
) -> Path:
    """Write a GIF of a whole walk (jaxexo.course.Course) to ``path`` in real time: both
    legs over the terrain at the walk's timing, the left leg blue, the right orange, the heels'
    paths traced behind. Returns the path."""
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps: must be > 0, got {fps!r}")
    if not len(course.samples):
        raise ValueError("course: no timed samples to animate (its first swing failed)")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = course.samples * CM
    t = course.samples[:, 0]
    idx = _frames(t, fps, hold_s)
    ter = course.terrain
    length = float(ter.y[-1] - ter.y[0])
    fig, ax = plt.subplots(figsize=(min(2.0 + 1.6 * length, 16.0), 3.2))
    ax.fill_between(ter.y * CM, 0.0, ter.z * CM, color="0.6", lw=0)
    ax.axhline(0.0, color="k", lw=0.8)
    # Each terrain update appears at its time (dashed): the walk goes on over it from then.
    news = [
        (u.time, ax.plot(u.terrain.y * CM, u.terrain.z * CM, color="tab:red", ls="--", lw=1)[0])
        for u in course.updates
    ]
    legs, traces = [], []
    for base, knee, c in ((3, 13, "tab:blue"), (7, 15, "tab:orange")):
        legs.append((base, knee, ax.plot([], [], "-o", color=c, ms=2, lw=2)[0]))
        traces.append((base, ax.plot([], [], color=c, lw=0.8, alpha=0.5)[0]))
    label = ax.text(0.01, 0.93, "", transform=ax.transAxes, fontsize=8, va="top")
    ax.set_xlim(ter.y[0] * CM - 10, ter.y[-1] * CM + 10)
    ax.set_ylim(-3, max(s[:, 12].max() + 5, 30))
    ax.set_aspect("equal")
    ax.set_xlabel("y, along the course (cm)")
    ax.set_title(
        f"{course.method}: {len(course.steps)} swings in {course.duration:.1f} s at the device limits "
        "(real time)",
        fontsize=9,
    )
    fig.tight_layout()

    def draw(k):
        j = idx[k]
        hip = s[j, 11:13]
        out = []
        for base, knee, line in legs:
            line.set_data(
                [hip[0], s[j, knee], s[j, base], s[j, base + 2]],
                [hip[1], s[j, knee + 1], s[j, base + 1], s[j, base + 3]],
            )
            out.append(line)
        for base, line in traces:
            line.set_data(s[: j + 1, base], s[: j + 1, base + 1])
            out.append(line)
        for at, line in news:
            line.set_visible(t[j] >= at)
        label.set_text(f"t = {t[j]:.2f} s, step {int(course.samples[j, 1])}")
        return out + [label]

    return _save(fig, draw, len(idx), path, fps, dpi)


def animate_replan(
    old, new, path: str | Path, fps: float = 25.0, hold_s: float = 0.4, dpi: int = 64
) -> Path:
    """Write a GIF of a swing replanned in flight (jaxexo.swing.replan) to ``path`` in real time:
    the legs follow ``new`` (the replanned TimedSwing; ``old`` before its last switch, the same
    curve there); until the update the old obstacle and the old plan (dashed) are shown, from it the
    new obstacle, a marker where the heel was, and the new plan; beside, the swing joints' angles,
    old dashed and new solid, with a line at the update. Returns the path."""
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps: must be > 0, got {fps!r}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    at = new.switch_times[-1]
    idx = _frames(new.time, fps, hold_s)
    fig, (ax, axq) = plt.subplots(1, 2, figsize=(9, 3.6), gridspec_kw={"width_ratios": [1.7, 1]})
    o_old, o_new = old.scene.obstacle.outline * CM, new.scene.obstacle.outline * CM
    (shape_old,) = ax.fill(o_old[:, 0], o_old[:, 1], color="0.75", label="estimated obstacle")
    (shape_new,) = ax.fill(o_new[:, 0], o_new[:, 1], color="0.45", label="obstacle (updated)")
    ax.plot(o_old[:, 0], o_old[:, 1], color="tab:purple", ls="--", lw=1.0)
    ax.axhline(0.0, color="k", lw=0.8)
    heel, oh = new.heel * CM, old.heel * CM
    ax.plot(oh[:, 0], oh[:, 1], color="0.3", ls="--", lw=0.9, label="old plan")
    after = new.time >= at
    (new_path,) = ax.plot(heel[after, 0], heel[after, 1], color="tab:red", lw=0.7, alpha=0.5)
    hs = new.at(np.array([at])).heel[0] * CM
    (mark,) = ax.plot([hs[0]], [hs[1]], "o", mfc="none", mec="tab:red", ms=8, mew=1.6)
    (trace,) = ax.plot([], [], color="tab:red", lw=1.4)
    (swing_leg,) = ax.plot([], [], "-o", color="tab:blue", ms=3, lw=2.5)
    (stance_leg,) = ax.plot([], [], "-o", color="0.35", ms=3, lw=2.5)
    label = ax.text(0.02, 0.95, "", transform=ax.transAxes, fontsize=8, va="top")
    ys = np.concatenate(
        [new.hip[:, 0], new.heel[:, 0], new.toe[:, 0], old.toe[:, 0], [new.scene.pivot_y + 0.2]]
    )
    ax.set_xlim(ys.min() * CM - 10, ys.max() * CM + 10)
    ax.set_ylim(-3, max(new.hip[:, 1].max() * CM + 5, 30))
    ax.set_aspect("equal")
    ax.set_xlabel("y, forward (cm)")
    ax.set_ylabel("z, up (cm)")
    ax.legend(fontsize=6, loc="center right")
    ax.set_title(
        f"replanned at t = {at:.2f} s: {old.duration:.2f} s -> {new.duration:.2f} s swing "
        f"({'ok' if new.ok else 'FAILED'})",
        fontsize=9,
    )
    cursor = _angle_panel(axq, old, new)
    fig.tight_layout()
    shown = (shape_new, new_path, mark)

    def draw(k):
        j = idx[k]
        t = new.time[j]
        hip, ks, kt = new.hip[j] * CM, new.knee_swing[j] * CM, new.knee_stance[j] * CM
        h, toe = heel[j], new.toe[j] * CM
        swing_leg.set_data([hip[0], ks[0], h[0], toe[0]], [hip[1], ks[1], h[1], toe[1]])
        p = new.scene.pivot_y * CM
        stance_leg.set_data([hip[0], kt[0], p, p + toe[0] - h[0]], [hip[1], kt[1], 0.0, 0.0])
        trace.set_data(heel[: j + 1, 0], heel[: j + 1, 1])
        for artist in shown:
            artist.set_visible(t >= at)
        shape_old.set_alpha(1.0 if t < at else 0.0)
        cursor.set_xdata([t, t])
        label.set_text(f"t = {t:.2f} s" + ("" if t < at else ": replanned"))
        return [swing_leg, stance_leg, trace, cursor, label]

    return _save(fig, draw, len(idx), path, fps, dpi)


def _angle_panel(axq, old, new):
    """The swing joints' angles of ``old`` (dashed) and ``new`` (solid), a line at each switch;
    returns the time cursor."""
    for col, name, c in ((0, "hip", "tab:green"), (1, "knee", "tab:blue")):
        axq.plot(old.time, np.degrees(old.joint_angles[:, col]), color=c, ls="--", lw=0.9)
        axq.plot(new.time, np.degrees(new.joint_angles[:, col]), color=c, label=f"swing {name}")
    for t in new.switch_times:
        axq.axvline(t, color="tab:red", ls=":", lw=0.9)
    axq.set_xlabel("time (s)")
    axq.set_ylabel("joint angle (deg); dashed: old plan")
    axq.legend(fontsize=7, loc="lower left")
    axq.grid(alpha=0.3)
    return axq.axvline(0.0, color="k", lw=0.8)


def _frames(time: np.ndarray, fps: float, hold_s: float) -> np.ndarray:
    """The sample shown in each frame: one frame every 1/fps s of ``time`` (real time), the last
    sample held ``hold_s``."""
    idx = np.searchsorted(time, np.arange(0.0, time[-1] + 1e-9, 1.0 / fps)).clip(0, len(time) - 1)
    return np.concatenate([idx, np.full(int(round(hold_s * fps)), len(time) - 1)])


def _save(fig, draw, frames: int, path, fps: float, dpi: int):
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    anim = FuncAnimation(fig, draw, frames=frames, blit=False)
    # Pillow writes to a file name: a private one, then the one output rule (jaxexo.storage.atomic).
    with tempfile.TemporaryDirectory(prefix="jaxexo-gif-") as tmp:
        gif = Path(tmp) / "animation.gif"
        try:
            anim.save(str(gif), writer=PillowWriter(fps=fps), dpi=dpi)
        except OSError as e:
            # A failed write of the private file (EFBIG past ``ulimit -f``, ENOSPC) is one of the
            # output: name it, as atomic_write names its own (the private file goes with tmp).
            text = f"could not write {path}: {e.strerror or e}"
            raise (OSError(e.errno, text) if e.errno else OSError(text)) from None
        finally:
            plt.close(fig)
        return atomic_write(path, gif.read_bytes())
