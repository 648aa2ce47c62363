"""`ratfit brdf ...`: fit measured BRDFs and evaluate BRDF fits on directions."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click
import numpy as np

from ratfit.brdf.options import BRDF_SOLVER, POLISH_ERRORS, VALUES, BRDFOptions
from ratfit.cli.main import (
    EXIT_NO_FIT,
    LazyGroup,
    _print_report,
    _progress,
    _write_json,
    csv_line,
    stdout_guard,
    trust_edited_option,
)
from ratfit.cli.options import aliased_option, check_size_flags, fit_options, pop_fit_params


@click.group("brdf", cls=LazyGroup, lazy={"compare": "ratfit.cli.export:compare_cmd"})
def brdf_group() -> None:
    """Measured BRDFs: MERL, ALTA, Cornell/pbrt, ASTM and EXR files."""


class FloorType(click.ParamType):
    """A number, or "auto": each channel's noise level estimated from the data."""

    name = "FLOAT|auto"

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> float | str:
        from ratfit.brdf.fitter import AUTO_FLOOR, is_auto_floor

        if is_auto_floor(value):
            return AUTO_FLOOR
        try:
            return float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is neither a number nor 'auto'", param, ctx)


def _split_channels(values: tuple[str, ...]) -> list[str]:
    return [c.strip() for v in values for c in v.split(",") if c.strip()]


