"""``jaxexo eval`` (jaxexo.evaluation.compare), ``jaxexo reproduce`` and ``jaxexo bench``'s summary, end to end on
the small policy trained once per session (conftest.trained_run)."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from jaxexo.evaluation.compare import evaluate_generators, make_scenarios
from jaxexo.evaluation.metrics import path_length, squared_jerk
from jaxexo.evaluation.report import markdown

from conftest import eval_against_cfftg

pytest.importorskip("jax")


def test_path_length_and_jerk_are_exact_on_known_paths():
    t = np.linspace(0.0, 2.0, 41)
    line = np.stack([0.3 * t, 0.4 * t], -1)
    np.testing.assert_allclose(path_length(line), 0.5 * 2.0)
    np.testing.assert_allclose(squared_jerk(line, t), 0.0, atol=1e-9)
    a = 0.7
    cubic = np.stack([a * t**3, 0 * t], -1)  # jerk 6a everywhere
    np.testing.assert_allclose(
        squared_jerk(cubic, t), (6 * a) ** 2 * (len(t) - 3) * (t[1] - t[0]), rtol=1e-9
    )


@pytest.fixture(scope="module")
def eval_out(trained_run, tmp_path_factory):
    out = tmp_path_factory.mktemp("eval")
    assert (
        eval_against_cfftg(trained_run, out, "--scenarios", "all", "--n", 30, "--batch", 100) == 0
    )
    return out


@pytest.mark.slow
def test_eval_writes_report_json_md_and_figures(eval_out, trained_run):
    from jaxexo.config import load_config

    lay = load_config(trained_run / "config.toml").layout
    train_kinds = (
        set(lay.terrain.families) if lay.terrain is not None else {o.kind for o in lay.obstacles}
    )
    assert train_kinds
    report = json.loads((eval_out / "report.json").read_text())
    assert set(report) == {"rl", "rl+cfftg", "cfftg"}
    for name, r in report.items():
        for key in (
            "accuracy",
            "success",
            "time_ms_median",
            "batch_1000_ms",
            "by_kind",
            "by_pivot",
        ):
            assert key in r, (name, key)
        assert r["n"] == 60 and r["batch_size"] == 100 and r["batch_1000_ms"] > 0
        # Test set (five thesis obstacles) and the training distribution: the run's procedural
        # terrain families (the default config) or its obstacle mixture's kinds.
        assert (
            set(r["by_kind"])
            == {"base1", "base2", "base3", "triangle", "half_circle"} | train_kinds
        )
        assert set(r["by_pivot"]) == {"agent", "obstacle", "between"}
    md = (eval_out / "report.md").read_text()
    assert "| rl | 60 |" in md and "| cfftg | 60 |" in md and "| rl+cfftg | 60 |" in md
    assert "(timed on 100, scaled)" in md
    # The summary first, then one table per concern, each narrow enough for a screen.
    heads = [ln for ln in md.splitlines() if ln.startswith("## ")]
    assert heads[:6] == [
        "## RL vs CFFTG",
        "## Safety and clearance",
        "## Wearer: lift and heel path",
        "## Wearer: device timing and smoothness",
        "## Generation time",
        "## Joint angles",
    ]
    tables = [ln for ln in md.splitlines() if ln.startswith("|")]
    assert max(ln.count("|") - 1 for ln in tables) <= 8
    # Cells read back against report.json: the summary's safe-swing column and a per-pivot row of
    # the safety table (each label's first row).
    cells: dict = {}
    for ln in tables:
        cells.setdefault(ln.split(" | ")[0][2:], ln.strip("| ").split(" | "))
    for name, r in report.items():
        assert cells[name][2] == f"{100 * r['success']:.1f}"
        assert cells[f"pivot between ({name})"][1] == str(r["by_pivot"]["between"]["n"])
    for fig in ("trajectories.png", "joint_angles.png"):
        assert (eval_out / fig).stat().st_size > 10_000


@pytest.mark.slow
def test_eval_numbers_are_consistent(eval_out):
    report = json.loads((eval_out / "report.json").read_text())
    for r in report.values():
        for key in ("by_kind", "by_pivot", "by_kind_pivot"):
            groups = r[key].values()
            assert sum(g["n"] for g in groups) == r["n"]
            assert all(g["batch_1000_ms"] > 0 for g in groups)
            for fig in (
                "accuracy",
                "success",
                "time_ms_mean",
                "hip_swing_mean_deg",
                "path_length_m_mean",
            ):
                np.testing.assert_allclose(
                    sum(g[fig] * g["n"] for g in groups) / r["n"], r[fig], rtol=1e-9
                )
        assert r["success"] <= r["accuracy"]
        assert r["time_ms_median"] <= r["time_ms_p95"]
        assert r["knee_swing_min_deg"] <= r["knee_swing_mean_deg"] <= 0.0 <= r["hip_swing_mean_deg"]
        assert r["min_clearance_m_worst"] <= r["min_clearance_m_mean"]
        assert r["path_length_m_mean"] > 0.6  # at least the step length
    # CFFTG plans every thesis and training obstacle of this config; the RL swing with the CFFTG
    # fallback is safe wherever either is.
    assert report["cfftg"]["success"] == 1.0
    assert report["rl+cfftg"]["success"] == 1.0 >= report["rl"]["success"]
    assert report["rl"]["fallback_rate"] == 0.0
    assert abs(report["rl+cfftg"]["fallback_rate"] - (1.0 - report["rl"]["success"])) < 1e-12


@pytest.mark.slow
def test_eval_figures_match_the_generators_own_outputs(trained_run):
    # The report's figures are those of the trajectories the generators return.
    from jaxexo.baselines import CFFTG
    from jaxexo.inference import TrajectoryGenerator

    rl = TrajectoryGenerator.load(trained_run / "policy.npz")
    gens = {"rl": rl, "cfftg": CFFTG(rl.config)}
    sc = make_scenarios(rl.config, "test", 20)
    report, trajs = evaluate_generators(gens, sc, batch_size=0)
    for name, g in gens.items():
        b = g.generate_batch(
            [s.obstacle for s in sc],
            pivot=[s.pivot for s in sc],
            start_y=[s.start_y for s in sc],
            step_length=[s.step_length for s in sc],
        )
        assert report[name]["success"] == pytest.approx(b.ok.mean())
        assert report[name]["accuracy"] == pytest.approx(b.collision_free.mean())
        np.testing.assert_allclose(
            report[name]["hip_swing_mean_deg"],
            np.degrees(b.joint_angles[..., 0].mean(axis=1).mean()),
            rtol=1e-6,
        )
        assert report[name]["batch_1000_ms"] is None
        # Device timing: the swings of the same paths timed for the [device] limits.
        from jaxexo.swing.timing import time_swings

        dev = report[name]["device"]
        timed = time_swings(trajs[name], rl.config)
        assert dev["swing_s_mean"] == pytest.approx(np.mean([t.duration for t in timed]))
        assert dev["device_within_limits"] == 1.0
        assert (
            dev["peak_knee_vel_deg_s_mean"] <= np.degrees(rl.config.device.joint_velocity[1]) + 1e-9
        )
        assert dev["uniform_peak_joint_vel_deg_s_median"] > dev["peak_knee_vel_deg_s_mean"]
        # What a wearer feels, recomputed here from the timed swings and the paths: duration p95 and max,
        # joint jerk (third differences of the exported angles at the control rate), lift above the top.
        dur = np.array([t.duration for t in timed])
        jerk = np.array(
            [
                float(((np.diff(t.joint_angles, n=3, axis=0) * t.rate**3) ** 2).sum() / t.rate)
                for t in timed
            ]
        )
        lift = np.array([t.heel[:, 1].max() - t.scene.obstacle.height for t in trajs[name]])
        assert dev["swing_s_p95"] == pytest.approx(np.percentile(dur, 95))
        assert dev["swing_s_max"] == pytest.approx(dur.max())
        assert dev["joint_jerk_median"] == pytest.approx(np.median(jerk), rel=1e-9)
        assert report[name]["peak_above_obstacle_m_p95"] == pytest.approx(np.percentile(lift, 95))
        for group in ("by_kind", "by_pivot"):
            for g, r in report[name][group].items():
                assert {"swing_s_p95", "joint_jerk_median", "joint_jerk_p95"} <= set(r["device"]), g
                assert "peak_above_obstacle_m_median" in r
    md = markdown(report, "t", [])
    assert "lift median cm" in md and "joint jerk median" in md
    with pytest.raises(ValueError, match="scenarios"):
        make_scenarios(rl.config, "everything", 5)


@pytest.mark.slow
def test_reproduce_tabulates_beside_the_thesis(trained_run, tmp_path):
    from jaxexo.evaluation.reproduce import run_reproduce

    # Finished runs are reused: stand the session's small policy in for models (a) and final.
    for name in ("a", "final"):
        d = tmp_path / "runs" / name
        d.mkdir(parents=True)
        for f in ("policy.npz", "eval.json"):
            shutil.copy(trained_run / f, d / f)
    res = run_reproduce(
        tmp_path, models=("a", "final"), n=15, batch_size=50, progress=lambda *_: None
    )
    assert set(res) == {"a", "final"} and "cfftg" in res["final"] and "cfftg" not in res["a"]
    md = (tmp_path / "reproduce.md").read_text()
    # Thesis values beside jaxexo's: Table 3.2 (a), 3.3, 3.10 accuracies, 3.11 CFFTG times.
    for thesis_value in (
        "2.46 / -51.0 / 35.4",
        "2.53 / -47.2 / 41.1",
        "| a | faithful | 58.2 |",
        "| final | faithful | 94.7 |",
        "2.055",
        "| a | faithful | 12 ± 3 min |",
        "| final | faithful | 55 min 27 s |",
    ):
        assert thesis_value in md, thesis_value
    assert (
        "Device timing" in md
        and f"| final (cfftg) | {res['final']['cfftg']['device']['swing_s_mean']:.3f} |" in md
    )
    acc, suc = 100 * res["final"]["rl"]["accuracy"], 100 * res["final"]["rl"]["success"]
    assert f"| final | faithful | 94.7 | {acc:.1f} | {suc:.1f} |" in md
    # The thesis's epsilon-greedy test (2.6) beside the greedy one, with its epsilon stated.
    from jaxexo.inference import TrajectoryGenerator

    eps = TrajectoryGenerator.load(trained_run / "policy.npz").config.train.eps_end
    assert res["a"]["test_epsilon"] == eps and f"ε = {eps:g}" in md
    assert res["a"]["rl_eps"]["n"] == 15 and "by_kind_pivot" not in res["a"]["rl"]
    # The exploring swings are not timed for the device (no table reads it); the greedy ones are.
    assert "device" not in res["a"]["rl_eps"] and "device" in res["a"]["rl"]
    assert json.loads((tmp_path / "reproduce.json").read_text())["a"]["rl"]["n"] == 15
    # A second call reuses each run's kept evaluation (same n, seed, batch size), and only then.
    said = []
    again = run_reproduce(
        tmp_path, models=("a", "final"), n=15, batch_size=50, progress=said.append
    )
    assert json.dumps(again, sort_keys=True) == json.dumps(res, sort_keys=True)
    assert sum("reusing its evaluation" in m for m in said) == 2
    said.clear()
    run_reproduce(tmp_path, models=("a",), n=10, batch_size=50, progress=said.append)
    assert not any("reusing its evaluation" in m for m in said)


def test_reproduce_refuses_unknown_models_and_variants():
    from jaxexo.evaluation.reproduce import run_names

    assert run_names(("a", "final"), "both") == ["a", "a-learns", "final", "final-learns"]
    assert run_names(("b",), "learns") == ["b-learns"]
    with pytest.raises(ValueError, match="--variant"):
        run_names(("a",), "fast")
    with pytest.raises(ValueError, match="--models: unknown model 'z'"):
        run_names(("z",), "both")


@pytest.mark.slow
def test_exploring_generator_is_seeded_and_differs_from_greedy(trained_run):
    """Epsilon-greedy testing (thesis 2.6): the same seed gives the same paths; epsilon 1 is a random
    walk that leaves the greedy path; the greedy generator is untouched by the copy."""
    from jaxexo.inference import Obstacle, TrajectoryGenerator

    gen = TrajectoryGenerator.load(trained_run / "policy.npz")
    scenes = [gen.scene(Obstacle.named("base1"), "obstacle", None, 0.0, 0.70)] * 4
    greedy = gen.rollout_batch(scenes)[0]
    a = gen.exploring(1.0, seed=3).rollout_batch(scenes)[0]
    b = gen.exploring(1.0, seed=3).rollout_batch(scenes)[0]
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert any(len(x) != len(g) or not np.allclose(x, g) for x, g in zip(a, greedy))
    assert all(np.array_equal(x, g) for x, g in zip(gen.rollout_batch(scenes)[0], greedy))
    assert all(
        np.array_equal(x, g) for x, g in zip(gen.exploring(0.0).rollout_batch(scenes)[0], greedy)
    )
    with pytest.raises(ValueError, match="epsilon"):
        gen.exploring(1.5)


@pytest.mark.slow
def test_bench_summary_from_the_compare_part(trained_run, tmp_path):
    from benchlib.run_all import run_all

    with pytest.raises(ValueError, match="--skip"):
        run_all(tmp_path, skip="gpu")
    res = run_all(
        tmp_path,
        policy=trained_run / "policy.npz",
        skip="env,train,generate,baseline,course",
        n=20,
        batch_size=50,
        progress=lambda *_: None,
    )
    summary = next(tmp_path.glob("summary_*.md")).read_text()
    assert "| rl on 20 test scenarios" in summary and "| cfftg on 20 test scenarios" in summary
    assert f"{res['compare']['cfftg']['success']:.3f}" in summary
    assert next(tmp_path.glob("compare_*.json")).stat().st_size > 1000
    # Skipped parts are summarised from their latest result files.
    for f in tmp_path.glob("summary_*"):
        f.unlink()
    run_all(
        tmp_path,
        skip=",".join(("env", "train", "generate", "compare", "baseline", "course")),
        progress=lambda *_: None,
    )
    again = next(tmp_path.glob("summary_*.md")).read_text()
    assert "| rl on 20 test scenarios" in again and "compare: from compare_" in again


def test_bench_keeps_the_policy_it_trained_until_the_course_part_has_run(tmp_path, monkeypatch):
    """Without --policy, ``jaxexo bench`` trains one into a temporary directory; the course part, the
    last to swing it, runs while that directory still exists (it once ran after the directory was
    removed). Training is stood in for by a policy file written where it would be."""
    from pathlib import Path

    from jaxexo.train import driver

    from benchlib import course_bench
    from benchlib.run_all import run_all
    from test_reliability_inputs import make_policy

    def train(cfg, out, **_):
        Path(out).mkdir(parents=True)
        make_policy(Path(out) / "policy.npz")

    seen = []

    def course(policy, out_dir, n, progress=None):
        seen.append(Path(policy).is_file())
        return {
            "planned": n,
            "courses_drawn": n,
            "refused": 0,
            "rl_alone_success": 1.0,
            "cfftg_success": 1.0,
            "duration_ratio_rl_over_cfftg": {"median": None},
            "per_step_over_one_swing_median": None,
        }

    monkeypatch.setattr(driver, "run_training", train)
    monkeypatch.setattr(course_bench, "run_course_benchmark", course)
    res = run_all(
        tmp_path,
        skip="env,train,generate,compare,baseline",
        courses=1,
        progress=lambda *_: None,
    )
    assert seen == [True]
    assert res["course"]["planned"] == 1
    assert "walks over 1 courses" in next(tmp_path.glob("summary_*.md")).read_text()


@pytest.mark.slow
def test_cli_generate_cfftg_with_a_policys_kinematics(trained_run, tmp_path):
    from jaxexo.baselines import CFFTG
    from jaxexo.cli import main
    from jaxexo.inference import TrajectoryGenerator

    g = CFFTG.from_policy(trained_run / "policy.npz")
    assert g.config == TrajectoryGenerator.load(trained_run / "policy.npz").config
    out = tmp_path / "c.json"
    assert (
        main(
            [
                "generate",
                "--method",
                "cfftg",
                "--policy",
                str(trained_run / "policy.npz"),
                "--obstacle",
                "half_circle",
                "--pivot",
                "between",
                "--out",
                str(tmp_path / "c.csv"),
                "--json",
                str(out),
            ]
        )
        == 0
    )
    doc = json.loads(out.read_text())
    assert doc["method"] == "cfftg" and doc["checks"]["ok"] and len(doc["raw"]) == 3


def test_device_metrics_time_the_moving_swings_and_count_a_still_one_as_zero(trained_run):
    # A policy that stands still (the faithful thesis configs learn to) makes a path the swing timer
    # cannot time; the report must still be written: that swing counts 0 s, the others are timed as alone.
    import dataclasses

    from jaxexo.evaluation.metrics import device_metrics
    from jaxexo.inference import TrajectoryGenerator
    from jaxexo.swing.timing import time_swings

    rl = TrajectoryGenerator.load(trained_run / "policy.npz")
    sc = make_scenarios(rl.config, "test", 2)
    moving = [
        rl.generate(s.obstacle, pivot=s.pivot, start_y=s.start_y, step_length=s.step_length)
        for s in sc
    ]
    t = moving[0]
    still = dataclasses.replace(
        t,
        heel=np.repeat(t.heel[:1], len(t.heel), 0),
        joint_angles=np.repeat(t.joint_angles[:1], len(t.joint_angles), 0),
    )
    with pytest.raises(ValueError, match="do not move"):
        time_swings([still], rl.config)
    m = device_metrics([moving[0], still, moving[1]], rl.config)
    alone = time_swings(moving, rl.config)
    np.testing.assert_allclose(m.swing_s, [alone[0].duration, 0.0, alone[1].duration])
    assert m.swing_s[0] > 0 and m.peak_hip_vel[1] == 0 and m.uniform_peak_vel[1] == 0
    assert m.within_limits.tolist() == [alone[0].within_limits, True, alone[1].within_limits]


def test_reproduce_refuses_a_finished_run_of_another_config(trained_run, tmp_path):
    """A run directory trained with a config other than the model's (the thesis file edited since, or a
    stray run) must not be tabulated under that model's name."""
    from jaxexo.evaluation.reproduce import run_reproduce

    d = tmp_path / "runs" / "a"
    d.mkdir(parents=True)
    for f in ("policy.npz", "eval.json", "config.toml"):
        shutil.copy(trained_run / f, d / f)  # the quick model's config, not thesis (a)'s
    with pytest.raises(ValueError, match=r"runs/a: trained with a different config than .*a\.toml"):
        run_reproduce(tmp_path, models=("a",), variant="faithful", n=5, progress=lambda *_: None)
