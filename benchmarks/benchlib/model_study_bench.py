"""The model study's measurements: every agent of a model-study sweep exported with ``--export-all``,
RL alone beside CFFTG. Run by benchmarks/bench_model_study.py; method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import csv
import json
import os
import time
from pathlib import Path

import numpy as np

from jaxexo.baselines import CFFTG
from jaxexo.evaluation.compare import run_generators
from jaxexo.evaluation.machine import machine_info, write_result
from jaxexo.inference import TrajectoryGenerator
from jaxexo.storage.atomic import atomic_write, write_figure
from jaxexo.summary import Summary, table

from benchlib.swing_quality_bench import run_set, scene_sets

# The wearer's targets against CFFTG on the scenes both swing safely (lift and timed median <= CFFTG's,
# timed p95 <= 1.1x), the longest RL swing on all scenes, RL alone's safe share on every set.
P95_FACTOR, LONGEST_S, SAFE_MIN = 1.1, 2.5, 0.999


def _both_safe(per: dict) -> dict:
    """Lift (cm) and timed swing (s) median / p95 of each generator on the scenes both swing safely."""
    both = per["rl"][0] & per["cfftg"][0]
    out = {"n_both_safe": int(both.sum())}
    for g, (_, lift, dur) in per.items():
        span = Summary.of(dur[both])
        out[g] = {
            "lift_cm": 100 * Summary.of(lift[both]).median,
            "dur_median_s": span.median,
            "dur_p95_s": span.p95,
        }
    return out


def screen_agent(gen: TrajectoryGenerator, time_n: int) -> dict:
    """The screen: one swing timed (RL alone and CFFTG alternating) on ``time_n`` held-out and unseen
    scenes each, and the RL swings' safe share and goal on those same scenes."""
    cf = CFFTG(gen.config)
    scenes = scene_sets(gen.config, time_n)
    timing = {}
    for name in ("held-out families", "unseen shapes"):
        runs = run_generators(
            {"rl": gen.with_defaults(fallback=None), "cfftg": cf}, scenes[name][:time_n], warmup=10
        )
        wall = {g: Summary.of(runs[g].wall_s) for g in ("rl", "cfftg")}
        cpu = {g: Summary.of(runs[g].cpu_s) for g in ("rl", "cfftg")}
        trajs = runs["rl"].trajectories
        timing[name] = {
            "rl_ms": wall["rl"].median * 1e3,
            "cfftg_ms": wall["cfftg"].median * 1e3,
            "ratio": wall["rl"].over(wall["cfftg"]).median,
            "cpu_ratio": cpu["rl"].over(cpu["cfftg"]).median,
            "raw_points": float(np.mean([len(t.raw) for t in trajs])),
            "rl_safe": float(np.mean([t.ok for t in trajs])),
            "rl_goal": float(np.mean([t.checks.reached_goal for t in trajs])),
            "cfftg_safe": float(np.mean([t.ok for t in runs["cfftg"].trajectories])),
        }
    return {"timing": timing, "smoothing": gen.smoothing}


def measure_agent(gen: TrajectoryGenerator, n: int) -> dict:
    cfg = gen.config
    cf = CFFTG(cfg)
    gens = {"rl": gen, "cfftg": cf}
    sets, pooled, longest = {}, {"rl": [[], [], []], "cfftg": [[], [], []]}, 0.0
    scenes = scene_sets(cfg, n)
    for name, sc in scenes.items():
        arrays = {}
        r = run_set(gens, sc, cfg, None, 0.0, None, arrays)
        sets[name] = {
            "rl_safe": r["rl"].safe,
            "cfftg_safe": r["cfftg"].safe,
            "rl_goal": r["rl"].reached_goal,
            "rl_longest_s": r["rl"].duration_s_max,
            "rl_corrected": r["rl"].corrected,
            **_both_safe(arrays),
        }
        longest = max(longest, r["rl"].duration_s_max)
        for g, (ok, lift, dur) in arrays.items():
            for k, v in enumerate((ok, lift, dur)):
                pooled[g][k].append(v)
    per = {g: tuple(np.concatenate(v) for v in vals) for g, vals in pooled.items()}
    return {"sets": sets, "pooled": _both_safe(per), "rl_longest_s": longest}


