"""Every command's --help: paragraphs are reflowed by the terminal, never broken mid-sentence
where the docstring's source lines ended."""

from __future__ import annotations

import itertools
import re

import typer.main
from typer.testing import CliRunner

from fleet.cli import app
from fleet.cli.help_text import reflow

runner = CliRunner()


def _command_paths() -> list[list[str]]:
    paths: list[list[str]] = []

    def walk(command: object, path: list[str]) -> None:
        paths.append(path)
        for name, sub in getattr(command, "commands", {}).items():
            walk(sub, [*path, name])

    walk(typer.main.get_command(app), [])
    return paths


def _text_lines(output: str) -> list[str]:
    """The help's prose: the lines outside the boxes of arguments and options."""
    return [ln.strip() for ln in output.splitlines() if ln.strip() and ln.strip()[0] not in "│╭╰"]


def test_every_help_keeps_each_paragraph_on_one_line() -> None:
    paths = _command_paths()
    assert ["plan", "mapf"] in paths and ["bench", "sim"] in paths and len(paths) > 20
    broken = []
    for path in paths:
        result = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "5000"})
        assert result.exit_code == 0, (path, result.output)
        lines = _text_lines(result.output)
        for line, after in itertools.pairwise(lines):
            # a sentence that goes on: no closing punctuation, the next line in lower case and
            # not an example command
            ends = re.search(r"[.:;!?)`]$", line)
            if not ends and re.match(r"[a-z(]", after) and not after.startswith("fleet "):
                broken.append((" ".join(path), line[-40:], after[:40]))
    assert not broken


def test_reflow_keeps_examples_and_list_items_on_their_own_lines() -> None:
    doc = """Summary.

    A paragraph broken
    where the source
    ended.

    Example: fleet a --b
    Example: fleet c

    - one item
      continued
    - two

        fleet plan mapf x.map
        fleet plan mapf y.map
    """
    assert reflow(doc).split("\n\n") == [
        "Summary.",
        "A paragraph broken where the source ended.",
        "Example: fleet a --b\nExample: fleet c",
        "- one item continued\n- two",
        "    fleet plan mapf x.map\n    fleet plan mapf y.map",
    ]
