"""``jaxexo reproduce``: the thesis's experiments (the seven thesis configs, faithful and learns,
``LEARNS_CHANGES``), rerun and tabulated beside its published values; runs and their evaluations
under OUT/runs/ are reused. What it writes and why: docs/thesis-reproduction.md."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path

from jaxexo.config import load_config, packaged_config
from jaxexo.evaluation.thesis_results import (
    THESIS_ACCURACY,
    THESIS_BATCH_1000_MS,
    THESIS_CROSS,
    THESIS_T32,
    THESIS_T311,
    THESIS_TRAIN_TIME,
)
from jaxexo.physics.kinematics import PIVOT_CONDITIONS
from jaxexo.storage.atomic import atomic_write
from jaxexo.storage.rundir import blocking_file
from jaxexo.summary import table

THESIS_MODELS = ("a", "b", "c", "1", "2", "3", "final")
# Members per learns model (jaxexo.train.population): which seed of a heel-only learner learns is
# chance, so each learns config trains this many seeds as one program and keeps the best on
# validation; why four: docs/thesis-reproduction.md.
REPRODUCE_POPULATION = 4
VARIANTS = ("faithful", "learns")
ENTRY = "reproduce_entry.json"  # a run's evaluated figures, beside its policy
# The changes from the thesis's text in the ``learns`` variant, each a named config switch (the
# faithful setting first); the evidence is benchmarks/results/thesis-learning_*.md.
LEARNS_CHANGES = ()
# The pivot condition each single-condition model was trained on (thesis 3.2; configs/thesis/*.toml).
TRAINED_PIVOT = {
    "a": "obstacle",
    "b": "agent",
    "c": "between",
    "1": "obstacle",
    "2": "agent",
    "3": "between",
}


def _fig(r: dict) -> tuple[float, float, float]:
    return r["time_ms_mean"], r["knee_swing_mean_deg"], r["hip_swing_mean_deg"]


def _triple(t) -> str:
    return f"{t[0]:.2f} / {t[1]:.1f} / {t[2]:.1f}"


def _cell(ref, fmt=_triple) -> str:
    """A thesis value, or '-' where the thesis gives none."""
    return "-" if ref is None else fmt(ref)


def _table(title: str, header, align: str, rows: list[str]) -> list[str]:
    """A titled table; ``rows``: each row's cells as text ("a | b")."""
    return ["", f"## {title}", "", *table(header, [(r,) for r in rows], align)]


def _pct(x: float) -> str:
    return f"{100 * x:.1f}"


def device_table(results: dict) -> list[str]:
    """Not in the thesis: each model's swings timed for the exoskeleton (jaxexo.swing.timing,
    the config's [device] joint limits), beside CFFTG's where it was run."""
    rows = []
    for name, r in results.items():
        for gen in ("rl", "cfftg"):
            d = r.get(gen, {}).get("device")
            if d:
                rows.append(
                    f"{name} ({gen}) | {d['swing_s_mean']:.3f} | {d['swing_s_max']:.3f} | "
                    f"{d['peak_hip_vel_deg_s_mean']:.0f} | {d['peak_knee_vel_deg_s_mean']:.0f} | "
                    f"{_pct(d['device_within_limits'])} | {d['uniform_peak_joint_vel_deg_s_median']:.0f}"
                )
    return _table(
        "Device timing (not in the thesis): shortest rest-to-rest swing within the [device] joint limits",
        ("model (generator)", "swing s mean", "swing s max", "peak hip vel deg/s")
        + ("peak knee vel deg/s", "within limits %", "uniform 1 s peak deg/s (median)"),
        "l" + "r" * 6,
        rows,
    )


def model_of(name: str) -> str:
    """Thesis model of a result name ("a", "a-learns" -> "a"; "default" stays)."""
    return name.removesuffix("-learns")


def variant_of(name: str) -> str:
    return "learns" if name.endswith("-learns") else ("faithful" if name in THESIS_MODELS else "-")


def _minutes(seconds: float) -> str:
    return f"{seconds / 60:.1f} min" if seconds >= 60 else f"{seconds:.0f} s"


