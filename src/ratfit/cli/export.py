"""`ratfit export`, `ratfit plot`, `ratfit report` and `ratfit brdf compare`."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from ratfit.cli.main import _write_json, console, fit_table, trust_edited_option
from ratfit.cli.options import aliased_option
from ratfit.errors import InputError

_FILE = click.Path(dir_okay=False, path_type=Path)

scale_option = click.option(
    "--scale", type=click.Choice(["auto", "linear", "log"]), default="auto", show_default=True,
    help="Value axes: auto draws on a log axis when the positive values span more than two "
         "decades (the caption says which was chosen).")
rel_floor_option = click.option(
    "--rel-floor", type=click.FloatRange(0.0, 1.0, min_open=True, max_open=True),
    default=1e-3, show_default=True,
    help="Relative errors are |fit - data| / max(|data|, floor), floor = this x the "
         "channel's largest |data|, so near-zero samples do not dominate.")


@click.command("export")
@trust_edited_option
@click.argument("fit_path", metavar="FIT.json", type=_FILE)
@click.option("--lang", type=click.Choice(["c", "glsl", "python"]), required=True)
@click.option("-o", "--output", type=_FILE, required=True, help="Source file to write.")
@click.option("--form", type=click.Choice(["auto", "horner", "clenshaw", "recurrence"]),
              default="auto",
              show_default=True,
              help="auto: Horner on the monomial form when it keeps full accuracy, else "
                   "Clenshaw in the fit's orthogonal basis.")
@click.option("--prefix", default="ratfit", show_default=True, help="Prefix of every name.")
@click.option("--data", "data_path", type=_FILE,
              help="Data whose segments (widths from the fit file) the exported formula must "
                   "meet, evaluated as the C/Python code evaluates it (default: the fit's input "
                   "file when it is unchanged). A miss refuses the export (exit 1).")
def export_cmd(fit_path: Path, lang: str, output: Path, form: str, prefix: str,
               data_path: Path | None) -> None:
    """Write C, GLSL or Python source evaluating a saved (verified) fit.

    The C and Python code evaluate with the same float64 operations, in the same order,
    that the check used; the header says whether every segment was checked with it.
    An ALTA rational function file is exported too, its header saying that ratfit
    did not verify it."""
    from ratfit._atomic import is_stream
    from ratfit.export.code import UnverifiedExport, export_fit

    try:
        res = export_fit(fit_path, lang, output, form=form, prefix=prefix, data=data_path)
    except UnverifiedExport as exc:
        click.echo(f"error: {exc}", err=True)
        raise click.exceptions.Exit(1) from None
    err = is_stream(output)  # code on stdout (-o -, a pipe): the notes go to stderr
    for line in res.describe():
        click.echo(line, err=err)
    if res.parametrization:
        click.echo(f"directions -> {res.parametrization}: {prefix}_coords, {prefix}_brdf",
                   err=err)
    click.echo(f"wrote {output}", err=err)


@click.command("plot")
@trust_edited_option
@click.argument("fit_path", metavar="FIT.json", type=_FILE)
@click.option("--data", "data_path", type=_FILE, help="Data file to show with the fit.")
@click.option("--kind", type=click.Choice(["slice", "polar", "sphere", "error", "relerror"]),
              default="slice", show_default=True,
              help="slice: fit and data along --dim with the signed error; error: signed "
                   "error at every sample; relerror: |fit - data| / max(|data|, floor); "
                   "polar: BRDF in the plane of incidence; sphere: rendered spheres.")
@click.option("-o", "--output", type=_FILE, required=True, help="PNG file to write.")
@click.option("--channel", type=int, default=0, show_default=True)
@click.option("--dim", type=int, default=0, show_default=True, help="Slice coordinate.")
@click.option("--model", "models", multiple=True,
              help="Analytic model(s) fitted to the data and drawn beside (BRDF fits), "
                   "e.g. lambert+ggx. Default for sphere: lambert+ggx.")
@click.option("--size", type=click.IntRange(16, 4096), default=128, show_default=True,
              help="Sphere image size.")
@scale_option
@rel_floor_option
def plot_cmd(fit_path: Path, data_path: Path | None, kind: str, output: Path, channel: int,
             dim: int, models: tuple[str, ...], size: int, scale: str,
             rel_floor: float) -> None:
    """Pictures of a fit: slice (fit, data, signed error), error, polar or sphere."""
    from ratfit.brdf.analytic_models import Model
    from ratfit.viz.report import LoadedFit, load_data_for

    if output.suffix.lower() != ".png":
        raise InputError(f"{output}: plots are PNG files (use a .png name)")
    for spec in models:
        Model(spec)  # check before any work
    fit = LoadedFit.load(fit_path)
    if not 0 <= channel < len(fit.saved.channels):
        raise InputError(f"channel {channel} out of range: the fit has "
                         f"{len(fit.saved.channels)} channel(s)")
    from ratfit.viz.pictures import PlotStyle
    from ratfit.viz.report import report_style

    style = report_style(fit, PlotStyle(scale=scale, rel_floor=rel_floor))
    ds = load_data_for(fit, data_path) if data_path is not None else None
    if kind in ("slice", "error", "relerror"):
        _plot_values(fit, ds, data_path, kind, output, channel, dim, style)
    else:
        if not fit.is_brdf:
            raise InputError(f"{fit_path}: --kind {kind} needs a BRDF fit (a fit file that "
                             "records its parametrization, from `ratfit brdf fit`)")
        _plot_brdf(fit, ds, kind, output, channel, models, size, style)
    click.echo(f"wrote {output}")


def _plot_values(fit: Any, ds: Any, data_path: Path | None, kind: str, output: Path,
                 channel: int, dim: int, style: Any) -> None:
    """A slice of the fit along one input (with the data), or its error at the data."""
    from ratfit.viz import pictures as pic
    from ratfit.viz.report import coordinate_names, segments_of

    if kind in ("error", "relerror") and ds is None:
        raise click.UsageError(f"--kind {kind} needs --data")
    if not 0 <= dim < fit.saved.space.dim:
        raise InputError(f"--dim {dim} out of range: the fit has "
                         f"{fit.saved.space.dim} input dimension(s)")
    seg = segments_of(fit, ds) if ds is not None else None
    lo, hi = (None, None) if seg is None else (seg.lo, seg.hi)
    names = coordinate_names(fit, ds)
    if kind == "slice":
        pic.plot_slice(fit.saved, output, x=None if ds is None else ds.x,
                       y=None if ds is None else ds.y, lo=lo, hi=hi, dim=dim,
                       channel=channel, names=names, style=style)
    elif kind == "error":
        pic.plot_error(fit.saved, output, ds.x, ds.y, lo=lo, hi=hi, dim=dim,
                       channel=channel, names=names, style=style)
    else:
        pic.plot_relative_error(fit.saved, output, ds.x, ds.y, lo=lo, hi=hi, dim=dim,
                                channel=channel, names=names, style=style)
    if seg is not None and data_path is not None:
        _say_recheck(fit, seg, data_path)


def _plot_brdf(fit: Any, ds: Any, kind: str, output: Path, channel: int,
               models: tuple[str, ...], size: int, style: Any) -> None:
    """Polar lobes or rendered spheres of a BRDF fit (and the data, and models)."""
    from ratfit.viz import pictures as pic
    from ratfit.viz.report import cos_factor, model_fit_for

    assert fit.param is not None
    cf = ds is not None and cos_factor(ds)
    funcs = {"rational": pic.fit_brdf_function(fit.brdf, cos_factor=cf)}
    if ds is not None:
        for spec in models or (("lambert+ggx",) if kind == "sphere" else ()):
            mf = model_fit_for(fit.param, ds, spec)
            funcs[mf.name] = mf.eval_dirs
    data_fn = None if ds is None else pic.DataBRDF(
        ds.x, ds.y, fit.param, cos_factor=cf, fold_phi_d=bool(ds.meta.get("fold_phi_d")))
    if kind == "polar":
        pic.plot_polar(funcs, output, channel=channel, data=data_fn, scale=style.scale)
        return
    imgs = {}
    if data_fn is not None:
        imgs["data"] = pic.render_sphere(data_fn, size=size)
    for name, f in funcs.items():
        imgs[name] = pic.render_sphere(f, size=size)
    pic.plot_spheres(imgs, output)


def _say_recheck(fit, seg, data_path: Path) -> None:
    """The fit verified again on the data's segments, one line per channel."""
    from ratfit.io.fitfile import segment_check

    for name, met, tot, worst in segment_check(fit.saved, seg):
        extra = "" if met == tot else f"; MISSED {tot - met}, worst by {worst:.3g}"
        click.echo(f"checked on {data_path}: channel {name}: {met} of {tot} segments met{extra}")


