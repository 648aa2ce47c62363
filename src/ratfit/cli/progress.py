"""Progress of long commands on stderr, never on stdout (``--json`` stays one object).

Counted steps go through :class:`ratfit._progress.StepProgress` (also the batch
runner's): on a terminal a rich bar with the steps done, the time spent and an
estimate of the time left. Without a terminal (a log, a pipe, CI): a plain line at most every
``PROGRESS_EVERY`` seconds (and at the last step), so a log shows the command moves
without a line per tick: ``ratfit: compare 5/24, 40 s, about 150 s left (G, start 2)``.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

import click

from ratfit._progress import StepProgress as _StepProgress

__all__ = ["StepProgress", "message_progress"]


def _every() -> float:
    """ratfit.cli.main.PROGRESS_EVERY, read at each use (tests shorten it)."""
    import importlib

    return float(importlib.import_module("ratfit.cli.main").PROGRESS_EVERY)


class StepProgress(_StepProgress):
    """:class:`ratfit._progress.StepProgress` whose plain lines come at most every
    ``ratfit.cli.main.PROGRESS_EVERY`` seconds (read at each line)."""

    def __init__(self, label: str, total: int, *, enabled: bool = True,
                 tty: bool | None = None, done: int = 0) -> None:
        super().__init__(label, total, enabled=enabled, tty=tty, done=done, every=_every)


def message_progress(*, tty: bool | None = None) -> tuple[Callable[[str], None],
                                                           Callable[[], None]]:
    """A sink for a job's progress lines, and a function that ends it.

    Lines that report a step (they start with ``"~"``: ``"~fit: pass 3/64, ..."``)
    update one transient status line on a terminal and appear at most every
    ``PROGRESS_EVERY`` seconds in a log; other lines (notes, phases) always print."""
    is_tty = sys.stderr.isatty() if tty is None else tty
    status: Any = None
    state = {"last": float("-inf")}  # the first step always prints (whatever the uptime)
    if is_tty:
        from rich.console import Console

        status = Console(stderr=True).status("")

    def say(msg: str) -> None:
        nonlocal status
        if not msg.startswith("~"):
            if status is not None:
                status.console.print(msg, highlight=False, markup=False)
            else:
                click.echo(msg, err=True)
            return
        text = msg[1:]
        if status is not None:
            from rich.markup import escape

            status.update(escape(text))
            status.start()
            return
        now = time.monotonic()
        final = " done" in text
        if now - state["last"] >= _every() or final:
            state["last"] = now
            click.echo(text, err=True)

    def stop() -> None:
        if status is not None:
            status.stop()

    return say, stop
