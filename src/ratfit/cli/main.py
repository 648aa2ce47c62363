"""Command-line interface: parse, call the library, print or write. No fitting logic.

Exit codes: 0 success, 1 a run that found no verified fit, 2 bad input or usage,
74 the work was done but writing to standard output failed (a full device: the
message lists the files that were written and are complete), 130 Ctrl-C.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import sys
import threading
import time
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import click

from ratfit.errors import RatfitError

EXIT_NO_FIT = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130
# sysexits.h EX_IOERR: not "bad input, no file" (2): the fit file may well be written
EXIT_STDOUT_FAILED = 74
# Without a terminal, a progress line on stderr at most this often (seconds).
PROGRESS_EVERY = 5.0


def one_line(text: str) -> str:
    """Collapse a message to one line: bad input gets exactly one ``error:`` line."""
    return " ".join(str(text).split())


def _usage_message(exc: click.UsageError) -> str:
    """click's Usage/Try/Error block folded into one ``error:`` line."""
    msg = one_line(exc.format_message())
    ctx = exc.ctx
    if ctx is None:
        return f"error: {msg}"
    usage = one_line(ctx.get_usage()).removeprefix("Usage: ")
    return f"error: {msg} (usage: {usage}; see '{ctx.command_path} --help')"


class StdoutError(Exception):
    """Writing to standard output failed (not a closed pipe): the command's work is done."""

    def __init__(self, exc: OSError) -> None:
        super().__init__(str(exc))
        self.exc = exc


@contextlib.contextmanager
def stdout_guard():
    """Turn a failed write to standard output (ENOSPC, EIO, ...) into :class:`StdoutError`."""
    try:
        yield
    except BrokenPipeError:
        raise
    except OSError as exc:
        if exc.filename is not None:
            raise
        raise StdoutError(exc) from None


class LazyGroup(click.Group):
    """A group whose commands may live in other modules, imported when first looked up.

    ``lazy`` maps a command name to ``"module:attribute"``; commands added the usual
    way (``@group.command``) sit beside them. Listing the commands (``--help``)
    imports every module; running one imports its own module only.
    """

    def __init__(self, *args: Any, lazy: Mapping[str, str] | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.lazy: dict[str, str] = dict(lazy or {})

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*self.commands, *self.lazy})

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in self.commands and cmd_name in self.lazy:
            module, _, attr = self.lazy[cmd_name].partition(":")
            cmd = getattr(importlib.import_module(module), attr)
            if not isinstance(cmd, click.Command) or cmd.name != cmd_name:
                raise TypeError(f"{self.lazy[cmd_name]} is not the command {cmd_name!r}")
            self.add_command(cmd)
        return super().get_command(ctx, cmd_name)


# Every command of ``ratfit``: name -> "module:attribute", imported on first use.
COMMANDS: dict[str, str] = {
    "batch": "ratfit.cli.batch:batch_cmd",
    "brdf": "ratfit.cli.brdf:brdf_group",
    "cdf": "ratfit.cli.cdf:cdf_cmd",
    "demo": "ratfit.cli.demo:demo_group",
    "eval": "ratfit.cli.fit:eval_cmd",
    "export": "ratfit.cli.export:export_cmd",
    "fit": "ratfit.cli.fit:fit_cmd",
    "plot": "ratfit.cli.export:plot_cmd",
    "render": "ratfit.cli.render:render_cmd",
    "report": "ratfit.cli.export:report_cmd",
    "sample": "ratfit.cli.cdf:sample_cmd",
    "tolerance": "ratfit.cli.tolerance:tolerance_cmd",
}