def verdicts(m: dict, success: float) -> dict:
    """Which of the study's targets an agent meets (pooled over the three sets)."""
    p = m["pooled"]
    return {
        "validation": success >= 0.99,
        "safe": all(s["rl_safe"] >= SAFE_MIN and s["rl_goal"] == 1.0 for s in m["sets"].values()),
        "lift": p["rl"]["lift_cm"] <= p["cfftg"]["lift_cm"],
        "timed_median": p["rl"]["dur_median_s"] <= p["cfftg"]["dur_median_s"],
        "timed_p95": p["rl"]["dur_p95_s"] <= P95_FACTOR * p["cfftg"]["dur_p95_s"],
        "longest": m["rl_longest_s"] <= LONGEST_S,
    }


def figure(rows: list[dict], path: Path, default_label: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(11, 4.6))
    for r in (r for r in rows if r["screened"]):
        x = r["timing"]["held-out families"]["cpu_ratio"]
        ok = all(r["meets"].values())
        for ax, y in zip(
            axs,
            (
                r["pooled"]["rl"]["dur_p95_s"] / r["pooled"]["cfftg"]["dur_p95_s"],
                r["pooled"]["rl"]["lift_cm"] - r["pooled"]["cfftg"]["lift_cm"],
            ),
        ):
            ax.scatter(
                x,
                y,
                s=18 + 30 * r["step_size"] / 0.03,
                marker="o" if r["layer_norm"] else "s",
                color={32: "tab:blue", 64: "tab:orange", 128: "tab:green"}.get(r["hidden"][0], "k"),
                edgecolors="k" if ok else "none",
                alpha=0.8,
            )
            if default_label in r["label"]:
                ax.scatter(x, y, s=220, facecolors="none", edgecolors="red", linewidths=1.5)
    axs[0].axhline(P95_FACTOR, color="grey", ls="--", lw=1)
    axs[0].set_yscale("log")
    axs[1].axhline(0.0, color="grey", ls="--", lw=1)
    axs[0].set_ylabel("timed swing p95, RL / CFFTG (both safe; log scale)")
    axs[1].set_ylabel("heel lift median, RL - CFFTG (cm, both safe)")
    for ax in axs:
        ax.set_xlabel("one swing, RL / CFFTG CPU time (medians, held-out families)")
        ax.grid(alpha=0.3)
    from matplotlib.lines import Line2D

    handles = [
        Line2D([], [], marker="o", ls="", color=c, label=f"{h}-{h}")
        for h, c in ((32, "tab:blue"), (64, "tab:orange"), (128, "tab:green"))
    ]
    handles += [
        Line2D([], [], marker="o", ls="", color="grey", label="LayerNorm"),
        Line2D([], [], marker="s", ls="", color="grey", label="no LayerNorm"),
        Line2D(
            [], [], marker="o", ls="", mfc="none", mec="red", ms=12, label="today's default config"
        ),
        Line2D([], [], marker="o", ls="", mfc="w", mec="k", label="black edge: meets every target"),
    ]
    axs[1].legend(handles=handles, fontsize=7, loc="upper right")
    fig.suptitle("Model study: one point per agent (marker size: step size 3 / 4.5 / 6 cm)")
    fig.tight_layout()
    write_figure(path, fig, dpi=90)
    plt.close(fig)


def config_summary(rows: list[dict]) -> list[dict]:
    """Per configuration: its seeds, how many pass the screen and meet every target, and the medians
    over seeds of the one-swing time and ratio (held-out families)."""
    out = {}
    for r in rows:
        e = out.setdefault(
            r["config_id"],
            {
                "config_id": r["config_id"],
                "label": r["label"],
                "hidden": r["hidden"],
                "layer_norm": r["layer_norm"],
                "step_size": r["step_size"],
                "seeds": 0,
                "screened": 0,
                "meets_all": 0,
                "ms": [],
                "ratio": [],
                "success": [],
            },
        )
        e["seeds"] += 1
        e["screened"] += bool(r["screened"])
        e["meets_all"] += bool(r.get("meets")) and all(r["meets"].values())
        e["ms"].append(r["timing"]["held-out families"]["rl_ms"])
        e["ratio"].append(r["timing"]["held-out families"]["cpu_ratio"])
        e["success"].append(r["success"])
    for e in out.values():
        e["ms"], e["ratio"] = Summary.of(e["ms"]).median, Summary.of(e["ratio"]).median
        e["success_min"] = float(min(e.pop("success")))
    return sorted(out.values(), key=lambda e: e["ratio"])


