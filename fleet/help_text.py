"""Help text from docstrings: each paragraph on one line, so the terminal wraps it instead of
breaking lines where the source did."""

from __future__ import annotations

import inspect


def reflow(doc: str) -> str:
    paragraphs = inspect.cleandoc(doc).split("\n\n")
    return "\n\n".join(" ".join(p.split("\n")) for p in paragraphs)
