"""MkDocs hook: the command-line reference's option lists, from the commands themselves.

A page line `<!-- ratfit-cli-help -->` becomes the `--help` text of every `ratfit`
command and subcommand, so the reference always matches the installed code.
"""

from __future__ import annotations

from typing import Any

MARKER = "<!-- ratfit-cli-help -->"


def _commands(group: Any, path: list[str]) -> list[list[str]]:
    import click

    found = [path]
    if isinstance(group, click.Group):
        for name in sorted(group.commands):
            found += _commands(group.commands[name], path + [name])
    return found


def _help_sections() -> str:
    from click.testing import CliRunner

    from ratfit.cli import main

    runner = CliRunner()
    parts = []
    for path in _commands(main, []):
        res = runner.invoke(main, [*path, "--help"], env={"COLUMNS": "96"},
                            prog_name="ratfit", terminal_width=96)
        if res.exit_code != 0:
            raise RuntimeError(f"ratfit {' '.join(path)} --help exited {res.exit_code}")
        title = " ".join(["ratfit", *path])
        parts.append(f"### `{title}`\n\n```text\n{res.output.rstrip()}\n```\n")
    return "\n".join(parts)


def on_page_markdown(markdown: str, **kwargs: Any) -> str:
    if MARKER not in markdown:
        return markdown
    return markdown.replace(MARKER, _help_sections())
