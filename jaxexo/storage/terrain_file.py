"""Terrain files: a measured ground profile as (y, z) points in metres, for a course (``jaxexo walk
--terrain``) or one swing's obstacle (``jaxexo generate --profile``); CSV or JSON by suffix. Every
rule is checked here and a bad file is a ``TerrainFileError`` naming the file and line. The format:
docs/walking.md#the-terrain-file.
"""

from __future__ import annotations

import json
import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from jaxexo.config.input_files import InputFileError, read_input

MIN_POINTS = 2
MAX_POINTS = 100_000  # a 100 m course measured every millimetre
MAX_LENGTH = 100.0  # m, first to last y
MAX_HEIGHT = 2.0  # m above the floor (twice the default leg: no swing clears it)
MAX_FILE_BYTES = 16 * 2**20  # 16 MiB: far above MAX_POINTS lines of text
MAX_JSON_DEPTH = 3  # {"points": [[y, z]]}: an object, the list, a pair
# A number (read_number): digits with an optional point and exponent; nan/inf (any case) reach the
# finite check.
_CSV_NUMBER = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_NON_FINITE = re.compile(r"[+-]?(?:nan|inf|infinity)", re.IGNORECASE)


class TerrainFileError(ValueError):
    """A terrain file that cannot be used; the message names the file and the bad line."""


@dataclass(frozen=True)
class Terrain:
    """A ground profile: y (n,) non-decreasing and z (n,) >= 0, metres; ``source`` names its file."""

    y: np.ndarray
    z: np.ndarray
    source: str = "<terrain>"
    # Where each point is written (``line 3``; ``point 2`` for points given as numbers), for
    # messages about a point found wanting after the file's own checks.
    where: tuple[str, ...] = ()

    @property
    def points(self) -> np.ndarray:
        return np.column_stack([self.y, self.z])

    def place(self, i: int) -> str:
        """Where point ``i`` is written: ``<file>, line 3`` (``point 2`` where no line is known)."""
        return f"{self.source}, {self.where[i] if i < len(self.where) else f'point {i}'}"

    @classmethod
    def from_points(cls, points, source: str = "<terrain>") -> "Terrain":
        """A terrain from (y, z) pairs (the API's way in), checked by the file rules (points named by
        index instead of line)."""
        try:
            pts = np.asarray(points, dtype=np.float64)
        except (TypeError, ValueError):
            raise TerrainFileError(
                f"{source}: points must be (y, z) pairs of numbers in metres"
            ) from None
        if pts.ndim != 2 or pts.shape[1:] != (2,):
            raise TerrainFileError(
                f"{source}: points must have shape (n, 2) of (y, z) in metres, got {pts.shape}"
            )
        return _checked(pts, [f"point {i}" for i in range(len(pts))], source)