@click.command("report")
@trust_edited_option
@click.argument("fit_path", metavar="FIT.json", type=_FILE)
@click.option("--data", "data_path", type=_FILE, help="Data file the fit is compared with.")
@aliased_option("-o", "--output", "outdir", hidden=["--outdir"], required=True,
                type=click.Path(file_okay=False, path_type=Path),
                help="Folder for index.html and its pictures.")
@click.option("--model", "models", multiple=True,
              help="Analytic model(s) to compare with (BRDF fits; default lambert+ggx).")
@scale_option
@rel_floor_option
def report_cmd(fit_path: Path, data_path: Path | None, outdir: Path,
               models: tuple[str, ...], scale: str, rel_floor: float) -> None:
    """One static HTML page with the metrics table and the pictures (opens offline)."""
    from ratfit.brdf.analytic_models import Model
    from ratfit.viz.pictures import PlotStyle
    from ratfit.viz.report import write_report

    for spec in models:
        Model(spec)
    res = write_report(fit_path, data_path, outdir, models=models or ("lambert+ggx",),
                       style=PlotStyle(scale=scale, rel_floor=rel_floor))
    if res.albedo is not None and res.albedo["flagged"]:
        click.echo(f"warning: the fit reflects more than it receives (max albedo "
                   f"{res.albedo['max_albedo']:.3g})", err=True)
    click.echo(f"wrote {res.index} ({len(res.pictures)} pictures)")


