"""``jaxexo sweep``: run a sweep's chunks on the local CPU devices or as Ray tasks, with one progress bar,
results streamed to DIR/results.csv and ``--resume``, then the report (jaxexo.sweep.report). The
backends and resume: docs/training.md, "Hyperparameter sweeps".
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from jaxexo.config import ConfigError
from jaxexo.storage.rundir import RunDirError, contents, describe, run_lock
from jaxexo.sweep import results as R
from jaxexo.sweep.plan import (
    Chunk,
    check_memory_budget,
    default_memory_budget,
    local_cpu_count,
    make_plan,
)
from jaxexo.sweep.spec import Sweep, sweep_from_dict

BACKENDS = ("local", "ray")


def _prepare(
    sweep: Sweep, out: Path, resume: bool, devices: int, budget: int
) -> tuple[dict, list[dict]]:
    """The plan (new, or the stored one on resume) and the rows of the chunks already finished."""
    plan_path, results = out / R.PLAN, out / R.RESULTS
    if resume:
        if not plan_path.exists():
            raise ConfigError(f"--resume: {out} holds no sweep to resume (no {R.PLAN})")
        plan = json.loads(plan_path.read_text())
        if plan["fingerprint"] != sweep.fingerprint():
            raise ConfigError(
                f"--resume: the sweep differs from the one in {out} (axes, seeds or base config "
                "changed); resume with the same sweep file or pick a new --out"
            )
        chunks = {c["chunk_id"]: Chunk.from_json(c) for c in plan["chunks"]}
        rows = R.read_rows(results)
        by_chunk: dict = {}
        for r in rows:
            by_chunk.setdefault(int(r["chunk"]), []).append(r)
        done = {
            c
            for c, rs in by_chunk.items()
            if c in chunks and len(rs) == len(chunks[c].agents) and R.chunk_path(out, c).exists()
        }
        rows = [r for r in rows if int(r["chunk"]) in done]
        R.write_rows(results, R.columns(sweep), rows)  # drops rows of unfinished chunks, torn lines
        return plan, rows
    if plan_path.exists():
        raise ConfigError(
            f"--out: {out} already holds a sweep; pass --resume to continue it or pick a new folder"
        )
    present = contents(out)
    if present:
        raise RunDirError(
            f"--out: {out} is not empty ({describe(present)}) and holds no sweep ({R.PLAN}); a new "
            "sweep needs an empty or absent directory: pick another --out, or move those files away"
        )
    chunks = make_plan(sweep, devices, budget)
    plan = {
        "fingerprint": sweep.fingerprint(),
        "devices": devices,
        "memory_budget": budget,
        "agents": sweep.num_agents,
        "chunks": [c.to_json() for c in chunks],
    }
    out.mkdir(parents=True, exist_ok=True)
    R.atomic_write(out / R.SWEEP_FILE, json.dumps(sweep.to_dict(), indent=1) + "\n")
    R.write_rows(results, R.columns(sweep), [])
    R.atomic_write(plan_path, json.dumps(plan, indent=1) + "\n")
    return plan, []


def _check_heatmap(sweep: Sweep, heatmap) -> None:
    if heatmap is not None:
        axes = [a.path for a in sweep.axes] + ["seed"]
        if len(heatmap) != 2 or any(h not in axes for h in heatmap) or heatmap[0] == heatmap[1]:
            raise ConfigError(
                f"--heatmap: expected two different axes of the sweep ({', '.join(axes)}), "
                f"got {','.join(heatmap)}"
            )


class Tally:
    """A sweep run's rows so far (the finished chunks' ones first) and its progress bar: each chunk's
    result, as it finishes, saved, its rows appended to results.csv and counted (env steps run, best
    success, diverged agents)."""

    def __init__(self, sweep: Sweep, out: Path, rows: list[dict], n_chunks: int, backend, progress):
        self.sweep, self.out, self.rows = sweep, out, rows
        self.group_of = {cid: g.group_id for g in sweep.groups for cid in g.config_ids}
        self.cols = R.columns(sweep)
        self.bar = None
        if progress:
            from tqdm.auto import tqdm

            self.bar = tqdm(
                total=sweep.num_agents,
                initial=len(rows),
                unit="agent",
                dynamic_ncols=True,
                desc=f"sweep ({n_chunks} chunks, {backend})",
            )
        self.t_start, self.steps_run = time.perf_counter(), 0.0
        self.best = max(
            (float(r["success"]) for r in rows if r["diverged"] == "0"), default=float("-inf")
        )
        self.diverged = sum(int(r["diverged"]) for r in rows)

    def finished(self, result: R.ChunkResult) -> None:
        R.save_chunk(self.out, result)
        new = R.chunk_rows(self.sweep, result, self.group_of)
        R.append_rows(self.out / R.RESULTS, self.cols, new)
        self.rows.extend(new)
        self.steps_run += float(result.scalars["env_steps"].sum())
        self.best = max([self.best] + [float(r["success"]) for r in new if r["diverged"] == "0"])
        self.diverged += sum(int(r["diverged"]) for r in new)
        if self.bar is not None:
            self.bar.update(len(new))
            self.bar.set_postfix(
                steps_per_s=f"{self.steps_run / (time.perf_counter() - self.t_start):.3g}",
                best_success=f"{self.best:.3f}",
                diverged=self.diverged,
            )

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _report(tally: Tally, heatmap, export_best: bool, export_all: bool) -> dict:
    """results.csv in config and seed order, the report, the exports; the report's figures."""
    from jaxexo.sweep import report

    sweep, out, rows = tally.sweep, tally.out, tally.rows
    rows.sort(key=lambda r: (int(r["config_id"]), int(r["seed"])))
    R.write_rows(out / R.RESULTS, tally.cols, rows)
    summary = report.write_report(sweep, out, rows, heatmap=heatmap)
    summary["wall_s_this_run"] = time.perf_counter() - tally.t_start
    summary["env_steps_this_run"] = tally.steps_run
    if export_best:
        summary["exported"] = report.export_best(sweep, out, rows)
    if export_all:
        summary["exported_all"] = report.export_all(sweep, out, rows)
    return summary


