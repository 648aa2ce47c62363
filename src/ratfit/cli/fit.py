"""`ratfit fit` and `ratfit eval`: fit interval data, evaluate a fit file."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click
import numpy as np

from ratfit.cli.main import (
    EXIT_NO_FIT,
    _fit_json,
    _monomials,
    _print_report,
    _progress,
    _write_json,
    main,
    trust_edited_option,
)
from ratfit.cli.options import fit_options, pop_fit_params, segment_options
from ratfit.errors import RatfitError
from ratfit.io.data import FORMATS


# ---------------------------------------------------------------------------- fit
@main.command("fit")
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
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def fit_cmd(input_path: Path, output: Path | None, fmt: str | None, dt: float | None,
            abs_width: float | None, channels: tuple[int, ...], monomial: bool, as_json: bool,
            shared: bool = False, **options: Any) -> None:
    """Fit INPUT (ALTA text data, CSV, .npz or NIST StRD) with the fewest coefficients.

    Each channel gets its own n, m. Segments: --dt and/or --abs-width around the
    file's y values, else the file's own intervals.

    Exit codes: 0 every channel has a verified fit; 1 the search found no
    verified fit (no fit file is written); 2 bad input or usage (one error line).
    """
    from ratfit.fitting.search import RationalFitter
    from ratfit.io.data import read_data
    from ratfit.io.fitfile import file_sha256, fit_document, save_fit

    time_limit = options["time_limit"]
    if not time_limit >= 0:
        raise click.UsageError(f"--time-limit must be >= 0 seconds, got {time_limit}")
    params = pop_fit_params(options)
    n, m, total = params["n"], params["m"], params["total"]
    if shared and (n is not None or total is not None):
        raise click.UsageError("--shared-denominator searches the numerator sizes itself: "
                               "drop --n/--total (--m fixes the shared denominator)")
    if (n is None) != (m is None) and not shared:
        raise click.UsageError("give both --n and --m, or neither")
    if n is not None and total is not None:
        raise click.UsageError("--n/--m and --total are exclusive")
    data = read_data(input_path, fmt=fmt)
    try:
        seg = data.segments(dt=dt, abs_width=abs_width)
    except RatfitError as exc:
        msg = str(exc)
        raise type(exc)(msg if str(input_path) in msg else f"{input_path}: {msg}") from None
    if channels:
        from ratfit.core.segments import Segments

        for c in channels:
            seg.channel(c)  # validates the index
        pick = list(channels)
        seg = Segments(seg.x, seg.lo[:, pick], seg.hi[:, pick],
                       None if seg.y is None else seg.y[:, pick],
                       tuple(seg.names[c] for c in pick))
    cb, stop = _progress(True)  # stderr: JSON on stdout stays clean
    shared_fit = None
    try:
        if shared:
            from ratfit.fitting.shared_denominator import SharedDenominatorFitter

            shared_fit = SharedDenominatorFitter(
                basis=params["basis"], index_set=params["index_set"], domain=params["domain"],
                m=m, max_n=params["max_total"] or 60, solver=params["solver"],
                cross_check=params["cross_check"], jobs=params["jobs"] or 1, callback=cb,
            ).fit(seg).result_
            results = shared_fit.results
        else:
            results = RationalFitter(**params, callback=cb).fit(seg).results_
    finally:
        stop()
    ok = all(r.success for r in results)
    if output is not None and ok:
        mono = _monomials(results, seg) if monomial else None
        segdesc: dict[str, Any] = {"dt": dt, "abs_width": abs_width,
                                   "explicit": dt is None and abs_width is None}
        doc = fit_document(results, monomial=mono, provenance={
            "input": str(input_path), "input_sha256": file_sha256(input_path),
            "n_points": seg.n_points, "segments": segdesc, "solver": params["solver"],
        })
        save_fit(output, doc)
    if as_json:
        # "infeasible_proof" (null when feasible) comes with each channel's summary:
        # top level for one channel, under "channels" for several.
        doc = _fit_json(results, output if ok else None)
        if shared_fit is not None:
            doc.update(shared_denominator=True, m_shared=shared_fit.m, total=shared_fit.total,
                       proven_minimal=shared_fit.proven)
        _write_json(doc)
    else:
        _print_report(results, output if ok and output else None)
        if shared_fit is not None:
            click.echo(f"shared denominator: n = {list(shared_fit.n)}, m = {shared_fit.m}, "
                       f"total {shared_fit.total} coefficients")
        if output is not None and not ok:
            click.echo(f"no fit file written: not every channel is verified ({output})", err=True)
    if not ok:
        sys.exit(EXIT_NO_FIT)


@main.command("eval")
@trust_edited_option
@click.argument("fit_path", metavar="FIT.json", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("input_path", metavar="INPUT", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Write values to .csv or .npy (default: CSV on stdout).")
@click.option("--format", "fmt", type=click.Choice(FORMATS))
def eval_cmd(fit_path: Path, input_path: Path, output: Path | None, fmt: str | None) -> None:
    """Values of a saved fit at the points of INPUT."""
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
    header = ",".join([f"x{k}" for k in range(data.dim)] + names)
    body = np.hstack([data.x, vals])
    if output is None:
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
