"""`ratfit cdf`, `ratfit sample` and `ratfit demo cdf`: monotone CDF fits and sampling.

INPUT formats of `ratfit cdf` (one input variable):

* ``--from pdf`` (default for text files): a CSV or ALTA table of x and density
  values (any normalisation; read with :func:`ratfit.io.data.read_data`).
* ``--from cdf``: a table of x and CDF values; with ``lo``/``hi`` columns and no
  ``--dt``/``--abs-width`` the intervals are taken as given.
* ``--from samples`` (default for ``.npy``): draws, as a ``.npy`` array or a text
  file with one number per line; the intervals are a DKW band at ``--confidence``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import click
import numpy as np

from ratfit.cdf.monotone import CDF_SOLVER
from ratfit.cli.main import (
    EXIT_NO_FIT,
    _progress,
    _write_json,
    stdout_guard,
    trust_edited_option,
)
from ratfit.cli.options import (
    MAX_DRAWS,
    MAX_POINTS,
    FiniteFloatRange,
    aliased_option,
    fit_options,
    pop_fit_params,
)
from ratfit.errors import FileFormatError, InputError, RatfitError
from ratfit.jobs.common import results_summary

SOURCES = ("pdf", "cdf", "samples")


def _read_samples(path: Path) -> np.ndarray:
    """Samples from .npy (numeric, 1-D or one column) or text (one number per line)."""
    if not path.is_file():
        raise FileFormatError(f"{path}: no such file")
    if path.suffix.lower() == ".npy":
        try:
            arr = np.load(path, allow_pickle=False)
        except (ValueError, OSError, EOFError) as exc:
            raise FileFormatError(f"{path}: not a readable .npy array ({exc})") from None
        if arr.dtype.kind not in "iuf":
            raise FileFormatError(f"{path}: samples must be numbers, got dtype {arr.dtype}")
        if arr.ndim == 2 and arr.shape[1] == 1:
            arr = arr[:, 0]
        if arr.ndim != 1:
            raise InputError(f"{path}: samples must be a 1-D array, got shape {arr.shape}")
        return arr.astype(float)
    vals: list[float] = []
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise FileFormatError(f"{path}: not a text file of samples") from None
    for n, line in enumerate(text.splitlines(), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        try:
            vals.append(float(s))
        except ValueError:
            raise FileFormatError(f"{path} line {n}: not a number: {s[:40]!r}") from None
    if not vals:
        raise FileFormatError(f"{path}: no samples")
    return np.asarray(vals)


def _segments(path: Path, source: str, fmt: str | None, dt: float | None,
              abs_width: float | None, confidence: float, points: int, channel: int,
              domain: tuple[float, float] | None):
    from ratfit.cdf.monotone import cdf_from_bounds, cdf_from_pdf, cdf_from_samples, cdf_from_table
    from ratfit.io.data import read_data

    if source == "samples":
        if dt is not None or abs_width is not None:
            raise click.UsageError("--dt/--abs-width do not apply to samples (use --confidence)")
        return cdf_from_samples(_read_samples(path), confidence=confidence, points=points,
                                domain=domain)
    data = read_data(path, fmt=fmt)
    if data.dim != 1:
        raise InputError(f"{path}: a CDF table has one input column, the file has {data.dim}")
    if not 0 <= channel < data.n_channels:
        raise InputError(f"{path}: channel {channel} out of range ({data.n_channels} channel(s))")
    if source == "cdf" and dt is None and abs_width is None and data.lo is not None:
        assert data.hi is not None
        return cdf_from_bounds(data.x[:, 0], data.lo[:, channel], data.hi[:, channel])
    if data.y is None:
        raise InputError(f"{path}: the file has only lo/hi bounds; use --from cdf")
    y = data.y[:, channel]
    if source == "pdf":
        return cdf_from_pdf(data.x[:, 0], y, dt=dt, abs_width=abs_width)
    return cdf_from_table(data.x[:, 0], y, dt=dt, abs_width=abs_width)


def _with_source(exc: RatfitError, path: Path) -> RatfitError:
    msg = str(exc)
    return type(exc)(msg if str(path) in msg else f"{path}: {msg}")


def cdf_json(fitter, output: Path | None) -> dict[str, Any]:
    """`ratfit fit --json` keys plus ``monotone`` (the CDF checks and constraint setup)."""
    res = fitter.result_
    doc = results_summary(fitter.results_, output)
    ver = res.verification
    mono: dict[str, Any] = ver.monotone_summary() if hasattr(ver, "monotone_summary") else {
        "verified": False}
    mono.update(form=fitter.form, grid=int(fitter.grid), data_points=fitter.segments_.n_points)
    doc["monotone"] = mono
    return doc


# ---------------------------------------------------------------------------- cdf
def _one_domain(pairs: list[list[float]] | None) -> tuple[float, float] | None:
    """The --domain of a CDF: one LO < HI pair, or None (the data's range)."""
    if pairs is None:
        return None
    if len(pairs) != 1:
        raise InputError(f"a CDF has one variable: give one --domain LO HI, got {len(pairs)}")
    lo, hi = (float(v) for v in pairs[0])
    if not hi > lo:
        raise InputError(f"zero-length or reversed domain {[lo, hi]}")
    return lo, hi


@click.command("cdf")
@click.argument("input_path", metavar="INPUT", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="CDF fit file to write (JSON; read by `ratfit sample`). Written only "
                   "when the fit is verified.")
@click.option("--from", "source", type=click.Choice(SOURCES), default=None,
              help="What INPUT holds (default: samples for .npy, else pdf).")
@click.option("--format", "fmt", type=click.Choice(["alta", "csv"]),
              help="Table format (default: from the file).")
@click.option("--dt", type=float,
              help="Relative width on the tail probability: F +- dt*min(F, 1-F).")
@click.option("--abs-width", type=float,
              help="Absolute half-width (default 1e-3 when --dt is not given either).")
@click.option("--confidence", type=FiniteFloatRange(0, 1, min_open=True, max_open=True),
              default=0.99, show_default=True, help="DKW band confidence for samples.")
@click.option("--points", type=click.IntRange(2, MAX_POINTS), default=256, show_default=True,
              help="ECDF evaluation points (quantiles) for samples.")
@click.option("--grid", type=click.IntRange(0, MAX_POINTS), default=0, show_default=True,
              help="K extra monotone constraint points, uniform on the domain.")
@click.option("--form", type=click.Choice(["two-row", "max"]), default="two-row",
              show_default=True, help="Derivative constraints: seed eq. 3 or eq. 5.")
@fit_options(exclude=("index_set", "formulation"), defaults={"solver": CDF_SOLVER},
             helps={"domain": "Domain of the CDF, LO HI (default: the data range)."})
@click.option("--channel", type=int, default=0, show_default=True,
              help="Column of a table with several output channels.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def cdf_cmd(input_path: Path, output: Path | None, source: str | None, fmt: str | None,
            dt: float | None, abs_width: float | None, confidence: float, points: int,
            grid: int, form: str, channel: int, as_json: bool, **options: Any) -> None:
    """Fit a monotone rational CDF to INPUT (a pdf table, a cdf table or samples)."""
    from ratfit.cdf.monotone import MonotoneFitter
    from ratfit.io.fitfile import file_sha256, fit_document, save_fit

    params = pop_fit_params(options)
    if (params["n"] is None) != (params["m"] is None):
        raise click.UsageError("give both --n and --m, or neither")
    if source is None:
        source = "samples" if input_path.suffix.lower() == ".npy" else "pdf"
    domain = _one_domain(params["domain"])
    try:
        seg = _segments(input_path, source, fmt, dt, abs_width, confidence, points, channel,
                        domain)
    except RatfitError as exc:
        raise _with_source(exc, input_path) from None
    cb, stop = _progress(True)  # stderr: JSON on stdout stays clean
    try:
        fitter = MonotoneFitter(form=form, grid=grid, callback=cb, **params).fit(seg)
    finally:
        stop()
    res = fitter.result_
    ok = res.success
    if output is not None and ok:
        from ratfit.cdf.sampling import RationalCDF

        assert res.rational is not None  # a verified fit has its rational
        model = RationalCDF(res.rational)
        doc = fit_document(fitter.results_, provenance={
            "input": str(input_path), "input_sha256": file_sha256(input_path),
            "n_points": seg.n_points, "solver": params["solver"],
            "cdf": {"from": source, "dt": dt, "abs_width": abs_width,
                    "confidence": confidence if source == "samples" else None,
                    "form": form, "grid": grid, "domain": [model.a, model.b],
                    "r_domain": [model.r_a, model.r_b]},
        })
        save_fit(output, doc)
    if as_json:
        _write_json(cdf_json(fitter, output if ok else None))
    else:
        from ratfit.cli.main import _print_report

        _print_report(fitter.results_, output if ok and output else None)
        ver = res.verification
        if ver is not None and not getattr(ver, "monotone", True):
            step = getattr(ver, "min_step", float("nan"))
            click.echo(f"not monotone between constraint points (min step {step:.3g}): "
                       "add constraint points with --grid K", err=True)
        if output is not None and not ok:
            click.echo(f"no fit file written: the CDF fit is not verified ({output})", err=True)
    if not ok:
        sys.exit(EXIT_NO_FIT)


# ---------------------------------------------------------------------------- sample
@click.command("sample")
@trust_edited_option
@click.argument("fit_path", metavar="CDF.json", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-n", "count", type=click.IntRange(1, MAX_DRAWS), required=True,
              help="Number of draws.")
@click.option("--seed", type=click.IntRange(min=0), default=None,
              help="Seed of numpy's default Generator (default: fresh entropy).")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the draws as a .npy array (default: one per line on stdout).")
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary on stdout.")
def sample_cmd(fit_path: Path, count: int, seed: int | None, output: Path | None,
               as_json: bool) -> None:
    """Draw N samples from a CDF fit file written by `ratfit cdf` (inverse CDF)."""
    from ratfit._atomic import atomic_open
    from ratfit.cdf.sampling import RationalCDF

    if output is not None and output.suffix.lower() != ".npy":
        raise click.UsageError(f"-o must name a .npy file, got {output}")
    model = RationalCDF.from_file(str(fit_path))
    t0 = time.perf_counter()
    draws = model.sample(count, np.random.default_rng(seed))
    secs = time.perf_counter() - t0
    if output is not None:
        with atomic_open(output, "wb") as fh:
            np.save(fh, draws)
    if as_json:
        _write_json({"n": count, "seed": seed, "output": str(output) if output else None,
                     "domain": [model.a, model.b], "mean": float(draws.mean()),
                     "min": float(draws.min()), "max": float(draws.max()),
                     "seconds": round(secs, 6)})
    elif output is None:
        with stdout_guard():
            click.echo("\n".join(repr(float(v)) for v in draws))


# ---------------------------------------------------------------------------- demo cdf
@click.command("cdf")
@aliased_option("-o", "--output", "outdir", hidden=["--outdir"],
                type=click.Path(file_okay=False, path_type=Path),
                default=Path("ratfit-cdf"), show_default=True,
                help="Folder for the figure and the CDF fit file.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def demo_cdf(outdir: Path, as_json: bool) -> None:
    """Fit the CDF of a Beckmann lobe (cos theta_h), sample it, plot pdf, histogram, CDF."""
    from ratfit.demos.cdf import run_demo_cdf

    run = run_demo_cdf(outdir)
    fitter, res = run["fitter"], run["result"]
    doc = cdf_json(fitter, run.get("fit_file"))
    for key in ("ks_statistic", "ks_pvalue", "samples", "seed", "alpha"):
        doc[key] = run.get(key)
    doc["figure"] = str(run["figure"]) if "figure" in run else None
    if as_json:
        _write_json(doc)
    else:
        click.echo(
            f"Beckmann alpha={run.get('alpha', 0.3)}: n={res.n}, m={res.m}, verified "
            f"{'yes' if res.success else 'NO'}, monotone on {doc['monotone'].get('check_points')}"
            f" points"
        )
        if res.success:
            click.echo(f"{run['samples']} samples (seed {run['seed']}): KS statistic "
                       f"{run['ks_statistic']:.4g}, p-value {run['ks_pvalue']:.3g}")
            click.echo(f"wrote {run['figure']}")
            click.echo(f"wrote {run['fit_file']}")
    if not res.success:
        sys.exit(EXIT_NO_FIT)
