"""What the benchmarks/*.py runners share: their command line's parser, which shows the script's
docstring as written and takes the policy to measure."""

from __future__ import annotations

import argparse


def parser(doc: str, policy: bool = True) -> argparse.ArgumentParser:
    """A runner's parser: ``doc`` (the script's docstring) as its help, a ``policy`` argument (the
    policy.npz to measure) unless ``policy`` is False."""
    p = argparse.ArgumentParser(
        description=doc, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    if policy:
        p.add_argument("policy", help="policy.npz")
    return p
