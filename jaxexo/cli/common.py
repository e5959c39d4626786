"""What the subcommands share: the default config, the output-path checks, the options checked by
the library's own checkers under the name the user typed (``--rate``), and generate's and walk's
generator, fallback and output files. NumPy only; JAX is imported by the subcommands that train."""

from __future__ import annotations

import argparse
import os
import re
from pathlib import Path

# Shipped inside the package (package data), so the default model is the same however jaxexo is
# installed; the repository's configs/default.toml is a byte-equal copy.
DEFAULT_CONFIG = Path(__file__).resolve().parent.parent / "config" / "default.toml"

# A file name to suggest for each output file (its kind's suffix).
OUTPUT_EXAMPLES = {
    "--out": "trajectory.csv",
    "--json": "trajectory.json",
    "--plot": "swing.png",
    "--animate": "swing.gif",
    "--ros": "trajectory_ros.json",
}


# The library's names (a field, a keyword) of what a subcommand has an option for: a refusal that
# names one (``step_length must be > 0``) is shown with the option as typed instead (``as_typed``).
FIELD_OPTIONS = {
    "start_y": "--start-y",
    "goal_y": "--goal-y",
    "step_length": "--step-length",
    "pivot_y": "--pivot-y",
    "pivot": "--pivot",
    "smoothing": "--smoothing",
    "double_support": "--double-support",
    "steps": "--steps",
    "n_points": "--points",
    "duration": "--duration",
    "rate": "--rate",
    "clearance": "--clearance",
    "fallback": "--fallback",
}
_LEADING_FIELD = re.compile(r"([a-z][a-z0-9_]*)(?=[: ])")
# A field with an underscore anywhere in a message (``... the start (start_y 1 m ...)``), not a
# config key's part (``layout.step_length``).
_INNER_FIELD = re.compile(r"(?<![\w.\-])([a-z]+_[a-z0-9_]+)(?![\w.\-])")
_WHOLE = re.compile(r"[+-]?[0-9]+")


def as_typed(message: str, args) -> str:
    """A refusal as the command line words it: each field of FIELD_OPTIONS whose option ``args``'
    subcommand has, at the message's start (``step_length must be``, ``start_y: ...``) or written with
    an underscore anywhere, is named by that option (``--step-length``); the rest stays as it is."""

    def option(field):
        o = FIELD_OPTIONS.get(field)
        return o if o is not None and hasattr(args, o[2:].replace("-", "_")) else None

    m = _LEADING_FIELD.match(message)
    if m is not None and option(m.group(1)) is not None:
        message = option(m.group(1)) + message[m.end() :]
    return _INNER_FIELD.sub(lambda f: option(f.group(1)) or f.group(1), message)


def real(text: str) -> float:
    """argparse type of every real-valued option: a number in the one syntax jaxexo reads numbers in
    (jaxexo.storage.terrain_file.read_number: no ``0_05``, which float() reads as 5)."""
    from jaxexo.storage.terrain_file import read_number

    v = read_number(text.strip())
    if v is None:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a number (digits with an optional '.' and exponent; no '_')"
        )
    return v


def whole(text: str) -> int:
    """argparse type of every whole-number option: digits with an optional sign (no ``1_0``, which
    int() reads as 10)."""
    if not _WHOLE.fullmatch(text.strip()):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a whole number (digits with an optional sign; no '_')"
        )
    return int(text)


def load(path):
    """The config at ``path`` (None: the packaged default) and the path as text."""
    from jaxexo.config import load_config

    path = DEFAULT_CONFIG if path is None else path
    return load_config(path), str(path)


def check_output_file(option: str, value, example: str | None = None) -> None:
    """An output path must name a file in an existing folder that can be written: refused before
    any work (and before any temporary file is made next to it). ``example``: a file name to
    suggest (default: OUTPUT_EXAMPLES')."""
    if value is None:
        return
    text = str(value)
    example = example or OUTPUT_EXAMPLES[option]
    if not text:
        raise ValueError(f"{option}: the option is empty; give a file name (e.g. {example})")
    p = Path(value)
    if text.endswith(("/", "\\")) or p.is_dir():
        raise ValueError(f"{option}: {text} is a directory; give a file name (e.g. {p / example})")
    if option == "--animate":
        _check_animation_name(text)
    if not p.parent.is_dir():
        _check_folder_part(option, p.parent, text)
        raise ValueError(f"{option}: the folder {p.parent} does not exist (for {text})")
    _check_writable(option, p.parent, text)


