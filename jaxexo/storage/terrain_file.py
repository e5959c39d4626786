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
# A CSV number: digits with an optional point and exponent; nan/inf (any case) reach the finite check.
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

    @property
    def points(self) -> np.ndarray:
        return np.column_stack([self.y, self.z])

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


def _csv_number(x: str, label: str, where: str) -> float:
    if _CSV_NUMBER.fullmatch(x) or _NON_FINITE.fullmatch(x):
        return float(x)
    raise TerrainFileError(f"{where}: {label} is not a number: {x!r}")


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


def _parse_json(text: str, name: str):
    if _json_depth(text) > MAX_JSON_DEPTH:
        raise TerrainFileError(
            f"{name}: JSON nested deeper than a terrain file is ({MAX_JSON_DEPTH} levels: "
            '{"points": [[y, z], ...]})'
        )
    try:
        doc = json.loads(
            text, parse_constant=lambda c: float(c)
        )  # NaN/Infinity: refused below by line
    except json.JSONDecodeError as e:
        raise TerrainFileError(f"{name}, line {e.lineno}: not valid JSON ({e.msg})") from None
    except (ValueError, RecursionError):  # a number of more digits than Python converts
        raise TerrainFileError(
            f"{name}: a number has more than {sys.get_int_max_str_digits()} digits; terrain "
            f"values are metres (at most {MAX_LENGTH:g} m long, {MAX_HEIGHT:g} m high)"
        ) from None
    pts = doc.get("points") if isinstance(doc, dict) else doc
    if not isinstance(pts, list):
        raise TerrainFileError(
            f'{name}: expected {{"points": [[y, z], ...]}} or a list of [y, z] pairs'
        )
    if len(pts) > MAX_POINTS:
        raise TerrainFileError(
            f"{name}: {len(pts)} points, more than a terrain file may have ({MAX_POINTS})"
        )
    # The line of each inner [y, z] pair, in order (json keeps no positions).
    lines = [text.count("\n", 0, m.start()) + 1 for m in re.finditer(r"\[[^\[\]]*\]", text)]
    where = [
        f"line {lines[i]} (points[{i}])" if len(lines) == len(pts) else f"points[{i}]"
        for i in range(len(pts))
    ]
    rows = []
    for i, p in enumerate(pts):
        if (
            not isinstance(p, list)
            or len(p) != 2
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in p)
        ):
            raise TerrainFileError(
                f"{name}, {where[i]}: expected a pair [y, z] of numbers (metres), got "
                f"{json.dumps(p)[:60]}"
            )
        try:
            rows.append([float(p[0]), float(p[1])])
        except OverflowError:
            raise TerrainFileError(
                f"{name}, {where[i]}: a number too large for metres (a terrain is at most "
                f"{MAX_LENGTH:g} m long, {MAX_HEIGHT:g} m high)"
            ) from None
    return np.asarray(rows, dtype=np.float64).reshape(-1, 2), where


def _checked(pts: np.ndarray, where: list[str], name: str) -> Terrain:
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
                    f"{name}, {where[i]}: {label} must be a finite number, got {pts[i, j]}"
                )
    neg = np.flatnonzero(pts[:, 1] < 0.0)
    if neg.size:
        i = int(neg[0])
        raise TerrainFileError(
            f"{name}, {where[i]}: z = {pts[i, 1]:g} m is below the floor (heights are above "
            "the floor, z >= 0)"
        )
    high = np.flatnonzero(pts[:, 1] > MAX_HEIGHT)
    if high.size:
        i = int(high[0])
        raise TerrainFileError(
            f"{name}, {where[i]}: z = {pts[i, 1]:g} m, higher than a terrain may be "
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
    return Terrain(pts[:, 0].copy(), pts[:, 1].copy(), name)


__all__ = ["Terrain", "TerrainFileError", "read_terrain", "MAX_POINTS", "MAX_LENGTH", "MIN_POINTS"]
