"""Generator benchmark: the shielded RL generator against CFFTG side by side in one process (one
swing, batches of 1000, the cold import, where the time goes). Method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from jaxexo.evaluation.timing import time_batch
from jaxexo.inference import TrajectoryGenerator
from jaxexo.inference.blas import blas_threads
from jaxexo.summary import Summary, table

THESIS_MS = {"rl_single": 3.0, "cfftg_single": 2.0, "rl_batch_1000": 1764.0}  # Table 3.11, §3.4
# Targets: one swing <= 1 ms and <= 1.5x CFFTG's; a batch of 1000 no slower than CFFTG's and <= 150 ms;
# >= 99 % of swings smoothed in one pass, none on the raw polyline; import <= 0.3 s
TARGETS = {
    "rl_single_ms": 1.0,
    "rl_over_cfftg_single": 1.5,
    "rl_batch_1000_ms": 150.0,
    "smoothed_once": 0.99,
    "import_s": 0.3,
}
SETS = ("unseen", "safety")


def time_import(repeats: int = 7) -> list[float]:
    """Seconds to import jaxexo.inference in a fresh interpreter (one process per repeat); fails if
    the import pulled in JAX or SciPy."""
    code = (
        "import sys, time; t = time.perf_counter(); import jaxexo.inference; dt = time.perf_counter() - t; "
        "bad = [m for m in ('jax', 'scipy') if m in sys.modules]; print(dt if not bad else 'imported ' + str(bad))"
    )
    out = []
    for _ in range(repeats):
        text = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True
        ).stdout
        if text.startswith("imported"):
            raise RuntimeError(f"import jaxexo.inference {text.strip()}")
        out.append(float(text))
    return out


_BATCH_CODE = """
import json, sys
from benchlib.generate_bench import _batch_ms
print(json.dumps(_batch_ms(sys.argv[1], int(sys.argv[2]))))
"""


def _batch_ms(policy, n: int, repeats: int = 5) -> dict:
    """Median ms per generate_batch of n held-out scenes (RL alone: ``fallback=None``), RL and CFFTG
    alternating, this process. ``rl_process_blas``: the RL batch with ``batch_blas_threads = None``,
    i.e. on the process's own BLAS threads instead of generate_batch's one (jaxexo.inference.blas)."""
    from jaxexo.baselines.cfftg import CFFTG

    gen = TrajectoryGenerator.load(policy)
    free = gen.with_options(batch_blas_threads=None)
    sc = scene_set(gen.config, "unseen", n)
    cf = CFFTG(gen.config)
    runs = (
        ("rl", gen, {"fallback": None}),
        ("rl_process_blas", free, {"fallback": None}),
        ("cfftg", cf, {}),
    )
    for _, g, kw in runs:
        time_batch(g, sc[:20], 1, **kw)  # warm-up
    times = {name: [] for name, _, _ in runs}
    for r in range(repeats):  # alternating, one batch each
        for name, g, kw in runs if r % 2 == 0 else runs[::-1]:
            times[name].append(time_batch(g, sc, 1, **kw)[0][0])
    return {name: Summary.of(t).median * 1e3 for name, t in times.items()}


def scene_set(config, which: str, n: int) -> list[dict]:
    """n scenes of ``which``: "unseen" (the held-out families, jaxexo.evaluation.unseen) or "safety"
    (the shifted thesis obstacles of jaxexo.inference.scenarios.safety_scenarios)."""
    if which == "unseen":
        from jaxexo.evaluation.compare import make_scenarios

        return make_scenarios(config, "unseen", n)[:n]
    from jaxexo.inference.scenarios import safety_scenarios

    return safety_scenarios(config, n)


def batch_single_thread(policy, n: int) -> dict:
    """``_batch_ms`` in a fresh process whose BLAS runs on one thread (the thread count is read at
    NumPy's import, so it cannot be changed in this process without threadpoolctl)."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    text = subprocess.run(
        [sys.executable, "-c", _BATCH_CODE, str(policy), str(n)],
        capture_output=True,
        text=True,
        check=True,
        env=env,
    ).stdout
    return json.loads(text.strip().splitlines()[-1])