def _intro(results: dict) -> list[str]:
    """The title, what the triples and variants mean (with the test epsilons), the learns switches."""
    eps = sorted({r["test_epsilon"] for r in results.values() if "test_epsilon" in r})
    eps_txt = ", ".join(f"{e:g}" for e in eps) or "-"
    lines = [
        "# Thesis experiments reproduced with jaxexo",
        "",
        "Each triple: mean generation time (ms) / mean swing knee angle (deg) / mean swing hip angle (deg). "
        "Thesis values from Tables 3.2-3.11; jaxexo's from the NumPy generator on the same scenario set "
        "for every model. Variant *faithful*: the thesis's text as written (configs/thesis/<m>.toml); "
        "*learns*: with the switches listed below (configs/thesis/<m>-learns.toml). *greedy*: the policy's "
        "best action at every step (what a device runs); *ε-greedy*: the thesis's test protocol (§2.6), a "
        f"random action with probability ε = {eps_txt} (the configs' final training ε; the thesis does not "
        "state its test ε).",
    ]
    changes = [f"- `{key}`: {text}" for key, text in LEARNS_CHANGES]
    if changes and any(variant_of(n) == "learns" for n in results):
        lines += [
            "",
            "Switches of the *learns* variant (thesis setting -> learns setting):",
            "",
            *changes,
        ]
    return lines


def _run_rows(results: dict, cells) -> list[str]:
    """A table row per run: its model and variant, then ``cells(model, figures)``."""
    return [
        f"{model_of(name)} | {variant_of(name)} | " + cells(model_of(name), r)
        for name, r in results.items()
    ]


def _accuracy_cells(model: str, r: dict) -> str:
    greedy = (
        f"{_cell(THESIS_ACCURACY.get(model), lambda x: f'{x:.1f}')} | "
        f"{_pct(r['rl']['accuracy'])} | {_pct(r['rl']['success'])} | {_pct(r['rl']['reached_goal'])} | "
    )
    if "rl_eps" not in r:
        return greedy + "- | - | -"
    e = r["rl_eps"]
    return greedy + f"{_pct(e['accuracy'])} | {_pct(e['success'])} | {_pct(e['reached_goal'])}"


def _training_cells(model: str, r: dict) -> str:
    return (
        f"{THESIS_TRAIN_TIME.get(model, '-')} | {_minutes(r['train_seconds'])} | "
        f"{r['train_seconds']:.1f} | {r['episodes']} | {r.get('env_steps', '-')}"
    )


def _overall_cells(model: str, r: dict) -> str:
    return (
        f"{_cell(THESIS_T32.get(model))} | {_triple(_fig(r['rl']))} | "
        f"{_triple(_fig(r['rl_eps'])) if 'rl_eps' in r else '-'}"
    )


# The tables with a row per run: title, header, alignment, and the row's cells after the model and
# variant.
RUN_TABLES = {
    "accuracy": (
        "Table 3.10: accuracy (eq 3.1) on the test scenarios, greedy and ε-greedy",
        ("model", "variant", "thesis accuracy %", "greedy accuracy %", "greedy strict success %")
        + ("greedy reached goal %", "ε-greedy accuracy %", "ε-greedy strict success %")
        + ("ε-greedy reached goal %",),
        "ll" + "r" * 7,
        _accuracy_cells,
    ),
    "training time": (
        "Training time per model (thesis: laptop GPU, Ryzen 7 + RTX 4060; jaxexo: this machine's CPU)",
        ("model", "variant", "thesis", "jaxexo", "jaxexo s", "episodes", "env steps"),
        "llllrrr",
        _training_cells,
    ),
    "overall": (
        "Table 3.2 / 3.9: every pivot condition together",
        ("model", "variant", "thesis", "jaxexo greedy", "jaxexo ε-greedy"),
        "lllll",
        _overall_cells,
    ),
}


def run_table(which: str, results: dict) -> list[str]:
    """One of RUN_TABLES: Table 3.10 (accuracy), the training times, Table 3.2 / 3.9 (overall)."""
    title, header, align, cells = RUN_TABLES[which]
    return _table(title, header, align, _run_rows(results, cells))


