"""A finished sweep's report: DIR/summary.md (configurations ranked by mean greedy success over seeds),
DIR/heatmap.png, DIR/curves.png, and the policies of ``--export-best`` and ``--export-all``. The
files: docs/training.md, "Hyperparameter sweeps".
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from jaxexo.config import ConfigError
from jaxexo.config.toml_io import config_to_toml
from jaxexo.storage.atomic import atomic_write, write_figure
from jaxexo.summary import table


def _save(fig, path) -> None:
    """A figure as PNG, written atomically (a link in its place is replaced, never written through)."""
    write_figure(path, fig, dpi=110)


from jaxexo.sweep import results as R  # noqa: E402
from jaxexo.sweep.spec import Sweep, format_value  # noqa: E402


def _nan_key(x: float) -> float:
    return -math.inf if math.isnan(x) else x


def rank(sweep: Sweep, rows: list[dict]) -> list[dict]:
    """One entry per configuration with results, best first."""
    by_cfg: dict = {}
    for r in rows:
        by_cfg.setdefault(int(r["config_id"]), []).append(r)
    entries = []
    for cid, rs in by_cfg.items():
        col = lambda k: np.array([float(r[k]) for r in rs])  # noqa: E731
        suc, reach = col("success"), col("episodes_to_90")
        reached = reach[np.isfinite(reach)]
        entries.append(
            {
                "config_id": cid,
                "label": sweep.members[cid].label,
                "values": sweep.members[cid].values,
                "seeds": len(rs),
                "success_mean": float(suc.mean()),
                "success_std": float(suc.std()),
                "success_min": float(suc.min()),
                "success_max": float(suc.max()),
                "held_out_success": float(col("held_out_success").mean()),
                "accuracy": float(col("accuracy").mean()),
                "train_return": float(col("train_return").mean()),
                "episodes_to_90": float(reached.mean()) if reached.size else math.nan,
                "reached_90": int(reached.size),
                "diverged": int(col("diverged").sum()),
            }
        )
    entries.sort(
        key=lambda e: (
            -_nan_key(e["success_mean"]),
            e["diverged"],
            -_nan_key(e["held_out_success"]),
            -_nan_key(e["train_return"]),
            e["config_id"],
        )
    )
    return entries


def _table(sweep: Sweep, entries: list[dict]) -> list[str]:
    axes = [a.path for a in sweep.axes]
    head = [
        "rank",
        "config",
        *[f"`{a}`" for a in axes],
        "success (mean ± std, min–max)",
        "held-out success",
        "accuracy",
        "train return",
        "episodes to 90 %",
        "diverged",
    ]
    rows = []
    for i, e in enumerate(entries, 1):
        reach = (
            "never"
            if not e["reached_90"]
            else f"{e['episodes_to_90']:,.0f} ({e['reached_90']}/{e['seeds']})"
        )
        rows.append(
            [
                str(i),
                str(e["config_id"]),
                *[format_value(e["values"][a]) for a in axes],
                f"{e['success_mean']:.3f} ± {e['success_std']:.3f} ({e['success_min']:.3f}–{e['success_max']:.3f})",
                f"{e['held_out_success']:.3f}",
                f"{e['accuracy']:.3f}",
                f"{e['train_return']:.2f}",
                reach,
                f"{e['diverged']}/{e['seeds']}",
            ]
        )
    return table(head, rows, align="ll" + "l" * len(axes) + "r" * 6)


def write_report(sweep: Sweep, out: Path, rows: list[dict], heatmap=None) -> dict:
    out = Path(out)
    entries = rank(sweep, rows)
    chunk_wall = {int(r["chunk"]): float(r["wall_s"]) for r in rows}
    steps = sum(float(r["env_steps"]) for r in rows)
    wall = sum(chunk_wall.values())
    axes = tuple(heatmap or sweep.heatmap)
    if len(axes) == 1:
        axes = (axes[0], "seed")
    figures = []
    if entries:
        plot_heatmap(out / "heatmap.png", sweep, entries, axes, rows)
        figures.append(("heatmap.png", f"success over `{axes[0]}` × `{axes[1]}`"))
    if entries:
        plot_curves(out / "curves.png", sweep, out, rows, entries[: sweep.top])
        figures.append(
            (
                "curves.png",
                f"learning curves of the top {min(sweep.top, len(entries))} configurations",
            )
        )
    seeds = ", ".join(map(str, sweep.seeds))
    lines = [
        "# Sweep summary",
        "",
        f"{len(sweep.members)} configurations × {len(sweep.seeds)} seeds ({seeds}) = {sweep.num_agents} agents "
        f"in {len(sweep.groups)} group(s) of equal static settings; {len(rows)} agents finished, "
        f"in {len(chunk_wall)} chunks.",
        f"{steps:,.0f} env steps; chunk wall time {wall:.1f} s in all (compilation included)"
        + (f", {steps / wall / 1e6:.3f} M env-steps/s." if wall > 0 else "."),
        "Axes: "
        + ", ".join(
            f"`{a.path}` ({a.kind}{', ' + str(len(a.values)) + ' values' if a.kind == 'grid' else ''})"
            for a in sweep.axes
        )
        + ".",
        "",
        "Ranked by mean greedy strict success on the agent's raw moves (eval.json's `success_raw`, not "
        "smoothed) on the test layouts (five thesis obstacles × three pivot conditions) over seeds; held-out: triangle and half-circle only. Train return: mean episode return "
        "over the last tenth of training. Episodes to 90 %: episodes finished when the training success rate "
        "first reached 90 % (mean over the seeds that reached it).",
        "",
        *_table(sweep, entries),
        "",
    ]
    bad = [e for e in entries if e["diverged"]]
    if bad:
        lines += [
            "Diverged (NaN or infinite parameters or loss): "
            + "; ".join(
                f"config {e['config_id']} ({e['label']}): {e['diverged']}/{e['seeds']} seeds"
                for e in bad
            ),
            "",
        ]
    lines += [f"![{text}]({name})" for name, text in figures]
    R.atomic_write(out / "summary.md", "\n".join(lines) + "\n")
    return {
        "ranking": entries,
        "agents": len(rows),
        "env_steps": steps,
        "chunk_wall_s": wall,
        "figures": [f for f, _ in figures],
    }


def _axis_levels(values: list):
    """Distinct values of an axis in a sensible order (numeric if numbers, else as they appear)."""
    keys = list(dict.fromkeys(format_value(v) for v in values))
    nums = {format_value(v): v for v in values}
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in nums.values()):
        keys.sort(key=lambda k: nums[k])
    return keys


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_heatmap(
    path: Path, sweep: Sweep, entries: list[dict], axes: tuple[str, str], rows: list[dict]
) -> None:
    """Mean success over two axes; with ``seed`` as the second axis, each seed's own success (the
    report's choice for a one-axis sweep)."""
    plt = _pyplot()
    kinds = {a.path: a.kind for a in sweep.axes}
    kinds["seed"] = "grid"
    for a in axes:
        if a not in kinds:
            raise ConfigError(
                f"heatmap: {a!r} is not an axis of this sweep (axes: {', '.join(kinds)})"
            )
    xa, ya = axes
    if ya == "seed":
        points = [
            (sweep.members[int(r["config_id"])].values[xa], int(r["seed"]), float(r["success"]))
            for r in rows
        ]
    else:
        points = [(e["values"][xa], e["values"][ya], e["success_mean"]) for e in entries]
    fig, ax = plt.subplots(figsize=(7, 5.5))
    if kinds[xa] == "grid" and kinds[ya] == "grid":
        xs, ys = _axis_levels([p[0] for p in points]), _axis_levels([p[1] for p in points])
        acc = np.zeros((len(ys), len(xs)))
        cnt = np.zeros_like(acc)
        for x, y, v in points:
            i, j = ys.index(format_value(y)), xs.index(format_value(x))
            acc[i, j] += v
            cnt[i, j] += 1
        grid = np.where(cnt > 0, acc / np.maximum(cnt, 1), np.nan)
        im = ax.imshow(grid, origin="lower", cmap="viridis", vmin=0.0, vmax=1.0, aspect="auto")
        ax.set_xticks(range(len(xs)), xs, rotation=30)
        ax.set_yticks(range(len(ys)), ys)
        for i in range(len(ys)):
            for j in range(len(xs)):
                if cnt[i, j]:
                    ax.text(
                        j,
                        i,
                        f"{grid[i, j]:.2f}",
                        ha="center",
                        va="center",
                        color="white" if grid[i, j] < 0.6 else "black",
                        fontsize=9,
                    )
    else:
        coords = []
        for k, axis in ((0, xa), (1, ya)):
            vals = [p[k] for p in points]
            if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
                coords.append([float(v) for v in vals])
                lo, hi = min(coords[-1]), max(coords[-1])
                if kinds[axis] == "random" and lo > 0 and hi / lo > 20:
                    (ax.set_xscale if k == 0 else ax.set_yscale)("log")
            else:  # categorical: one position per level, labelled
                levels = _axis_levels(vals)
                coords.append([float(levels.index(format_value(v))) for v in vals])
                (ax.set_xticks if k == 0 else ax.set_yticks)(range(len(levels)), levels)
        im = ax.scatter(
            coords[0], coords[1], c=[p[2] for p in points], cmap="viridis", vmin=0.0, vmax=1.0, s=60
        )
    fig.colorbar(
        im,
        ax=ax,
        label="greedy success" + (" (mean over seeds and other axes)" if ya != "seed" else ""),
    )
    ax.set_xlabel(xa)
    ax.set_ylabel(ya)
    ax.set_title("Sweep: success on the test layouts")
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def plot_curves(path: Path, sweep: Sweep, out: Path, rows: list[dict], entries: list[dict]) -> None:
    plt = _pyplot()
    want = {e["config_id"] for e in entries}
    curves: dict = {}
    names = None
    for chunk_id in sorted({int(r["chunk"]) for r in rows if int(r["config_id"]) in want}):
        data = R.load_chunk(out, chunk_id)
        names = data["metrics"]
        for (cid, _seed), c in zip(data["agents"], data["curves"]):
            if cid in want:
                curves.setdefault(cid, []).append(c)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True)
    if names is not None:
        col = {m: i for i, m in enumerate(names)}
        for rank_i, e in enumerate(entries, 1):
            c = np.stack(curves[e["config_id"]])  # (seeds, bins, metrics): sums per bin
            ep = c[..., col["episodes"]]
            x = np.cumsum(ep, axis=1).mean(0)
            ok = (ep > 0).any(0)
            n = np.maximum((ep > 0).sum(0), 1)
            # Mean over the seeds that finished episodes in the bin.
            rate = (np.where(ep > 0, c[..., col["successes"]] / np.maximum(ep, 1), 0.0).sum(0) / n)[
                ok
            ]
            ret = (np.where(ep > 0, c[..., col["return_sum"]] / np.maximum(ep, 1), 0.0).sum(0) / n)[
                ok
            ]
            label = f"#{rank_i} config {e['config_id']}: {e['label']}"
            a1.plot(x[ok], rate, label=label)
            a2.plot(x[ok], ret, label=label)
    a1.set_ylabel("training success rate")
    a1.set_ylim(-0.02, 1.02)
    a1.set_title("Top configurations: learning curves (mean over seeds)")
    a1.grid(alpha=0.3)
    a1.legend(fontsize=7, loc="lower right")
    a2.set_ylabel("mean episode return")
    a2.set_xlabel("episodes")
    a2.grid(alpha=0.3)
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def _export_agent(sweep: Sweep, chunk: dict, row: dict, dest: Path, trainer=None) -> None:
    """Write one agent's final parameters (from its loaded ``chunk``, ``R.load_chunk``) as dest/policy.npz
    and its resolved config as dest/config.toml; ``trainer``: its configuration's Trainer, if built."""
    from jaxexo.sweep.program import unflatten
    from jaxexo.train.export import export_policy
    from jaxexo.train.trainer import Trainer

    cid, seed = int(row["config_id"]), int(row["seed"])
    params = unflatten(chunk["params"], chunk["agents"].index((cid, seed)))
    cfg = sweep.members[cid].config
    dest.mkdir(parents=True, exist_ok=True)
    export_policy(dest / "policy.npz", cfg, trainer or Trainer(cfg), params)
    atomic_write(dest / "config.toml", config_to_toml(cfg))