# ---------------------------------------------------------------------------- brdf compare
def _compare(data_path: Path, fits: tuple[str, ...], models: tuple[str, ...], param: str | None,
             starts: int, as_json: bool, rel_floor: float = 1e-3) -> None:

    from ratfit.brdf.analytic_models import Model, is_model_file, load_model_fit
    from ratfit.brdf.io import brdf_dataset
    from ratfit.viz.report import LoadedFit

    for spec in models:
        Model(spec)
    if not fits and not models:
        raise click.UsageError("give at least one FIT file or --model")
    # everything is read before the long part: a bad file fails in a second, not after
    # minutes of model fitting
    loaded: list[tuple[str, LoadedFit]] = []
    model_files = []
    for f in fits:
        if is_model_file(f):
            model_files.append(Path(f))
            continue
        lf = LoadedFit.load(f)
        if not lf.is_brdf:
            raise InputError(f"{f}: not a BRDF fit (it records no parametrization)")
        loaded.append((f, lf))
    mfs = [(mp, load_model_fit(mp)) for mp in model_files]
    first = loaded[0][1] if loaded else None
    ds = brdf_dataset(data_path, first.param if first is not None else param)
    rows = _compare_rows(data_path, ds, loaded, mfs, models, starts, rel_floor)
    if as_json:
        _write_json({"data": str(data_path), "n_points": ds.n_points, "rows": rows})
        return
    _print_compare(rows, f"{data_path} ({ds.n_points} samples)", rel_floor)


def _compare_rows(data_path: Path, ds: Any, loaded: list, mfs: list, models: tuple[str, ...],
                  starts: int, rel_floor: float) -> list[dict]:
    """The metric rows of each fit file, model file and model fitted here, with progress:
    one step per fit file and per start of each model's channel."""
    from ratfit.cli.progress import StepProgress
    from ratfit.viz.report import load_data_for, model_fit_for, model_metrics, rational_metrics

    pname = str(ds.meta.get("param_in"))
    rows: list[dict] = []
    total = len(loaded) + len(models) * ds.n_channels * starts
    with StepProgress("compare", total) as bar:
        for f, lf in loaded:
            for r in rational_metrics(lf, load_data_for(lf, data_path), rel_floor):
                r["name"] = Path(f).name
                rows.append(r)
            bar.advance(1, Path(f).name)
        for mp, mf in mfs:
            for r in model_metrics(mf, pname, ds, rel_floor):
                r["name"] = f"{mp.name} ({mf.name})"
                rows.append(r)
        for spec in models:
            def step(note: str, spec: str = spec) -> None:
                bar.advance(1, f"{spec} {note}")

            mf = model_fit_for(pname, ds, spec, starts=starts, progress=step)
            rows += model_metrics(mf, pname, ds, rel_floor)
    return rows


def _print_compare(rows: list[dict], title: str, rel_floor: float) -> None:
    """The table; a terminal narrower than it loses the optional columns (said below
    it), a file or a pipe gets every column: nothing there is too narrow."""
    from ratfit.viz.report import METRIC_COLUMNS, compare_table

    con = console(160)
    columns = ["fit", "channel", "coefs", *METRIC_COLUMNS, "parameters"]
    tty = sys.stdout.isatty()
    table, dropped = fit_table(con, title, columns, compare_table(rows),
                               optional=("cos_rmse", "log_rmse") if tty else (),
                               left=("fit", "parameters"))
    if not tty:
        from rich.console import Console

        width = con.measure(table, options=con.options.update_width(100_000)).maximum
        con = Console(width=max(width, con.width), file=sys.stdout)
    con.print(table)
    if dropped:
        con.print(f"(narrow terminal: {', '.join(dropped)} in --json)", highlight=False)
    floors = {str(r["channel"]): r["rel_floor"] for r in rows if "rel_floor" in r}
    con.print(f"rel_rmse: RMS of |fit - data| / max(|data|, floor), floor = {rel_floor:g} x the "
              "channel's largest |data| (" + ", ".join(f"{c} {v:.4g}" for c, v in
                                                     floors.items()) + ")",
              highlight=False, markup=False)


@click.command("compare")
@click.argument("data_path", metavar="DATA", type=_FILE)
@click.argument("fits", metavar="FIT...", nargs=-1)
@click.option("--model", "models", multiple=True,
              help="Analytic model fitted to DATA, e.g. lambert+ggx, lambert+lafortune*2 "
                   "(repeatable). Lobes: lambert, blinn, ward, beckmann, ggx, lafortune.")
@click.option("--param", default=None,
              help="Parametrization for --model-only runs (default: the file's).")
@click.option("--starts", type=click.IntRange(1, 1000), default=8, show_default=True,
              help="Random starts per analytic fit.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
@rel_floor_option
@trust_edited_option
def compare_cmd(data_path: Path, fits: tuple[str, ...], models: tuple[str, ...],
                param: str | None, starts: int, as_json: bool, rel_floor: float) -> None:
    """Metrics of rational fits (FIT files) and analytic models side by side on DATA.

    Shows progress and an estimate of the time left on stderr."""
    _compare(data_path, fits, models, param, starts, as_json, rel_floor)