def run_sweep(
    sweep: Sweep,
    out: str | Path,
    *,
    resume: bool = False,
    backend: str = "local",
    address: str | None = None,
    memory_budget: int | None = None,
    task_cpus: int | None = None,
    progress: bool = True,
    export_best: bool = False,
    export_all: bool = False,
    heatmap=None,
    devices=None,
) -> dict:
    """Run (or finish) the sweep into ``out``; write the report; return the report's figures.

    ``devices``: local backend only, the JAX devices to split chunks over (default: all local ones).
    ``task_cpus``: Ray backend only, CPUs (and JAX devices) per chunk task (default: this machine's
    core count)."""
    if backend not in BACKENDS:
        raise ConfigError(f"--backend: must be one of {list(BACKENDS)}, got {backend!r}")
    out = Path(out)
    _check_heatmap(sweep, heatmap)
    budget = memory_budget or sweep.memory_budget or default_memory_budget()
    if backend == "local" and (memory_budget or sweep.memory_budget):
        check_memory_budget(budget, f"{budget / 2**30:.4g} GiB", "memory_budget")
    if backend == "local":
        import jax

        devices = list(devices or jax.local_devices())
        n_dev = len(devices)
    else:
        n_dev = task_cpus or local_cpu_count()
    # One sweep process per directory for the whole run (jaxexo.storage.rundir): a second one would
    # interleave results.csv rows and overwrite chunk files.
    with run_lock(out, "sweep", create=not resume):
        plan, rows = _prepare(sweep, out, resume, n_dev, budget)
        chunks = [Chunk.from_json(c) for c in plan["chunks"]]
        done = {int(r["chunk"]) for r in rows}
        pending = [c for c in chunks if c.chunk_id not in done]
        if backend == "local" and plan["devices"] != n_dev:
            raise ConfigError(
                f"--resume: the sweep was planned for {plan['devices']} device(s), this process has "
                f"{n_dev}; resume it on the same number of CPU devices"
            )
        tally = Tally(sweep, out, rows, len(chunks), backend, progress)
        if pending:
            if backend == "local":
                from jaxexo.sweep.program import run_chunk

                for c in pending:
                    tally.finished(run_chunk(sweep, c, devices))
            else:
                _run_ray(sweep, pending, plan["devices"], address, tally.finished)
        tally.close()
        return _report(tally, heatmap, export_best, export_all)


# --------------------------------------------------------------------------------------------
# Ray
# --------------------------------------------------------------------------------------------

_WORKER_SWEEPS: dict = {}


def ray_chunk_task(sweep_dict: dict, chunk: dict, devices: int) -> R.ChunkResult:
    """A Ray task: one chunk on a worker exposing ``devices`` CPU devices to JAX."""
    from jaxexo.train.devices import use_all_cpu_cores

    use_all_cpu_cores(devices)
    import jax

    from jaxexo.sweep.program import run_chunk

    local = jax.local_devices()
    if len(local) < devices:
        raise RuntimeError(
            f"this Ray worker has {len(local)} JAX device(s), the sweep was planned for {devices}; "
            "start workers without XLA_FLAGS forcing another host device count"
        )
    key = json.dumps(sweep_dict, sort_keys=True, default=repr)
    if key not in _WORKER_SWEEPS:
        _WORKER_SWEEPS.clear()
        _WORKER_SWEEPS[key] = sweep_from_dict(sweep_dict)
    return run_chunk(_WORKER_SWEEPS[key], Chunk.from_json(chunk), local[:devices])


def _run_ray(
    sweep: Sweep, pending: list[Chunk], devices: int, address: str | None, finished
) -> None:
    try:
        import ray
    except ImportError:
        raise ConfigError(
            "--backend ray: Ray is not installed (pip install 'jaxexo[distributed]')"
        ) from None
    started = not ray.is_initialized()
    if started:
        if address:
            ray.init(address=address, logging_level="WARNING")
        else:
            ray.init(
                num_cpus=max(devices, local_cpu_count()),
                include_dashboard=False,
                logging_level="WARNING",
            )
    try:
        task = ray.remote(num_cpus=devices, max_retries=0)(ray_chunk_task)
        spec = ray.put(sweep.to_dict())
        waiting = [task.remote(spec, c.to_json(), devices) for c in pending]
        while waiting:
            ready, waiting = ray.wait(waiting, num_returns=1)
            finished(ray.get(ready[0]))
    finally:
        if started:
            ray.shutdown()
