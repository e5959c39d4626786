"""What the benchmarks/*.py runners share: their command line's parser, which shows the script's
docstring as written and takes the policy to measure, and (run_script) the whole runner of a
benchmark whose options are its function's parameters; ``Record``, the base of the frozen records
the benchmark modules pass each other; and ``timed_calls``, the compile-then-repeat timing loop."""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import time


def parser(doc: str, policy: bool = True) -> argparse.ArgumentParser:
    """A runner's parser: ``doc`` (the script's docstring) as its help, a ``policy`` argument (the
    policy.npz to measure) unless ``policy`` is False."""
    p = argparse.ArgumentParser(
        description=doc, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    if policy:
        p.add_argument("policy", help="policy.npz")
    return p


def run_script(doc: str, benchmark, options, out_dir, argv=None):
    """A runner script: its parser (``doc``, the policy) with ``options``, (flag, parameter, help)
    triples, each an option of the type and default of ``benchmark``'s parameter of that name; then
    ``benchmark(policy, out_dir, **options)``, whose result it returns."""
    p = parser(doc)
    params = inspect.signature(benchmark).parameters
    for flag, name, helptext in options:
        default = params[name].default
        metavar = flag.lstrip("-").replace("-", "_").upper()  # as argparse names the flag's own
        p.add_argument(
            flag, dest=name, metavar=metavar, type=type(default), default=default, help=helptext
        )
    a = vars(p.parse_args(argv))
    return benchmark(a.pop("policy"), out_dir, **a)


@dataclasses.dataclass(frozen=True)
class Record:
    """A frozen record passed between benchmark modules; ``to_dict``: its JSON, field by field."""

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def timed_calls(step, state, repeats: int) -> tuple[float, list[float]]:
    """Seconds of ``state = step(state)`` (ready) once, compilation included, then ``repeats`` times
    more: (the first call's, [the others']). ``step`` returns what the next call takes."""
    import jax

    times = []
    for _ in range(repeats + 1):
        t0 = time.perf_counter()
        state = jax.block_until_ready(step(state))
        times.append(time.perf_counter() - t0)
    return times[0], times[1:]
