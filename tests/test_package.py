"""Package-level promises: NumPy-only imports, the README's test command, the CLI."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

from conftest import ROOT


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120
    )


def test_import_does_not_pull_in_jax():
    code = (
        "import sys\n"
        "import jaxexo, jaxexo.config, jaxexo.physics.geometry, jaxexo.physics.kinematics, jaxexo.physics.rewards\n"
        "from jaxexo import Config, ConfigError, load_config, Obstacle, GeometryError\n"
        "cfg = load_config('configs/default.toml')\n"
        "Obstacle.named('half_circle').clearance([[0.0, 0.0]], 0.2)\n"
        "bad = sorted(m for m in sys.modules if m == 'jax' or m.startswith(('jax.', 'jaxlib', 'flax')))\n"
        "print('LOADED', bad)\n"
    )
    out = _run(code)
    assert out.returncode == 0, out.stderr
    assert "LOADED []" in out.stdout, out.stdout


def test_env_import_does_pull_in_jax():
    # Sanity check of the probe above: the environment does need JAX.
    out = _run("import sys, jaxexo.env\nprint('jax' in sys.modules)")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "True"


def _bash_blocks(text: str) -> list[str]:
    return [b.strip() for b in re.findall(r"```bash\n(.*?)```", text, flags=re.S)]


def test_readme_test_command_is_what_ci_runs():
    readme = (ROOT / "README.md").read_text()
    blocks = _bash_blocks(readme)
    assert len(blocks) >= 2
    test_cmd = blocks[1]
    assert "pytest" in test_cmd
    ci_lines = [
        ln.strip()
        for ln in (ROOT / ".ci" / "run").read_text().splitlines()
        if ln.strip() and not ln.lstrip().startswith("#")
    ]
    # The README's steps run in .ci/run in its order, the style gate (ruff) between install and tests.
    ci_steps = [step for ln in ci_lines for step in ln.split(" && ")]
    readme_steps = test_cmd.split(" && ")
    at = [ci_steps.index(step) for step in readme_steps if step in ci_steps]
    assert len(at) == len(readme_steps) and at == sorted(at), (
        f"README test command {test_cmd!r} not run step by step by .ci/run"
    )
    gate = [
        ci_steps.index(".venv/bin/ruff format --check ."),
        ci_steps.index(".venv/bin/ruff check ."),
    ]
    assert at[-2] < min(gate) and max(gate) < at[-1], (
        "ruff runs after the install, before the tests"
    )
    # The CI runs it from the repository root on a fresh environment.
    ci = (ROOT / ".ci" / "run").read_text()
    assert "set -euo pipefail" in ci and 'cd "$(dirname "$0")/.."' in ci and "rm -rf .venv" in ci
    # The test extra the command installs holds the tools this suite imports.
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert "[train,test]" in test_cmd
    for tool in ("pytest", "hypothesis", "gymnax"):
        assert re.search(rf'test = \[[^\]]*"{tool}', pyproject), tool
    assert re.search(r'train = \[[^\]]*"chex', pyproject)


def test_cli_help():
    out = subprocess.run(
        [sys.executable, "-m", "jaxexo.cli", "--help"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    assert "bench-env" in out.stdout
    assert out.stdout.startswith("usage: jaxexo")


def test_cli_requires_a_command():
    out = subprocess.run(
        [sys.executable, "-m", "jaxexo.cli"], capture_output=True, text=True, cwd=ROOT, timeout=120
    )
    assert out.returncode == 2
    assert "required" in out.stderr


def test_cli_bad_config_is_a_clean_error(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[env]\nstep_size = -1\n")
    out = subprocess.run(
        [sys.executable, "-m", "jaxexo.cli", "bench-env", "--config", str(bad), "--envs", "1"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert out.returncode == 2
    assert "env.step_size" in out.stderr and "Traceback" not in out.stderr


@pytest.mark.parametrize("envs", ["0", "a,b", ""])
def test_cli_bad_envs(envs):
    from jaxexo.cli import build_parser

    with pytest.raises(SystemExit):
        build_parser().parse_args(["bench-env", "--envs", envs])


def test_version():
    import jaxexo

    assert re.fullmatch(r"\d+\.\d+\.\d+", jaxexo.__version__)
    assert set(jaxexo.__all__) >= {
        "Config",
        "ConfigError",
        "load_config",
        "Obstacle",
        "GeometryError",
    }


def test_the_benchmark_commands_outside_a_checkout_name_the_missing_folder(
    tmp_path, monkeypatch, capsys
):
    """An installed jaxexo has no benchmark suite: bench and bench-env say which folder they lack."""
    from jaxexo.cli import bench, main

    monkeypatch.setattr(bench, "SUITE", tmp_path / "benchmarks")
    for argv in (["bench-env", "--envs", "1"], ["bench", "--skip", "env"]):
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert f"no {tmp_path}/benchmarks/benchlib" in err and "source checkout" in err, err


def test_bench_runs_the_checkouts_suite_from_any_folder(tmp_path):
    """``jaxexo bench`` from outside the checkout's root: the suite (benchmarks/benchlib) is found
    beside the package; every part skipped, it writes the (empty) summary."""
    skip = "env,train,generate,compare,baseline,course"
    out = subprocess.run(
        [sys.executable, "-m", "jaxexo.cli", "bench", "--skip", skip, "--out", str(tmp_path / "r")],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    assert "# jaxexo benchmark summary" in out.stdout and list(
        (tmp_path / "r").glob("summary_*.md")
    )