def pivot_table(results: dict) -> list[str]:
    """Tables 3.3-3.8: per model and pivot condition, the one it was trained on marked."""
    cross = []
    for name, r in results.items():
        model = model_of(name)
        trained = TRAINED_PIVOT.get(model)
        for p, rp in (
            (p, r["rl"]["by_pivot"][p]) for p in PIVOT_CONDITIONS if p in r["rl"]["by_pivot"]
        ):
            re_ = r.get("rl_eps", {}).get("by_pivot", {}).get(p)
            cross.append(
                f"{model} ({trained or 'all'}) | {variant_of(name)} | {p}{' (trained)' if trained == p else ''} | "
                f"{_cell(THESIS_CROSS.get(model, {}).get(p))} | {_triple(_fig(rp))} | "
                f"{_pct(rp['accuracy'])} | {_pct(rp['success'])} | "
                f"{_triple(_fig(re_)) if re_ else '-'} | {_pct(re_['success']) if re_ else '-'}"
            )
    return _table(
        "Tables 3.3-3.8: per pivot condition",
        ("model (trained on)", "variant", "pivot", "thesis", "jaxexo greedy", "greedy accuracy %")
        + ("greedy success %", "jaxexo ε-greedy", "ε-greedy success %"),
        "lllllrrlr",
        cross,
    )


def cfftg_tables(results: dict) -> list[str]:
    """Table 3.11 and the batch of 1000, for each final model compared with CFFTG."""
    lines = []
    for name in ("final", "final-learns"):
        final = results.get(name)
        if not (final and "cfftg" in final):
            continue
        rows = []
        for k, rk in final["rl"]["by_kind"].items():
            ck = final["cfftg"]["by_kind"][k]
            ref = THESIS_T311.get(k, (float("nan"),) * 2)
            rows.append(
                f"{k} | {ref[0]:.3f} | {ref[1]:.3f} | {ck['time_ms_mean']:.3f} | {rk['time_ms_mean']:.3f} | "
                f"{_pct(ck['success'])} | {_pct(rk['success'])}"
            )
        lines += _table(
            f"Table 3.11: generation time per obstacle (ms, mean), {name} model vs CFFTG",
            ("obstacle", "thesis CFFTG", "thesis final", "jaxexo CFFTG", "jaxexo final (RL)")
            + ("jaxexo CFFTG success %", "jaxexo RL success %"),
            "l" + "r" * 6,
            rows,
        )
        lines += [
            "",
            f"Batch of 1000 (median): RL {final['rl']['batch_1000_ms']:.0f} ms, CFFTG "
            f"{final['cfftg']['batch_1000_ms']:.0f} ms (thesis final model: {THESIS_BATCH_1000_MS:.0f} ms).",
        ]
    return lines


def tables(results: dict) -> str:
    """The reproduction's Markdown: every table beside the thesis's values. ``results`` maps a run name
    ("a", "a-learns", "default") to its figures: ``rl`` greedy, ``rl_eps`` epsilon-greedy (thesis 2.6)."""
    lines = [
        *_intro(results),
        *run_table("accuracy", results),
        *population_table(results),
        *run_table("training time", results),
        *run_table("overall", results),
        *pivot_table(results),
        *device_table(results),
        *cfftg_tables(results),
    ]
    return "\n".join(lines) + "\n"


def meets_target(model: str, success: float, reached_goal: float) -> bool | None:
    """The target for a thesis model: the goal reached in >= 95 % of the test trajectories and
    strict success >= the thesis's accuracy (Table 3.10); None for a model the thesis gives none for."""
    ref = THESIS_ACCURACY.get(model)
    return None if ref is None else bool(reached_goal >= 0.95 and 100 * success >= ref)