def export_best(sweep: Sweep, out: Path, rows: list[dict]) -> dict:
    """Write the best configuration's policy (its best seed's final parameters) and resolved config."""
    entries = rank(sweep, rows)
    if not entries:
        raise ConfigError("--export-best: the sweep has no results yet")
    for e in entries:
        cands = [r for r in rows if int(r["config_id"]) == e["config_id"] and r["diverged"] == "0"]
        if cands:
            break
    else:
        raise ConfigError("--export-best: every agent of the sweep diverged; nothing to export")
    best_row = max(cands, key=lambda r: (float(r["success"]), -int(r["seed"])))
    cid, seed = int(best_row["config_id"]), int(best_row["seed"])
    best = Path(out) / "best"
    _export_agent(sweep, R.load_chunk(out, int(best_row["chunk"])), best_row, best)
    selection = {
        "config_id": cid,
        "seed": seed,
        "label": sweep.members[cid].label,
        "success": float(best_row["success"]),
        "held_out_success": float(best_row["held_out_success"]),
        "mean_success_over_seeds": e["success_mean"],
    }
    atomic_write(best / "selection.json", json.dumps(selection, indent=1) + "\n")
    return selection


AGENTS = "agents"


def agent_dir(out: Path, config_id: int, seed: int) -> Path:
    """Where ``--export-all`` writes one agent: DIR/agents/config_CCC_seed_S/."""
    return Path(out) / AGENTS / f"config_{config_id:03d}_seed_{seed}"