def _ms(x) -> dict:
    ms = Summary.of(np.asarray(x) * 1e3)
    return {"median": ms.median, "mean": ms.mean, "p95": ms.p95}


def rollout_states(sp, scene, raw, acts) -> list[tuple]:
    """The network's and the shield's inputs at each step of a rollout (``raw`` heel path, ``acts``
    its moves): heel y, z, the step, whether the mid goal was visited, the previous move (-1 first)."""
    from jaxexo.physics import transition
    from jaxexo.physics.transition import scalar

    mid_y, mid_z = transition.mid_goal(scalar, sp, scene.center_y, scene.height)
    visited, states = False, []
    for j in range(len(acts)):
        hy, hz = float(raw[j, 0]), float(raw[j, 1])
        states.append((hy, hz, float(j), 1.0 if visited else 0.0, int(acts[j - 1]) if j else -1))
        visited = visited or transition.in_mid_goal(
            scalar, sp, float(raw[j + 1, 0]), float(raw[j + 1, 1]), mid_y, mid_z
        )
    return states


def time_breakdown(gen, cf, scenarios: list[dict], repeats: int = 3) -> dict:
    """Where one swing's time goes, per generator (medians over the scenes of the best of ``repeats``
    timings each, microseconds). RL (``fallback=None``): the rollout per swing and its steps; per step
    the network (``StepNetwork.q_values``) and the shield's choice (``SwingShield.certain``, jaxexo.shield.scalar), replayed on
    the rollout's own states; per swing the observation's scene part (folded into the first layer), the
    smoothing and correction (``clear_rows``) and the rest of the finishing (verdict, retries,
    kinematics and joint angles). CFFTG: the plan with its checks and re-plans (``plan``) and the
    rest (``assemble``: kinematics and joint angles)."""
    import time

    from jaxexo.shield import make_shield
    from jaxexo.swing.clearing import clear_rows

    def best(fn):
        out = float("inf")
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn()
            out = min(out, time.perf_counter() - t0)
        return out * 1e6

    sp, step, n_pts, smooth = gen.sp, gen.step_net, 100, gen.smoothing
    rows = {
        k: []
        for k in (
            "steps",
            "rollout",
            "network_per_step",
            "shield_per_step",
            "observation",
            "smoothing_correction",
            "verdict_angles",
            "rl_total",
            "cfftg_plan",
            "cfftg_assemble",
            "cfftg_total",
        )
    }
    for s in scenarios:
        scene = gen.scene(s.obstacle, s.pivot, None, s.start_y, s.step_length)
        raw, acts = gen.rollout(scene)
        k = len(acts)
        states = rollout_states(sp, scene, raw, acts)
        basis = gen._basis(scene)
        step.set_scene(basis)
        qs = [step.q_values(*st[:4]).copy() for st in states]
        rows["steps"].append(k)
        rows["rollout"].append(best(lambda: gen.rollout(scene)))
        rows["observation"].append(best(lambda: step.set_scene(gen._basis(scene))))
        rows["network_per_step"].append(best(lambda: [step.q_values(*st[:4]) for st in states]) / k)
        if gen.shield:
            sh = make_shield("scalar", gen.np_params, sp).swing(scene)
            rows["shield_per_step"].append(
                best(lambda: [sh.certain(st[0], st[1], q, st[4]) for st, q in zip(states, qs)]) / k
            )
        fin = best(lambda: gen.finish([scene], [raw], n_pts, smooth, 1.0, None))
        cl = best(
            lambda: clear_rows(
                [raw], [scene.outline], sp.foot_length, sp.min_clearance, n_pts, smooth
            )
        )
        rows["smoothing_correction"].append(cl)
        rows["verdict_angles"].append(max(fin - cl, 0.0))
        at = s.options()
        rows["rl_total"].append(best(lambda: gen.generate(s.obstacle, **at, fallback=None)))
        plan = best(lambda: cf.plan([scene]))
        tot = best(lambda: cf.finish([scene], n_pts, 1.0))
        rows["cfftg_plan"].append(plan)
        rows["cfftg_assemble"].append(max(tot - plan, 0.0))
        rows["cfftg_total"].append(best(lambda: cf.generate(s.obstacle, **at)))
    return {k: Summary.of(v).median for k, v in rows.items() if v}