class _Main(LazyGroup):
    """Maps library errors to one-line messages and exit codes, without tracebacks.

    Warnings raised while a command runs are held back: when the input turns out
    bad, the one ``error:`` line is all the user sees; otherwise they follow the
    output as ``warning:`` lines.
    """

    def main(self, args: Any = None, prog_name: str | None = None,
             complete_var: str | None = None, standalone_mode: bool = True,
             **extra: Any) -> Any:
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode, **extra)
        from ratfit.core.memory import prefer_small_pages

        prefer_small_pages()  # the process is the command's (see ratfit.core.memory)
        try:
            rv = super().main(args, prog_name, complete_var, False, **extra)
        except click.UsageError as exc:
            click.echo(_usage_message(exc), err=True)
            sys.exit(EXIT_BAD_INPUT)
        except click.ClickException as exc:
            click.echo(f"error: {one_line(exc.format_message())}", err=True)
            sys.exit(exc.exit_code)
        except click.Abort:
            click.echo("interrupted", err=True)
            sys.exit(EXIT_INTERRUPTED)
        sys.exit(rv if isinstance(rv, int) else 0)

    def invoke(self, ctx: click.Context) -> Any:
        from ratfit._atomic import forget_completed

        forget_completed()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("default")
            try:
                rv = self._invoke(ctx)
            except click.exceptions.Exit as exc:
                if exc.exit_code not in (0, EXIT_NO_FIT):
                    raise
                _replay(caught)
                raise
            except SystemExit as exc:
                if exc.code not in (0, None, EXIT_NO_FIT):
                    raise
                _replay(caught)
                raise
        _replay(caught)
        return rv

    def _invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except (click.exceptions.Exit, click.ClickException, click.Abort):
            raise
        except KeyboardInterrupt:
            # Ctrl-C: stop now. Fit files are written atomically at the end, so nothing
            # partial is left; worker threads still inside a QP are not waited for.
            click.echo("interrupted", err=True)
            sys.stdout.flush()
            sys.stderr.flush()
            if threading.active_count() > 1 and sys.stdout is sys.__stdout__:
                os._exit(EXIT_INTERRUPTED)  # a real process (not a test runner's streams)
            ctx.exit(EXIT_INTERRUPTED)
        except BrokenPipeError:
            # The reader went away (``ratfit eval ... | head``): not an input error.
            # Point stdout at devnull so the interpreter's final flush stays quiet.
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            ctx.exit(141)
        except RatfitError as exc:
            click.echo(f"error: {one_line(str(exc))}", err=True)
            ctx.exit(EXIT_BAD_INPUT)
        except StdoutError as exc:
            from ratfit._atomic import completed

            done = completed()
            said = (f"; written before that and complete: {', '.join(done)}" if done
                    else "; no output file was written")
            click.echo(f"error: could not write to standard output "
                       f"({exc.exc.strerror or exc.exc}){said}", err=True)
            ctx.exit(EXIT_STDOUT_FAILED)
        except OSError as exc:
            name = f"{exc.filename}: " if exc.filename else ""
            click.echo(f"error: {one_line(name + str(exc.strerror or exc))}", err=True)
            ctx.exit(EXIT_BAD_INPUT)
        except MemoryError:
            click.echo("error: out of memory (try fewer points or a smaller max total)", err=True)
            ctx.exit(EXIT_BAD_INPUT)
        except RecursionError:
            click.echo("error: input nested too deeply to read", err=True)
            ctx.exit(EXIT_BAD_INPUT)
        except Exception as exc:  # an internal bug: say so, keep the trace behind a variable
            if os.environ.get("RATFIT_DEBUG"):
                raise
            click.echo(
                f"internal error: {type(exc).__name__}: {one_line(str(exc))} "
                "(set RATFIT_DEBUG=1 for a trace)",
                err=True,
            )
            ctx.exit(3)


def _replay(caught: list[warnings.WarningMessage]) -> None:
    """Warnings held back during a successful command, one line each, without repeats."""
    seen: set[str] = set()
    for w in caught:
        text = one_line(str(w.message))
        if text in seen:
            continue
        seen.add(text)
        click.echo(f"warning: {text}", err=True)


@click.group(cls=_Main, lazy=COMMANDS,
             context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="ratfit")
def main() -> None:
    """Verified rational fits of vertical segments (interval data).

    Exit codes: 0 success, 1 no verified fit found, 2 bad input or usage, 130 on Ctrl-C.
    """