def _check_writable(option: str, folder: Path, text: str) -> None:
    """The folder of an output written by replacement (atomic_write's temporary file is made there)
    must take a new file; else refused before any work, not after the other outputs are written."""
    from jaxexo.storage.atomic import direct_output

    if direct_output(text):
        return
    if not os.access(
        folder, os.W_OK | os.X_OK, effective_ids=os.access in os.supports_effective_ids
    ):
        raise ValueError(f"{option}: the folder {folder} cannot be written (for {text})")


def _check_animation_name(text: str) -> None:
    """--animate writes a GIF (Pillow's writer): its file is named .gif, or is a special output
    (``-``, a device, a FIFO) that takes the bytes as they are."""
    from jaxexo.storage.atomic import direct_output

    if Path(text).suffix.lower() != ".gif" and not direct_output(text):
        raise ValueError(
            f"--animate: {text} would hold GIF data (the animation is written as a GIF); "
            f"name it .gif (e.g. {Path(text).with_suffix('.gif')})"
        )


def _check_folder_part(option: str, folder: Path, text: str) -> None:
    """Refuse a path whose nearest existing ancestor is a file (``afile/t.csv``), saying so."""
    from jaxexo.storage.rundir import blocking_file

    q = blocking_file(folder)
    if q is not None:
        raise ValueError(f"{option}: {q} is a file, not a folder (for {text})")


def _same_file(a, b) -> bool:
    """Whether two paths name one file: the same path after symbolic links, or the same inode."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _output_id(path) -> tuple[int, int] | None:
    """(st_dev, st_ino) of the file an output lands in: standard output's for ``-``, the existing
    file's (after links: /dev/stdout is the file fd 1 is) otherwise; None where there is none yet."""
    from jaxexo.storage.atomic import STDOUT

    try:
        st = os.fstat(1) if str(path) == STDOUT else os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def _same_output(a, b) -> bool:
    """Whether two outputs land in one file: the same name (``-`` is standard output, not a file
    named ``-``), the same path after links, or the same file (``-`` and /dev/stdout redirected)."""
    a_id = _output_id(a)
    if a_id is not None and a_id == _output_id(b):
        return True
    if "-" in (str(a), str(b)):
        return str(a) == str(b)
    return _same_file(a, b)


def check_paths(inputs, outputs, examples=None) -> None:
    """Each output a file in an existing, writable folder (``check_output_file``, suggesting the
    file names of ``examples`` (option: name) where given), none replacing an input, no two landing
    in one file: refused before any work. ``inputs``, ``outputs``: (option, path or None) pairs."""
    for option, value in outputs:
        check_output_file(option, value, (examples or {}).get(option))
    outs = [(o, v) for o, v in outputs if v is not None]
    for i, (option, value) in enumerate(outs):
        for other, v in outs[:i]:
            if _same_output(value, v):
                also = "" if str(v) == str(value) else f" ({other} {v})"
                raise ValueError(
                    f"{option}: {value} is also the {other} output{also}; give each output its "
                    "own path"
                )
        for other, v in inputs:
            if v is not None and _same_file(value, v):
                raise ValueError(
                    f"{option}: {value} is the {other} input; an output never replaces an input, "
                    "pick another path"
                )


def check_rate(rate, option: str = "--rate") -> None:
    """A control-rate option (Hz; None: not given) by the timing's own check (check_rate, the
    [device] control_rate bounds), the message naming the option as typed."""
    if rate is not None:
        from jaxexo.swing.timing import check_rate as check

        check(rate, option)


def check_count(value, option: str, lo: int = 1) -> None:
    """A whole-number option (a count; None: not given) at least ``lo``, refused naming it."""
    if value is not None and value < lo:
        raise ValueError(f"{option}: must be >= {lo}, got {value}")


def check_clearance(clearance, config) -> None:
    """--clearance against the model's env.min_clearance, before any work (names the option)."""
    from jaxexo.physics.scene import check_clearance as check

    try:
        check(clearance, config.env.min_clearance)
    except (TypeError, ValueError) as e:
        raise ValueError(f"--{e}") from None