@brdf_group.command("fit")
@click.argument("input_path", metavar="INPUT", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Fit file (JSON); written only when every channel is verified (the "
                   "verified ones are then kept in a new NAME.partial.json beside it).")
@click.option("--format", "fmt", type=click.Choice(["merl", "alta", "cornell", "astm", "exr"]),
              help="Input format (default: from the file).")
@click.option("--param", "param", default=None,
              help="Parametrization to fit in (ALTA names, e.g. RUSIN_TH_TD_PD, COS_TH_TD_PD, "
                   "STARK_2D); default: the file's own (ISOTROPIC_TV_TL_DPHI for Cartesian "
                   "pairs), and for isotropic light and view angles the half-vector frame "
                   "RUSIN_TH_TD_SYM first (RUSIN_TH_TD_PD with --cosine), keeping the "
                   "better verified fit (narrower segments, then fewer coefficients); a "
                   "MERL table: RUSIN_TH_TD_FOLD (its table defaults: a subset of 5000 "
                   "cells by direction pairs, --values log, --dt 0.22 --abs-width 0.001, "
                   "--n 113 --m 112; each option given replaces its part).")
@click.option("--dt", type=float,
              help="Relative segment width: [(1-dt) y, (1+dt) y]. Without --dt, --abs-width "
                   "and --floor-rel: the file's own intervals, else 0.05 (widened where "
                   "nearby samples need it) with a floor: for a table of every cell "
                   "(MERL) 1e-3 1/sr, the noise level, samples within 2 % of each axis "
                   "of each other whose segments are disjoint getting the hull of the "
                   "two (samples at one point: of the group); for scattered "
                   "measurements in the half-vector frame (log values by default) each "
                   "channel's noise level, as --abs-width auto; with --values linear "
                   "0.1 % of each channel's peak there, and 0.2 % in other frames. A "
                   "floor of a fraction of the peak is halved up to twice while the "
                   "fit stays at most 12 coefficients per channel and most samples lie "
                   "under it. "
                   "When nothing verifies and every split tested was infeasible, that "
                   "default is widened 1.5x (up to 0.9) until a try has a candidate "
                   "(not with --max-total).")
@click.option("--abs-width", type=FloorType(),
              help="Absolute half-width (floor: the noise level, in the data's units); "
                   "with --dt each segment takes the larger. 'auto': each channel's noise "
                   "level estimated from the data (half the 90th percentile of the "
                   "differences between samples within 1 % of each axis of each other, "
                   "at least 1e-3), relative polish, nearby disjoint segments joined, and "
                   "without --dt each channel at the width its own nearby samples need, "
                   "widened alone while it has no candidate.")
@click.option("--floor-rel", type=float,
              help="Absolute half-width per channel as a fraction of the channel's maximum.")
@click.option("--cosine", is_flag=True, help="Fit BRDF x cos(theta_l); evaluation undoes it.")
@click.option("--clamp", type=float, help="Raise values below this to it before fitting.")
@click.option("--positive-q", is_flag=True,
              help="Constrain the denominator to be positive on a grid of the valid "
                   "configurations inside the QP (sparse or gappy measurements).")
@aliased_option("--channel", "channels", hidden=["--channels"], multiple=True,
                help="Channels to fit, by name or 0-based index (repeat or comma-separate).")
@click.option("--color", type=click.Choice(["rgb", "xyz", "spectral"]), default="rgb",
              show_default=True, help="Spectral (Cornell) data: CIE 1931 -> linear sRGB, XYZ, "
                                      "or the bands as they are.")
@click.option("--max-points", type=int,
              help="Fit a random subset of this many samples (a MERL table: 5000 drawn by "
                   "direction pairs by default; more than its cells fits every cell).")
@click.option("--subset-by", type=click.Choice(["samples", "pairs", "energy"]),
              default="samples", show_default=True,
              help="How --max-points draws: every sample alike; (a MERL table) each cell "
                   "as often as uniformly random direction pairs fall in it; or half so and "
                   "half weighted by the table's luminance, so the highlight renders look "
                   "at is drawn too.")
@click.option("--holdout", type=int, metavar="K",
              help="Also fit K times, each without one of K folds of the samples (seeded: "
                   "the same folds every run), and report the errors at the samples each "
                   "fit never saw (RMSE, cos-weighted RMSE, RMS of log((f+1e-3)/(y+1e-3))); "
                   "recorded in the fit file.")
@fit_options(exclude=("domain",), defaults={"solver": BRDF_SOLVER},
             helps={"time_limit": "Wall-clock seconds per channel before the search, the "
                                  "polish and the validity proof stop with what they have "
                                  "(default: none). With a clock the answer can depend on "
                                  "the machine's load.",
                    "work_limit": "QP solves per channel before the search stops with what "
                                  "it has (its repairs included); the polish and the final "
                                  "proof's repair get a quarter of it more, a search again "
                                  "with the full validity proof a quarter: the same answer "
                                  "on any load and any --jobs."})
@click.option("--no-polish", "no_polish", is_flag=True,
              help="Keep the search's minimum-norm fit (default: replace it by the "
                   "least-squares fit of the same size inside the segments when that "
                   "verifies).")
@click.option("--polish-error", "polish_error", type=click.Choice(POLISH_ERRORS),
              default=BRDFOptions.polish_error, show_default=True,
              help="What the polish minimises: plain squared errors, or errors relative "
                   "to |y| + 1e-3 1/sr (a diffuse part far below the peak counts as much "
                   "as the peak).")
@click.option("--values", "values", type=click.Choice(VALUES), default=BRDFOptions.values,
              show_default=True,
              help="What p / q fits: the values, or their logarithms (the fit is "
                   "exp(p / q): never negative, proved free of poles like any fit, and a "
                   "relative width costs the same at the diffuse values as at the peak; "
                   "with no width option its floor is each channel's noise level, as "
                   "--abs-width auto, and with no size option a channel that needs more "
                   "than 72 coefficients at its width is widened alone); auto: log in the "
                   "half-vector frame for a full MERL table and for scattered "
                   "measurements with no width option (or --abs-width auto alone), else "
                   "linear.")
@click.option("--envelope/--no-envelope", "envelope", default=None,
              help="Fits of log values (p / q fits have no ceiling): keep p / q under "
                   "twice the largest upper end among the samples as far from the mirror "
                   "direction (theta_h, less 0.05 rad at the search's points) or farther, "
                   "at their incidence or nearer grazing (theta_d), and nearer the normal "
                   "only as much less as the highlight's samples grow toward grazing; "
                   "and over half the lower end of each highlight sample nearer the "
                   "mirror direction and nearer grazing than it; "
                   "prove both (the ceiling less 0.1 rad) on the whole evaluated region, "
                   "not only twice the channel's largest. Default: on for scattered "
                   "measurements, "
                   "whose unsampled pairs a fit may otherwise fill with highlights; off "
                   "for a full MERL table.")
@click.option("--held-out-size/--smallest-size", "held_out_size", default=None,
              help="Fits of log values: also polish the smallest verified fit at 1.25, "
                   "1.5 and 2 times its n and m, and keep the size with the lowest 5-fold "
                   "held-out relative error when it is proved valid and, off the "
                   "highlight, rises no further above the samples near it than the "
                   "smallest (brdf.held_out_size in the fit file). Default: on for "
                   "scattered measurements with no width or size option; --smallest-size "
                   "keeps the fewest coefficients.")
@click.option("--shared-denominator", "shared", is_flag=True,
              help="One denominator q for every channel, one numerator p_c per channel: "
                   "minimises sum(n_c) + m (--m fixes q's size, --max-total bounds each "
                   "numerator). Each channel is verified and proved valid as p_c / q and "
                   "stored that way; the fit is not polished.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def brdf_fit(input_path: Path, output: Path | None, fmt: str | None, param: str | None,
             dt: float | None, abs_width: float | str | None, floor_rel: float | None,
             cosine: bool,
             clamp: float | None, positive_q: bool, channels: tuple[str, ...], color: str,
             max_points: int | None, subset_by: str, holdout: int | None, no_polish: bool,
             polish_error: str, as_json: bool, shared: bool = False, values: str = "linear",
             envelope: bool | None = None, held_out_size: bool | None = None,
             **options: Any) -> None:
    """Fit each channel of a measured BRDF with a verified rational function."""
    from ratfit.jobs import BRDFFitRequest, fit_brdf_file

    params = pop_fit_params(options)
    check_size_flags(params, shared=shared)
    if max_points is not None and max_points < 2:
        raise click.UsageError("--max-points must be >= 2")
    if subset_by != "samples" and max_points is None:
        raise click.UsageError("--subset-by says how --max-points draws: give --max-points")
    if holdout is not None and holdout < 2:
        raise click.UsageError("--holdout must be >= 2 folds")
    request = BRDFFitRequest.from_settings(input_path, {
        **params, "format": fmt, "parametrization": param, "dt": dt, "abs_width": abs_width,
        "floor_rel": floor_rel, "cosine": cosine, "clamp": clamp, "positive_q": positive_q,
        "channels": _split_channels(channels), "color": color, "max_points": max_points,
        "subset_by": subset_by, "holdout": holdout, "polish": not no_polish,
        "polish_error": polish_error,
        "values": values, "envelope": envelope, "held_out_size": held_out_size,
        "shared_denominator": shared,
        "output": output})
    cb, stop = _progress(True)  # stderr: JSON on stdout stays clean
    try:
        report = fit_brdf_file(request.with_progress(cb))
    finally:
        stop()
    if as_json:
        _write_json(report.summary())
    else:
        for line in report.notes():
            click.echo(line, err=True)
        _print_brdf_report(report)
        if output is not None and not report.success:
            click.echo(f"no fit file written: not every channel is verified ({output})", err=True)
        if report.kept is not None:
            click.echo(f"kept the verified channels {', '.join(report.kept_names)} in "
                       f"{report.kept}", err=True)
    if not report.success:
        hint = report.hint()
        if hint:
            click.echo(hint, err=True)
        sys.exit(EXIT_NO_FIT)


def _print_brdf_report(report: Any) -> None:
    """The table of ``ratfit fit``, then the frame, the status and the errors."""
    seg, meta = report.segments, report.meta
    _print_report(report.results, report.written, verified_as="subset" if report.subset else None,
                  work_limit=report.request.options.work_limit)
    click.echo(f"parametrization {report.parametrization}, {seg.n_points} samples")
    sh = meta.get("shared")
    if sh and report.success:
        click.echo(f"shared denominator: one q (m = {sh['m']}) for {', '.join(seg.names)}, "
                   f"n = {sh['n']}: {sh['coefficients']} coefficients with q counted once, "
                   f"{sh['stored_coefficients']} stored (p_c / q per channel; not polished)")
    if report.subset and report.success:
        click.echo("status: " + str(report.status()))
    if meta.get("dropped_coords"):
        click.echo("constant coordinates dropped (recorded in the fit): "
                   + ", ".join(f"#{k} = {v:.6g}" for k, v in meta["dropped_coords"].items()))
    for name, v in zip(seg.names, meta.get("validity") or [], strict=False):
        if v:
            click.echo(f"{name}: physical check: {v}")
    for name, mm in (report.metrics or {}).items():
        click.echo(f"{name}: " + ", ".join(f"{k} {v:.4g}" for k, v in mm.items()))
    if report.holdout is not None:
        for line in report.holdout.lines():
            click.echo(line)


@brdf_group.command("merge")
@click.argument("inputs", metavar="FIT.json...", nargs=-1, required=True,
                type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="The merged fit file (JSON).")
def brdf_merge(inputs: tuple[Path, ...], output: Path) -> None:
    """Join BRDF fit files of the same data whose channels were fitted in separate runs.

    A fit whose channels did not all verify keeps the verified ones in NAME.partial.json;
    refit the others alone (--channel) and merge the files. They must be fits of the same
    input in the same frame, value form and subset; each channel keeps its own proof,
    which is made again before the file is written.
    """
    from ratfit.jobs import BRDFMergeRequest, merge_brdf_fits

    if len(inputs) < 2:
        raise click.UsageError("give two or more fit files to merge")
    report = merge_brdf_fits(BRDFMergeRequest(inputs, output))
    click.echo(f"wrote {output}: channels {', '.join(report.channels)} from {len(inputs)} files")


@brdf_group.command("eval")
@trust_edited_option
@click.argument("fit_path", metavar="FIT.json", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--dirs", "dirs", type=click.Path(dir_okay=False, path_type=Path),
              help="Directions: CSV/text rows 'lx ly lz vx vy vz' (a header line is allowed).")
@click.option("--coords", "coords", type=click.Path(dir_okay=False, path_type=Path),
              help="Rows of coordinates in the fit's parametrization.")
@click.option("--data", "data", type=click.Path(dir_okay=False, path_type=Path),
              help="A BRDF file: print the metrics of the fit against it (JSON).")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Write values to .csv or .npy (default: CSV on stdout).")
def brdf_eval(fit_path: Path, dirs: Path | None, coords: Path | None, data: Path | None,
              output: Path | None) -> None:
    """BRDF values of a fit at directions (or coordinates), or its errors on a data file."""
    from ratfit._atomic import atomic_open
    from ratfit.brdf.fitter import brdf_metrics, cos_theta_l, load_brdf_fit
    from ratfit.brdf.io import brdf_dataset
    from ratfit.errors import InputError

    if sum(v is not None for v in (dirs, coords, data)) != 1:
        raise click.UsageError("give exactly one of --dirs, --coords, --data")
    fit = load_brdf_fit(fit_path)
    if data is not None:
        ds = brdf_dataset(data, fit.parametrization)
        assert ds.y is not None
        if ds.n_channels != fit.n_channels:
            raise InputError(f"{data} has {ds.n_channels} channel(s), the fit {fit.n_channels}")
        pred = fit.eval_coords(ds.x)
        try:
            cl = cos_theta_l(ds.x, fit.parametrization)
        except InputError:
            cl = None
        _write_json({"fit": str(fit_path), "data": str(data), "n_points": ds.n_points,
                     "parametrization": fit.parametrization,
                     "metrics": brdf_metrics(pred, ds.y, cl, fit.channel_names)})
        return
    path = dirs if dirs is not None else coords
    assert path is not None
    from ratfit.brdf.parametrizations import get_parametrization

    width = 6 if dirs is not None else get_parametrization(fit.parametrization).dim
    table = _read_table(path, width)
    if dirs is not None:
        vals = fit.eval_dirs(table[:, :3], table[:, 3:])
        cols = ["lx", "ly", "lz", "vx", "vy", "vz"]
    else:
        vals = fit.eval_coords(table)
        cols = list(get_parametrization(fit.parametrization).coords)
    names = list(fit.channel_names)
    if output is not None and output.suffix.lower() == ".npy":
        with atomic_open(output, "wb") as fh:
            np.save(fh, vals)
        return
    lines = [csv_line(cols + names)]
    lines += [",".join(repr(float(v)) for v in row) for row in np.hstack([table, vals])]
    if output is None:
        with stdout_guard():
            click.echo("\n".join(lines))
    else:
        with atomic_open(output, "w") as fh:
            fh.write("\n".join(lines) + "\n")


def _read_table(path: Path, width: int) -> np.ndarray:
    """Numbers from a CSV/blank-separated text file, `width` per row; one header line allowed."""
    from ratfit.errors import FileFormatError

    if not path.is_file():
        raise FileFormatError(f"{path}: no such file")
    rows: list[list[float]] = []
    for n, raw in enumerate(path.read_text(errors="replace").splitlines(), start=1):
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        toks = s.replace(",", " ").split()
        try:
            vals = [float(t) for t in toks]
        except ValueError:
            if not rows:
                continue  # a header line
            raise FileFormatError(f"{path} line {n}: non-numeric value in {s[:60]!r}") from None
        if len(vals) != width:
            raise FileFormatError(f"{path} line {n}: expected {width} numbers, got {len(vals)}")
        rows.append(vals)
    if not rows:
        raise FileFormatError(f"{path}: no rows of numbers")
    arr = np.asarray(rows)
    if not np.all(np.isfinite(arr)):
        raise FileFormatError(f"{path}: non-finite values")
    return arr


@brdf_group.command("model")
@click.argument("data_path", metavar="DATA", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--model", "spec", default="lambert+ggx", show_default=True,
              help="Analytic model, e.g. lambert+ggx, lambert+ggx*2, lambert+lafortune*2. "
                   "Lobes: lambert, blinn, ward, beckmann, ggx, lafortune.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Model file (JSON) for `ratfit render`, `brdf compare`.")
@click.option("--starts", type=click.IntRange(1, 1000), default=8, show_default=True,
              help="Random starts of the nonlinear least-squares fit per channel.")
@click.option("--color", type=click.Choice(["rgb", "xyz", "spectral"]), default="rgb",
              show_default=True, help="Spectral (Cornell) data: as for `brdf fit`.")
def brdf_model(data_path: Path, spec: str, output: Path, starts: int, color: str) -> None:
    """Fit an analytic model (the ones `brdf compare` fits) to a measured BRDF and save it,
    so `ratfit render` draws it the way it draws a rational fit."""
    from ratfit.brdf.analytic_models import Model
    from ratfit.brdf.io import brdf_dataset
    from ratfit.errors import InputError
    from ratfit.viz.report import model_fit_for

    model = Model(spec)
    ds = brdf_dataset(data_path, None, color=color)
    if ds.y is None:
        raise InputError(f"{data_path}: no BRDF values to fit")
    mf = model_fit_for(str(ds.meta.get("param_in")), ds, model.spec, starts=starts)
    mf.info["data"] = str(data_path)
    mf.save(output)
    click.echo(f"{model.spec} fitted to {ds.n_points} samples of {data_path} "
               f"({model.n_params} parameters per channel) -> {output}")
    for name, p, m in zip(mf.channel_names, mf.params, mf.metrics, strict=True):
        click.echo(f"{name}: " + ", ".join(f"{k} {v:.4g}" for k, v in m.items())
                   + "; " + ", ".join(f"{a} {b:.4g}" for a, b in
                                      zip(model.param_names, p, strict=True)))
