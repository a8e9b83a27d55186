"""Help text from docstrings: each paragraph on one line, so the terminal wraps it instead of
breaking lines where the source did."""

from __future__ import annotations

import inspect
import re

import typer

# A line that starts one of its own: a list item or an example. In a paragraph that starts
# indented (example commands) every line does.
_OWN_LINE = re.compile(r"^([-*•] |\d+[.)] |Examples?: )")


def reflow(doc: str) -> str:
    """``doc`` with each paragraph's lines joined, but for examples and list items, which keep
    their own lines."""
    paragraphs = inspect.cleandoc(doc).split("\n\n")
    return "\n\n".join(_join_lines(p) for p in paragraphs)


def _join_lines(paragraph: str) -> str:
    if paragraph[:1].isspace():
        return paragraph
    lines: list[str] = []
    for line in paragraph.split("\n"):
        if lines and not _OWN_LINE.match(line):
            lines[-1] = f"{lines[-1]} {line.strip()}"
        else:
            lines.append(line)
    return "\n".join(lines)


def reflow_commands(app: typer.Typer) -> None:
    """Give every command of ``app`` and of its groups, that has no help of its own, its
    docstring reflowed as help."""
    for command in app.registered_commands:
        if command.help is None and command.callback is not None and command.callback.__doc__:
            command.help = reflow(command.callback.__doc__)
    for group in app.registered_groups:
        if group.typer_instance is not None:
            reflow_commands(group.typer_instance)
