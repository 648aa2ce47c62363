"""Progress on a non-terminal: a line at least every PROGRESS_EVERY seconds, also
while no split reports (one long QP, a long verification)."""

from __future__ import annotations

import importlib
import time

import pytest

from ratfit.core.qp import Attempt

# the module (ratfit.cli.main is also the name of the click group)
cli_main = importlib.import_module("ratfit.cli.main")


@pytest.mark.slow
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


def test_json_runs_show_progress_on_stderr_and_keep_stdout_one_object(
        monkeypatch, tmp_path) -> None:
    """--json puts the result on stdout; a long run still tells stderr it moves."""
    import json

    import numpy as np
    from conftest import run_cli, write_file

    monkeypatch.setattr(cli_main, "PROGRESS_EVERY", 0.01)
    x = np.linspace(0.0, 3.0, 300)
    data = write_file(tmp_path, "d.csv", "x,y\n" + "".join(
        f"{a:.6f},{b:.9f}\n" for a, b in zip(x, np.exp(x) / (1.5 + np.sin(3 * x)), strict=True)))
    r = run_cli("fit", data, "--dt", "0.01", "-o", tmp_path / "f.json", "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["success"] is True and doc["verified"] is True
    import re

    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("ratfit:")]
    assert lines and all(re.fullmatch(r"ratfit: \d+ s, tested \d+ splits(; last .*)?", ln)
                         for ln in lines), lines[:3]
    assert max(int(ln.split("tested ")[1].split()[0]) for ln in lines) <= doc["qp_solves"]


def test_step_lines_are_throttled_notes_are_not(monkeypatch, capsys) -> None:
    """Long jobs' steps (render passes) print at most every PROGRESS_EVERY seconds in a
    log, their first step (the first estimate), last step and every note always;
    stdout gets nothing."""
    from ratfit.cli.progress import StepProgress, message_progress

    monkeypatch.setattr(cli_main, "PROGRESS_EVERY", 3600.0)
    say, stop = message_progress(tty=False)
    say("note: something a reader must see")
    for k in range(1, 5):
        say(f"~fit: pass {k}/4, {k}/4 spp, 1.0 s, " + ("done" if k == 4 else "about 3 s left"))
    stop()
    out = capsys.readouterr()
    assert out.out == ""
    assert out.err.splitlines() == ["note: something a reader must see",
                                    "fit: pass 1/4, 1/4 spp, 1.0 s, about 3 s left",
                                    "fit: pass 4/4, 4/4 spp, 1.0 s, done"]
    monkeypatch.setattr(cli_main, "PROGRESS_EVERY", 0.0)
    with StepProgress("compare", 4, tty=False) as bar:
        for k in range(4):
            bar.advance(1, f"start {k + 1}")
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 4 and all(ln.startswith("ratfit: compare ") for ln in lines)
    assert "s left (start 1)" in lines[0] and lines[-1].startswith("ratfit: compare 4/4, ")
    with StepProgress("quiet", 2, enabled=False, tty=False) as bar:
        bar.advance(2)
    assert capsys.readouterr().err == ""


def test_step_progress_estimates_from_the_steps_run_now(capsys) -> None:
    """A resumed batch: steps done before count in the total, not in the rate; the
    running status sits after the count; the estimate switches to minutes at 120 s."""
    from ratfit._progress import StepProgress, time_left

    bar = StepProgress("batch", 10, tty=False, done=4, every=3600.0).start()
    bar.t0 = 1000.0
    bar.advance(2, status="1 failed or no fit")  # the first line waits for `every`
    assert capsys.readouterr().err == ""
    # 2 steps run now in 30 s: 4 left take 60 s (the 4 resumed ones are not timed)
    assert bar.line(now=1030.0, note="R", status="1 failed or no fit") == (
        "ratfit: batch 6/10, 1 failed or no fit, 30 s, about 60 s left (R)")
    assert bar.line(now=1300.0) == "ratfit: batch 6/10, 300 s, about 10 min left"
    bar.advance(4, status="1 failed or no fit")  # the last step always prints
    (last,) = capsys.readouterr().err.splitlines()
    assert last.startswith("ratfit: batch 10/10, 1 failed or no fit, ") and "left" not in last
    assert time_left(10.0, 0, 5) == "" and time_left(10.0, 5, 5) == ""
    assert time_left(59.0, 1, 3) == "about 118 s left"
    assert time_left(61.0, 1, 3) == "about 2 min left"