def population_summary(ev: dict, model: str) -> dict:
    """A population run's members from its eval.json: each member's seed, validation score, and test
    figures on its raw greedy moves (eval.json's, jaxexo.train.evaluate: the same test scenes, without
    the NumPy generator's smoothing), whether those meet the target, and which member was exported."""
    members = []
    for m in ev["members"]:
        t = m["test"]
        members.append(
            {
                "seed": m["seed"],
                "validation_success_raw": m["validation_success_raw"],
                "diverged_chunk": m["diverged_chunk"],
                "success_raw": t and t["success_raw"],
                "reached_goal": t and t["reached_goal"],
                "meets_target": bool(t)
                and bool(meets_target(model, t["success_raw"], t["reached_goal"])),
            }
        )
    return {
        "size": len(members),
        "exported_member": ev["exported_member"],
        "exported_seed": ev["seed"],
        "base_seed": ev.get("base_seed"),
        "members": members,
        "members_meeting_target": sum(m["meets_target"] for m in members),
    }


def population_table(results: dict) -> list[str]:
    """Per learns model trained as a population: the exported member and how many members meet the
    target on their raw greedy moves."""
    rows = []
    for name, r in results.items():
        p = r.get("population")
        if not p:
            continue
        model = model_of(name)
        exported = p["members"][p["exported_member"]]
        verdict = meets_target(model, r["rl"]["success"], r["rl"]["reached_goal"])
        rows.append(
            f"{model} | {p['size']} | {p['exported_seed']} | {exported['validation_success_raw']:.3f} | "
            f"{_pct(r['rl']['success'])} / {_pct(r['rl']['reached_goal'])} | "
            f"{'yes' if verdict else ('no' if verdict is not None else '-')} | "
            f"{p['members_meeting_target']} of {p['size']} | "
            + ", ".join(
                f"{m['seed']}: {_pct(m['success_raw'])}/{_pct(m['reached_goal'])}"
                if m["success_raw"] is not None
                else f"{m['seed']}: diverged"
                for m in p["members"]
            )
        )
    return (
        _table(
            "Populations (learns): the member exported (best on validation, training layouts) and the "
            "members meeting the target (reached goal >= 95 %, strict success >= the thesis's accuracy)",
            ("model", "members", "exported seed", "its validation success")
            + (
                "exported: strict success / reached goal % (NumPy generator)",
                "exported meets target",
            )
            + ("members meeting target (raw greedy moves)",)
            + ("per member seed: strict success / reached goal % (raw greedy moves)",),
            "lrrrllll",
            rows,
        )
        if rows
        else []
    )


def run_names(models=THESIS_MODELS, variant: str = "both") -> list[str]:
    """Run names in table order: per model, the faithful run ("a") then the learns run ("a-learns")."""
    if variant not in (*VARIANTS, "both"):
        raise ValueError(f"--variant: must be one of {[*VARIANTS, 'both']}, got {variant!r}")
    for m in models:
        if m not in THESIS_MODELS:
            raise ValueError(f"--models: unknown model {m!r} (known: {', '.join(THESIS_MODELS)})")
    kinds = VARIANTS if variant == "both" else (variant,)
    return [m if v == "faithful" else f"{m}-learns" for m in models for v in kinds]


def check_reproduce_options(out, n, results_dir=None, population=None, seed: int = 0) -> None:
    """Every option of ``jaxexo reproduce`` that no model needs to be trained to judge, checked before
    any work: --n, --population, --seed (with the population's seeds after it), and --out and
    --results naming folders (not files)."""
    from jaxexo.config import Config, check_seed, with_population
    from jaxexo.evaluation.compare import MAX_SCENARIOS

    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_SCENARIOS:
        raise ValueError(
            f"--n: test scenarios per model must be an integer from 1 to {MAX_SCENARIOS:,}, "
            f"got {n!r}"
        )
    if population is not None:
        with_population(Config(), population, "--population")
    check_seed(seed, "--seed", REPRODUCE_POPULATION if population is None else population)
    for option, folder in (("--out", out), ("--results", results_dir)):
        if folder is None:
            continue
        q = blocking_file(folder)
        if q is not None:
            raise ValueError(f"{option}: {q} is a file, not a folder (for {folder})")


