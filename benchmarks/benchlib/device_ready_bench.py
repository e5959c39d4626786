"""Device-ready swing benchmark: ``generate`` + ``time_swing`` of one swing, RL alone and CFFTG
alternating in CPU time, by part, and ``time_swings`` of a batch. Method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from jaxexo.summary import Summary, table

# The targets: time_swing alone per swing (ms, both generators) by rate, the device-ready
# swing (generate + time_swing at 100 Hz), generate alone RL / CFFTG, time_swings of 1000 by rate.
TARGETS = {
    "time_swing_ms": {"100": 1.5, "1000": 2.0},
    "rl_device_ready_ms": 4.0,
    "rl_over_cfftg": 1.3,
    "rl_generate_over_cfftg": 2.0,
    "batch_1000_s": {"100": 1.0, "1000": 1.5},
}
# benchmarks/bench_device_ready.py's options (benchlib.runner.run_script).
OPTIONS = (
    ("--n", "n", "unseen-shape scenes"),
    ("--batch", "batch", "swings timed in one time_swings call"),
    ("--rate", "rate", "control rate, Hz"),
)
# The timing's stages: the jaxexo.swing.timing functions (module globals, so wrapping them there
# reaches every call) each one's CPU time is read from, exclusive of the stages nested in it (the
# passes call the check). "other": the rest of time_swing (inputs, curves, records).
PARTS = {
    "path": ("_joint_samples", "_joint_paths"),
    "passes": ("_run_passes", "lowered_cap"),
    "proof": ("with_bounds",),
    "final law": ("final_law",),
    "samples": ("_samples",),
    "verdict": ("_path_checks", "_curve_verdict"),
}
STAGES = (*PARTS, "other")
_FUNCTIONS = {n: k for k, names in PARTS.items() for n in names}


def _split_timing(swing_timing):
    """Wrap the timing's stages to accumulate their exclusive CPU time (restored by the returned
    undo)."""
    acc = dict.fromkeys(PARTS, 0.0)
    saved = {n: getattr(swing_timing, n) for n in _FUNCTIONS}
    nested = [0.0]  # CPU time of wrapped calls inside the running one

    def wrap(key, fn):
        def inner(*a, **k):
            outer, nested[0] = nested[0], 0.0
            t0 = time.process_time()
            try:
                return fn(*a, **k)
            finally:
                spent = time.process_time() - t0
                acc[key] += spent - nested[0]
                nested[0] = outer + spent

        return inner

    for n, k in _FUNCTIONS.items():
        setattr(swing_timing, n, wrap(k, saved[n]))

    def undo():
        for n in _FUNCTIONS:
            setattr(swing_timing, n, saved[n])

    return acc, undo


def _staged(swing_timing, fn) -> tuple[float, dict]:
    """CPU seconds of fn() and their split by stage (``STAGES``)."""
    acc, undo = _split_timing(swing_timing)
    try:
        t0 = time.process_time()
        fn()
        total = time.process_time() - t0
    finally:
        undo()
    return total, acc | {"other": total - sum(acc.values())}


def rate_table(rl, cf, n: int) -> list[dict]:
    """Per benchmark set and generator, the safe swings timed at 100 Hz and at 1 kHz."""
    from jaxexo.physics.scenarios import batch_options
    from jaxexo.swing.timing import time_swings

    from benchlib.scenes import safety_sets

    optimum = _optimum()
    rows = []
    for name, scenes in safety_sets(rl.config, n).items():
        obs, kw = [s.obstacle for s in scenes], batch_options(scenes)
        batches = {
            "rl": rl.generate_batch(obs, fallback=None, **kw),
            "cfftg": cf.generate_batch(obs, **kw),
        }
        for g, batch in batches.items():
            safe = [t for t in batch if t.ok]
            row = {"set": name, "generator": g, "n": len(safe)}
            for r in (100, 1000):
                timed = time_swings(safe, rl.config, rate=float(r))
                d = Summary.of([t.duration for t in timed])
                row[f"median_{r}"], row[f"p95_{r}"] = d.median, d.p95
                if optimum is not None:
                    o = Summary.of([t.duration / optimum(t) for t in timed])
                    row[f"optimum_median_{r}"], row[f"optimum_max_{r}"] = o.median, o.max
                if r == 1000:
                    row["within"] = float(np.mean([t.within_limits for t in timed]))
                    row["safe"] = float(np.mean([t.ok for t in timed]))
            rows.append(row)
    return rows


def _optimum():
    """toppra's velocity-acceleration optimum of a timed swing (benchlib.toppra_reference),
    or None where toppra is not installed (the bench extra installs it)."""
    try:
        import toppra  # noqa: F401
    except ImportError:
        return None
    from benchlib.toppra_reference import va_optimum

    return va_optimum


def _per_swing(gens, sc, cfg, rate: float, swing_timing) -> dict:
    """Per scene, both generators alternating: generate + time_swing CPU ms, and time_swing's
    stages (mean ms)."""
    total = {k: [] for k in gens}
    gen_ms = {k: [] for k in gens}
    timing_ms = {k: [] for k in gens}
    parts = {name: dict.fromkeys(STAGES, 0.0) for name in gens}
    for s in sc:
        for name, g in gens.items():
            t0 = time.process_time()
            traj = g(s)
            gen = time.process_time() - t0
            timed, acc = _staged(
                swing_timing, lambda: swing_timing.time_swing(traj, cfg, rate=rate)
            )
            total[name].append(1e3 * (gen + timed))
            gen_ms[name].append(1e3 * gen)
            timing_ms[name].append(1e3 * timed)
            for k, v in acc.items():
                parts[name][k] += 1e3 * v / len(sc)
    ready = {k: Summary.of(v) for k, v in total.items()}
    gen = {k: Summary.of(v) for k, v in gen_ms.items()}
    return {
        "device_ready_ms_median": {k: v.median for k, v in ready.items()},
        "device_ready_ms_p95": {k: v.p95 for k, v in ready.items()},
        "generate_ms_median": {k: v.median for k, v in gen.items()},
        "time_swing_ms_median": {k: Summary.of(v).median for k, v in timing_ms.items()},
        "rl_generate_over_cfftg": gen["rl"].over(gen["cfftg"]).median,
        "timing_parts_ms_mean": parts,
        "rl_over_cfftg": ready["rl"].over(ready["cfftg"]).median,
    }


def run_device_ready_benchmark(
    policy: str | Path, out_dir: str | Path, n: int = 300, batch: int = 1000, rate: float = 100.0
) -> dict:
    """``rate``: the first rate measured; 1 kHz is measured beside it."""
    from jaxexo.baselines import CFFTG
    from jaxexo.evaluation.machine import machine_info, write_result
    from jaxexo.inference import TrajectoryGenerator
    from jaxexo.inference.scenarios import safety_scenarios
    from jaxexo.swing import timing as swing_timing

    load_before = _load()
    rl = TrajectoryGenerator.load(policy)
    cfg = rl.config
    cf = CFFTG(cfg)
    sc = safety_scenarios(cfg, n, unseen=True)
    gens = {
        "rl": lambda s: rl.generate(s.obstacle, fallback=None, **s.options()),
        "cfftg": lambda s: cf.generate(s.obstacle, **s.options()),
    }
    for g in gens.values():  # warm caches (config scalars, smoothing bases)
        swing_timing.time_swing(g(sc[0]), cfg, rate=rate)
    # Every scene generated once first: a scene's first generation compiles for its shapes (on
    # threads whose CPU time the process time counts), which the first rate measured would carry.
    for s in sc:
        for g in gens.values():
            g(s)
    rates = sorted({float(rate), 1000.0})
    by_rate = {f"{r:g}": _per_swing(gens, sc, cfg, r, swing_timing) for r in rates}
    trajs = [gens["rl"](s) for s in (sc * (batch // len(sc) + 1))[:batch]]
    batch_s, batch_cpu, batch_parts = {}, {}, {}
    for r in rates:
        t0 = time.perf_counter()
        cpu, acc = _staged(swing_timing, lambda: swing_timing.time_swings(trajs, cfg, rate=r))
        batch_s[f"{r:g}"] = time.perf_counter() - t0
        batch_cpu[f"{r:g}"], batch_parts[f"{r:g}"] = cpu, acc
    payload = {
        "policy": str(policy),
        "n": len(sc),
        "scenes": "unseen shapes (safety_scenarios unseen=True)",
        "by_rate_hz": by_rate,
        "time_swings_batch": {
            "n": batch,
            "seconds_by_rate_hz": batch_s,
            "cpu_seconds_by_rate_hz": batch_cpu,
            "stages_cpu_s_by_rate_hz": batch_parts,
        },
        "durations_by_rate": rate_table(rl, cf, n),
        "targets": TARGETS,
        "machine": machine_info(),
        # 1/5/15-minute load averages (os.getloadavg) at the start and the end: a shared machine
        "load_average": {"start": load_before, "end": _load()},
    }
    md = _markdown(payload, policy)
    write_result("device_ready", payload, md, out_dir)
    print(md)
    return payload


def _load() -> list[float] | None:
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except (AttributeError, OSError):  # not on this platform
        return None


def _markdown(payload: dict, policy) -> str:
    m, by_rate, gens = payload["machine"], payload["by_rate_hz"], ("rl", "cfftg")
    lines = [
        "# Device-ready swing: generate + time_swing, RL alone vs CFFTG",
        "",
        f"Policy `{policy}`; {payload['n']} unseen-shape scenes, both generators alternating scene "
        f"by scene in one process; CPU ms per swing (process time); machine: {m['cpu']}, "
        f"{m['cores']} cores; other jobs may have run (load average 1/5/15 min: "
        f"{payload['load_average']['start']} at the start, {payload['load_average']['end']} at "
        "the end). The time law is the passes with their check on the curve.",
        "",
        *table(
            RATE_HEADER, [_rate_cells(r, f, k) for r, f in by_rate.items() for k in gens], "rlrrrrl"
        ),
        "",
    ] + [_rate_line(r, f) for r, f in by_rate.items()]
    b = payload["time_swings_batch"]
    lines += [
        "",
        f"time_swings of {b['n']} RL swings: "
        + ", ".join(
            f"{v:.2f} s at {k} Hz (target <= {TARGETS['batch_1000_s'].get(k, float('nan'))} s)"
            for k, v in b["seconds_by_rate_hz"].items()
        )
        + ". CPU s by stage ("
        + " / ".join(STAGES)
        + "): "
        + "; ".join(
            f"{k} Hz {b['cpu_seconds_by_rate_hz'][k]:.2f} = "
            + " / ".join(f"{v[x]:.2f}" for x in STAGES)
            for k, v in b["stages_cpu_s_by_rate_hz"].items()
        )
        + ".",
        "",
        "Timed swings (safe swings of each generator, RL alone) at 100 Hz and 1 kHz: duration "
        "median and p95 (s), the 1 kHz / 100 Hz ratio of each, the duration over toppra's "
        "velocity-acceleration optimum on the same joint path at the same (planned) limits "
        "(median and largest; benchlib.toppra_reference; n/a without toppra), and the "
        "shares within the limits on the curve and safe.",
        "",
        *table(
            DURATION_HEADER, map(_duration_cells, payload["durations_by_rate"]), "ll" + "r" * 13
        ),
    ]
    return "\n".join(lines + [""])


RATE_HEADER = (
    *("rate Hz", "generator", "device-ready median ms", "p95 ms", "of which generate (median)"),
    "time_swing alone (median)",
    "time_swing by stage (mean ms): " + " / ".join(STAGES),
)
DURATION_HEADER = (
    *("set", "generator", "n", "median 100 Hz", "p95 100 Hz", "median 1 kHz", "p95 1 kHz"),
    *("ratio median", "ratio p95"),
    *("/ optimum 100 Hz median", "max", "/ optimum 1 kHz median", "max"),
    *("within", "safe"),
)


def _rate_line(r: str, f: dict) -> str:
    """Rate ``r``'s figures against their targets."""
    t, ms = TARGETS, f["time_swing_ms_median"]
    return (
        f"{r} Hz: time_swing alone median RL {ms['rl']:.2f} ms, CFFTG {ms['cfftg']:.2f} ms (target "
        f"<= {t['time_swing_ms'].get(r, float('nan'))} ms); device-ready RL median "
        f"{f['device_ready_ms_median']['rl']:.2f} ms (target <= {t['rl_device_ready_ms']} ms), "
        f"RL / CFFTG **{f['rl_over_cfftg']:.2f}** (target <= {t['rl_over_cfftg']}); generate "
        f"RL / CFFTG {f['rl_generate_over_cfftg']:.2f} (target <= {t['rl_generate_over_cfftg']})."
    )


