"""`ratfit batch`: fit a manifest of inputs x channels x settings on Dask."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from ratfit.cli.main import EXIT_NO_FIT, _write_json, console, fit_table
from ratfit.cli.options import MAX_WORKERS, aliased_option

EXIT_INTERRUPTED = 130


@click.command("batch")
@click.argument("manifest", type=click.Path(dir_okay=False, path_type=Path))
@aliased_option("-o", "--output", "outdir", hidden=["--outdir"], required=True,
                type=click.Path(file_okay=False, path_type=Path),
              help="Folder for the fit files and summary.csv / summary.parquet.")
@click.option("--scheduler", metavar="ADDRESS",
              help="Address of a running Dask scheduler (default: start a local cluster).")
@click.option("--workers", type=click.IntRange(1, MAX_WORKERS),
              help="Worker processes of the local cluster (default: one per core).")
@click.option("--rerun-failed", is_flag=True,
              help="Run again the tasks that failed or found no verified fit.")
@click.option("--allowed-failures", type=click.IntRange(0, 10**6), default=3, show_default=True,
              help="Worker deaths a task may witness before it counts as failed "
                   "(local cluster only).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def batch_cmd(manifest: Path, outdir: Path, scheduler: str | None, workers: int | None,
              rerun_failed: bool, allowed_failures: int, as_json: bool) -> None:
    """Fit every input x channel x settings of MANIFEST (TOML or JSON); resumable.

    Each verified fit goes to its own JSON fit file in OUTDIR; finished results
    are skipped when the command is run again. Exit code 1 when some task found
    no verified fit or failed (see the summary), 130 on Ctrl-C.
    """
    from ratfit.batch.runner import BatchInterrupted, run

    if scheduler is not None and workers is not None:
        raise click.UsageError("--workers applies to the local cluster; not with --scheduler")
    try:
        summary = run(
            manifest, outdir=outdir, scheduler=scheduler, workers=workers,
            rerun_failed=rerun_failed, allowed_failures=allowed_failures,
            # on stderr (stdout keeps the result): a bar with the time left on a
            # terminal, a line every few seconds in a log
            progress=True,
        )
    except BatchInterrupted as exc:
        s = exc.summary
        done = sum(r["status"] != "pending" for r in s.rows)
        click.echo(
            f"interrupted: {done} of {len(s.rows)} results written to {s.outdir}; "
            "run the same command again to resume", err=True,
        )
        sys.exit(EXIT_INTERRUPTED)
    counts = summary.counts
    if as_json:
        _write_json({
            "outdir": str(summary.outdir), "summary_csv": str(summary.csv),
            "summary_parquet": str(summary.parquet), "tasks": len(summary.rows),
            "fitted": summary.fitted, "skipped": summary.skipped,
            "ok": counts["ok"], "no_fit": counts["no-fit"], "failed": counts["failed"],
            "rows": summary.rows,
        })
    else:
        _print_batch(summary)
    if not summary.ok:
        sys.exit(EXIT_NO_FIT)


def _print_batch(summary) -> None:
    from rich.markup import escape

    con = console()
    counts = summary.counts
    table, _ = fit_table(con, f"ratfit batch: {len(summary.rows)} task(s)",
                         ["ok", "no fit", "failed", "run now", "resumed"],
                         [[str(counts["ok"]), str(counts["no-fit"]), str(counts["failed"]),
                           str(summary.fitted), str(summary.skipped)]], boxed=True)
    con.print(table)
    for r in summary.rows:
        if r["status"] == "failed":
            what = f"{r['input']} {r['channel']} {r['settings_id']}: {r['message']}"
            con.print(f"[bold red]failed[/] {escape(what)}", highlight=False)
    con.print(f"wrote {escape(str(summary.csv))} and {escape(str(summary.parquet))}",
              highlight=False)
