"""Merge the per-run evaluations (runs/<name>/reproduce_entry.json, or a reproduce.json) of several
`jaxexo reproduce --out DIR` folders into one benchmarks/results/reproduce_<date>_<machine>.{json,md}, slimmed
to the tabulated figures (< 100 KB). Used when the models were reproduced in parallel processes.

Run: python benchmarks/reproduce_combine.py DIR [DIR ...]"""
import json, sys
from pathlib import Path
from jaxexo.evaluation.reproduce import run_names, tables
from jaxexo.evaluation.machine import write_result
dirs = [Path(p) for p in sys.argv[1:]]
results = {}
for name in run_names(("a", "b", "c", "1", "2", "3", "final"), "both"):
    for d in dirs:
        e = d / "runs" / name / "reproduce_entry.json"
        if e.exists():
            results[name] = json.loads(e.read_text())["result"]; break
    else:
        for d in dirs:
            j = d / "reproduce.json"
            if j.exists() and name in (data := json.loads(j.read_text())):
                results[name] = data[name]; break
from jaxexo.evaluation.reproduce import compact
for r in results.values():
    for g in ("rl", "rl_eps", "cfftg"):
        if g in r: r[g] = compact(r[g])
print("have", list(results))
md = tables(results)
Path("/tmp/repro/reproduce.md").write_text(md)
KEEP = ("n", "accuracy", "success", "reached_goal", "time_ms_mean", "knee_swing_mean_deg", "hip_swing_mean_deg")
def slim(r):
    out = {k: r[k] for k in KEEP if k in r}
    for g in ("by_kind", "by_pivot"):
        if g in r: out[g] = {x: {k: v[k] for k in KEEP if k in v} for x, v in r[g].items()}
    for k in ("batch_1000_ms", "device"):
        if r.get(k) is not None: out[k] = r[k]
    return out
small = {n: {k: (slim(v) if k in ("rl", "rl_eps", "cfftg") else v) for k, v in r.items()} for n, r in results.items()}
for p in write_result("reproduce", json.loads(json.dumps(small)), md, "benchmarks/results"):
    print(p, p.stat().st_size)
