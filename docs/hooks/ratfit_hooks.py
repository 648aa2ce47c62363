"""MkDocs hooks: the command-line reference from the commands themselves; Sphinx roles.

A page line `<!-- ratfit-cli-help -->` becomes the `--help` text of every `ratfit`
command and subcommand, so the reference always matches the installed code.
"""

from __future__ import annotations

import re
from typing import Any

MARKER = "<!-- ratfit-cli-help -->"


def _commands(group: Any, path: list[str]) -> list[list[str]]:
    import click

    found = [path]
    if isinstance(group, click.Group):
        ctx = click.Context(group)
        for name in group.list_commands(ctx):  # its commands, modules imported on first use
            found += _commands(group.get_command(ctx, name), path + [name])
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


# Docstrings cite names with Sphinx roles (:class:`~ratfit.x.Y`); mkdocstrings renders
# Markdown, where the role stays as text. Drop the role, and with "~" keep the last name.
_ROLE = re.compile(r":(?:class|func|meth|data|attr|mod|obj|exc):<code>(~?)([\w.]+)</code>")


def _role(match: re.Match[str]) -> str:
    name = match.group(2).rsplit(".", 1)[-1] if match.group(1) else match.group(2)
    return f"<code>{name}</code>"


def on_page_content(html: str, **kwargs: Any) -> str:
    return _ROLE.sub(_role, html)
