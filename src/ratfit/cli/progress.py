"""Progress of long commands on stderr, never on stdout (``--json`` stays one object).

On a terminal: a rich bar with the steps done, the time spent and an estimate of
the time left. Without a terminal (a log, a pipe, CI): a plain line at most every
``PROGRESS_EVERY`` seconds (and at the last step), so a log shows the command moves
without a line per tick: ``ratfit: compare 5/24, 40 s, about 150 s left (G, start 2)``.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

import click

__all__ = ["StepProgress", "message_progress"]


def _every() -> float:
    """ratfit.cli.main.PROGRESS_EVERY, read at each use (tests shorten it)."""
    import importlib

    return float(importlib.import_module("ratfit.cli.main").PROGRESS_EVERY)


def _eta(elapsed: float, done: float, total: float) -> str:
    if done <= 0 or total <= done:
        return ""
    left = elapsed / done * (total - done)
    return f", about {left:.0f} s left" if left < 120 else f", about {left / 60:.0f} min left"


class StepProgress:
    """``total`` counted steps of ``label`` (a context manager); :meth:`advance` after
    each. ``enabled`` False shows nothing; ``tty`` None asks stderr."""

    def __init__(self, label: str, total: int, *, enabled: bool = True,
                 tty: bool | None = None) -> None:
        self.label, self.total, self.enabled = label, max(int(total), 1), enabled
        self.tty = sys.stderr.isatty() if tty is None else tty
        self.done = 0
        self.t0 = time.monotonic()
        self.last = self.t0
        self._bar: Any = None
        self._task: Any = None

    def __enter__(self) -> StepProgress:
        self.t0 = self.last = time.monotonic()
        if self.enabled and self.tty:
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            self._bar = Progress(
                TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                TimeElapsedColumn(), TextColumn("left"), TimeRemainingColumn(),
                TextColumn("{task.fields[note]}"), console=Console(stderr=True),
                transient=True)
            self._task = self._bar.add_task(self.label, total=self.total, note="")
            self._bar.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None

    def advance(self, n: int = 1, note: str = "") -> None:
        """``n`` more steps done; ``note`` says which (shown beside the count)."""
        self.done = min(self.done + n, self.total)
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.update(self._task, completed=self.done, note=note)
            return
        now = time.monotonic()
        if now - self.last >= _every() or self.done == self.total:
            self.last = now
            elapsed = now - self.t0
            click.echo(f"ratfit: {self.label} {self.done}/{self.total}, {elapsed:.0f} s"
                       f"{_eta(elapsed, self.done, self.total)}"
                       + (f" ({note})" if note else ""), err=True)


def message_progress(*, tty: bool | None = None) -> tuple[Callable[[str], None],
                                                           Callable[[], None]]:
    """A sink for a job's progress lines, and a function that ends it.

    Lines that report a step (they start with ``"~"``: ``"~fit: pass 3/64, ..."``)
    update one transient status line on a terminal and appear at most every
    ``PROGRESS_EVERY`` seconds in a log; other lines (notes, phases) always print."""
    is_tty = sys.stderr.isatty() if tty is None else tty
    status: Any = None
    state = {"last": 0.0}
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
