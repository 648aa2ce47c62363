"""`ratfit fit` and `ratfit eval`: fit interval data, evaluate a fit file."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click
import numpy as np

from ratfit.cli.main import (
    EXIT_NO_FIT,
    _print_report,
    _progress,
    _write_json,
    csv_line,
    stdout_guard,
    trust_edited_option,
)
from ratfit.cli.options import check_size_flags, fit_options, pop_fit_params, segment_options
from ratfit.io.data import FORMATS


# ---------------------------------------------------------------------------- fit
@click.command("fit")
@click.argument("input_path", metavar="INPUT", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Fit file to write (JSON); written only when every channel is verified.")
@click.option("--format", "fmt", type=click.Choice(FORMATS),
              help="Input format (default: from the file).")
@segment_options()
@fit_options(helps={"max_total": "Largest total n + m searched (default 100; with "
                                 "--shared-denominator: the largest numerator, default 60)."})
@click.option("--channel", "channels", multiple=True, type=int,
              help="Fit only these channels (0-based; repeatable).")
@click.option("--monomial/--no-monomial", default=True, show_default=True,
              help="Store the monomial form (original variables) in the fit file.")
@click.option("--shared-denominator", "shared", is_flag=True,
              help="One q for every channel, one p per channel; minimises sum(n) + m "
                   "(--m fixes the denominator size).")
@click.option("--between", "between", type=click.FloatRange(0, 1e6), metavar="MARGIN",
              help="1-D: also bound the fit between neighbouring samples. Allowed: the two "
                   "neighbours' segments (min lo .. max hi) widened by MARGIN times the data's "
                   "range (max hi - min lo). Rows at points between samples (the midpoints, "
                   "then each gap's worst point, up to 8 refits) ask for half that widening; "
                   "the fit is then checked between every pair of samples (critical points "
                   "of p/q and a grid) and is not verified unless it stays within the "
                   "allowance. Without it the largest excursion is only reported.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def fit_cmd(input_path: Path, output: Path | None, fmt: str | None, dt: float | None,
            abs_width: float | None, channels: tuple[int, ...], monomial: bool, as_json: bool,
            shared: bool = False, between: float | None = None, **options: Any) -> None:
    """Fit INPUT (ALTA text data, CSV, .npz or NIST StRD) with the fewest coefficients.

    Each channel gets its own n, m. Segments: --dt and/or --abs-width around the
    file's y values, else the file's own intervals.

    Exit codes: 0 every channel has a verified fit; 1 the search found no
    verified fit (no fit file is written); 2 bad input or usage (one error line).
    """
    from ratfit.jobs import FitRequest, fit_file

    if options["time_limit"] is not None and not options["time_limit"] >= 0:
        raise click.UsageError(f"--time-limit must be >= 0 seconds, got {options['time_limit']}")
    params = pop_fit_params(options)
    check_size_flags(params, shared=shared)
    request = FitRequest.from_settings(input_path, {
        **params, "format": fmt, "dt": dt, "abs_width": abs_width,
        "channels": channels, "monomial": monomial, "output": output,
        "shared_denominator": shared, "between": between})
    cb, stop = _progress(True)  # stderr: JSON on stdout stays clean
    try:
        report = fit_file(request.with_progress(cb))
    finally:
        stop()
    for note in report.messages:
        click.echo(f"warning: {note}", err=True)
    if as_json:
        # "infeasible_proof" (null when feasible) comes with each channel's summary:
        # top level for one channel, under "channels" for several.
        _write_json(report.summary())
    else:
        _print_report(report.results, report.written)
        _print_excursions(report)
        if report.shared is not None:
            sh = report.shared
            click.echo(f"shared denominator: n = {list(sh.n)}, m = {sh.m}, "
                       f"total {sh.total} coefficients")
        if output is not None and not report.success:
            click.echo(f"no fit file written: not every channel is verified ({output})", err=True)
    if not report.success:
        sys.exit(EXIT_NO_FIT)


def _print_excursions(report: Any) -> None:
    """r between neighbouring samples, one wrapped paragraph per channel (1-D fits)."""
    from rich.markup import escape

    from ratfit.cli.main import console

    done = [e for e in report.excursions if e is not None]
    if not done:
        return
    con = console()
    with stdout_guard():
        for exc in done:
            con.print(escape(exc.describe()), highlight=False)
        con.print(escape(f"(between samples: {done[0].method})"), highlight=False)


@click.command("eval")
@trust_edited_option
@click.argument("fit_path", metavar="FIT.json", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("input_path", metavar="INPUT", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Write values to .csv or .npy (default: CSV on stdout).")
@click.option("--format", "fmt", type=click.Choice(FORMATS))
def eval_cmd(fit_path: Path, input_path: Path, output: Path | None, fmt: str | None) -> None:
    """Values of a saved fit at the points of INPUT.

    FIT.json is a ratfit fit file or an ALTA rational function file (read as an
    unverified fit), as for export, plot and report.
    """
    from ratfit._atomic import atomic_open
    from ratfit.errors import InputError
    from ratfit.io.data import read_data
    from ratfit.io.fitfile import load_fit

    saved = load_fit(fit_path)
    data = read_data(input_path, fmt=fmt)
    if data.dim != saved.space.dim:
        raise InputError(
            f"{input_path} has {data.dim} input dimension(s) but the fit has {saved.space.dim}"
        )
    _recheck(saved, data, input_path)
    vals = saved(data.x)
    names = [c.name for c in saved.channels]
    if output is not None and output.suffix.lower() == ".npy":
        with atomic_open(output, "wb") as fh:
            np.save(fh, vals)
        return
    header = csv_line([f"x{k}" for k in range(data.dim)] + names)
    body = np.hstack([data.x, vals])
    if output is None:
        with stdout_guard():
            click.echo(header)
            for row in body:
                click.echo(",".join(repr(float(v)) for v in row))
    else:
        with atomic_open(output, "w") as fh:
            fh.write(header + "\n")
            for row in body:
                fh.write(",".join(repr(float(v)) for v in row) + "\n")


# ---------------------------------------------------------------------------- demo


def _recheck(saved: Any, data: Any, input_path: Path) -> None:
    """Evaluating at the fit's own data (same file content): verify again before writing
    anything; a sealed file that misses its own segments is refused. On other data with
    known segments, a missed segment is worth a warning line, not an error."""
    from ratfit.errors import InputError
    from ratfit.io.fitfile import file_sha256, recorded_segments, segment_check

    seg = recorded_segments(saved, data)
    if seg is None:
        return
    bad = [(n, met, tot, w) for n, met, tot, w in segment_check(saved, seg) if met < tot]
    if not bad:
        return
    what = "; ".join(f"channel {n}: {tot - met} of {tot} segments missed, worst by {w:.3g}"
                     for n, met, tot, w in bad)
    own = saved.provenance.get("input_sha256") == file_sha256(input_path)
    if own and saved.integrity == "sealed":
        raise InputError(f"{input_path}: the fit does not meet the segments of the data it "
                         f"was verified on ({what}): the fit file is corrupt")
    import warnings

    warnings.warn(f"{input_path}: the fit misses segments of this data ({what})",
                  stacklevel=2)
