"""Argument parsers of the ``python -m fastvi`` commands: plain-text help with defaults."""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

__all__ = ["study_parser", "default_out", "plain", "write_sections"]


def plain(text: str) -> str:
    """``text`` without reST markup (roles, literals, ``::``), for terminal help."""
    text = re.sub(r":[a-z]+:`~?([^`]+)`", r"\1", text)
    text = text.replace("``", "").replace("`", "")
    return re.sub(r"::$", ":", text, flags=re.M)


def default_out(name: str) -> str:
    """Where a study writes unless told otherwise: a directory of the user's, in the current
    directory; the package's own ``docs/`` only with ``--out docs`` (the Makefile does that)."""
    return f"fastvi-study-{name}"


def study_parser(prog: str, doc: str) -> argparse.ArgumentParser:
    """A parser whose description is the first paragraph of ``doc`` as plain text and whose
    ``--help`` shows every option's default."""
    first = plain(doc.strip().split("\n\n")[0])
    return argparse.ArgumentParser(prog=prog, description=" ".join(first.split()),
                                   formatter_class=argparse.ArgumentDefaultsHelpFormatter)


def write_sections(path, parts) -> str:
    """Write ``parts``, pairs ``(title, body)``, as Markdown sections ``## title`` to ``path``
    (its directory created) and to standard output; returns the text."""
    text = "\n\n".join(f"## {title}\n\n{body}" for title, body in parts) + "\n"
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text, encoding="utf-8")
    sys.stdout.write(text)
    return text
