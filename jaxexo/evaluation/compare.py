"""Side-by-side evaluation of trajectory generators (the RL policy and CFFTG) on the same scenarios,
``jaxexo eval``: the scenario sets, the timed runs and the report (figures in
jaxexo.evaluation.metrics, files in jaxexo.evaluation.report). Scenario sets and timing:
docs/generation.md#jaxexo-eval-both-generators-side-by-side."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from jaxexo.config import Config
from jaxexo.evaluation.metrics import (
    device_metrics,
    summarize,
    summarize_device,
    trajectory_metrics,
)
from jaxexo.evaluation.report import check_report_folder, write_report
from jaxexo.evaluation.thesis_results import (
    THESIS_ACCURACY,
    THESIS_BATCH_1000_MS,
    THESIS_CFFTG_MS,
    THESIS_T32,
)
from jaxexo.evaluation.timing import BATCH
from jaxexo.inference.scenarios import sample_scenarios, training_scenarios
from jaxexo.physics.kinematics import PIVOT_CONDITIONS
from jaxexo.physics.scenarios import Scenario
from jaxexo.summary import Summary, table

BATCH_REPEATS = 3
# Bounds checked before any work (each single call's trajectory is kept for the metrics, so the
# memory grows with --n; --batch sizes one generate_batch call's arrays).
MAX_SCENARIOS = 100_000  # per set: 200,000 swings for `all`, a few GB at most
MAX_BATCH = 100_000
SCENARIO_SETS = ("train", "test", "all", "unseen")
# The thesis's figures the report quotes beside jaxexo's (jaxexo.evaluation.thesis_results).
THESIS_REFERENCE = (
    f"Thesis reference (Tables 3.9-3.11): final model accuracy {THESIS_ACCURACY['final']:g} %, "
    f"{THESIS_T32['final'][0]:g} ms per trajectory, {THESIS_BATCH_1000_MS / 1000:g} s per 1000; "
    f"CFFTG about {THESIS_CFFTG_MS:g} ms per trajectory."
)


def make_scenarios(cfg: Config, which: str, n: int, seed: int = 12345) -> list[Scenario]:
    """``test``: n scenarios of jaxexo.inference.scenarios.sample_scenarios (the five thesis obstacles
    over the three pivot conditions); ``train``: n of the config's training distribution; ``all``:
    both (2 n); ``unseen``: the fixed held-out benchmark of jaxexo.evaluation.unseen (at least n
    scenes; its seed is fixed, ``seed`` does not apply). Each a jaxexo.physics.scenarios.Scenario."""
    if which not in SCENARIO_SETS:
        raise ValueError(f"scenarios must be one of {SCENARIO_SETS}, got {which!r}")
    if which == "unseen":
        from jaxexo.physics.scenarios import repeats_for, unseen_scenarios

        return unseen_scenarios(cfg.kinematics.foot_length, repeats_for(n))
    out: list[Scenario] = []
    if which in ("test", "all"):
        out += sample_scenarios(cfg, n, seed)
    if which in ("train", "all"):
        out += training_scenarios(cfg, n, seed + 1)
    return out


def batch_time(
    gen, scenarios: list[Scenario], size: int = BATCH, repeats: int = BATCH_REPEATS
) -> float:
    """Median wall time (ms) of ``generate_batch`` on ``size`` scenarios (cycled if fewer), timed by
    the generator benchmark's own function, scaled to a batch of 1000 (exact when size = 1000)."""
    from jaxexo.evaluation.timing import time_batch

    t = time_batch(gen, [scenarios[i % len(scenarios)] for i in range(size)], repeats)[0]
    return Summary.of(t).median * 1e3 * BATCH / size


@dataclass(frozen=True)
class GeneratorRun:
    """One generator's pass over N scenarios: its trajectories and each call's wall and CPU seconds
    [N] (CPU time too: on a shared machine a long call is preempted more often than a short one,
    which the wall clock charges to it)."""

    trajectories: list
    wall_s: np.ndarray
    cpu_s: np.ndarray


