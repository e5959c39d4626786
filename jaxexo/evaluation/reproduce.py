"""``jaxexo reproduce``: the thesis's experiments, rerun and tabulated beside its published values.

Trains the seven thesis configs (jaxexo/config/thesis/{a,b,c,1,2,3,final}.toml, shipped with the package;
configs/thesis/ holds byte-equal copies; thesis 3.2), then for each
model generates the n test scenarios of ``jaxexo.evaluation.compare`` (the five obstacles of Table 3.1 over the
three pivot conditions, the model's own starts) with the NumPy generator, and writes:

- Table 3.2 / 3.9: per model, mean generation time and mean swing knee and hip angles;
- Tables 3.3-3.8: per model and pivot condition (the thesis gives the two it was not trained on);
- Table 3.10: accuracy (eq 3.1) per model, and jaxexo's strict success beside it;
- Table 3.11: generation time per obstacle, final model against CFFTG, timed in one process;
- the same tables for jaxexo's default model when ``--default`` is given (configs/default.toml).

Run directories go under OUT/runs/<name>; an existing policy.npz there is reused, so an interrupted
reproduction continues where it stopped. OUT/reproduce.md and OUT/reproduce.json hold the tables.
"""

from __future__ import annotations

import json
from pathlib import Path

from jaxexo.config import PIVOT_CONDITIONS, load_config, packaged_config

THESIS_MODELS = ("a", "b", "c", "1", "2", "3", "final")
# The pivot condition each single-condition model was trained on (thesis 3.2; configs/thesis/*.toml).
TRAINED_PIVOT = {"a": "obstacle", "b": "agent", "c": "between", "1": "obstacle", "2": "agent", "3": "between"}

# Published values. Table 3.2: (mean generation time ms, mean knee deg, mean hip deg), 1000 episodes.
THESIS_T32 = {"a": (2.46, -51.031, 35.363), "b": (2.03, -52.995, 33.744), "c": (2.12, -49.407, 33.0341),
              "1": (2.50, -50.483, 33.729), "2": (1.21, -10.544, 14.458), "3": (2.64, -49.462, 33.703),
              "final": (2.31, -56.604, 37.532)}  # final: Table 3.9
# Tables 3.3-3.8: the same three figures in the two pivot conditions a model was not trained on.
THESIS_CROSS = {
    "a": {"agent": (2.53, -47.175, 41.131), "between": (2.30, -52.136, 39.453)},       # Table 3.3
    "b": {"obstacle": (2.28, -52.334, 29.733), "between": (2.27, -56.731, 38.730)},    # Table 3.4
    "c": {"obstacle": (2.55, -46.396, 28.419), "agent": (2.06, -52.572, 41.442)},      # Table 3.5
    "1": {"agent": (2.46, -51.204, 41.345), "between": (2.19, -51.066, 37.621)},       # Table 3.6
    "2": {"obstacle": (2.49, -8.377, 11.367), "between": (1.23, -11.675, 16.849)},     # Table 3.7
    "3": {"obstacle": (2.14, -49.266, 29.942), "agent": (2.52, -49.424, 41.001)},      # Table 3.8
}
THESIS_ACCURACY = {"final": 94.7, "a": 58.2, "b": 75.8, "c": 74.1, "1": 56.9, "2": 3.8, "3": 58.0}  # Table 3.10
# Table 3.11: generation time per obstacle (ms), CFFTG and the final model.
THESIS_T311 = {"base1": (2.055, 3.001), "base2": (1.974, 3.028), "base3": (2.003, 3.002),
               "triangle": (1.982, 3.353), "half_circle": (1.958, 3.001)}


def _fig(r: dict) -> tuple[float, float, float]:
    return r["time_ms_mean"], r["knee_swing_mean_deg"], r["hip_swing_mean_deg"]


def _triple(t) -> str:
    return f"{t[0]:.2f} / {t[1]:.1f} / {t[2]:.1f}"