def markdown(rows: list[dict], meta: dict) -> str:
    lines = [
        "# Model study: network x LayerNorm x step size, 3 seeds, measured agent by agent",
        "",
        f"Sweep `{meta['sweep']}`. Screen: one swing timed on {meta['time_n']} held-out-family and "
        f"{meta['time_n']} unseen-shape scenes, RL alone (`fallback=None`) and CFFTG alternating in one process, "
        "and the RL swings' verdict on those scenes; an agent passes with validation success >= 0.99 and every "
        f"screened RL swing safe. Agents that pass are measured on {meta['n']} scenes per set (held-out "
        "families, thesis five shifted, unseen shapes) beside CFFTG: lift and timed swing (default [device] "
        "limits) pooled over the three sets on the scenes both swing safely. Load average at the start: "
        f"{meta['load']}.",
        "",
        "Times: the one-swing ratio is of CPU time (`time.process_time`, RL / CFFTG medians over the same "
        "scenes): on a loaded machine a longer call is preempted more often, which the wall clock charges to "
        "it; the wall-clock medians are listed too.",
        "",
        "## Per configuration (median over seeds)",
        "",
        *table(
            ("config", "seeds passing the screen", "seeds meeting every target")
            + ("min validation success", "one swing ms, wall", "ratio, CPU"),
            [
                (
                    e["label"],
                    f"{e['screened']} of {e['seeds']}",
                    f"{e['meets_all']} of {e['seeds']}",
                )
                + (f"{e['success_min']:.3f}", f"{e['ms']:.2f}", f"{e['ratio']:.2f}")
                for e in config_summary(rows)
            ],
        ),
        "",
        "## Per agent",
        "",
    ]
    agents = []  # each agent's cells as text ("a | b")
    for r in rows:
        t = r["timing"]
        head = (
            f"{r['label']} | {r['seed']} | {r['success']:.3f} | "
            f"{100 * t['held-out families']['rl_safe']:.1f} / {100 * t['unseen shapes']['rl_safe']:.1f} | "
        )
        tail = (
            f"{t['held-out families']['rl_ms']:.2f} / {t['held-out families']['cfftg_ms']:.2f} | "
            f"{t['held-out families']['cpu_ratio']:.2f} / {t['unseen shapes']['cpu_ratio']:.2f} | "
            f"{t['held-out families']['raw_points']:.1f} | "
        )
        if not r["screened"]:
            agents.append(head + "| | | | | | " + tail + "screen failed")
            continue
        s, p = r["sets"], r["pooled"]
        safe = " / ".join(f"{100 * v['rl_safe']:.1f}" for v in s.values())
        csafe = " / ".join(f"{100 * v['cfftg_safe']:.1f}" for v in s.values())
        missed = [k for k, v in r["meets"].items() if not v]
        agents.append(
            head + f"{safe} | {csafe} | {p['rl']['lift_cm']:.2f} / {p['cfftg']['lift_cm']:.2f} | "
            f"{p['rl']['dur_median_s']:.3f} / {p['cfftg']['dur_median_s']:.3f} | {p['rl']['dur_p95_s']:.3f} / "
            f"{p['cfftg']['dur_p95_s']:.3f} | {r['rl_longest_s']:.2f} | "
            + tail
            + f"{'all' if not missed else 'not ' + ', '.join(missed)}"
        )
    return "\n".join(lines + table(AGENT_HEADER, [(a,) for a in agents], "lrrllllllrllrl"))