def _rate_cells(r: str, f: dict, k: str) -> tuple[str, ...]:
    """Rate ``r``'s row of generator ``k``: device-ready median and p95, generate, the parts (ms)."""
    p = f["timing_parts_ms_mean"][k]
    ms = (
        f["device_ready_ms_median"][k],
        f["device_ready_ms_p95"][k],
        f["generate_ms_median"][k],
        f["time_swing_ms_median"][k],
    )
    return (r, k, *(f"{x:.2f}" for x in ms), " / ".join(f"{p[x]:.2f}" for x in STAGES))


def _duration_cells(r: dict) -> tuple[str, ...]:
    """One set's and generator's timed durations at 100 Hz and 1 kHz, their ratios and shares."""
    d = (r["median_100"], r["p95_100"], r["median_1000"], r["p95_1000"])
    ratios = (r["median_1000"] / r["median_100"], r["p95_1000"] / r["p95_100"])
    return (
        *(r["set"], r["generator"], str(r["n"])),
        *(f"{x:.3f}" for x in d),
        *(f"{x:.4f}" for x in ratios),
        *(
            f"{r[k]:.3f}" if k in r else "n/a"
            for k in (
                "optimum_median_100",
                "optimum_max_100",
                "optimum_median_1000",
                "optimum_max_1000",
            )
        ),
        *(f"{r[k]:.3f}" for k in ("within", "safe")),
    )
