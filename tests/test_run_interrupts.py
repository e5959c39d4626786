"""Runs that do what was asked, or say why not: Ctrl-C honoured from the first instant of
``jaxexo train`` (it was lost in JAX's garbage-collector callback and the run trained on to exit 0),
never in the middle of a write; a resume refused when metrics.jsonl no longer holds the chunks its
checkpoint proves; a sweep's memory budget bounded by the memory this process can use
(docs/reliability.md, "Runs and replays")."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from jaxexo.config import ConfigError
from jaxexo.config.toml_io import config_to_toml

from conftest import (
    ROOT,
    SEED,
    TINY_N,
    TINY_T,
    cli_cmd,
    run_cli,
    tiny_config,
    without_compilation_cache,
)

RUN_FILES = {
    ".jaxexo.lock",
    "config.toml",
    "metrics.jsonl",
    "checkpoint.msgpack",
    "checkpoint.json",
}


def start(argv, env=None) -> subprocess.Popen:
    """``argv`` as a terminal runs it: SIGINT at its default (a pytest-xdist worker ignores it, and a
    child inherits that), standard error piped."""
    return subprocess.Popen(
        argv,
        cwd=ROOT,
        env=without_compilation_cache(dict(os.environ) if env is None else env),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )


def interrupt(p: subprocess.Popen) -> tuple[str, float]:
    """SIGINT to ``p``; its standard error and the seconds it took to end."""
    p.send_signal(signal.SIGINT)
    t0 = time.monotonic()
    _, err = p.communicate(timeout=120)
    return err, time.monotonic() - t0


def assert_interrupted(p: subprocess.Popen, err: str, seconds: float) -> None:
    assert seconds < 10, (seconds, err[-2000:])  # at once: not after a compile or the training
    assert p.returncode == 130, (p.returncode, err[-3000:])
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxexo: interrupted"), err[-3000:]


def assert_nothing_half_written(run, cfg) -> None:
    """Only the run's own files, each whole: no temporary file, a config.toml that is the run's."""
    if not run.exists():
        return
    names = {p.name for p in run.iterdir()}
    assert names <= RUN_FILES, names
    if "config.toml" in names:
        from jaxexo.config import load_config

        assert load_config(run / "config.toml") == cfg


@pytest.mark.slow
def test_ctrl_c_in_the_first_seconds_ends_train_at_once(tmp_path):
    """SIGINT while Python imports, JAX starts or the programs compile: exit 130 with the one-line
    message within seconds, nothing half written. (It was lost in a garbage-collector callback and
    the run trained to exit 0, or ended in a traceback from inside the import of JAX, or SIGSEGV.)"""
    # A budget no machine finishes before the signal.
    cfg = tiny_config(budget_env_steps=TINY_N * TINY_T * 20_000)
    cfg_path = tmp_path / "long.toml"
    cfg_path.write_text(config_to_toml(cfg))
    codes = []
    for i, delay in enumerate((0.3, 0.6, 1.0, 2.0)):
        run = tmp_path / f"run{i}"
        p = start(cli_cmd("train", cfg_path, "--out", run, "--quiet"))
        time.sleep(delay)
        err, seconds = interrupt(p)
        codes.append(p.returncode)
        if p.returncode == -signal.SIGINT:
            # Python's own start-up, before jaxexo's command line was read: nothing ran yet.
            assert "KeyboardInterrupt" in err and "in main" not in err, err[-3000:]
            assert not run.exists()
        else:
            assert_interrupted(p, err, seconds)
        assert_nothing_half_written(run, cfg)
    assert 130 in codes, codes


@pytest.mark.slow
def test_ctrl_c_while_compiling_then_resume_ends_as_the_uninterrupted_run(tiny_reference, tmp_path):
    from test_reliability import assert_same_run, one_device_env

    cfg_path, run = tiny_reference["cfg_path"], tmp_path / "run"
    p = start(
        cli_cmd("train", cfg_path, "--out", run, "--quiet", "--seed", SEED), env=one_device_env()
    )
    t0 = time.monotonic()
    while not (run / "config.toml").exists():  # the directory prepared: compiling next
        assert p.poll() is None, p.stderr.read()[-3000:]
        assert time.monotonic() - t0 < 300
        time.sleep(0.005)
    err, seconds = interrupt(p)
    assert_interrupted(p, err, seconds)
    assert "--resume" in err
    assert_nothing_half_written(run, tiny_config())
    r = run_cli("train", cfg_path, "--out", run, "--quiet", "--seed", SEED, "--resume",
                env=one_device_env(), timeout=900)  # fmt: skip
    assert r.returncode == 0, r.stderr[-3000:]
    assert_same_run(tiny_reference["run"], run)


def run_python(code: str) -> subprocess.CompletedProcess:
    """``code`` in a Python subprocess with SIGINT at its default (``start``)."""
    p = start([sys.executable, "-c", textwrap.dedent(code)])
    _, err = p.communicate(timeout=60)
    return subprocess.CompletedProcess(p.args, p.returncode, "", err)


def test_an_interrupt_in_a_garbage_collector_callback_is_not_lost():
    """JAX collects XLA's garbage in a gc callback, where Python drops a KeyboardInterrupt: the
    mechanism of the lost Ctrl-C, reproduced without JAX."""
    code = """
        import gc, os, signal, time
        from jaxexo.cli.interrupt import honoured

        def callback(phase, info):
            if phase == "start":
                os.kill(os.getpid(), signal.SIGINT)
                for _ in range(10**5):  # Python runs here: the signal's handler with it
                    pass
                time.sleep(0.2)

        with honoured(lambda: "jaxexo: interrupted (test)"):
            gc.callbacks.append(callback)
            gc.collect()
            gc.callbacks.remove(callback)
            time.sleep(5)
        print("ran on", flush=True)
    """
    r = run_python(code)
    assert r.returncode == 130, r.stderr
    assert r.stderr.strip() == "jaxexo: interrupted (test)"


def test_an_interrupt_during_a_write_ends_the_process_after_it(tmp_path):
    """SIGINT mid-write (here: in the write's fsync): the file is written whole, then the process
    ends; no temporary file is left."""
    target = tmp_path / "out.txt"
    code = f"""
        import os, signal, time
        from jaxexo.cli.interrupt import honoured
        from jaxexo.storage.atomic import atomic_write

        fsync = os.fsync

        def slow_fsync(fd):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.5)
            fsync(fd)

        os.fsync = slow_fsync
        with honoured(lambda: "jaxexo: interrupted (test)"):
            atomic_write({str(target)!r}, "a whole file\\n")
            time.sleep(5)
    """
    t0 = time.monotonic()
    r = run_python(code)
    assert r.returncode == 130, r.stderr
    assert time.monotonic() - t0 < 4  # ended after the write, not after the sleep
    assert target.read_text() == "a whole file\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.txt"]


def test_honoured_restores_the_handling_it_found():
    import threading

    from jaxexo.cli.interrupt import honoured

    # As in a terminal (a pytest-xdist worker ignores SIGINT, and honoured then leaves it so).
    found = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        threads = threading.active_count()
        with honoured(lambda: "unused"):
            assert signal.getsignal(signal.SIGINT) is not signal.default_int_handler
            assert threading.active_count() == threads + 1  # the watcher
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
        assert threading.active_count() == threads  # the watcher stopped
        assert signal.set_wakeup_fd(-1) == -1  # none left set
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        with honoured(lambda: "unused"):  # an ignored SIGINT stays ignored (a background job)
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, found)


# --------------------------------------------------------------------------------------------
# --resume over a metrics.jsonl that no longer holds the checkpoint's chunks
# --------------------------------------------------------------------------------------------


@pytest.fixture
def finished_run(tiny_reference, tmp_path):
    """A copy of the tiny reference run (3 chunks, all checkpointed) and its metrics lines."""
    run = tmp_path / "run"
    shutil.copytree(tiny_reference["run"], run)
    lines = (run / "metrics.jsonl").read_text().splitlines(keepends=True)
    assert [json.loads(x)["chunk"] for x in lines] == [1, 2, 3]
    return run, lines


@pytest.mark.parametrize(
    "keep, message",
    [
        ([0, 2], "lacks the rows of chunk(s) 2 (rows deleted, or the file cut short)"),
        ([0], "lacks the rows of chunk(s) 2..3 (rows deleted, or the file cut short)"),
        ([], "holds no rows"),
        ([1, 0, 2], "has chunk 2 on line 1, where chunk 1 belongs"),
        ([0, 1, 1], "lacks the rows of chunk(s) 3"),
        (None, "is missing"),
    ],
    ids=["middle-row-deleted", "last-rows-lost", "emptied", "reordered", "row-doubled", "deleted"],
)
def test_resume_refuses_a_log_that_no_longer_matches_the_checkpoint(finished_run, keep, message):
    from jaxexo.train.driver import run_training

    run, lines = finished_run
    log = run / "metrics.jsonl"
    if keep is None:
        log.unlink()
    else:
        log.write_text("".join(lines[i] for i in keep))
    files = lambda: {p.name: p.read_bytes() for p in run.iterdir() if p.name != ".jaxexo.lock"}  # noqa: E731
    before = files()
    with pytest.raises(ConfigError) as e:
        run_training(tiny_config(), run, seed=SEED, resume=True, progress=False)
    assert f"--resume: {log} {message}" in str(e.value), str(e.value)
    assert "the checkpoint holds" in str(e.value) and "start a new run" in str(e.value)
    assert files() == before  # nothing changed


@pytest.mark.slow
def test_cli_resume_over_a_cut_log_exits_2_naming_the_file(finished_run):
    from test_reliability import one_device_env

    run, lines = finished_run
    (run / "metrics.jsonl").write_text(lines[0])
    r = run_cli("train", "--out", run, "--seed", SEED, "--resume", env=one_device_env())
    assert r.returncode == 2, r.stderr[-2000:]
    assert "Traceback" not in r.stderr
    assert f"jaxexo: error: --resume: {run / 'metrics.jsonl'} lacks the rows of chunk(s) 2..3" in (
        r.stderr
    )
    assert (run / "metrics.jsonl").read_text() == lines[0]


def test_rows_past_the_checkpoint_are_still_cut_back(tmp_path):
    """A killed run's rows after its checkpoint (a torn last line among them) are not a mismatch:
    the resumed run recomputes them."""
    from jaxexo.train.metrics_log import metrics_line, read_metrics_rows

    log = tmp_path / "metrics.jsonl"
    rows = [{"chunk": n, "loss": 0.5} for n in (1, 2, 3)]
    log.write_text("".join(metrics_line(r) for r in rows) + '{"chunk": 4, "lo')
    assert read_metrics_rows(log, 2) == rows[:2]
    assert read_metrics_rows(log, 3) == rows


# --------------------------------------------------------------------------------------------
# sweep --memory-budget: bounded by the memory this process can use
# --------------------------------------------------------------------------------------------

SWEEP = '[sweep]\nseeds = [0]\n[sweep.grid]\n"train.lr" = [0.001, 0.002]\n'


def assert_refused(r, *needles):
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    assert "Traceback" not in r.stderr and "jaxexo: error:" in r.stderr, r.stderr[-2000:]
    for n in needles:
        assert n in r.stderr, (n, r.stderr)


@pytest.mark.parametrize(
    "budget, needles",
    [
        ("1000TiB", ["--memory-budget: 1000TiB is more memory than this process can use"]),
        ("0", ["--memory-budget: must be > 0, got '0'"]),
        ("-1", ["--memory-budget: must be > 0, got '-1'"]),
    ],
)
def test_sweep_refuses_a_memory_budget_beyond_this_process(tmp_path, budget, needles):
    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP)
    r = run_cli("sweep", sweep, "--out", tmp_path / "run", f"--memory-budget={budget}")
    assert_refused(r, *needles)
    assert not (tmp_path / "run").exists()


def test_a_sweep_files_memory_budget_is_bounded_too(tmp_path):
    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP.replace("[sweep]\n", '[sweep]\nmemory_budget = "1000TiB"\n'))
    r = run_cli("sweep", sweep, "--out", tmp_path / "run")
    assert_refused(
        r, f"{sweep}: sweep.memory_budget: 1.024e+06 GiB is more memory than this process"
    )
    assert not (tmp_path / "run").exists()


def test_the_bound_is_the_process_limit_where_one_is_set(tmp_path):
    """Under ``ulimit -v`` the budget is bounded by the limit, not by the machine's memory."""
    import resource

    from jaxexo.config.memory import machine_memory_bytes

    limit = 4 * 2**30
    if (machine_memory_bytes() or 0) <= limit + 2**30:
        pytest.skip("the machine's own memory is below the limit tried here")
    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP)
    r = subprocess.run(
        cli_cmd("sweep", sweep, "--out", tmp_path / "run", "--memory-budget", "5GiB"),
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (limit, limit)),
    )
    assert_refused(r, "--memory-budget: 5GiB is more memory than this process can use (4.0 GiB, "
                   "the process's limit, ulimit -v)")  # fmt: skip
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("where", ["reading the command line", "running the command"])
def test_ctrl_c_anywhere_in_main_is_one_line_and_exit_130(monkeypatch, capsys, where):
    """A KeyboardInterrupt raised in main itself (its imports and argument parsing run before
    train's own handling is set up; other commands have none): the one line and exit 130, not a
    traceback. (A SIGINT that landed in main's imports once ended in Python's traceback through
    main.)"""
    import jaxexo.cli as cli

    def interrupted(*_a, **_k):
        raise KeyboardInterrupt

    if where == "reading the command line":
        monkeypatch.setattr(cli, "build_parser", interrupted)
    else:
        monkeypatch.setattr(cli.generate, "cmd_generate", interrupted)
        monkeypatch.setattr(cli, "cmd_generate", interrupted)
    try:
        code = cli.main(["generate", "--method", "cfftg", "--obstacle", "base1", "--out", "x.csv"])
    except KeyboardInterrupt:  # caught here: pytest would take it for the user's own Ctrl-C
        pytest.fail("main let the KeyboardInterrupt through (a traceback on the command line)")
    err = capsys.readouterr().err
    assert code == 130 and err == "jaxexo: interrupted\n", (code, err)