def _cell(ref, fmt=_triple) -> str:
    """A thesis value, or '-' where the thesis gives none."""
    return "-" if ref is None else fmt(ref)


def _table(title: str, header: str, align: str, rows: list[str]) -> list[str]:
    return ["", f"## {title}", "", header, align, *rows]


def _pct(x: float) -> str:
    return f"{100 * x:.1f}"


def device_table(results: dict) -> list[str]:
    """Not in the thesis: each model's swings timed for the exoskeleton (jaxexo.inference.swing_timing,
    the config's [device] joint limits), beside CFFTG's where it was run."""
    rows = []
    for name, r in results.items():
        for gen in ("rl", "cfftg"):
            d = r.get(gen, {}).get("device")
            if d:
                rows.append(f"| {name} ({gen}) | {d['swing_s_mean']:.3f} | {d['swing_s_max']:.3f} | "
                            f"{d['peak_hip_vel_deg_s_mean']:.0f} | {d['peak_knee_vel_deg_s_mean']:.0f} | "
                            f"{_pct(d['device_within_limits'])} | {d['uniform_peak_joint_vel_deg_s_median']:.0f} |")
    return _table("Device timing (not in the thesis): shortest rest-to-rest swing within the [device] joint limits",
                  "| model (generator) | swing s mean | swing s max | peak hip vel deg/s | peak knee vel deg/s | "
                  "within limits % | uniform 1 s peak deg/s (median) |", "|---|---:|---:|---:|---:|---:|---:|", rows)


def tables(results: dict) -> str:
    """The reproduction's Markdown: every table beside the thesis's values."""
    lines = ["# Thesis experiments reproduced with jaxexo", "",
             "Each cell: mean generation time (ms) / mean swing knee angle (deg) / mean swing hip angle (deg). "
             "Thesis values from Tables 3.2-3.11; jaxexo's from the NumPy generator on the same scenario set "
             "for every model."]
    lines += _table("Table 3.2 / 3.9: every pivot condition together",
                    "| model | thesis | jaxexo | train s (jaxexo) | episodes |", "|---|---|---|---:|---:|",
                    [f"| {name} | {_cell(THESIS_T32.get(name))} | {_triple(_fig(r['rl']))} | "
                     f"{r['train_seconds']:.1f} | {r['episodes']} |" for name, r in results.items()])
    cross = []
    for name, r in results.items():
        trained = TRAINED_PIVOT.get(name)
        for p, rp in ((p, r["rl"]["by_pivot"][p]) for p in PIVOT_CONDITIONS if p in r["rl"]["by_pivot"]):
            cross.append(f"| {name} ({trained or 'all'}) | {p}{' (trained)' if trained == p else ''} | "
                         f"{_cell(THESIS_CROSS.get(name, {}).get(p))} | {_triple(_fig(rp))} | "
                         f"{_pct(rp['accuracy'])} | {_pct(rp['success'])} |")
    lines += _table("Tables 3.3-3.8: per pivot condition",
                    "| model (trained on) | pivot | thesis | jaxexo | jaxexo accuracy % | jaxexo success % |",
                    "|---|---|---|---|---:|---:|", cross)
    lines += _table("Table 3.10: accuracy (eq 3.1) on the test scenarios",
                    "| model | thesis accuracy % | jaxexo accuracy % | jaxexo strict success % | reached goal % |",
                    "|---|---:|---:|---:|---:|",
                    [f"| {name} | {_cell(THESIS_ACCURACY.get(name), lambda x: f'{x:.1f}')} | "
                     f"{_pct(r['rl']['accuracy'])} | {_pct(r['rl']['success'])} | {_pct(r['rl']['reached_goal'])} |"
                     for name, r in results.items()])
    lines += device_table(results)
    final = results.get("final")
    if final and "cfftg" in final:
        rows = []
        for k, rk in final["rl"]["by_kind"].items():
            ck = final["cfftg"]["by_kind"][k]
            ref = THESIS_T311.get(k, (float("nan"),) * 2)
            rows.append(f"| {k} | {ref[0]:.3f} | {ref[1]:.3f} | {ck['time_ms_mean']:.3f} | {rk['time_ms_mean']:.3f} | "
                        f"{_pct(ck['success'])} | {_pct(rk['success'])} |")
        lines += _table("Table 3.11: generation time per obstacle (ms, mean), final model vs CFFTG",
                        "| obstacle | thesis CFFTG | thesis final | jaxexo CFFTG | jaxexo final (RL) | "
                        "jaxexo CFFTG success % | jaxexo RL success % |", "|---|---:|---:|---:|---:|---:|---:|", rows)
        lines += ["", f"Batch of 1000 (median): RL {final['rl']['batch_1000_ms']:.0f} ms, CFFTG "
                  f"{final['cfftg']['batch_1000_ms']:.0f} ms (thesis final model: 1764 ms)."]
    return "\n".join(lines) + "\n"


