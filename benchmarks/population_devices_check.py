"""Does a population member's arithmetic depend on the number of CPU devices?

tests/test_population.py checks group-size independence in one process (one device). This script
trains the test's tiny config in fresh processes with 1, 2 and 4 CPU devices: seed 3 alone and as
the fourth member of a population of 5, each on every device the process has (the devices a
population of 5 uses; jaxexo.train.population.population_devices gives at least two), and compares
the final parameters' bytes within each process and across device counts.

Writes benchmarks/results/population-devices_<date>_<machine>.{json,md}.

Run: python benchmarks/population_devices_check.py
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

CHILD = r"""
import hashlib, json, sys
sys.path.insert(0, sys.argv[1])
import numpy as np
import jax
import test_population as T
from jaxexo.train import population as P

P.population_devices = lambda n, devices: list(devices)    # every device of the process
five = T.train_members([0, 1, 2, T.SEED, 4])[T.SEED]
one = T.train_members([T.SEED])[0]
digest = lambda m: hashlib.sha256(b"".join(np.ascontiguousarray(x).tobytes() for x in T.leaves(m["params"]))
                                  + m["metrics"].tobytes()).hexdigest()
print("RESULT " + json.dumps({"devices": len(jax.local_devices()), "alone": digest(one), "fourth_of_five": digest(five)}))
"""


def run(devices: int) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={devices}"
    out = subprocess.run([sys.executable, "-c", CHILD, str(ROOT / "tests")], cwd=ROOT / "tests", env=env,
                         capture_output=True, text=True, timeout=1800)
    if out.returncode:
        raise RuntimeError(out.stderr[-3000:])
    return json.loads(next(x for x in out.stdout.splitlines() if x.startswith("RESULT "))[7:])


def main() -> None:
    from jaxexo.evaluation.machine import write_result

    rows = [run(d) for d in (1, 2, 4)]
    lines = ["# Population members across device counts", "",
             "The tiny config of tests/test_population.py, seed 3, trained alone and as the fourth member of a "
             "population of 5, in a fresh process with 1, 2 and 4 CPU devices (the population spread over all of "
             "them); sha256 of the final parameters and per-update metrics.", "",
             "| devices | alone | fourth of five | equal |", "|---:|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['devices']} | {r['alone'][:16]} | {r['fourth_of_five'][:16]} | "
                     f"{'yes' if r['alone'] == r['fourth_of_five'] else 'no'} |")
    same = {f"{a['devices']} vs {b['devices']}": a["alone"] == b["alone"] for a in rows for b in rows
            if a["devices"] < b["devices"]}
    lines += ["", "Across device counts (alone): " + ", ".join(f"{k}: {'equal' if v else 'differ'}"
                                                         for k, v in same.items())]
    for p in write_result("population-devices", {"rows": rows, "across": same}, "\n".join(lines),
                          ROOT / "benchmarks" / "results"):
        print(p)


if __name__ == "__main__":
    main()
