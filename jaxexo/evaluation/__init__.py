"""Evaluation layer: RL against CFFTG on shared scenes (``compare``), the thesis's tables
(``reproduce``), generator timing and the machine facts recorded beside every figure.

Imports the library layers below it, never the benchmark suite (benchmarks/benchlib)."""