def run_reproduce(out: str | Path, models=THESIS_MODELS, n: int = 1000, seed: int = 0, include_default: bool = False,
                  root: Path | None = None, batch_size: int = 1000, results_dir: str | Path | None = None,
                  progress=print) -> dict:
    """Train (or reuse) each model, evaluate it, write OUT/reproduce.{md,json}; returns the results.
    ``batch_size``: scenarios of the timed batch for the models compared with CFFTG; ``results_dir``:
    also write the tables as a benchmark result (reproduce_<date>_<machine>.{json,md})."""
    from jaxexo.baselines import CFFTG
    from jaxexo.evaluation.compare import WithFallback, evaluate_generators, make_scenarios
    from jaxexo.inference import TrajectoryGenerator
    from jaxexo.storage.rundir import contents
    from jaxexo.train.driver import run_training

    # The thesis and default configs ship inside the package (jaxexo/config/); ``root``: a tree with
    # its own configs/thesis/*.toml and configs/default.toml instead.
    base = root / "configs" if root else Path(packaged_config("default")).parent
    out = Path(out)
    paths = {m: base / "thesis" / f"{m}.toml" for m in models}
    if include_default:
        paths["default"] = base / "default.toml"
    results: dict = {}
    for name, cfg_path in paths.items():
        run = out / "runs" / name
        if (run / "policy.npz").exists() and (run / "eval.json").exists():
            ev = json.loads((run / "eval.json").read_text())
            progress(f"{name}: reusing {run}")
        else:
            progress(f"{name}: training {cfg_path}")
            # A run stopped part way (killed, full disk) is continued, not refused.
            started = run.is_dir() and bool(contents(run))
            ev = run_training(load_config(cfg_path), run, seed=seed, resume=started, progress=False)
        gen = TrajectoryGenerator.load(run / "policy.npz")
        gens = {"rl": WithFallback(gen, None)}     # the thesis tables score the RL swing alone
        if name in ("final", "default"):
            gens["cfftg"] = CFFTG(gen.config)
        scenarios = make_scenarios(gen.config, "test", n)
        report, _ = evaluate_generators(gens, scenarios, batch_size=batch_size if len(gens) > 1 else 0)
        results[name] = {**report, "train_seconds": ev["train_seconds"], "episodes": ev["episodes"],
                         "eval_json": {k: ev[k] for k in ("accuracy", "success")}}
        r = report["rl"]
        progress(f"{name}: accuracy {r['accuracy']:.3f}, success {r['success']:.3f}, "
                 f"{r['time_ms_mean']:.2f} ms per trajectory")
    out.mkdir(parents=True, exist_ok=True)
    (out / "reproduce.json").write_text(json.dumps(results, indent=1) + "\n")
    (out / "reproduce.md").write_text(tables(results))
    if results_dir is not None:
        from jaxexo.evaluation.machine import write_result

        write_result("reproduce", json.loads(json.dumps(results)), tables(results), results_dir)
    return results