def option_values(args, *names, **renamed) -> dict:
    """Keyword arguments from the parsed options: ``name=args.name`` for each of ``names`` and
    ``key=args.<option>`` for each ``key=option`` of ``renamed``."""
    return {
        **{n: getattr(args, n) for n in names},
        **{k: getattr(args, v) for k, v in renamed.items()},
    }


def swing_outputs(args, inputs):
    """generate's and walk's output files (--out, --json, --plot, --animate, --ros) as (option,
    path), checked against each other and the ``inputs`` (``check_paths``)."""
    outputs = (
        ("--out", args.out),
        ("--json", args.json),
        ("--plot", args.plot),
        ("--animate", args.animate),
        ("--ros", getattr(args, "ros", None)),
    )
    check_paths(inputs, outputs)
    return outputs


def generator(args):
    """The generator --method names (jaxexo.inference.registry): the trained policy, or one with
    the kinematics and joint limits of --policy's config when one is given (else the default
    config's)."""
    from jaxexo.inference.registry import generator_class

    cls = generator_class(args.method)
    if cls.needs_policy and not args.policy:
        raise ValueError(f"--policy: required with --method {args.method} (the trained policy.npz)")
    return cls.from_policy(args.policy) if args.policy else cls.from_config(load(None)[0])


def write_outputs(args, data, draw, animate) -> list[str]:
    """``data`` (a swing or a course) as --out's CSV and --json's JSON, --plot drawn by
    ``draw(path)`` and --animate by ``animate(path)`` (None: no GIF); the files written, in order."""
    data.to_csv(args.out)
    written = [args.out]
    for path, write in ((args.json, data.to_json), (args.plot, draw), (args.animate, animate)):
        if path and write is not None:
            write(path)
            written.append(path)
    return written


def add_policy(p) -> None:
    """generate's and walk's --policy: the model, or for cfftg only its kinematics."""
    p.add_argument(
        "--policy",
        help="policy.npz written by jaxexo train (required for --method rl; for cfftg it "
        "supplies the kinematics, default: configs/default.toml)",
    )


class Registered:
    """The names of the registered generators (jaxexo.inference.registry) that ``keep(cls)``, as an
    option's choices: read when the option is checked or its help shown (the registry imports the
    generators, which a command line that does not generate need not)."""

    def __init__(self, keep=lambda cls: True):
        self.keep = keep

    def _names(self) -> list[str]:
        from jaxexo.inference.registry import generator_class, names

        return [n for n in names() if self.keep(generator_class(n))]

    def __iter__(self):
        return iter(self._names())

    def __contains__(self, name) -> bool:
        return name in self._names()


def add_method(p, helptext: str) -> None:
    """generate's and walk's --method: a registered generator."""
    p.add_argument("--method", choices=Registered(), default="rl", help=helptext)


def add_fallback(p, helptext: str) -> None:
    """generate's and walk's --fallback: what stands in for an RL swing that is not safe (not given:
    None, read by ``fallback``)."""
    p.add_argument("--fallback", choices=("cfftg", "none"), help=helptext + " (default: cfftg)")


def refuse_unused(args, option: str, got: str = "") -> None:
    """--``option`` given (not None) with a --method whose generator does not take it: ValueError
    saying which do and why not this one (and ``got``, the values as typed)."""
    from jaxexo.inference.registry import generator_class

    cls = generator_class(args.method)
    if getattr(args, option) is not None and not cls.takes(option):
        takers = ", ".join(Registered(lambda c: c.takes(option)))
        raise ValueError(
            f"--{option}: applies to --method {takers} only ({cls.why_not(option)}){got}"
        )


def fallback(args) -> str | None:
    """--fallback's one rule for generate and walk: for a generator that takes it only (given with
    --method cfftg it is refused, whatever its value); not given, "cfftg"; "none" is None."""
    refuse_unused(args, "fallback", f", got --fallback {args.fallback} with --method {args.method}")
    return None if args.fallback == "none" else "cfftg"


def method_options(gen, **options) -> dict:
    """Of ``options`` (generate's keywords), those the generator ``gen`` takes."""
    return {k: v for k, v in options.items() if gen.takes(k)}