def run_generators(
    generators: dict, scenarios: list[Scenario], warmup: int = 20
) -> dict[str, GeneratorRun]:
    """Generate every scenario with every generator, alternating their order per scenario."""
    names = list(generators)
    for s in scenarios[:warmup]:
        for g in generators.values():
            g.generate(s.obstacle, **s.options())
    out = {n: GeneratorRun([], np.empty(len(scenarios)), np.empty(len(scenarios))) for n in names}
    for i, s in enumerate(scenarios):
        for n in names if i % 2 == 0 else names[::-1]:
            c0, t0 = time.process_time(), time.perf_counter()
            tr = generators[n].generate(s.obstacle, **s.options())
            out[n].wall_s[i], out[n].cpu_s[i] = time.perf_counter() - t0, time.process_time() - c0
            out[n].trajectories.append(tr)
    return out


def evaluate_generators(
    generators: dict,
    scenarios: list[Scenario],
    batch_size: int = BATCH,
    batch_repeats: int = BATCH_REPEATS,
    device: bool = True,
) -> tuple[dict, dict]:
    """The report's figures per generator, and the trajectories (for figures). ``device``: time
    every swing for the device too (jaxexo.swing.timing; the report's "device" figures), off where
    no table reads them (the epsilon-greedy protocol's exploring swings)."""
    runs = run_generators(generators, scenarios)
    kinds = np.array([s.kind for s in scenarios])
    pivots = np.array([s.pivot for s in scenarios])
    report, trajs = {}, {}
    groups = {
        "by_kind": {k: kinds == k for k in dict.fromkeys(kinds)},
        "by_pivot": {p: pivots == p for p in PIVOT_CONDITIONS if (pivots == p).any()},
        "by_kind_pivot": {
            f"{k}/{p}": (kinds == k) & (pivots == p)
            for k in dict.fromkeys(kinds)
            for p in PIVOT_CONDITIONS
            if ((kinds == k) & (pivots == p)).any()
        },
    }
    for name, run in runs.items():
        gen, tr, times = generators[name], run.trajectories, run.wall_s
        m = trajectory_metrics(tr)
        dm = device_metrics(tr, gen.config) if device else None
        entry = summarize(m, times, np.ones(len(tr), bool))
        if device:
            entry["device"] = summarize_device(dm, np.ones(len(tr), bool))
        entry["batch_1000_ms"] = (
            batch_time(gen, scenarios, batch_size, batch_repeats) if batch_size else None
        )
        entry["batch_size"] = batch_size
        for key, masks in groups.items():
            entry[key] = {}
            for g, mask in masks.items():
                entry[key][g] = summarize(m, times, mask)
                if device:
                    entry[key][g]["device"] = summarize_device(dm, mask)
                # The group's own scenarios in one generate_batch call, scaled to 1000.
                sub = [scenarios[i] for i in np.flatnonzero(mask)]
                entry[key][g]["batch_1000_ms"] = (
                    batch_time(gen, sub, len(sub), 1) if batch_size else None
                )
        entry["failures"] = [
            {
                "scenario": i,
                "kind": str(kinds[i]),
                "pivot": str(pivots[i]),
                "reasons": list(t.checks.reasons),
            }
            for i, t in enumerate(tr)
            if not t.ok
        ][:20]
        report[name] = entry
        trajs[name] = tr
    return report, trajs


def check_eval_counts(n, batch, n_option: str = "--n", batch_option: str = "--batch") -> None:
    """``jaxexo eval``'s counts, bounded before any work; ValueError naming the option and bound."""
    for option, value, what, bound in (
        (n_option, n, "scenarios per set", MAX_SCENARIOS),
        (batch_option, batch, "scenarios per generate_batch call", MAX_BATCH),
    ):
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= bound:
            raise ValueError(
                f"{option}: {what} must be an integer from 1 to {bound:,}, got {value!r}"
            )


def compared_generators(rl, against: str | None) -> dict:
    """The generators ``jaxexo eval`` runs, by their report's names: ``rl``'s swing alone (its
    fallback off), and with ``against`` (the name of a registered generator built from ``rl``'s
    config) that one too, and where it is ``rl``'s fallback generator the two combined
    ("rl+cfftg": ``rl`` with its fallback on, the option's default)."""
    from jaxexo.inference.registry import generator_class, names

    gens = {rl.name: rl.with_defaults(fallback=None)}
    if against is None:
        return gens
    if against not in names() or generator_class(against).needs_policy:
        raise ValueError(f"against must be 'cfftg' or None, got {against!r}")
    if rl.fallback_generator().name == against:
        gens[f"{rl.name}+{against}"] = rl
    gens[against] = generator_class(against).from_config(rl.config)
    return gens


