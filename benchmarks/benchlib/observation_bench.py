"""Observation study: does seeing the obstacle's height profile (env.obs_profile = "shape") beat its
bounding box ("bbox") on shapes never trained on? Method: docs/benchmarks.md#what-each-benchmark-measures."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from jaxexo.config import config_from_dict
from jaxexo.evaluation.unseen import family_cells
from jaxexo.physics import terrain
from jaxexo.summary import table

from benchlib.scenes import set_table

STUDY_SEED = 7
SEEN_SEED = 31_337
MAX_WIDTH = 0.26


def training_profiles(per_family: int = 8, seed: int = STUDY_SEED) -> list[dict]:
    """Config ``layout.obstacles`` entries: per training family, ``per_family`` drawn shapes."""
    rng = np.random.default_rng(seed)
    out = []
    for fam in terrain.TRAIN_FAMILIES:
        got = 0
        while got < per_family:
            u, _ = terrain.draw_uniforms(rng, 1)
            o, w, h = terrain.one_family_outline(np, fam, u.astype(np.float64))
            w, h = float(w[0]), float(h[0])
            if w > MAX_WIDTH:
                continue
            pts = terrain.unpad(o[0])
            out.append(
                {
                    "kind": "profile",
                    "points": [[float(y), float(z)] for y, z in pts],
                    "width": [0.85 * w, w],
                    "height": [0.85 * h, h],
                }
            )
            got += 1
    return out


def study_config(base_toml: str | Path, obs_profile: str, budget: int, per_family: int = 8):
    import tomllib

    raw = tomllib.loads(Path(base_toml).read_text())
    raw["env"]["obs_profile"] = obs_profile
    raw["layout"]["obstacles"] = training_profiles(per_family)
    raw["layout"]["step_length"] = [0.65, 0.80]
    raw["train"]["budget_env_steps"] = int(budget)
    return config_from_dict(raw)


def run_observation_study(
    out_dir: str | Path,
    base_toml: str | Path,
    runs_dir: str | Path,
    budget: int = 8_000_000,
    repeats: int = 2,
    seed: int = 0,
) -> dict:
    from jaxexo.baselines import CFFTG
    from jaxexo.evaluation.compare import run_generators
    from jaxexo.evaluation.machine import write_result
    from jaxexo.evaluation.unseen import family_table
    from jaxexo.inference import TrajectoryGenerator
    from jaxexo.physics.scenarios import unseen_scenarios
    from jaxexo.train.driver import run_training

    runs_dir = Path(runs_dir)
    models, train_info = {}, {}
    for mode in ("bbox", "shape"):
        cfg = study_config(base_toml, mode, budget)
        t0 = time.perf_counter()
        ev = run_training(cfg, runs_dir / mode, seed=seed, progress=False)
        train_info[mode] = {
            "train_seconds": time.perf_counter() - t0,
            "eval_success": ev.get("success"),
            "episodes": ev.get("episodes"),
            "env_steps": ev.get("env_steps"),
        }
        models[mode] = TrajectoryGenerator.load(runs_dir / mode / "policy.npz")
    foot = models["bbox"].config.kinematics.foot_length
    sets = {
        "unseen": unseen_scenarios(foot, repeats),
        "seen": unseen_scenarios(foot, repeats, seed=SEEN_SEED, families=terrain.TRAIN_FAMILIES),
    }
    gens = {
        "rl_bbox": models["bbox"],
        "rl_shape": models["shape"],
        "cfftg": CFFTG(models["bbox"].config),
    }
    tables, overall = {}, {}
    for name, sc in sets.items():
        runs = run_generators(gens, sc, warmup=5)
        trajs = {g: r.trajectories for g, r in runs.items()}
        tables[name] = family_table(trajs, sc)
        overall[name] = {
            g: {
                "n": len(tr),
                "success": float(np.mean([t.ok for t in tr])),
                "accuracy": float(np.mean([t.checks.collision_free for t in tr])),
            }
            for g, tr in trajs.items()
        }
    payload = {
        "budget_env_steps": budget,
        "seed": seed,
        "repeats": repeats,
        "train": train_info,
        "overall": overall,
        "by_family": tables,
    }
    md = markdown(payload)
    write_result("observation", payload, md, out_dir)
    return payload


def markdown(p: dict) -> str:
    lines = [
        "# Observation study: bbox vs shape profile on unseen obstacle families",
        "",
        f"Two policies trained from configs/default.toml on profile obstacles drawn from the training "
        f"families ({', '.join(terrain.TRAIN_FAMILIES)}), differing only in env.obs_profile; "
        f"{p['budget_env_steps']:,} env steps each, seed {p['seed']}. Scored by the NumPy generator on "
        f"the held-out benchmark (families {', '.join(terrain.HELD_OUT_FAMILIES)}) and on fresh draws of "
        "the training families placed the same way (seen); CFFTG on the same scenes.",
        "",
        *table(
            ("model", "train s", "trainer eval success (its own test layouts)"),
            [(m, f"{t['train_seconds']:.0f}", t["eval_success"]) for m, t in p["train"].items()],
        ),
        "",
    ]
    lines += set_table(
        ("n", "strict success %", "accuracy %"),
        p["overall"],
        lambda r: f"{r['n']} | {100 * r['success']:.1f} | {100 * r['accuracy']:.1f}",
    )
    header = ("family", "generator", "n", "strict success %", "accuracy %", "clearance min cm")
    header += ("p5 cm", "median cm", "path length mean cm")
    for s, fams in p["by_family"].items():
        rows = [(fam, g, *family_cells(r)) for fam, gens in fams.items() for g, r in gens.items()]
        lines += ["", f"## {s}: per family", "", *table(header, rows, "ll" + "r" * 7)]
    return "\n".join(lines)