def compact(report: dict) -> dict:
    """A generator's figures without the per-(kind, pivot) groups and with at most 5 failures, so
    that the committed JSON stays small (the device figures only overall)."""
    out = {k: v for k, v in report.items() if k != "by_kind_pivot"}
    out["failures"] = report.get("failures", [])[:5]
    for group in ("by_kind", "by_pivot"):
        out[group] = {
            g: {k: v for k, v in r.items() if k != "device"}
            for g, r in report.get(group, {}).items()
        }
    return out


@dataclasses.dataclass(frozen=True)
class Protocol:
    """How every model of one reproduction is trained and evaluated: ``n`` test scenarios, the
    training and exploring seed, the timed batch's size, the learns models' population size and
    where progress goes."""

    n: int
    seed: int
    batch_size: int
    population: int
    progress: Callable

    def compared(self, name: str) -> bool:
        """Whether the run is evaluated beside CFFTG (with a timed batch)."""
        return model_of(name) in ("final", "default")

    def key(self, name: str) -> dict:
        """What a run's kept evaluation (ENTRY) must have been made with to be reused."""
        return {
            "n": self.n,
            "seed": self.seed,
            "batch_size": self.batch_size if self.compared(name) else 0,
        }


def config_paths(root, models, variant: str, include_default: bool) -> dict[str, Path]:
    """Each run's config, in table order. The thesis and default configs ship inside the package
    (jaxexo/config/); ``root``: a tree with its own configs/thesis/*.toml and configs/default.toml
    instead."""
    base = root / "configs" if root else Path(packaged_config("default")).parent
    paths = {name: base / "thesis" / f"{name}.toml" for name in run_names(models, variant)}
    if include_default:
        paths["default"] = base / "default.toml"
    return paths


def train_or_reuse(name: str, cfg_path: Path, run: Path, p: Protocol) -> dict:
    """The run's eval.json figures: those of a finished run of this very config, or a new training
    (continued where a stopped one left off)."""
    from jaxexo.config import with_population
    from jaxexo.storage.rundir import contents
    from jaxexo.train.driver import run_training

    cfg = load_config(cfg_path)
    if variant_of(name) == "learns":
        # A population, the best member on validation exported; the faithful configs (documented not to
        # learn) and the default model train one agent.
        cfg = with_population(cfg, p.population, "--population")
    if (run / "policy.npz").exists() and (run / "eval.json").exists():
        # A finished run is reused only if it trained this very config: a config edited since
        # would otherwise be tabulated with the old one's numbers.
        if (run / "config.toml").exists() and load_config(run / "config.toml") != cfg:
            raise ValueError(
                f"{run}: trained with a different config than {cfg_path} (edited since?); "
                f"remove that run or choose another --out"
            )
        ev = json.loads((run / "eval.json").read_text())
        p.progress(f"{name}: reusing {run}")
        return ev
    p.progress(f"{name}: training {cfg_path}")
    # A run stopped part way (killed, full disk) is continued, not refused.
    started = run.is_dir() and bool(contents(run))
    return run_training(cfg, run, seed=p.seed, resume=started, progress=False)


def kept_evaluation(entry: Path, key: dict, ev: dict) -> dict | None:
    """A run's kept figures (ENTRY), if they were made with ``key`` for this very training."""
    if (
        entry.exists()
        and (cached := json.loads(entry.read_text())).get("key") == key
        and cached.get("train_seconds") == ev["train_seconds"]
    ):
        return cached["result"]
    return None


