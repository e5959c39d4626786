"""The figures every report quotes of a sample (``Summary``: median, p95, ...), the ratio of two
generators' figures, and the one Markdown table builder. NumPy only; what each benchmark measures is in
docs/benchmarks.md."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, fields

import numpy as np


@dataclass(frozen=True)
class Summary:
    """A sample x [N]: its size and its figures, in x's unit (NaN for an empty sample)."""

    n: int
    mean: float
    median: float
    p5: float
    p95: float
    min: float
    max: float

    @classmethod
    def of(cls, x) -> Summary:
        """The figures of x [N] (array-like). Each is NumPy's own reduction of x as given (no cast), so
        it is the very number a hand-written ``float(np.median(x))`` gives."""
        a = np.asarray(x)
        if a.size == 0:
            nan = float("nan")
            return cls(0, nan, nan, nan, nan, nan, nan)
        return cls(
            n=int(a.size),
            mean=float(a.mean()),
            median=float(np.median(a)),
            p5=float(np.percentile(a, 5)),
            p95=float(np.percentile(a, 95)),
            min=float(a.min()),
            max=float(a.max()),
        )

    def over(self, other: Summary) -> Summary:
        """Figure by figure, this sample's over ``other``'s (e.g. RL's median over CFFTG's); n is this
        sample's."""
        ratios = {f.name: getattr(self, f.name) / getattr(other, f.name) for f in fields(self)[1:]}
        return Summary(n=self.n, **ratios)

    def to_dict(self) -> dict:
        return asdict(self)


def table(header: Sequence[str], rows: Iterable[Sequence], align: str | None = None) -> list[str]:
    """A Markdown table's lines: the header, the alignment row and one line per row of cells (each cell
    as ``str`` gives it, an empty one as ``| |``). ``align``: a letter per column, ``l`` (``---``) or
    ``r`` (``---:``); by default the first column ``l``, the others ``r``."""
    align = align or "l" + "r" * (len(header) - 1)
    assert len(align) == len(header), (align, header)
    rule = "".join("---|" if a == "l" else "---:|" for a in align)

    def line(cells) -> str:
        return "|" + "".join(f" {c} |" if str(c) else " |" for c in cells)

    return [line(header), "|" + rule, *map(line, rows)]