def test_a_ctrl_c_wrapped_by_a_class_definition_ends_with_the_one_line(monkeypatch, capsys):
    """A KeyboardInterrupt raised while an import makes a class reaches main as a RuntimeError
    (Python 3.11 wraps an exception in __set_name__): still one line and exit 130; any other
    RuntimeError is not an interrupt and propagates."""
    import jaxexo.cli as cli

    def wrapped(argv):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as e:
            raise RuntimeError("Error calling __set_name__ on 'Field' instance") from e

    monkeypatch.setattr(cli, "_main", wrapped)
    assert cli.main([]) == 130
    assert capsys.readouterr().err == "jaxexo: interrupted\n"

    def other(argv):
        raise RuntimeError("a real error")

    monkeypatch.setattr(cli, "_main", other)
    with pytest.raises(RuntimeError, match="a real error"):
        cli.main([])


def test_a_ctrl_c_handled_after_it_landed_in_generated_code_ends_with_130(tmp_path):
    """A Ctrl-C that lands in code run from a string (a dataclass's generated methods, exec'd while
    the imports run) and is handled by main: the process ends with 130 and main's one line. Python
    run with -m would otherwise end such a process by SIGINT whatever its exit status (seen as a
    returncode of -2 after the message, in CI)."""
    (tmp_path / "ctrl_c_in_exec.py").write_text(
        textwrap.dedent(
            """
            import os, signal, sys
            import jaxexo.cli as cli

            def main(argv=None):
                try:
                    exec("import os, signal\\nos.kill(os.getpid(), signal.SIGINT)\\nx = 1")
                except KeyboardInterrupt:
                    print("jaxexo: interrupted", file=sys.stderr)
                    return 130
                return 0

            cli.main = main
            cli.run()
            """
        )
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(tmp_path)])}
    p = subprocess.run(
        [sys.executable, "-m", "ctrl_c_in_exec"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
    )
    assert p.returncode == 130, (p.returncode, p.stderr[-2000:])
    assert p.stderr.strip().splitlines() == ["jaxexo: interrupted"]
