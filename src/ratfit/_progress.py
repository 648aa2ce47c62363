"""Progress of counted steps on stderr, never on stdout, with an estimate of the time left.

One implementation for every long task that counts its steps (``ratfit compare``'s
fits, the render sampler's CDFs, a batch's tasks): on a terminal a rich bar with the
steps done, the time spent and the time left; without one (a log, a pipe, CI) a plain
line at most every ``every`` seconds and at the last step, e.g.
``ratfit: batch 5/24, 0 failed or no fit, 40 s, about 150 s left``.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

__all__ = ["StepProgress", "time_left"]


def time_left(elapsed: float, done: float, total: float) -> str:
    """``"about 12 s left"`` (``"about 3 min left"`` from two minutes on) at the rate so
    far; ``""`` before the first step or after the last."""
    if done <= 0 or total <= done:
        return ""
    left = elapsed / done * (total - done)
    return f"about {left:.0f} s left" if left < 120 else f"about {left / 60:.0f} min left"


class StepProgress:
    """``total`` counted steps of ``label`` (a context manager); :meth:`advance` after
    each.

    ``done``: steps already done before this run (a resumed batch): shown in the count,
    left out of the rate. ``every``: seconds between plain lines, or a function read at
    each line. ``enabled`` False shows nothing; ``tty`` None asks stderr."""

    def __init__(self, label: str, total: int, *, enabled: bool = True,
                 tty: bool | None = None, done: int = 0,
                 every: float | Callable[[], float] = 5.0) -> None:
        self.label, self.total, self.enabled = label, max(int(total), 1), enabled
        self.tty = sys.stderr.isatty() if tty is None else tty
        self.done0 = self.done = min(max(int(done), 0), self.total)
        self.every = every
        self.t0 = time.monotonic()
        self.last = self.t0
        self._bar: Any = None
        self._task: Any = None

    def _interval(self) -> float:
        return float(self.every() if callable(self.every) else self.every)

    def __enter__(self) -> StepProgress:
        return self.start()

    def start(self) -> StepProgress:
        """Start the clock (and the bar on a terminal); what entering the ``with`` does."""
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
                TextColumn("{task.fields[status]}"), TimeElapsedColumn(), TextColumn("left"),
                TimeRemainingColumn(), TextColumn("{task.fields[note]}"),
                console=Console(stderr=True), transient=True)
            self._task = self._bar.add_task(self.label, total=self.total,
                                            completed=self.done, note="", status="")
            self._bar.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def stop(self) -> None:
        """End the bar (also what leaving the ``with`` block does)."""
        if self._bar is not None:
            self._bar.stop()
            self._bar = None

    def line(self, now: float | None = None, note: str = "", status: str = "") -> str:
        """The plain line: label, count, status, seconds spent, the estimate, the note."""
        elapsed = (time.monotonic() if now is None else now) - self.t0
        left = time_left(elapsed, self.done - self.done0, self.total - self.done0)
        return (f"ratfit: {self.label} {self.done}/{self.total}"
                + (f", {status}" if status else "") + f", {elapsed:.0f} s"
                + (f", {left}" if left else "") + (f" ({note})" if note else ""))

    def advance(self, n: int = 1, note: str = "", status: str = "") -> None:
        """``n`` more steps done; ``note`` says which (shown after the estimate),
        ``status`` a running count (shown after the steps, e.g. "2 failed")."""
        self.done = min(self.done + n, self.total)
        if not self.enabled:
            return
        if self._bar is not None:
            self._bar.update(self._task, completed=self.done, note=note, status=status)
            return
        now = time.monotonic()
        if now - self.last >= self._interval() or self.done == self.total:
            self.last = now
            print(self.line(now, note, status), file=sys.stderr, flush=True)
