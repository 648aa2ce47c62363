"""`ratfit brdf ...`: fit measured BRDFs and evaluate BRDF fits on directions."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click
import numpy as np

from ratfit.brdf.fitter import BRDF_SOLVER, DEFAULT_DT
from ratfit.cli.main import (
    EXIT_NO_FIT,
    _fit_json,
    _print_report,
    _progress,
    _write_json,
    main,
    trust_edited_option,
)
from ratfit.cli.options import aliased_option, fit_options, pop_fit_params


@main.group("brdf")
def brdf_group() -> None:
    """Measured BRDFs: MERL, ALTA, Cornell/pbrt, ASTM and EXR files."""


def _split_channels(values: tuple[str, ...]) -> list[str]:
    return [c.strip() for v in values for c in v.split(",") if c.strip()]


_ISOTROPIC_DEFAULT = {"CARTESIAN": "ISOTROPIC_TV_TL_DPHI"}


@brdf_group.command("fit")
@click.argument("input_path", metavar="INPUT", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Fit file (JSON); written only when every channel is verified.")
@click.option("--format", "fmt", type=click.Choice(["merl", "alta", "cornell", "astm", "exr"]),
              help="Input format (default: from the file).")
@click.option("--param", "param", default=None,
              help="Parametrization to fit in (ALTA names, e.g. RUSIN_TH_TD_PD, COS_TH_TD_PD, "
                   "STARK_2D); default: the file's own (ISOTROPIC_TV_TL_DPHI for Cartesian "
                   "pairs), and for isotropic angles RUSIN_TH_TD_PD first, keeping the "
                   "better verified fit (narrower segments, then fewer coefficients).")
@click.option("--dt", type=float,
              help="Relative segment width: [(1-dt) y, (1+dt) y]. Without --dt, --abs-width "
                   "and --floor-rel: the file's own intervals, else 0.05 (widened where "
                   "nearby samples need it) with --floor-rel 0.002 (0.001 in "
                   "RUSIN_TH_TD_PD; halved up to twice while the fit stays at most 12 "
                   "coefficients per channel and most samples lie under the floor). "
                   "When nothing verifies and every split tested was infeasible, that "
                   "default is widened 1.5x (up to 0.9) until a try has a candidate "
                   "(not with --max-total).")
@click.option("--abs-width", type=float,
              help="Absolute half-width (floor); with --dt each segment takes the larger.")
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
@click.option("--max-points", type=int, help="Fit a random subset of this many samples.")
@fit_options(exclude=("domain",), defaults={"solver": BRDF_SOLVER})
@click.option("--no-polish", "no_polish", is_flag=True,
              help="Keep the search's minimum-norm fit (default: replace it by the "
                   "least-squares fit of the same size inside the segments when that "
                   "verifies).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def brdf_fit(input_path: Path, output: Path | None, fmt: str | None, param: str | None,
             dt: float | None, abs_width: float | None, floor_rel: float | None, cosine: bool,
             clamp: float | None, positive_q: bool, channels: tuple[str, ...], color: str,
             max_points: int | None, no_polish: bool, as_json: bool,
             **options: Any) -> None:
    """Fit each channel of a measured BRDF with a verified rational function."""
    from ratfit.brdf.fitter import (
        brdf_metrics,
        candidate_parametrizations,
        cos_theta_l,
        fit_brdf_auto,
        save_brdf_fit,
        subset_status,
    )
    from ratfit.brdf.io import brdf_dataset
    from ratfit.brdf.parametrizations import get_parametrization
    from ratfit.io.fitfile import file_sha256

    params = pop_fit_params(options)
    if (params["n"] is None) != (params["m"] is None):
        raise click.UsageError("give both --n and --m, or neither")
    if max_points is not None and max_points < 2:
        raise click.UsageError("--max-points must be >= 2")
    user_param = param is not None
    if param is not None:
        param = get_parametrization(param).name
    ds = brdf_dataset(input_path, param, fmt=fmt, channels=_split_channels(channels) or None,
                      color=color, max_points=max_points)
    own = str(ds.meta.get("param_in"))
    if param is None and own in _ISOTROPIC_DEFAULT:
        # 6-D Cartesian pairs of an isotropic material (Cornell files): 3-D angles carry
        # the same information with no constant column and far fewer coefficients.
        param = _ISOTROPIC_DEFAULT[own]
        ds = brdf_dataset(input_path, param, fmt=fmt,
                          channels=_split_channels(channels) or None, color=color,
                          max_points=max_points)
    # No --param and no fixed size: the half-vector frame first, then the angles.
    names = (str(ds.meta.get("param_in")),) if user_param or params["n"] is not None \
        or params["total"] is not None else \
        candidate_parametrizations(str(ds.meta.get("param_in")))
    datasets = [ds if name == ds.meta.get("param_in") else
                brdf_dataset(input_path, name, fmt=fmt,
                             channels=_split_channels(channels) or None, color=color,
                             max_points=max_points) for name in names]
    cb, stop = _progress(True)  # stderr: JSON on stdout stays clean
    try:
        fitter, seg, meta = fit_brdf_auto(
            datasets, dt=dt, abs_width=abs_width, floor_rel=floor_rel, cosine=cosine,
            clamp=clamp, positive_q=positive_q, polish=not no_polish, callback=cb, **params,
        )
    finally:
        stop()
    ds = next(d for d in datasets if d.meta.get("param_in") == meta["parametrization"])
    if len(datasets) == 1 and own in _ISOTROPIC_DEFAULT and not user_param and not as_json:
        click.echo(f"parametrization: {param} (chosen for the file's {own}; "
                   "--param overrides)", err=True)
    if len(datasets) > 1 and not as_json:
        def said(c: dict[str, Any]) -> str:
            if c.get("narrowed_floor_from"):
                got = (f"{c['coefficients']} coefficients" if c["verified"]
                       else "no verified fit, not kept")
                return f"floor {c['floor_rel']:g}: {got}"
            if c.get("widened_from"):
                got = (f"{c['coefficients']} coefficients" if c["verified"] else
                       "no candidate either" if c.get("no_candidate") else
                       "no verified fit")
                return (f"{c['parametrization']} widened from {c['widened_from']:.3g} "
                        f"to {c['dt']:.3g}: {got}")
            if c.get("skipped"):
                return f"{c['parametrization']}: not tried, {c['skipped']}"
            if c["verified"]:
                return f"{c['parametrization']}: {c['coefficients']} coefficients"
            up = f" up to {c['searched_up_to']} per channel" if c["searched_up_to"] else ""
            if c.get("no_candidate"):
                return (f"{c['parametrization']} at {c['dt']:.3g}: no candidate{up} "
                        "(every split infeasible)")
            return f"{c['parametrization']}: no verified fit{up}"

        click.echo(f"parametrization: {meta['parametrization']} ("
                   + "; ".join(said(c) for c in meta["candidates"])
                   + "; narrower segments, then fewer coefficients win; --param fixes one)",
                   err=True)
    widths = meta["segments"]
    if widths["default"] and not as_json:
        ladder = widths.get("widened_from") or []
        base = ladder[0] if ladder else widths["dt"]
        why = "" if base == DEFAULT_DT else (
            f", widened from {DEFAULT_DT:g}" + (f" to {base:.3g}" if ladder else "")
            + " so that samples measured at nearly the same point have overlapping segments")
        if ladder:
            why += ("; then to " + ", ".join(f"{w:.3g}" for w in [*ladder[1:], widths["dt"]])
                    + ": at " + ", ".join(f"{w:.3g}" for w in ladder)
                    + " every split the search tested was infeasible")
        if widths.get("narrowed_floor_from"):
            why += (f"; floor narrowed from {widths['narrowed_floor_from']:g}: the fit "
                    "there was small and most samples lay under the floor")
        click.echo(f"segments: y +- {widths['dt']:.3g} y with a floor of "
                   f"{widths['floor_rel']:g} x the channel's largest value (default{why}; "
                   "--dt, --abs-width, --floor-rel override)", err=True)
    results = fitter.results_
    ok = all(r.success for r in results)
    metrics: dict[str, Any] | None = None
    if ok:
        pred = np.stack([r.rational(seg.x) for r in results], axis=1)
        cl = None
        if meta["parametrization"] in ("UNKNOWN",):
            cl = None
        else:
            try:
                cl = cos_theta_l(seg.x, meta["parametrization"])
            except Exception:  # parametrizations without theta_l: no cos-weighted metric
                cl = None
        metrics = brdf_metrics(pred, seg.center, cl, seg.names)
    if output is not None and ok:
        save_brdf_fit(output, results, meta, provenance={
            "input": str(input_path), "input_sha256": file_sha256(input_path),
            "n_points": seg.n_points, "solver": params["solver"],
            "segments": {"dt": dt, "abs_width": abs_width, "floor_rel": floor_rel},
        })
    subset = ds.meta.get("subset")
    if as_json:
        doc = _fit_json(results, output if ok else None)
        doc["parametrization"] = meta["parametrization"]
        doc["parametrization_candidates"] = meta["candidates"]
        doc["n_points"] = seg.n_points
        doc["verified_on"] = meta["verified_on"]
        if subset:
            doc["subset"] = dict(subset)
            doc["status"] = subset_status(subset["points"], subset["of"]) if ok else (
                "no verified fit")
        doc["metrics"] = metrics
        _write_json(doc)
    else:
        _print_report(results, output if ok and output else None,
                      verified_as="subset" if subset else None)
        click.echo(f"parametrization {meta['parametrization']}, {seg.n_points} samples")
        if subset and ok:
            click.echo("status: " + subset_status(subset["points"], subset["of"]))
        if meta.get("dropped_coords"):
            click.echo("constant coordinates dropped (recorded in the fit): "
                       + ", ".join(f"#{k} = {v:.6g}" for k, v in meta["dropped_coords"].items()))
        for name, v in zip(seg.names, meta.get("validity") or [], strict=False):
            if v:
                click.echo(f"{name}: physical check: {v}")
        for name, mm in (metrics or {}).items():
            click.echo(f"{name}: " + ", ".join(f"{k} {v:.4g}" for k, v in mm.items()))
        if output is not None and not ok:
            click.echo(f"no fit file written: not every channel is verified ({output})", err=True)
    if not ok:
        if widths["default"]:
            limited = any(r.time_limited for r in results)
            click.echo(
                f"hint: no verified fit at the default segments (y +- {widths['dt']:.3g} y); "
                f"wider ones (--dt {min(2 * float(widths['dt']), 1.0):.2g}) "
                + ("or a longer --time-limit (the search ran out of time) " if limited else "")
                + "may give one", err=True)
        sys.exit(EXIT_NO_FIT)


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
    lines = [",".join(cols + names)]
    lines += [",".join(repr(float(v)) for v in row) for row in np.hstack([table, vals])]
    if output is None:
        click.echo("\n".join(lines))
    else:
        with atomic_open(output, "w") as fh:
            fh.write("\n".join(lines) + "\n")


def _read_table(path: Path, width: int) -> np.ndarray:
    """Numbers from a CSV/blank-separated text file, `width` per row; one header line allowed."""
    from ratfit.errors import FileFormatError

    if not path.is_file():
        raise FileFormatError(f"{path}: no such file")
    rows = []
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