AGENT_HEADER = (
    *("config", "seed", "val. success", "screen: RL safe % fam / shapes"),
    *("RL safe % (fam / five / shapes)", "CFFTG safe %", "lift cm RL / CFFTG"),
    *("timed median s RL / CFFTG", "p95 s RL / CFFTG", "longest RL s"),
    *("one swing ms RL / CFFTG (fam, wall)", "CPU ratio fam / shapes", "raw pts", "meets"),
)


DEFAULT_LABEL = "today's default"  # the label of the default's configuration, marked in the figure


def rerender(json_path) -> str:
    """The tables and figure of an earlier run's JSON again (no measuring), written over its .json,
    .md and .png."""
    res = json.loads(Path(json_path).read_text())
    md = markdown(res["rows"], res)
    res["configs"] = config_summary(res["rows"])
    atomic_write(json_path, json.dumps(res, indent=2) + "\n")
    atomic_write(
        Path(json_path).with_suffix(".md"),
        md + f"\n\nMachine: {res['machine']['cpu']}, "
        f"{res['machine']['cores']} cores; {res['date']}.\n",
    )
    figure(res["rows"], Path(json_path).with_suffix(".png"), DEFAULT_LABEL)
    print(md)
    return md


def agent_row(sweep_dir: Path, entry: dict, wall_s: float, n: int, time_n: int) -> dict:
    """One exported agent (an agents/index.json entry): screened, and measured in full only where the
    screen passes (validation and RL alone safe on the screen's scenes)."""
    gen = TrajectoryGenerator.load(sweep_dir / entry["dir"] / "policy.npz")
    gen_cfg = gen.config
    row = {
        "config_id": entry["config_id"],
        "seed": entry["seed"],
        "label": entry["label"],
        "success": entry["success"],
        "held_out_success": entry["held_out_success"],
        "hidden": list(gen_cfg.train.hidden),
        "layer_norm": bool(gen_cfg.train.layer_norm),
        "step_size": float(gen_cfg.env.step_size),
        "sweep_wall_s": wall_s,
        **screen_agent(gen, time_n),
    }
    row["screened"] = entry["success"] >= 0.99 and all(
        t["rl_safe"] == 1.0 and t["rl_goal"] == 1.0 for t in row["timing"].values()
    )
    if row["screened"]:
        row.update(measure_agent(gen, n))
        row["meets"] = verdicts(row, entry["success"])
    return row


def run_model_study(
    sweep_dir, out_dir, n: int = 120, time_n: int = 80, configs=None, tag: str = ""
) -> dict:
    """Every exported agent of the sweep in ``sweep_dir`` (only the config ids in ``configs`` when
    given), printed and written as model_study[_tag]_<date>_<machine>.{json,md,png}."""
    d = Path(sweep_dir)
    index = json.loads((d / "agents" / "index.json").read_text())
    with open(d / "results.csv") as f:
        results = {(int(r["config_id"]), int(r["seed"])): r for r in csv.DictReader(f)}
    meta = {
        "sweep": str(d),
        "n": n,
        "time_n": time_n,
        "load": [round(x, 2) for x in os.getloadavg()],
    }
    rows = []
    for e in index:
        if not e["exported"] or (configs is not None and e["config_id"] not in configs):
            continue
        t0 = time.perf_counter()
        row = agent_row(d, e, float(results[(e["config_id"], e["seed"])]["wall_s"]), n, time_n)
        rows.append(row)
        print(
            f"{e['label']} seed {e['seed']}: screened {row['screened']} {json.dumps(row.get('meets'))} "
            f"ratio {row['timing']['held-out families']['ratio']:.2f} ({time.perf_counter() - t0:.0f} s)",
            flush=True,
        )
    md = markdown(rows, meta)
    print(md)
    res = {**meta, "rows": rows, "configs": config_summary(rows), "machine": machine_info()}
    paths = write_result("model_study" + (f"_{tag}" if tag else ""), res, md, out_dir)
    figure(rows, paths[1].with_suffix(".png"), DEFAULT_LABEL)
    print(*paths, paths[1].with_suffix(".png"))
    return res
