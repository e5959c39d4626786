"""The ``jaxexo`` command line: the parser and ``main`` (the ``jaxexo`` entry point and ``python -m
jaxexo.cli``), one module per subcommand, each option checked by the library's own checker under the
name the user typed. Subcommands import JAX lazily, after the CPU-device setup."""

from __future__ import annotations

import argparse
import os
import sys

from jaxexo.cli import bench, evaluate, generate, mjcf, replay, reproduce, sweep, train, walk
from jaxexo.cli.bench import cmd_bench, cmd_bench_env
from jaxexo.cli.common import DEFAULT_CONFIG, as_typed
from jaxexo.cli.evaluate import cmd_eval
from jaxexo.cli.generate import cmd_generate
from jaxexo.cli.mjcf import cmd_mjcf
from jaxexo.cli.replay import cmd_replay
from jaxexo.cli.reproduce import cmd_reproduce
from jaxexo.cli.scene import obstacle_from_args
from jaxexo.cli.sweep import cmd_sweep
from jaxexo.cli.train import cmd_train
from jaxexo.cli.walk import cmd_walk

DESCRIPTION = (
    "The ``jaxexo`` command line. Subcommands import JAX lazily, after the CPU-device setup."
)

# (name, help, the module's options) of every subcommand, in --help's order.
SUBCOMMANDS = (
    (
        "bench-env",
        "environment steps per second (random actions, full reward)",
        bench.add_env_options,
    ),
    ("train", "train a policy (TD(lambda)); writes a run directory", train.add_options),
    (
        "generate",
        "a smoothed, checked swing trajectory from policy.npz (NumPy only)",
        generate.add_options,
    ),
    (
        "mjcf",
        "the legs and the obstacle as a MuJoCo model (MJCF), for MuJoCo's viewer",
        mjcf.add_options,
    ),
    (
        "replay",
        "a swing replayed in MuJoCo: its distance to the obstacle, and driven at the "
        "[device] limits with --driven (needs the sim extra)",
        replay.add_options,
    ),
    (
        "walk",
        "a walk over a measured course: footholds, every swing and both legs timed "
        "for the device (NumPy only)",
        walk.add_options,
    ),
    (
        "sweep",
        "train a grid of configurations x seeds as compiled, vmapped programs",
        sweep.add_options,
    ),
    (
        "eval",
        "evaluate the RL generator (and CFFTG) side by side; writes report.md/.json "
        "and figures (NumPy only)",
        evaluate.add_options,
    ),
    (
        "reproduce",
        "train the seven thesis configs and tabulate them beside the thesis's Tables 3.2-3.11",
        reproduce.add_options,
    ),
    (
        "bench",
        "every benchmark (environment, trainer, generator, CFFTG, thesis-style "
        "baseline) into benchmarks/results with a summary table",
        bench.add_options,
    ),
)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="jaxexo", description=DESCRIPTION)
    sub = p.add_subparsers(dest="command", required=True)
    for name, helptext, add_options in SUBCOMMANDS:
        add_options(sub.add_parser(name, help=helptext))
    return p


def _warning_line(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as one line ``jaxexo: warning: ...`` (not Python's source-line form)."""
    print(f"jaxexo: warning: {message}", file=sys.stderr if file is None else file)


def main(argv=None) -> int:
    try:
        return _main(argv)
    except (KeyboardInterrupt, RuntimeError) as e:
        # Ctrl-C before a command's own handling took over (jaxexo.cli.interrupt: train's, from its
        # first line) or in a command without one: one line, not a traceback; every file written so
        # far is whole (jaxexo.storage.atomic removes its temporary file on any exception). A
        # Ctrl-C while an import makes a class reaches here wrapped (Python 3.11 raises a
        # RuntimeError from an exception in __set_name__).
        if not interrupted(e):
            raise
        from jaxexo.cli.interrupt import EXIT_CODE

        print("jaxexo: interrupted", file=sys.stderr)
        return EXIT_CODE


def run() -> None:
    """The ``jaxexo`` command: ``main`` on the command line's arguments, its status the process's.
    A Ctrl-C that main handled (its one line said) ends the process with 130 at once: one that
    landed in code run from a string (a dataclass's or a namedtuple's generated methods, made by
    exec or eval while the imports run) marks the interpreter as interrupted for good, and its
    normal exit would then end the process by SIGINT whatever the status. Every file written is
    whole (jaxexo.storage.atomic)."""
    from jaxexo.cli.interrupt import EXIT_CODE

    code = main()
    if code == EXIT_CODE:
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        os._exit(code)
    sys.exit(code)


def interrupted(e: BaseException) -> bool:
    """Whether ``e`` is a Ctrl-C: a KeyboardInterrupt, or an exception raised from one."""
    while e is not None:
        if isinstance(e, KeyboardInterrupt):
            return True
        e = e.__cause__
    return False


def _main(argv) -> int:
    import warnings

    args = build_parser().parse_args(argv)
    from jaxexo.config import ConfigError
    from jaxexo.physics.geometry import GeometryError
    from jaxexo.storage.policy_file import PolicyFileError
    from jaxexo.storage.rundir import TrainingDiverged

    shown, warnings.showwarning = warnings.showwarning, _warning_line
    try:
        return args.func(args)
    except (ConfigError, GeometryError, PolicyFileError, ValueError) as e:
        # Bad input (config, files, options, a checkpoint or run directory that cannot be used),
        # named by the option the user typed where the library names its field.
        print(f"jaxexo: error: {as_typed(str(e), args)}", file=sys.stderr)
        return 2
    except TrainingDiverged as e:
        print(f"jaxexo: error: {e}", file=sys.stderr)
        return 3
    except OSError as e:
        # A write that failed (full disk, file-size limit, permissions): what was written before is intact.
        print(f"jaxexo: error: {e}", file=sys.stderr)
        return 1
    finally:
        warnings.showwarning = shown
