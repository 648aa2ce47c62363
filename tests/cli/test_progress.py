"""Progress on a non-terminal: a line at least every PROGRESS_EVERY seconds, also
while no split reports (one long QP, a long verification)."""

from __future__ import annotations

import importlib
import time

from ratfit.core.qp import Attempt

# the module (ratfit.cli.main is also the name of the click group)
cli_main = importlib.import_module("ratfit.cli.main")


def test_progress_lines_while_nothing_reports(monkeypatch, capsys) -> None:
    monkeypatch.setattr(cli_main, "PROGRESS_EVERY", 0.2)
    cb, stop = cli_main._progress(True)  # pytest's stderr is not a terminal
    assert cb is not None
    cb(Attempt(3, 2, "infeasible"))
    time.sleep(0.9)  # no attempt reports meanwhile
    stop()
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("ratfit:")]
    assert 3 <= len(lines) <= 6, lines
    assert "tested 1 splits; last (n=3, m=2): infeasible" in lines[-1]
    time.sleep(0.5)  # stopped: no more lines
    assert capsys.readouterr().err == ""