def export_all(sweep: Sweep, out: Path, rows: list[dict]) -> dict:
    """Write every agent's policy and config (``agent_dir``) and DIR/agents/index.json (each agent's
    directory, label, and success, by configuration and seed); diverged agents are listed but not
    exported. Agents are written chunk by chunk, so each chunk file is read once and only one is held."""
    from jaxexo.train.trainer import Trainer

    if not rows:
        raise ConfigError("--export-all: the sweep has no results yet")
    trainers, index = {}, []
    chunk_id, chunk = None, None
    for r in sorted(rows, key=lambda r: (int(r["chunk"]), int(r["config_id"]), int(r["seed"]))):
        cid, seed = int(r["config_id"]), int(r["seed"])
        dest = agent_dir(out, cid, seed)
        diverged = r["diverged"] != "0"
        if not diverged:
            if int(r["chunk"]) != chunk_id:
                chunk_id, chunk = int(r["chunk"]), R.load_chunk(out, int(r["chunk"]))
            if cid not in trainers:
                trainers[cid] = Trainer(sweep.members[cid].config)
            _export_agent(sweep, chunk, r, dest, trainers[cid])
        index.append(
            {
                "config_id": cid,
                "seed": seed,
                "label": sweep.members[cid].label,
                "dir": str(dest.relative_to(out)),
                "exported": not diverged,
                "success": float(r["success"]),
                "held_out_success": float(r["held_out_success"]),
            }
        )
    index.sort(key=lambda e: (e["config_id"], e["seed"]))
    atomic_write(Path(out) / AGENTS / "index.json", json.dumps(index, indent=1) + "\n")
    return {"agents": len(index), "exported": sum(e["exported"] for e in index)}