def run_eval(
    policy: str | Path,
    out: str | Path,
    against: str | None = "cfftg",
    scenarios: str = "test",
    n: int = 1000,
    seed: int = 12345,
    figures: bool = True,
    batch_size: int = BATCH,
    force: bool = False,
    replay: bool = False,
) -> dict:
    """``jaxexo eval``: the policy (and CFFTG) on the chosen scenarios; writes the report.
    ``batch_size``: scenarios per timed ``generate_batch`` call (the figure is scaled to 1000);
    ``force``: replace an earlier report in ``out`` (else refused, as is a report over its policy);
    ``replay``: also replay every swing in MuJoCo (jaxexo.sim.replay; needs the sim extra)."""
    check_report_folder(out, policy, force)
    if replay:
        from jaxexo.sim.replay import require_mujoco

        require_mujoco()  # refused before any work
    from jaxexo.evaluation.machine import machine_info
    from jaxexo.inference.registry import generator_class

    rl = generator_class("rl").from_policy(policy)
    gens = compared_generators(rl, against)
    sc = make_scenarios(rl.config, scenarios, n, seed)
    report, trajs = evaluate_generators(gens, sc, batch_size)
    info = machine_info()
    context = [
        f"Policy `{policy}`; scenarios `{scenarios}` ({len(sc)}, seed {seed}); both generators in one "
        f"process, alternating; {info['cpu']}, {info['cores']} cores.",
        THESIS_REFERENCE,
    ]
    for entry in report.values():
        entry["scenarios"] = scenarios
        entry["policy"] = str(policy)
    sections: list[str] = []
    if scenarios == "unseen":
        from jaxexo.evaluation.unseen import family_table, markdown_lines
        from jaxexo.physics.scenarios import UNSEEN_SEED

        table = family_table(trajs, sc)
        for name, entry in report.items():
            entry["by_family"] = {fam: gens[name] for fam, gens in table.items()}
        context[0] = context[0].replace(f"seed {seed}", f"fixed seed {UNSEEN_SEED}")
        sections = markdown_lines(table)
    if replay:
        from jaxexo.sim.replay import replay_trajectories

        for name, entry in report.items():
            entry["mujoco"] = replay_trajectories(trajs[name], gens[name].config)
        sections = [
            *sections,
            *([""] if sections else []),
            *mujoco_lines(report, rl.config.device.control_rate),
        ]
    return write_report(
        out,
        report,
        trajs,
        sc,
        "jaxexo eval: RL generator" + (" vs CFFTG" if against else ""),
        context,
        figures,
        sections,
    )


def mujoco_lines(report: dict, rate: float) -> list[str]:
    """The report's MuJoCo figures (``replay``), one row per generator, as Markdown."""
    mm = lambda x: "-" if x is None else f"{1000 * x:.1f}"  # noqa: E731
    rows = []
    for name, entry in report.items():
        k, d = entry["mujoco"]["kinematic"], entry["mujoco"].get("driven", {"n": 0})
        drv = (
            f"{mm(d['heel_error_p95_m'])} / {mm(d['heel_error_max_m'])} | {mm(d['toe_error_p95_m'])} / "
            f"{mm(d['toe_error_max_m'])} | {d['contacts']} | {mm(d['min_distance_m'])} | {d['saturated']}"
            if d["n"]
            else "- | - | - | - | -"
        )
        rows.append(
            (name, k["n"], k["flagged_ok"], k["flagged_ok_within_margin"])
            + (
                mm(k["min_mujoco_distance_of_ok_m"]),
                f"{1e6 * (k['max_disagreement_m'] or 0.0):.3f}",
                drv,
            )
        )
    return [
        f"Replayed in MuJoCo (jaxexo.sim.replay): every swing timed for the [device] limits at {rate:g} Hz; "
        "kinematic: MuJoCo's own distance at every sample and 3 poses between; driven (swings flagged ok): "
        "position actuators, setpoints within the limits.",
        "",
        *table(MUJOCO_HEADER, rows),
    ]


MUJOCO_HEADER = (
    *("generator", "n", "flagged ok", "ok, within margin in MuJoCo"),
    *("min MuJoCo distance of ok, mm", "max disagreement, um", "heel error p95 / max, mm"),
    *("toe error p95 / max, mm", "contacts", "min distance driven, mm", "saturated"),
)