def read_terrain(path: str | Path) -> Terrain:
    """The terrain in ``path`` (format: docs/walking.md#the-terrain-file), checked; a
    TerrainFileError naming the line otherwise."""
    p = Path(path)
    name = str(path)
    try:  # the one read of an input file: a regular file, at most MAX_FILE_BYTES
        raw = read_input(p, "terrain file", MAX_FILE_BYTES)
    except InputFileError as e:
        raise TerrainFileError(f"{name}: {e.reason}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        line = raw[: e.start].count(b"\n") + 1
        raise TerrainFileError(f"{name}, line {line}: not UTF-8 text") from None
    text = text.removeprefix("\ufeff")  # a byte-order mark, as configs accept
    if p.suffix.lower() == ".json":
        pts, where = _parse_json(text, name)
    else:
        pts, where = _parse_csv(text, name)
    return _checked(pts, where, name)


_HEADER = re.compile(r"^\s*[A-Za-z_][\w \-\(\)\[\]/]*,\s*[A-Za-z_][\w \-\(\)\[\]/]*\s*$")


def _parse_csv(text: str, name: str):
    rows, where = [], []
    seen_data = False
    for k, line in enumerate(text.splitlines(), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        if not seen_data and not rows and _HEADER.match(s):
            seen_data = True  # the one header line
            continue
        seen_data = True
        if len(rows) >= MAX_POINTS:
            raise TerrainFileError(
                f"{name}, line {k}: more than {MAX_POINTS} points (a terrain file may have "
                f"at most {MAX_POINTS})"
            )
        parts = [x.strip() for x in s.split(",")]
        if len(parts) != 2:
            raise TerrainFileError(
                f"{name}, line {k}: expected two numbers 'y,z' (metres), got {s!r}"
            )
        rows.append([_csv_number(x, label, f"{name}, line {k}") for label, x in zip("yz", parts)])
        where.append(f"line {k}")
    return np.asarray(rows, dtype=np.float64).reshape(-1, 2), where


def read_number(text: str) -> float | None:
    """The number ``text`` writes in the one syntax jaxexo reads numbers in (a terrain CSV's values,
    the command line's numeric options): digits with an optional point and exponent, or nan/inf;
    None for anything else (``1_0``, which Python's float() reads as 10)."""
    if _CSV_NUMBER.fullmatch(text) or _NON_FINITE.fullmatch(text):
        return float(text)
    return None


def _csv_number(x: str, label: str, where: str) -> float:
    v = read_number(x)
    if v is None:
        raise TerrainFileError(f"{where}: {label} is not a number: {x!r}")
    return v


def _json_depth(text: str) -> int:
    """The deepest nesting of arrays and objects in ``text`` (brackets inside strings not counted)."""
    depth = deepest = 0
    # Strings (with their escapes) removed first, so that no bracket inside one counts.
    brackets = re.sub(r"[^\[\]{}]+", "", re.sub(r'"(?:[^"\\]|\\.)*"', '""', text))
    for c in brackets:
        if c in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif c in "]}":
            depth -= 1
    return deepest


# A line break as an editor counts them (JSON's own positions count "\n" alone).
_LINE_BREAK = re.compile(r"\r\n|\r|\n")


def _lines_at(text: str, positions) -> np.ndarray:
    """The line (from 1) of each offset in ``positions``: one pass over ``text``, however many."""
    ends = np.fromiter((m.end() for m in _LINE_BREAK.finditer(text)), dtype=np.int64)
    return np.searchsorted(ends, np.asarray(positions, dtype=np.int64), side="right") + 1


def _value_lines(text: str) -> list[tuple[int, int]]:
    """For each innermost [..] of ``text`` in order (the [y, z] pairs), the lines of its first and
    second values (of its "[" for one it lacks): a pretty-printed file writes each on its own line."""
    starts = []
    for m in re.finditer(r"\[[^\[\]]*\]", text):
        values = [
            m.start() + 1 + k + len(part) - len(part.lstrip())
            for k, part in _parts(m.group()[1:-1])
            if part.strip()
        ]
        starts.extend((values + [m.start()] * 2)[:2])
    lines = _lines_at(text, starts).tolist()
    return list(zip(lines[0::2], lines[1::2]))


def _parts(inner: str):
    """(offset, text) of each comma-separated part of a pair's inside."""
    k = 0
    for part in inner.split(","):
        yield k, part
        k += len(part) + 1


def _object_of(twice: list):
    """json's object_pairs_hook: the object as a dict, each key it has twice noted in ``twice``."""

    def hook(pairs):
        seen = set()
        for k, _ in pairs:
            if k in seen:
                twice.append(k)
            seen.add(k)
        return dict(pairs)

    return hook


def _duplicate_key(text: str, name: str, key: str) -> TerrainFileError:
    """The refusal of a key written twice in one object, at the line of its second writing."""
    found = [m.start() for m in re.finditer(rf'(?<!\\)"{re.escape(key)}"\s*:', text)]
    at = f", line {_lines_at(text, found[1:2])[0]}" if len(found) > 1 else ""
    return TerrainFileError(
        f"{name}{at}: the key {json.dumps(key)} is written twice (JSON would keep the last one "
        "silently); write it once"
    )


def _parse_json(text: str, name: str):
    if _json_depth(text) > MAX_JSON_DEPTH:
        raise TerrainFileError(
            f"{name}: JSON nested deeper than a terrain file is ({MAX_JSON_DEPTH} levels: "
            '{"points": [[y, z], ...]})'
        )
    twice = []  # keys written twice in one object (json.loads would keep the last silently)
    try:
        doc = json.loads(
            text,
            parse_constant=lambda c: float(c),  # NaN/Infinity: refused below by line
            object_pairs_hook=_object_of(twice),
        )
    except json.JSONDecodeError as e:
        line = _lines_at(text, [e.pos])[0]
        raise TerrainFileError(f"{name}, line {line}: not valid JSON ({e.msg})") from None
    except (ValueError, RecursionError):  # a number of more digits than Python converts
        raise TerrainFileError(
            f"{name}: a number has more than {sys.get_int_max_str_digits()} digits; terrain "
            f"values are metres (at most {MAX_LENGTH:g} m long, {MAX_HEIGHT:g} m high)"
        ) from None
    if twice:
        raise _duplicate_key(text, name, twice[0])
    pts = doc.get("points") if isinstance(doc, dict) else doc
    if not isinstance(pts, list):
        raise TerrainFileError(
            f'{name}: expected {{"points": [[y, z], ...]}} or a list of [y, z] pairs'
        )
    if len(pts) > MAX_POINTS:
        raise TerrainFileError(
            f"{name}: {len(pts)} points, more than a terrain file may have ({MAX_POINTS})"
        )
    # The lines of each inner [y, z] pair's values, in order (json keeps no positions).
    lines = _value_lines(text)
    known = len(lines) == len(pts)
    where, z_where = (
        [f"line {lines[i][j]} (points[{i}])" if known else f"points[{i}]" for i in range(len(pts))]
        for j in (0, 1)
    )
    rows = []
    for i, p in enumerate(pts):
        pair = isinstance(p, list) and len(p) == 2
        # The value at fault, where the pair has two: its line is the one to name.
        j = 1 if pair and _is_number(p[0]) else 0
        if not pair or not all(map(_is_number, p)):
            raise TerrainFileError(
                f"{name}, {(where, z_where)[j][i]}: expected a pair [y, z] of numbers (metres), "
                f"got {json.dumps(p)[:60]}"
            )
        rows.append([_metres(x, f"{name}, {(where, z_where)[j][i]}") for j, x in enumerate(p)])
    return np.asarray(rows, dtype=np.float64).reshape(-1, 2), (where, z_where)


def _metres(x, where: str) -> float:
    try:
        return float(x)
    except OverflowError:  # an integer of more than float's range
        raise TerrainFileError(
            f"{where}: a number too large for metres (a terrain is at most {MAX_LENGTH:g} m long, "
            f"{MAX_HEIGHT:g} m high)"
        ) from None


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _checked(pts: np.ndarray, where, name: str) -> Terrain:
    """The points held to the file rules; ``where`` names each point (a list), or its y and its z
    apart (a pair of lists: a pretty-printed JSON writes them on lines of their own)."""
    where, z_where = where if isinstance(where, tuple) else (where, where)
    n = len(pts)
    if n < MIN_POINTS:
        raise TerrainFileError(
            f"{name}: {n} point{'s' * (n != 1)}, a profile needs at least {MIN_POINTS}"
        )
    if n > MAX_POINTS:
        raise TerrainFileError(f"{name}: {n} points, more than a terrain may have ({MAX_POINTS})")
    for i in range(n):
        for j, label in ((0, "y"), (1, "z")):
            if not math.isfinite(pts[i, j]):
                raise TerrainFileError(
                    f"{name}, {(where, z_where)[j][i]}: {label} must be a finite number, got "
                    f"{pts[i, j]}"
                )
    neg = np.flatnonzero(pts[:, 1] < 0.0)
    if neg.size:
        i = int(neg[0])
        raise TerrainFileError(
            f"{name}, {z_where[i]}: z = {pts[i, 1]:g} m is below the floor (heights are above "
            "the floor, z >= 0)"
        )
    high = np.flatnonzero(pts[:, 1] > MAX_HEIGHT)
    if high.size:
        i = int(high[0])
        raise TerrainFileError(
            f"{name}, {z_where[i]}: z = {pts[i, 1]:g} m, higher than a terrain may be "
            f"({MAX_HEIGHT:g} m)"
        )
    back = np.flatnonzero(np.diff(pts[:, 0]) < 0.0)
    if back.size:
        i = int(back[0]) + 1
        raise TerrainFileError(
            f"{name}, {where[i]}: y = {pts[i, 0]:g} m is behind the point before it "
            f"(y = {pts[i - 1, 0]:g} m); y must increase along the course"
        )
    length = pts[-1, 0] - pts[0, 0]
    if length <= 0.0:
        raise TerrainFileError(f"{name}: the profile has no length (every y is {pts[0, 0]:g} m)")
    if length > MAX_LENGTH:
        raise TerrainFileError(
            f"{name}, {where[-1]}: the profile is {length:g} m long, more than a terrain may "
            f"be ({MAX_LENGTH:g} m)"
        )
    return Terrain(pts[:, 0].copy(), pts[:, 1].copy(), name, tuple(where))


__all__ = ["Terrain", "TerrainFileError", "read_terrain", "MAX_POINTS", "MAX_LENGTH", "MIN_POINTS"]