def breakdown_lines(b: dict) -> list[str]:
    """The breakdown's table (microseconds, medians; the parts are medians of their own, so they need
    not add up to the total exactly)."""
    shield = b.get("shield_per_step", float("nan"))
    rows = [
        ("total (`generate`)", f"{b['rl_total']:.0f}", f"{b['cfftg_total']:.0f}"),
        (f"rollout: {b['steps']:.0f} steps per swing", f"{b['rollout']:.0f}", ""),
        ("... per step: network", f"{b['network_per_step']:.1f}", ""),
        ("... per step: shield's choice", f"{shield:.1f}", ""),
        (
            "... per swing: the observation's scene part (first layer)",
            f"{b['observation']:.0f}",
            "",
        ),
        ("plan with its checks and re-plans (CFFTG)", "", f"{b['cfftg_plan']:.0f}"),
        (
            "finishing: smoothing and correction (`clear_rows`)",
            f"{b['smoothing_correction']:.0f}",
            "",
        ),
    ]
    rows.append(
        (
            "finishing: verdict, retries, kinematics, joint angles",
            f"{b['verdict_angles']:.0f}",
            f"{b['cfftg_assemble']:.0f}",
        )
    )
    return table(("where one swing's time goes (median us)", "RL", "CFFTG"), rows)


def smoothing_counts(trajs) -> dict:
    """Fractions of RL swings: smoothed in one pass (no retry with less smoothing), with the requested
    smoothing itself, with a per-path candidate, on the raw polyline; safe (the verdict)."""
    retried = np.array([any("brought the foot" in n for n in t.notes) for t in trajs])
    cand = np.array([any("per-path candidate" in n for n in t.notes) for t in trajs])
    raw = np.array([np.isnan(t.smoothing) for t in trajs])
    return {
        "smoothed_once": float(np.mean(~retried)),
        "requested_smoothing": float(np.mean(~retried & ~cand & ~raw)),
        "candidate_smoothing": float(np.mean(cand)),
        "raw_polyline": float(np.mean(raw)),
        "safe": float(np.mean([t.ok for t in trajs])),
    }