# ---------------------------------------------------------------------------- helpers
def trust_edited_option(f: Callable) -> Callable:
    """``--trust-edited``: load fit files whose content no longer matches their digest."""

    def cb(ctx: click.Context, param: click.Parameter, value: bool) -> None:
        if value:
            from ratfit.io.fitfile import _TRUST_EDITED

            token = _TRUST_EDITED.set(True)
            ctx.call_on_close(lambda: _TRUST_EDITED.reset(token))

    return click.option(
        "--trust-edited", is_flag=True, expose_value=False, callback=cb,
        help="Use a fit file edited after ratfit wrote it (its digest no longer matches) "
             "as an UNVERIFIED function instead of refusing it.")(f)


def _progress(enabled: bool) -> tuple[Callable | None, Callable[[], None]]:
    """A rich status line on stderr while a search runs; without a terminal, a
    plain line every PROGRESS_EVERY seconds (logs of long runs show they move)."""
    if not enabled:
        return None, lambda: None
    if not sys.stderr.isatty():
        t0 = time.monotonic()
        state: dict[str, Any] = {"qps": 0, "last": t0, "att": None}
        lock = threading.Lock()
        done = threading.Event()

        def emit(now: float) -> None:
            att = state["att"]
            last = "" if att is None else f"; last (n={att.n}, m={att.m}): {att.status}"
            click.echo(f"ratfit: {now - t0:.0f} s, tested {state['qps']} splits{last}", err=True)
            state["last"] = now

        def line(att) -> None:
            with lock:
                state["qps"] += 1
                state["att"] = att
                now = time.monotonic()
                if now - state["last"] >= PROGRESS_EVERY:
                    emit(now)

        def tick() -> None:
            # a line at least every PROGRESS_EVERY seconds, also while one split (or
            # the verification of a fit) runs long and no attempt reports
            while not done.wait(PROGRESS_EVERY / 5):
                with lock:
                    now = time.monotonic()
                    if now - state["last"] >= PROGRESS_EVERY:
                        emit(now)

        ticker = threading.Thread(target=tick, daemon=True)
        ticker.start()

        def stop() -> None:
            done.set()
            ticker.join()

        return line, stop
    from rich.console import Console

    status = Console(stderr=True).status("searching ...")
    status.start()
    seen = {"qps": 0}

    def cb(att) -> None:
        seen["qps"] += 1
        status.update(
            f"tested {seen['qps']} splits; last (n={att.n}, m={att.m}): {att.status}"
        )

    return cb, status.stop


def csv_line(fields: Any) -> str:
    """One CSV record, fields quoted by the csv module wherever they hold a comma, a
    quote, CR or LF: a channel name read from a file never adds a column or a row."""
    import csv
    import io

    buf = io.StringIO()
    # "\r\n" as the terminator makes the writer quote a lone CR too; it is cut off here
    csv.writer(buf, lineterminator="\r\n").writerow([str(f) for f in fields])
    return buf.getvalue()[:-2]


def _write_json(obj: Any) -> None:
    text = json.dumps(obj, indent=1, allow_nan=False)
    with stdout_guard():
        click.echo(text)


def console(pipe_width: int = 120) -> Any:
    """A rich console: the terminal's width, or $COLUMNS (else ``pipe_width``) in a pipe."""
    from rich.console import Console

    if sys.stdout.isatty():
        return Console()
    cols = os.environ.get("COLUMNS", "")
    return Console(width=int(cols) if cols.isdigit() and int(cols) > 20 else pipe_width)