def evaluate_run(name: str, run: Path, ev: dict, p: Protocol) -> dict:
    """A run's figures: its policy greedy (beside CFFTG for the compared models) and
    epsilon-greedy on the n test scenarios, its training figures and its population."""
    from jaxexo.evaluation.compare import evaluate_generators, make_scenarios
    from jaxexo.inference.registry import generator_class

    gen = generator_class("rl").from_policy(run / "policy.npz")
    gens = {
        gen.name: gen.with_defaults(fallback=None)
    }  # the thesis tables score the RL swing alone
    if p.compared(name):
        cf = generator_class("cfftg").from_config(gen.config)
        gens[cf.name] = cf
    scenarios = make_scenarios(gen.config, "test", p.n)
    report, _ = evaluate_generators(
        gens, scenarios, batch_size=p.batch_size if len(gens) > 1 else 0
    )
    # The thesis's test protocol (2.6): epsilon-greedy, with the run's final training epsilon. Its
    # swings are not timed for the device: no table reads their timing, and an exploring policy's
    # swing wanders (each random move a stop and a turn for the time law).
    eps = float(gen.config.train.eps_end)
    eps_report, _ = evaluate_generators(
        {"rl": gen.exploring(eps, seed=p.seed).with_defaults(fallback=None)},
        scenarios,
        batch_size=0,
        device=False,
    )
    result = {
        **{k: compact(v) for k, v in report.items()},
        "rl_eps": compact(eps_report["rl"]),
        "test_epsilon": eps,
        "model": model_of(name),
        "variant": variant_of(name),
        "train_seconds": ev["train_seconds"],
        "episodes": ev["episodes"],
        "env_steps": ev.get("env_steps"),
        "eval_json": {k: ev[k] for k in ("accuracy", "success")},
    }
    if ev.get("population", 1) > 1:  # one agent's eval.json (any jaxexo's) has no other member
        result["population"] = population_summary(ev, model_of(name))
    return result


def _evaluated(name: str, result: dict) -> str:
    """The progress line of a run just evaluated."""
    r, re_ = result["rl"], result["rl_eps"]
    return (
        f"{name}: greedy accuracy {r['accuracy']:.3f}, success {r['success']:.3f}, reached goal "
        f"{r['reached_goal']:.3f}; eps-greedy ({result['test_epsilon']:g}) success {re_['success']:.3f}; "
        f"{r['time_ms_mean']:.2f} ms per trajectory"
    )


def write_tables(out: Path, results: dict, results_dir) -> None:
    """OUT/reproduce.{json,md}, and the tables as a benchmark result in ``results_dir`` if given."""
    out.mkdir(parents=True, exist_ok=True)
    atomic_write(out / "reproduce.json", json.dumps(results, indent=1) + "\n")
    atomic_write(out / "reproduce.md", tables(results))
    if results_dir is not None:
        from jaxexo.evaluation.machine import write_result

        write_result("reproduce", json.loads(json.dumps(results)), tables(results), results_dir)


def run_reproduce(
    out: str | Path,
    models=THESIS_MODELS,
    n: int = 1000,
    seed: int = 0,
    include_default: bool = False,
    root: Path | None = None,
    batch_size: int = 1000,
    results_dir: str | Path | None = None,
    variant: str = "faithful",
    progress=print,
    population: int | None = None,
) -> dict:
    """Train (or reuse) each model, evaluate it greedily and epsilon-greedily, write
    OUT/reproduce.{md,json}; returns the results. ``variant``: "faithful", "learns" or "both";
    ``batch_size``: scenarios of the timed batch for the models compared with CFFTG; ``results_dir``:
    also write the tables as a benchmark result (reproduce_<date>_<machine>.{json,md})."""
    check_reproduce_options(out, n, results_dir, population)
    population = REPRODUCE_POPULATION if population is None else population
    p = Protocol(n, seed, batch_size, population, progress)
    out = Path(out)
    results: dict = {}
    for name, cfg_path in config_paths(root, models, variant, include_default).items():
        run = out / "runs" / name
        ev = train_or_reuse(name, cfg_path, run, p)
        # A run's evaluation is kept beside it (ENTRY), so that rerunning reproduce to tabulate more models
        # does not re-evaluate the finished ones; it is reused only for the same n, seed and batch size.
        key, entry = p.key(name), run / ENTRY
        kept = kept_evaluation(entry, key, ev)
        if kept is not None:
            results[name] = kept
            progress(f"{name}: reusing its evaluation {entry}")
            continue
        results[name] = evaluate_run(name, run, ev, p)
        atomic_write(
            entry,
            json.dumps({"key": key, "train_seconds": ev["train_seconds"], "result": results[name]})
            + "\n",
        )
        progress(_evaluated(name, results[name]))
    write_tables(out, results, results_dir)
    return results
