"""The documentation: every relative link in README.md and docs/*.md resolves, the README stays short,
and the configuration reference names every config field."""

from __future__ import annotations

import dataclasses
import re
import unicodedata
from pathlib import Path
from urllib.parse import unquote

import pytest

from conftest import ROOT

README_MAX_LINES = 250

# [text](target) and ![alt](target); the target ends at whitespace or ")" (an optional "title" follows).
_LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_FENCE = re.compile(r"^(```|~~~)")
_HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")


def doc_files(root: Path = ROOT) -> list[Path]:
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


def _prose_lines(text: str, keep_code: bool = False) -> list[tuple[int, str]]:
    """(line number, line) outside fenced code blocks; inline code spans removed unless keep_code."""
    out, fenced = [], False
    for n, line in enumerate(text.splitlines(), 1):
        if _FENCE.match(line.lstrip()):
            fenced = not fenced
            continue
        if not fenced:
            out.append((n, line if keep_code else re.sub(r"`[^`]*`", "", line)))
    return out


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: markup dropped, lower case, punctuation removed, spaces to '-'."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # links: keep their text
    text = text.replace("`", "").strip().lower()
    text = "".join(
        c for c in text if c in "-_ " or unicodedata.category(c)[0] in "LNM"
    )  # letters, digits, marks
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Every heading anchor of a markdown file (repeated headings get -1, -2, ... as on GitHub)."""
    seen: dict[str, int] = {}
    out = set()
    for _, line in _prose_lines(path.read_text(), keep_code=True):  # headings may hold code
        m = _HEADING.match(line)
        if not m:
            continue
        base = slug(m.group(2))
        k = seen.get(base, 0)
        seen[base] = k + 1
        out.add(base if k == 0 else f"{base}-{k}")
    return out


def broken_links(path: Path, root: Path = ROOT) -> list[str]:
    """'file:line: target (why)' for each relative link of ``path`` that does not resolve."""
    problems = []
    for n, line in _prose_lines(path.read_text()):
        for target in _LINK.findall(line):
            if re.match(r"^[a-z][a-z0-9+.-]*:", target, flags=re.I):  # http:, https:, mailto: ...
                continue
            file_part, _, anchor = target.partition("#")
            dest = path if not file_part else (path.parent / unquote(file_part)).resolve()
            where = f"{path.relative_to(root)}:{n}: {target}"
            if file_part and not dest.is_relative_to(root.resolve()):
                problems.append(f"{where} (outside the repository)")
            elif not dest.exists():
                problems.append(f"{where} (no such file)")
            elif anchor and dest.suffix == ".md" and unquote(anchor) not in anchors(dest):
                problems.append(f"{where} (no heading with this anchor)")
    return problems


def test_readme_is_short():
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= README_MAX_LINES, (
        f"README.md has {len(lines)} lines (at most {README_MAX_LINES})"
    )


def test_readme_reaches_a_generated_trajectory_early():
    lines = (ROOT / "README.md").read_text().splitlines()
    first = next(
        i for i, ln in enumerate(lines, 1) if ".generate(" in ln or "jaxexo generate" in ln
    )
    assert first <= 60, f"the first generated trajectory is on line {first}"


def test_docs_exist_and_are_linked_from_the_readme():
    pages = sorted((ROOT / "docs").glob("*.md"))
    assert pages
    readme = (ROOT / "README.md").read_text()
    for page in pages:
        assert f"docs/{page.name}" in readme, f"README.md does not link docs/{page.name}"


@pytest.mark.parametrize("path", doc_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(path):
    assert broken_links(path) == []


def test_a_broken_link_is_caught(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "page.md").write_text("# A page\n\n## Some `code` heading, here\n")
    (tmp_path / "README.md").write_text(
        "[`ok`](docs/page.md) [ok](docs/page.md#some-code-heading-here) [ok](#top) [web](https://x.org/a)\n"
        "```\n[inside a fence](nowhere.md)\n```\n"
        "[missing](docs/nope.md) [bad anchor](docs/page.md#nope) ![img](docs/gone.gif)\n"
        "# Top\n"
    )
    problems = broken_links(tmp_path / "README.md", tmp_path)
    assert [p.split(": ", 1)[1] for p in problems] == [
        "docs/nope.md (no such file)",
        "docs/page.md#nope (no heading with this anchor)",
        "docs/gone.gif (no such file)",
    ]


def test_slugs_match_github():
    assert (
        slug("The shield: the policy chooses only among safe moves")
        == "the-shield-the-policy-chooses-only-among-safe-moves"
    )
    assert (
        slug("`jaxexo eval`: both generators side by side")
        == "jaxexo-eval-both-generators-side-by-side"
    )
    assert (
        slug("Device-ready swings: joint limits, timing, control rate")
        == "device-ready-swings-joint-limits-timing-control-rate"
    )
    assert slug("`[env]`") == "env"


def test_configuration_reference_names_every_field():
    """Each section of Config has a heading in docs/configuration.md and a table row per field."""
    from jaxexo import Config

    text = (ROOT / "docs" / "configuration.md").read_text()
    missing = []
    for section in dataclasses.fields(Config):
        heading = f"## `[{section.name}]`"
        if heading not in text:
            missing.append(f"[{section.name}]")
            continue
        body = text.split(heading, 1)[1].split("\n## ", 1)[0]
        for f in dataclasses.fields(section.default_factory()):
            if f"| `{f.name}` |" not in body:
                missing.append(f"{section.name}.{f.name}")
    assert missing == [], f"docs/configuration.md does not document: {missing}"


# A tracker's issue number ("issue" and a number) means nothing to a reader of the repository: the
# code, tests, configs, benchmarks and documentation say what and why instead (history is in git).
_ISSUE_NUMBER = re.compile(r"\bissues?\s*#?\s*\d+", re.IGNORECASE)


def _prose_files():
    for folder, pattern in (
        ("jaxexo", "**/*.py"),
        ("jaxexo", "**/*.toml"),
        ("tests", "*.py"),
        ("benchmarks", "**/*.py"),
        ("configs", "**/*.toml"),
        ("docs", "*.md"),
    ):
        yield from sorted((ROOT / folder).glob(pattern))
    yield ROOT / "README.md"


def test_no_issue_numbers_in_code_or_docs():
    found = [
        f"{p.relative_to(ROOT)}:{i}: {line.strip()}"
        for p in _prose_files()
        for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
        if _ISSUE_NUMBER.search(line)
    ]
    assert not found, "issue numbers (say what and why instead):\n" + "\n".join(found[:20])


def test_the_issue_number_check_catches_one():
    assert _ISSUE_NUMBER.search("the shield (Iss" + "ue 11)") and _ISSUE_NUMBER.search(
        "iss" + "ues 12, 19"
    )
    assert not _ISSUE_NUMBER.search("an issue with 3 vertices") and not _ISSUE_NUMBER.search(
        "tissue 4"
    )