def fit_table(con: Any, title: str, columns: list[str], rows: list[list[str]],
              optional: tuple[str, ...] = (), left: tuple[str, ...] = (),
              boxed: bool = False) -> tuple[Any, list[str]]:
    """A table that fits the console: ``optional`` columns are dropped (in that order)
    while it is too wide, and what remains wraps instead of ending in "...": a number
    is never shown cut short. Returns the table and the names of dropped columns."""
    from rich import box
    from rich.markup import escape
    from rich.table import Table

    # cells and title hold text from files (channel, file and model names): shown as
    # written, never read as rich markup ("[/]" would stop the command)
    title = escape(title)
    rows = [[escape(str(c)) for c in r] for r in rows]
    dropped: list[str] = []
    while True:
        keep = [j for j, c in enumerate(columns) if c not in dropped]
        table = (Table(title=title) if boxed else
                 Table(title=title, box=box.SIMPLE_HEAD, collapse_padding=True, pad_edge=False))
        for j in keep:
            table.add_column(columns[j], justify="left" if columns[j] in left else "right",
                             overflow="fold")
        for r in rows:
            table.add_row(*[r[j] for j in keep])
        rest = [c for c in optional if c not in dropped]
        natural = con.measure(table, options=con.options.update_width(100_000)).maximum
        if natural <= con.width or not rest:
            return table, dropped
        dropped.append(rest[0])


SHOWN_DISAGREEMENTS = 3


def _print_report(results, out: Path | None, verified_as: str | None = None,
                  work_limit: int | None = None) -> None:
    """``verified_as``: what the verified column says of a success instead of "yes"
    (a fit verified on a subset of the data says "subset"). ``work_limit``: the
    ``--work-limit`` the fit ran with, for the footer (default: the largest channel
    budget; a BRDF channel searched again has a quarter of it)."""
    with stdout_guard():
        _report_table(results, out, verified_as, work_limit)


def _report_table(results, out: Path | None, verified_as: str | None,
                  work_limit: int | None = None) -> None:
    from rich.markup import escape as esc

    con = console()
    cols = ["channel", "n", "m", "total", "verified", "max viol.", "Linf", "RMSE", "max rel.",
            "delta", "QPs", "s"]
    rows = []
    for r in results:
        s = r.summary()
        rows.append([
            s["channel"], str(s["n"]), str(s["m"]), str(s["total"]),
            ((verified_as or "yes") + ("*" if r.time_limited else "")) if s["verified"]
            else "NO", _fmt(s["max_violation"]),
            _fmt(s["linf"]),
            _fmt(s["l2"]), _fmt(s["max_rel_error"]), _fmt(s["delta"]),
            str(s["qp_solves"]) if s.get("work_limit") is None
            else f"{s['qp_solves']}/{s['work_limit']}",
            f"{s['seconds']:.3f}",
        ])
    table, dropped = fit_table(con, "ratfit fit", cols, rows,
                               optional=("QPs", "delta", "s", "max viol."), left=("channel",))
    con.print(table)
    if dropped:
        con.print(f"(narrow terminal: {', '.join(dropped)} in --json)", highlight=False)
    budgets = {r.work_limit for r in results if r.work_limit is not None}
    if budgets and "QPs" not in dropped:
        limit = max(budgets) if work_limit is None else work_limit
        share = "" if budgets == {limit} else \
            "; a channel searched again with the full validity proof has a quarter"
        con.print(f"QPs: solves / budget per channel (--work-limit {limit}{share})",
                  highlight=False)
    for r in results:
        if not r.success:
            con.print(f"[bold red]{esc(r.channel)}[/]: {esc(r.message)}")
        elif r.time_limited:
            con.print(f"[yellow]{esc(r.channel)}*[/]: {esc(r.message)}", highlight=False)
        # a few, then a count: on a large fit DAQP's false "infeasible" (each one
        # cross-checked) came as 25 lines per channel
        for d in r.disagreements[:SHOWN_DISAGREEMENTS]:
            con.print(f"[yellow]{esc(r.channel)} solver disagreement[/] {esc(str(d))}")
        if len(r.disagreements) > SHOWN_DISAGREEMENTS:
            con.print(f"[yellow]{esc(r.channel)}[/]: "
                      f"{len(r.disagreements) - SHOWN_DISAGREEMENTS} "
                      "more solver disagreement(s), each settled by a cross-check "
                      "(all in --json)", highlight=False)
    if out is not None:
        con.print(f"wrote {esc(str(out))}", highlight=False)


def _fmt(v: float | None) -> str:
    return "-" if v is None else f"{v:.3g}"