def set_figures(gen, cf, scenarios: list[dict], n: int) -> dict:
    """One scene set's figures: one swing, RL alone (``fallback=None``) and CFFTG alternating per
    scene, medians of 3 passes (wall and CPU time); the plain reference (``plain_reference``) against
    the fast generator on the first quarter of the n scenes; smoothing counts, safe swings and the
    shield's steps left to the full mask."""
    from jaxexo.evaluation.compare import run_generators
    from jaxexo.inference.generator import plain_reference

    gens = {"rl": gen.with_defaults(fallback=None), "cfftg": cf}
    stats = gen.shield_stats
    before = (stats.steps, stats.steps_to_full_mask)
    passes = [run_generators(gens, scenarios) for _ in range(3)]
    steps = (stats.steps - before[0], stats.steps_to_full_mask - before[1])
    single = {k: np.median([p[k].wall_s for p in passes], axis=0) for k in gens}
    cpu = {k: np.median([p[k].cpu_s for p in passes], axis=0) for k in gens}
    plain = plain_reference(gen).with_defaults(fallback=None)
    ref = run_generators(
        {"rl": gen.with_defaults(fallback=None), "rl_reference": plain}, scenarios[: max(1, n // 4)]
    )
    trajs = passes[-1]["rl"].trajectories
    return {
        "n": len(scenarios),
        "single_ms": {k: _ms(v) for k, v in single.items()},
        "ratio_rl_over_cfftg": Summary.of(single["rl"]).over(Summary.of(single["cfftg"])).median,
        "single_cpu_ms": {k: _ms(v) for k, v in cpu.items()},
        "cpu_ratio_rl_over_cfftg": Summary.of(cpu["rl"]).over(Summary.of(cpu["cfftg"])).median,
        "reference_ms": {
            "rl": _ms(ref["rl"].wall_s),
            "rl_reference": _ms(ref["rl_reference"].wall_s),
            "n": len(ref["rl"].wall_s),
        },
        "rl_over_cfftg_scenes": float(np.mean(single["rl"] > single["cfftg"])),
        "smoothing": smoothing_counts(trajs),
        "cfftg_safe": float(np.mean([t.ok for t in passes[-1]["cfftg"].trajectories])),
        "shield_steps_full_mask": steps[1] / max(steps[0], 1),
    }


def _miss(ok) -> str:
    return "met" if ok else "**missed**"


def _swing_table(sets: dict) -> list[str]:
    """The one-swing table: a column per scene set."""

    def row(label, cell, target=""):
        """A table row: the label, ``cell`` of each scene set's figures, the target."""
        return (label, *(cell(sets[w]) for w in SETS), target)

    rows = [
        row(
            "one swing, RL / CFFTG median ratio",
            lambda d: (
                f"**{d['ratio_rl_over_cfftg']:.2f}** ({_miss(d['ratio_rl_over_cfftg'] <= 1.5)})"
            ),
            "<= 1.5",
        ),
        row(
            "one swing, RL median",
            lambda d: (
                f"{d['single_ms']['rl']['median']:.3f} ms "
                f"({_miss(d['single_ms']['rl']['median'] <= 1.0)})"
            ),
            "<= 1.0 ms",
        ),
        row(
            "one swing, CPU time (process_time): RL / CFFTG ratio, RL and CFFTG medians",
            lambda d: (
                f"**{d['cpu_ratio_rl_over_cfftg']:.2f}**: {d['single_cpu_ms']['rl']['median']:.3f} / "
                f"{d['single_cpu_ms']['cfftg']['median']:.3f} ms"
            ),
        ),
        row("one swing, CFFTG median", lambda d: f"{d['single_ms']['cfftg']['median']:.3f} ms"),
        row(
            "one swing, RL mean / p95",
            lambda d: f"{d['single_ms']['rl']['mean']:.3f} / {d['single_ms']['rl']['p95']:.3f} ms",
        ),
        row(
            "one swing, plain reference (`plain_reference`) vs fast, median (first quarter of the scenes)",
            lambda d: (
                f"{d['reference_ms']['rl_reference']['median']:.3f} vs {d['reference_ms']['rl']['median']:.3f} ms"
            ),
        ),
        row(
            "RL swings smoothed in one pass (no retry)",
            lambda d: (
                f"{d['smoothing']['smoothed_once']:.1%} "
                f"({_miss(d['smoothing']['smoothed_once'] >= 0.99)})"
            ),
            ">= 99 %",
        ),
        row(
            "... with the requested smoothing / a per-path candidate",
            lambda d: (
                f"{d['smoothing']['requested_smoothing']:.1%} / {d['smoothing']['candidate_smoothing']:.1%}"
            ),
        ),
        row(
            "RL swings on the raw polyline (every smoothing failed)",
            lambda d: (
                f"{d['smoothing']['raw_polyline']:.1%} "
                f"({_miss(d['smoothing']['raw_polyline'] == 0)})"
            ),
            "0",
        ),
        row(
            "safe swings, RL alone / CFFTG",
            lambda d: f"{d['smoothing']['safe']:.1%} / {d['cfftg_safe']:.1%}",
            "RL >= 99.5 %",
        ),
        row(
            "shield steps left to the full mask (one swing)",
            lambda d: f"{d['shield_steps_full_mask']:.2%}",
        ),
    ]
    header = ("figure", "unseen (held-out families)", "safety scenes", "target")
    return table(header, rows, "lrrl")


def _batch_table(res: dict) -> list[str]:
    """The batch table: default and single-threaded BLAS, scaled to 1000 scenes (exact for n = 1000)."""
    batch, batch_1t = res["batch_ms"]["default_threads"], res["batch_ms"]["single_thread_blas"]
    b = lambda d, k: d[k] * 1000 / res["n"]  # noqa: E731
    ok = lambda d: _miss(d["rl"] <= d["cfftg"] and b(d, "rl") <= 150)  # noqa: E731
    rows = [
        (
            "default BLAS threads (this process)",
            *(f"{b(batch, k):.1f} ms" for k in ("rl", "cfftg")),
            f"**{batch['rl'] / batch['cfftg']:.2f}**",
            f"<= 1 and <= 150 ms: {ok(batch)}",
        ),
        (
            "single-threaded BLAS (a fresh process)",
            *(f"{b(batch_1t, k):.1f} ms" for k in ("rl", "cfftg")),
            f"**{batch_1t['rl'] / batch_1t['cfftg']:.2f}**",
            ok(batch_1t),
        ),
        (
            "RL on the process's BLAS threads (`batch_blas_threads = None`): default / single-threaded",
            f"{b(batch, 'rl_process_blas'):.1f} / {b(batch_1t, 'rl_process_blas'):.1f} ms",
            *("", "", ""),
        ),
    ]
    return table(
        ("batch of 1000 held-out scenes", "RL", "CFFTG", "RL / CFFTG", "target"), rows, "lrrrl"
    )


def report_lines(res: dict) -> list[str]:
    """The benchmark's Markdown, from its figures (``run_generate_benchmark``'s result)."""
    n = res["n"]
    return [
        "# Generator benchmark (NumPy only): the shielded RL generator against CFFTG, side by side",
        "",
        f"Policy `{res['policy']}`; RL alone (`fallback=None`). One swing: `generate` (rollout, smoothing, every "
        "safe-swing check, joint angles), RL and CFFTG alternating per scene, median of 3 passes per scene. "
        f"Batch: `generate_batch` of {n} held-out scenes, RL and CFFTG alternating, median of 5. "
        f"Load average at the start: {res['load_average']}.",
        "",
        *_swing_table(res["sets"]),
        "",
        *_batch_table(res),
        "",
        f"`import jaxexo.inference`, cold process: {res['import_s']['median']:.3f} s (<= 0.3 s: "
        f"{_miss(res['import_s']['median'] <= 0.3)}).",
        "",
        f"Where the time goes, {max(1, n // 5)} held-out scenes, each part timed alone (best of 3):",
        "",
        *breakdown_lines(res["breakdown_us"]),
    ]


def run_generate_benchmark(policy: str | Path, out_dir, n: int = 1000, progress=print) -> dict:
    """One swing (``generate``, RL alone: ``fallback=None``) RL and CFFTG alternating per scene on the
    held-out families and on the safety scenes (and the plain reference, ``plain_reference``, on a
    quarter of them); batches of 1000 with default and single-threaded BLAS; smoothing counts; the
    cold import."""
    from jaxexo.baselines.cfftg import CFFTG
    from jaxexo.evaluation.machine import write_result

    load = [round(x, 2) for x in os.getloadavg()]
    gen = TrajectoryGenerator.load(policy)
    cf = CFFTG(gen.config)

    scene_sets = {which: scene_set(gen.config, which, n) for which in SETS}
    sets = {which: set_figures(gen, cf, scene_sets[which], n) for which in SETS}
    breakdown = time_breakdown(gen, cf, scene_sets["unseen"][: max(1, n // 5)])
    batch = _batch_ms(policy, n)
    batch_1t = batch_single_thread(policy, n)
    imports = time_import()
    res = {
        "policy": str(policy),
        "n": n,
        "sets": sets,
        # the held-out set's figures under the keys the summary (run_all) reads
        "single_ms": sets["unseen"]["single_ms"],
        "batch_ms": {"default_threads": batch, "single_thread_blas": batch_1t},
        "import_s": {"median": Summary.of(imports).median, "runs": imports},
        "breakdown_us": breakdown,
        "blas_threads_default": blas_threads(),
        "load_average": load,
        "targets": TARGETS,
        "thesis_ms": THESIS_MS,
    }
    lines = report_lines(res)
    jpath, _ = write_result("generate", res, "\n".join(lines), out_dir)
    progress("\n".join(lines))
    progress(f"wrote {jpath}")
    return res
