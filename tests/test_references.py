"""Every file and section the documentation and the code comments cite exists.

Checked in the Markdown pages (README.md, CHANGELOG.md, docs/**/*.md) and in the text of
the sources (``fastvi/``, ``tests/``, ``bench/``, ``examples/``, ``docs/**/*.py``, the
Makefile, ``.ci/run``):

* relative Markdown links ``[text](path#anchor)``: the file exists, and the anchor is a
  heading of the target page;
* repository paths such as ``docs/benchmarks.md`` or ``fastvi/kernels/step.py``, and bare
  page names such as ``method.md``: the file exists (a bare page name anywhere under docs/
  or at the root);
* sections cited by number, ``method.md §11``: the page has a heading ``## 11.``;
* sections cited by title or date, ``docs/benchmarks.md, "Large mechanisms"``: a heading
  of the page contains the title.
"""

from __future__ import annotations

import re
import unicodedata
from functools import lru_cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SKIP_DIRS = {".git", ".venv", "_build", "generated", "auto_examples", "__pycache__", ".release",
             ".pytest_cache", ".benchmarks"}
#: paths that commands write (not files of the repository)
GENERATED = {"bench/results.json"}

LINK = re.compile(r"(?<!!)\[[^\]\n]*\]\(([^)\s]+)\)|!\[[^\]\n]*\]\(([^)\s]+)\)")
REPO_PATH = re.compile(r"(?<![\w/.-])((?:docs|fastvi|tests|bench|examples)/[\w./-]*\w\.(?:md|py|rst|patch|png))\b")
BARE_PAGE = re.compile(r"(?<![\w/.-])([\w-]+\.md)\b")
SECTION_NUMBER = re.compile(r"([\w./-]+\.md)[`'\])(]*(?:\([\w./#-]*\))?\s*§\s?(\d+)")
SECTION_TITLE = re.compile(r"([\w./-]+\.md)[`'\])]*,\s*(?:[\"“]([^\"”\n]{3,120})[\"”]|(20\d\d-\d\d-\d\d[\w ()-]*))")


def _files(patterns: list[str]) -> list[Path]:
    out = []
    for pattern in patterns:
        for path in sorted(ROOT.glob(pattern)):
            if path.is_file() and not SKIP_DIRS & set(path.relative_to(ROOT).parts):
                out.append(path)
    return out


def markdown_files() -> list[Path]:
    return _files(["*.md", "docs/**/*.md"])


def text_files() -> list[Path]:
    # this file's own examples of broken citations are left out
    sources = _files(["fastvi/**/*.py", "tests/**/*.py", "bench/**/*.py", "examples/**/*.py",
                      "docs/**/*.py", "docs/**/*.rst", "Makefile", ".ci/run", "pyproject.toml"])
    return [p for p in markdown_files() + sources if p != Path(__file__).resolve()]


def slug(heading: str) -> str:
    """The anchor GitHub and myst-parser give a heading: lower case, punctuation dropped,
    spaces turned into hyphens (``## 8. Forces and time`` -> ``8-forces-and-time``)."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = "".join(c for c in text if c in " -" or unicodedata.category(c)[0] in "LN")
    return text.replace(" ", "-")


@lru_cache(maxsize=None)
def headings(path: Path) -> tuple[str, ...]:
    text = path.read_text(encoding="utf-8")
    text = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)  # no headings inside code
    return tuple(m.group(1).strip() for m in re.finditer(r"^#{1,6}\s+(.+)$", text, re.M))


def flattened(text: str) -> str:
    """The text with line breaks (and the comment markers that continue a comment) turned
    into single spaces, so that a citation wrapped over two lines is still one citation."""
    return re.sub(r"\s*\n\s*(?:#:?\s|//\s)?\s*", " ", text)


def page(name: str, cited_from: Path) -> Path | None:
    """The page a citation ``name`` means: a path from the root or from the citing file,
    or a bare page name found at the root or under docs/."""
    for base in (ROOT, cited_from.parent):
        if (base / name).is_file():
            return (base / name).resolve()
    if "/" not in name:
        hits = [p for p in [ROOT / name, *ROOT.glob(f"docs/**/{name}")]
                if p.is_file() and not SKIP_DIRS & set(p.relative_to(ROOT).parts)]
        if hits:
            return hits[0].resolve()
    return None


def broken_links(path: Path) -> list[str]:
    problems = []
    text = re.sub(r"^```.*?^```", "", path.read_text(encoding="utf-8"), flags=re.S | re.M)
    text = re.sub(r"`[^`\n]*`", "", text)  # links inside inline code are examples, not links
    for m in LINK.finditer(text):
        target = m.group(1) or m.group(2)
        if re.match(r"[a-z]+:", target):  # http:, https:, mailto:
            continue
        file_part, _, anchor = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        if not dest.exists():
            problems.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in {slug(h) for h in headings(dest)}:
            problems.append(f"{target}: no heading with anchor #{anchor}")
    return problems


def broken_citations(path: Path) -> list[str]:
    problems = []
    text = path.read_text(encoding="utf-8")
    flat = flattened(text)
    for m in REPO_PATH.finditer(text):
        name = m.group(1)
        if name not in GENERATED and not (ROOT / name).exists():
            problems.append(f"{name}: no such file")
    for m in BARE_PAGE.finditer(text):
        if page(m.group(1), path) is None:
            problems.append(f"{m.group(1)}: no such page")
    for m in SECTION_NUMBER.finditer(flat):
        target = page(m.group(1), path)
        number = m.group(2)
        if target is not None and not any(re.match(rf"{number}[.\s]", h) for h in headings(target)):
            problems.append(f"{m.group(1)} §{number}: no such section")
    for m in SECTION_TITLE.finditer(flat):
        target = page(m.group(1), path)
        title = (m.group(2) or m.group(3)).strip().lower().rstrip(".,;)")
        if target is not None and not any(title in h.lower() for h in headings(target)):
            problems.append(f"{m.group(1)}, {title!r}: no heading of that page contains it")
    return problems


def test_slug_matches_github_anchors():
    assert slug("8. Forces and time") == "8-forces-and-time"
    assert slug("Compile and set-up time") == "compile-and-set-up-time"
    assert slug("`fastvi` (top level)") == "fastvi-top-level"


def test_checker_finds_what_is_broken(tmp_path):
    doc = tmp_path / "page.md"
    doc.write_text("# Title\n\n## 2. Second\n\n[ok](page.md#2-second) [bad](missing.md) "
                   "[bad anchor](page.md#nowhere)\n", encoding="utf-8")
    assert broken_links(doc) == ["missing.md: no such file", "page.md#nowhere: no heading with anchor #nowhere"]
    src = tmp_path / "code.py"
    src.write_text(f"# see {doc.name} §2 and {doc.name} §3, and\n# {doc.name}, \"Second\" "
                   f"or {doc.name}, \"Third\"; docs/no-such-page-here.md\n", encoding="utf-8")
    found = broken_citations(src)
    assert "page.md §3: no such section" in found
    assert "page.md, 'third': no heading of that page contains it" in found
    assert "docs/no-such-page-here.md: no such file" in found
    assert not any("§2" in p or "'second'" in p for p in found)


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_markdown_links_resolve(path):
    assert broken_links(path) == []


@pytest.mark.parametrize("path", text_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_cited_files_and_sections_exist(path):
    assert broken_citations(path) == []
