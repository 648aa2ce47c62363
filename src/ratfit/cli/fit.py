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
)
from ratfit.errors import RatfitError


# ---------------------------------------------------------------------------- fit
@main.command("fit")
@click.argument("input_path", metavar="INPUT", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Fit file to write (JSON); written only when every channel is verified.")
@click.option("--format", "fmt", type=click.Choice(["alta", "csv", "npz", "nist"]),
              help="Input format (default: from the file).")
@click.option("--basis", type=click.Choice(["legendre", "chebyshev", "monomial"]),
              default="legendre", show_default=True)
@click.option("--index-set", type=click.Choice(["total", "tensor"]), default="total",
              show_default=True, help="n-D graded order of basis functions.")
@click.option("--dt", type=float, help="Relative segment width: [(1-dt) y, (1+dt) y].")
@click.option("--abs-width", type=float, help="Absolute segment half-width: [y-w, y+w].")
@click.option("--n", "n", type=int, help="Numerator coefficients (fixes the split).")
@click.option("--m", "m", type=int, help="Denominator coefficients (fixes the split).")
@click.option("--total", type=int, help="Try every split of this total.")
@click.option("--min-total", type=int, default=2, show_default=True)
@click.option("--max-total", type=int, default=None, help="Default 100.")
@click.option("--strategy", type=click.Choice(["staircase", "exhaustive"]), default="staircase",
              show_default=True)
@click.option("--split-rule", type=click.Choice(["min-m", "error"]), default="min-m",
              show_default=True, help="Which feasible split of the minimal total to keep.")
@click.option("--solver", default="quadprog", show_default=True,
              help="QP solver: quadprog, daqp, clarabel.")
@click.option("--cross-check", type=click.Choice(["orth", "lp", "none"]), default="orth",
              show_default=True, help="How a solver's 'infeasible' is checked.")
@click.option("--jobs", type=int, default=None, help="Threads for independent QPs.")
@click.option("--formulation", type=click.Choice(["auto", "arnoldi", "basis"]), default="auto",
              show_default=True,
              help="arnoldi: data-orthonormal bases (smallest fits); basis: the seed's matrix.")
@click.option("--domain", "domain", type=(float, float), multiple=True, metavar="LO HI",
              help="Bounds mapped to [-1, 1], one per input dimension, in order "
                   "(default: the data bounds).")
@click.option("--channel", "channels", multiple=True, type=int,
              help="Fit only these channels (0-based; repeatable).")
@click.option("--monomial/--no-monomial", default=True, show_default=True,
              help="Store the monomial form (original variables) in the fit file.")
@click.option("--shared-denominator", "shared", is_flag=True,
              help="One q for every channel, one p per channel; minimises sum(n) + m "
                   "(--m fixes the denominator size).")
@click.option("--time-limit", type=float, default=120.0, show_default=True,
              help="Seconds per channel before the search stops with what it has "
                   "(0: no limit).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def fit_cmd(input_path: Path, output: Path | None, fmt: str | None, basis: str, index_set: str,
            dt: float | None, abs_width: float | None, n: int | None, m: int | None,
            total: int | None, min_total: int, max_total: int | None, strategy: str,
            split_rule: str, solver: str, cross_check: str, jobs: int | None,
            formulation: str, domain: tuple[tuple[float, float], ...],
            channels: tuple[int, ...], monomial: bool, as_json: bool,
            shared: bool = False, time_limit: float = 120.0) -> None:
    """Fit INPUT (ALTA text data, CSV, .npz or NIST StRD) with the fewest coefficients."""
    from ratfit.fitting.search import RationalFitter
    from ratfit.io.data import read_data
    from ratfit.io.fitfile import file_sha256, fit_document, save_fit

    if shared and (n is not None or total is not None):
        raise click.UsageError("--shared-denominator searches the numerator sizes itself: "
                               "drop --n/--total (--m fixes the shared denominator)")
    if not time_limit >= 0:
        raise click.UsageError(f"--time-limit must be >= 0 seconds, got {time_limit}")
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
    cb, stop = _progress(not as_json)
    shared_fit = None
    try:
        if shared:
            from ratfit.fitting.shared_denominator import SharedDenominatorFitter

            shared_fit = SharedDenominatorFitter(
                basis=basis, index_set=index_set, domain=list(domain) or None, m=m,
                max_n=max_total or 60, solver=solver, cross_check=cross_check, jobs=jobs or 1,
                callback=cb,
            ).fit(seg).result_
            results = shared_fit.results
        else:
            results = RationalFitter(
                basis=basis, index_set=index_set, n=n, m=m, total=total, min_total=min_total,
                max_total=max_total, strategy=strategy, split_rule=split_rule, solver=solver,
                cross_check=cross_check, jobs=jobs, callback=cb, domain=list(domain) or None,
                formulation=formulation, time_limit=time_limit if time_limit > 0 else None,
            ).fit(seg).results_
    finally:
        stop()
    ok = all(r.success for r in results)
    if output is not None and ok:
        mono = _monomials(results, seg) if monomial else None
        segdesc: dict[str, Any] = {"dt": dt, "abs_width": abs_width,
                                   "explicit": dt is None and abs_width is None}
        doc = fit_document(results, monomial=mono, provenance={
            "input": str(input_path), "input_sha256": file_sha256(input_path),
            "n_points": seg.n_points, "segments": segdesc, "solver": solver,
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
@click.argument("fit_path", metavar="FIT.json", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("input_path", metavar="INPUT", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Write values to .csv or .npy (default: CSV on stdout).")
@click.option("--format", "fmt", type=click.Choice(["alta", "csv", "npz", "nist"]))
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
