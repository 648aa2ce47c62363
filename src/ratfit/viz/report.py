"""One static HTML page per fit: metrics table, albedo check and pictures (opens offline).

Also the shared plumbing of ``ratfit plot``, ``ratfit report`` and
``ratfit brdf compare``: loading a fit file with its parametrization (if it is a
BRDF fit), reading data in the fit's coordinates, and computing the same
metrics (:func:`ratfit.brdf.analytic_models.channel_metrics`) for rational and analytic fits.
"""

from __future__ import annotations

import html
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ratfit._atomic import atomic_dir
from ratfit.brdf.validity import reprove_saved
from ratfit.errors import InputError
from ratfit.io.data import Dataset
from ratfit.io.fitfile import SavedFit, scope_text, subset_of
from ratfit.viz.pictures import DEFAULT_STYLE, REL_FLOOR, PlotStyle

__all__ = ["LoadedFit", "compare_table", "load_data_for", "write_report"]

Array = NDArray[np.float64]


@dataclass
class LoadedFit:
    path: str
    saved: SavedFit
    brdf: Any = None  # ratfit.brdf.fitter.BRDFFit for a BRDF fit, else None

    @property
    def param(self) -> str | None:
        """Parametrization name of a BRDF fit, else None."""
        return None if self.brdf is None else str(self.brdf.parametrization)

    @property
    def is_brdf(self) -> bool:
        return self.param is not None

    @property
    def channel_names(self) -> list[str]:
        return [c.name for c in self.saved.channels]

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> LoadedFit:
        """A ratfit fit file; BRDF fits (through :mod:`ratfit.brdf`) keep their
        parametrization (:func:`ratfit.export.code.load_any_fit`)."""
        from ratfit.export.code import load_any_fit

        saved, bf = load_any_fit(path)
        return cls(str(path), saved, bf)


def load_data_for(fit: LoadedFit, data_path: str | os.PathLike[str]) -> Dataset:
    """The data file in the fit's coordinates (BRDF files converted to its parametrization)."""
    if fit.is_brdf:
        from ratfit.brdf.io import brdf_dataset

        ds = brdf_dataset(data_path, fit.param)
        if ds.n_channels != len(fit.saved.channels):
            names = set(fit.channel_names)
            keep = [j for j, n in enumerate(ds.output_names) if n in names]
            if len(keep) != len(fit.saved.channels):
                raise InputError(
                    f"{data_path} has channels {list(ds.output_names)} but the fit has "
                    f"{fit.channel_names}")
            assert ds.y is not None  # BRDF files have values
            ds = Dataset(ds.x, ds.y[:, keep], None if ds.lo is None else ds.lo[:, keep],
                         None if ds.hi is None else ds.hi[:, keep], ds.input_names,
                         tuple(ds.output_names[j] for j in keep), dict(ds.meta))
    else:
        from ratfit.io.data import read_data

        ds = read_data(data_path)
        if ds.n_channels != len(fit.saved.channels):
            raise InputError(f"{data_path} has {ds.n_channels} channel(s) but the fit has "
                             f"{len(fit.saved.channels)}")
    if ds.dim != fit.saved.space.dim:
        raise InputError(f"{data_path} has {ds.dim} input dimension(s) but the fit has "
                         f"{fit.saved.space.dim}")
    if ds.y is None:
        raise InputError(f"{data_path} has only bounds, no values to compare with")
    return ds


def cos_factor(ds: Dataset) -> bool:
    """ALTA's INV_STERADIAN_COSINE_FACTOR: the values are f cos(theta_l)."""
    return "COSINE" in str(ds.meta.get("param_out", "")).upper()


def data_dirs(param: str, ds: Dataset) -> tuple[Array, Array]:
    """Directions of the data samples, whose coordinates are in ``param``."""
    from ratfit.brdf.parametrizations import get_parametrization

    return get_parametrization(param).to_dirs(ds.x)


def segments_of(fit: LoadedFit, ds: Dataset):
    """The fit's segments on this data, from the widths recorded in the fit file."""
    if fit.brdf is not None:
        meta = fit.saved.extra.get("brdf", {})
        seg = meta.get("segments") or {}
        try:
            from ratfit.brdf.fitter import brdf_segments

            kw = {"abs_width": seg.get("abs_width"), "floor_rel": seg.get("floor_rel"),
                  "cosine": bool(meta.get("cosine_weighted")), "clamp": meta.get("clamp")}
            out = brdf_segments(ds, dt=seg.get("dt"), **kw)
            widths = seg.get("channel_dt")
            own = seg.get("per_channel")  # channels of runs merged by ratfit brdf merge
            if own and len(own) == out.n_channels:
                specs = [{**kw, **c} for c in own]
            elif widths and len(widths) == out.n_channels:  # a channel at a width of its own
                specs = [{**kw, "dt": d} for d in widths]
            else:
                return out
            lo, hi = out.lo.copy(), out.hi.copy()
            for j, spec in enumerate(specs):
                one = brdf_segments(ds, **spec)
                lo[:, j], hi[:, j] = one.lo[:, j], one.hi[:, j]
            return type(out)(out.x, lo, hi, out.y, out.names)
        except InputError:
            return None
    seg = (fit.saved.provenance or {}).get("segments") or {}
    dt, aw = seg.get("dt"), seg.get("abs_width")
    try:
        if dt is None and aw is None:
            return ds.segments() if ds.lo is not None else None
        return ds.segments(dt=dt, abs_width=aw)
    except InputError:
        return None


def rational_metrics(fit: LoadedFit, ds: Dataset, rel_floor: float = REL_FLOOR
                     ) -> list[dict[str, Any]]:
    from ratfit.brdf.analytic_models import channel_metrics

    assert fit.brdf is not None and fit.param is not None and ds.y is not None
    pred = fit.brdf.eval_coords(ds.x)
    cos_l = data_dirs(fit.param, ds)[0][:, 2]
    out: list[dict[str, Any]] = []
    for j, ch in enumerate(fit.saved.channels):
        out.append({**floored(channel_metrics(pred[:, j], ds.y[:, j], cos_l), pred[:, j],
                              ds.y[:, j], rel_floor),
                    "name": "rational", "channel": ch.name, "coefficients": ch.rational.total,
                    "detail": f"n={ch.rational.n}, m={ch.rational.m}"})
    return out


def floored(m: dict[str, Any], pred: Any, y: Any, rel_floor: float) -> dict[str, Any]:
    """``m`` with its relative errors measured against max(|y|, floor), floor =
    ``rel_floor`` x max |y|: rel_rmse (RMS), max_rel (largest) and the floor itself.

    Dividing by |y| alone lets a few near-zero samples decide the number (a rel. RMSE
    of 500 on a blue paint's red channel, whose errors are all below 0.33 1/sr)."""
    from ratfit.viz.pictures import rel_floor_value, relative_error

    floor = rel_floor_value(y, rel_floor)
    rel = relative_error(pred, y, floor)
    return {**m, "rel_rmse": float(np.sqrt(np.mean(rel**2))), "max_rel": float(np.max(rel)),
            "rel_floor": floor}


def model_fit_for(param: str, ds: Dataset, spec: str, *, starts: int = 6, seed: int = 0,
                  progress: Callable[[str], None] | None = None):
    """Fit an analytic model to the data (BRDF values; a cosine factor is divided out);
    ``progress`` is called after each start of each channel."""
    from ratfit.brdf.analytic_models import Model, fit_model

    L, V = data_dirs(param, ds)
    y = np.asarray(ds.y, dtype=float)
    if cos_factor(ds):
        y = y / np.maximum(L[:, 2:3], 1e-6)
    return fit_model(Model(spec), L, V, y, channel_names=ds.output_names, starts=starts,
                     seed=seed, progress=progress)


def model_metrics(mf, param: str, ds: Dataset, rel_floor: float = REL_FLOOR
                  ) -> list[dict[str, Any]]:
    """Metrics of an analytic fit on the data values as the file gives them."""
    from ratfit.brdf.analytic_models import channel_metrics

    assert ds.y is not None
    L, V = data_dirs(param, ds)
    pred = mf.eval_dirs(L, V)
    if cos_factor(ds):
        pred = pred * L[:, 2:3]
    out: list[dict[str, Any]] = []
    for j in range(ds.n_channels):
        pj = pred[:, min(j, pred.shape[1] - 1)]
        m = floored(channel_metrics(pj, ds.y[:, j], L[:, 2]), pj, ds.y[:, j], rel_floor)
        p = mf.params[min(j, mf.n_channels - 1)]
        out.append({**m, "name": mf.name, "channel": ds.output_names[j],
                    "coefficients": int(p.size),
                    "detail": ", ".join(f"{n}={v:.4g}" for n, v in
                                        zip(mf.model.param_names, p, strict=True))})
    return out


METRIC_COLUMNS = ("rmse", "rel_rmse", "log_rmse", "linf", "cos_rmse")


def compare_table(rows: list[dict[str, Any]]) -> list[list[str]]:
    """Rows of strings: name, channel, coefficients, metrics, detail."""
    out = []
    for r in rows:
        out.append([str(r["name"]), str(r["channel"]), str(r["coefficients"])]
                   + [("-" if r.get(c) is None else f"{r[c]:.4g}") for c in METRIC_COLUMNS]
                   + [str(r.get("detail", ""))])
    return out


@dataclass
class ReportResult:
    index: Path
    pictures: list[Path] = field(default_factory=list)
    metrics: list[dict[str, Any]] = field(default_factory=list)
    albedo: dict[str, Any] | None = None
    # the fit re-verified on the data's segments: (met, total, worst violation) per channel
    recheck: list[tuple[str, int, int, float]] | None = None


def coordinate_names(fit: LoadedFit, ds: Dataset | None) -> list[str]:
    """Names of the fit's input coordinates: the parametrization's, else the data's."""
    d = fit.saved.space.dim
    if fit.is_brdf:
        from ratfit.brdf.parametrizations import get_parametrization

        coords = list(get_parametrization(str(fit.param)).coords)
        if len(coords) == d:
            return coords
    if ds is not None and len(ds.input_names) == d:
        return list(ds.input_names)
    return [f"x{k}" for k in range(d)]


def recheck(fit: LoadedFit, seg: Any) -> list[tuple[str, int, int, float]]:
    """Verify the stored function again on the data's segments (a fit file's record of
    verification is not taken on trust when the data is at hand)."""
    from ratfit.io.fitfile import segment_check

    return segment_check(fit.saved, seg)


def write_report(fit_path: str | os.PathLike[str], data_path: str | os.PathLike[str] | None,
                 outdir: str | os.PathLike[str], *, models: tuple[str, ...] = ("lambert+ggx",),
                 size: int = 96, style: PlotStyle = DEFAULT_STYLE) -> ReportResult:
    """index.html and its PNGs in ``outdir``; everything is read and checked first.

    ``style``: its ``scale`` (value axes: "auto", "linear" or "log") and ``rel_floor``
    (relative errors are |fit - data| / max(|data|, rel_floor x max |data|)); labels
    and units follow the fit (1/sr and degrees for a BRDF)."""
    from ratfit._version import __version__

    fit = LoadedFit.load(fit_path)
    ds = load_data_for(fit, data_path) if data_path is not None else None
    out = Path(outdir)
    res = ReportResult(out / "index.html")
    style = report_style(fit, style)
    seg = segments_of(fit, ds) if ds is not None else None
    lo = None if seg is None else seg.lo
    hi = None if seg is None else seg.hi
    # metrics first: a failure here leaves no folder behind
    model_fits = []
    if ds is not None:
        if fit.param is not None:
            res.metrics = rational_metrics(fit, ds, style.rel_floor)
            for spec in models:
                mf = model_fit_for(fit.param, ds, spec)
                model_fits.append(mf)
                res.metrics += model_metrics(mf, fit.param, ds, style.rel_floor)
        else:
            res.metrics = _plain_metrics(fit, ds, style.rel_floor)
    if seg is not None:
        res.recheck = recheck(fit, seg)
    # every picture and the page are written into a folder beside ``outdir`` that
    # moves into place only when all of them are written: a full disk midway leaves
    # nothing (an error naming ``outdir``), never half a report
    with atomic_dir(out) as work:
        pics = _pictures(fit, ds, lo, hi, model_fits, res, work, size, style)
        res.pictures = [out / p.name for _, p in pics]
        page = _html(fit, data_path, res, pics, __version__, style)
        (work / res.index.name).write_text(page)
    return res


def report_style(fit: LoadedFit, style: PlotStyle = DEFAULT_STYLE) -> PlotStyle:
    """``style``'s scale and floor with the fit's labels: BRDF values in 1/sr (or
    f cos(theta_l) as an ALTA file gives them) over unitless or angle coordinates;
    other data in the units of its file, which ratfit does not know."""
    from dataclasses import replace

    if fit.is_brdf:
        return replace(style, value_label="BRDF (1/sr)", coord_unit="unitless")
    return replace(style, value_label="value (file units)", coord_unit="file units")


def _scale_note(scale: str, style: PlotStyle) -> str:
    if scale == "log":
        return ("Values on a log axis" + (" (chosen automatically: the values span more than "
                                          "two decades)" if style.scale == "auto" else "")
                + "; samples at or below 0 cannot be drawn there.")
    return ("Values on a linear axis" + (" (chosen automatically: they span at most two "
                                         "decades)" if style.scale == "auto" else "") + ".")


def _pictures(fit: LoadedFit, ds: Dataset | None, lo: Any, hi: Any, model_fits: list,
              res: ReportResult, out: Path, size: int, style: PlotStyle
              ) -> list[tuple[str, Path]]:
    """The report's pictures written into ``out``: (caption, path) each; every
    caption says what the panel shows, its units and scale."""
    from ratfit.viz import pictures as pic

    pics: list[tuple[str, Path]] = []
    dx = None if ds is None else ds.x
    dy = None if ds is None else ds.y
    names = coordinate_names(fit, ds)
    _, xlabel = pic.coord_axis(names[0], style)
    units = ("BRDF values in 1/sr, angles in degrees" if fit.is_brdf else
             "Values and coordinates in the units of the data file")
    for j in range(len(fit.saved.channels)):
        cname = fit.channel_names[j]
        path, scale = pic._slice(fit.saved, out / f"slice_{j}.png", dx, dy, lo, hi, 0, j,
                                 None, None, names, style)
        slab = "" if fit.saved.space.dim == 1 else (
            " The fit is drawn along a line through the data (the other coordinates fixed "
            "as the title says); the dots are the samples on that line or, for scattered "
            "data, within 5 % of it, so a dot may sit off the curve by the fit's change "
            "across that slab.")
        pics.append((f"Channel {cname}: the fit (orange) and the data (blue dots) against "
                     f"{xlabel}, with each sample's allowed segment (grey bars); below, the "
                     f"signed error fit - data inside the allowed band (grey). {units}. "
                     + _scale_note(scale, style) + slab, path))
        if ds is not None:
            assert ds.y is not None
            pics.append((f"Channel {cname}: signed error fit - data at every data point "
                         f"against {xlabel}; grey bars: the allowed error (segment bounds "
                         f"- data). A verified fit keeps every red dot inside its bar.",
                         pic.plot_error(fit.saved, out / f"error_{j}.png", ds.x, ds.y, lo=lo,
                                        hi=hi, channel=j, names=names, style=style)))
            rpath, floor = pic.plot_relative_error(
                fit.saved, out / f"relerr_{j}.png", ds.x, ds.y, lo=lo, hi=hi, channel=j,
                names=names, style=style)
            pics.append((f"Channel {cname}: relative error |fit - data| / max(|data|, floor) "
                         f"at every data point, log axis; floor = {floor:.4g} "
                         f"({style.rel_floor:g} x the channel's largest |data|), so samples "
                         "near zero are measured against the floor instead of blowing up. "
                         "Grey dashes: the allowed half-width on the same scale.", rpath))
    if fit.is_brdf:
        assert fit.param is not None
        cf = ds is not None and cos_factor(ds)
        funcs = {"rational": pic.fit_brdf_function(fit.brdf, cos_factor=cf)}
        for mf in model_fits:
            funcs[mf.name] = mf.eval_dirs
        data_fn = None
        if ds is not None:
            assert ds.y is not None
            data_fn = pic.DataBRDF(ds.x, ds.y, fit.param, cos_factor=cf,
                                   fold_phi_d=bool(ds.meta.get("fold_phi_d")))
        first = fit.channel_names[0]
        slice_scale = "log" if style.scale == "auto" else style.scale
        pics.append((f"Channel {first}: BRDF (1/sr, {slice_scale} axis) against the half "
                     "angle theta_h (deg), one panel per difference angle theta_d (deg), "
                     "phi_d = 90 deg (Rusinkiewicz angles); the rational fit, the analytic "
                     "model(s) fitted to the same data, and (black dots) the nearest data "
                     "sample where one lies near. A curve that stops, or a panel that names "
                     "a fit with no value, is outside that fit's domain: it is the box of "
                     "the data's coordinates, and measured data rarely reach L = V "
                     "(theta_d = 0) or grazing angles, so the fit is not extrapolated there.",
                     pic.plot_brdf_slices(funcs, out / "brdf_slices.png", scale=slice_scale,
                                          data=data_fn)))
        pics.append((f"Channel {first}: BRDF in the plane of incidence, for three incidence "
                     "angles theta_i (deg); the angle of each point is the viewing direction "
                     "(0 = normal, the mirror direction on the side opposite the gold dot, "
                     "which marks the light), its radius the BRDF in 1/sr"
                     + (" on a log scale, four decades down from the largest value drawn"
                        if style.scale == "log" else " on a linear scale" if
                        style.scale == "linear" else " (a log scale, four decades down from "
                        "the largest value drawn, where the fit's values span more than two "
                        "decades; else linear)") + ". Black dots: the nearest data samples; "
                     "open circles on the rim (linear scale): data above the radial range.",
                     pic.plot_polar(funcs, out / "polar.png", data=data_fn,
                                    scale="auto" if style.scale == "auto" else style.scale)))
        imgs = {}
        if data_fn is not None:
            imgs["data"] = pic.render_sphere(data_fn, size=size)
        imgs.update({k: pic.render_sphere(f, size=size) for k, f in funcs.items()})
        pics.append(("A unit sphere under a point light, seen from above by an orthographic "
                     "camera, each pixel the BRDF x cos(theta_l) x irradiance (one exposure "
                     "for all images, 99th percentile to white, gamma 2.2); grey: no value "
                     "(no data sample near, or outside the fit's domain).",
                     pic.plot_spheres(imgs, out / "spheres.png")))
        from ratfit.brdf.albedo import directional_albedo

        alb = directional_albedo(funcs["rational"], n_mu=48, n_phi=96)
        res.albedo = alb.to_dict()
        if np.any(np.isfinite(alb.albedo)):  # else the page says why, with no empty plot
            pics.append(("Directional albedo of the rational fit (the fraction of light from "
                         "incidence theta_i, in degrees, reflected into the hemisphere; "
                         "unitless) per channel; above the red line at 1 the fit would "
                         "create energy.",
                         _plot_albedo(alb, fit.channel_names, out / "albedo.png")))
    return pics


def _plain_metrics(fit: LoadedFit, ds: Dataset, rel_floor: float = REL_FLOOR
                   ) -> list[dict[str, Any]]:
    from ratfit.brdf.analytic_models import channel_metrics

    assert ds.y is not None
    pred = fit.saved(ds.x)
    out: list[dict[str, Any]] = []
    for j, ch in enumerate(fit.saved.channels):
        out.append({**floored(channel_metrics(pred[:, j], ds.y[:, j]), pred[:, j], ds.y[:, j],
                              rel_floor), "name": "rational",
                    "channel": ch.name, "coefficients": ch.rational.total,
                    "detail": f"n={ch.rational.n}, m={ch.rational.m}"})
    return out


def _coverage_note(alb: dict[str, Any]) -> str:
    cov = [c for c in np.ravel(alb.get("coverage") or []) if c is not None]
    if not cov or min(cov) >= 0.999:
        return ""
    return (f"; computed only over the part of the hemisphere inside the fit's domain "
            f"(down to {100 * min(cov):.0f} % of it), so energy outside is not counted")


def _num(v: Any) -> str:
    """A metric for people: 4 significant digits, not 16."""
    if v is None:
        return "-"
    try:
        return f"{float(v):.4g}"
    except (TypeError, ValueError):
        return html.escape(str(v))


def _plot_albedo(alb, names: list[str], path: Path) -> Path:
    from ratfit.viz._figures import plain
    from ratfit.viz.pictures import _plt, _save

    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 3.5))
    for j, n in enumerate(names):
        ax.plot(np.degrees(alb.theta_i), alb.albedo[:, j], ".-", label=plain(n))
    ax.axhline(1.0, color="r", lw=0.8, ls="--", label="energy limit")
    ax.set_xlabel("incidence theta_i (deg)")
    ax.set_ylabel("directional albedo (unitless)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def _metrics_note(res: ReportResult, style: PlotStyle, unit: str) -> str:
    """What each metric means, with the relative-error floor of each channel."""
    floors: dict[str, float] = {}
    for m in res.metrics:
        if m.get("rel_floor") is not None:
            floors.setdefault(str(m["channel"]), float(m["rel_floor"]))
    said = ", ".join(f"{c}: {v:.4g}{unit}" for c, v in floors.items())
    return ("RMSE = sqrt(mean((fit - data)^2)); rel. RMSE = sqrt(mean((|fit - data| / "
            f"max(|data|, floor))^2)) with floor = {style.rel_floor:g} x the channel's "
            f"largest |data|" + (f" ({said})" if said else "") + ", so near-zero samples do "
            "not decide it; max rel. error: the largest of those ratios; log RMSE: the RMSE "
            "of log(1 + fit) - log(1 + data); cos RMSE weighs each error by cos(theta_l); "
            "Linf = max |fit - data|. Without --data no relative error is shown.")


def _html(fit: LoadedFit, data_path, res: ReportResult, pics, version: str,
          style: PlotStyle) -> str:
    e = html.escape
    rows = compare_table(res.metrics)
    unit = " (1/sr)" if fit.is_brdf else ""
    head = ["fit", "channel", "coefficients", f"RMSE{unit}", "rel. RMSE (floored)",
            "log RMSE", f"Linf{unit}", f"cos RMSE{unit}", "parameters"]
    table = ""
    if rows:
        table = ("<table><tr>" + "".join(f"<th>{e(h)}</th>" for h in head) + "</tr>"
                 + "".join("<tr>" + "".join(f"<td>{e(c)}</td>" for c in r) + "</tr>"
                           for r in rows) + "</table>")
    # the largest relative error on the data, floored; without data none is shown (the
    # fit file's own figure divides by |y| alone, so near-zero samples decide it)
    max_rel = {str(m["channel"]): m.get("max_rel") for m in res.metrics
               if m.get("name") == "rational"}
    diag = ("<table><tr><th>channel</th><th>n</th><th>m</th><th>verified</th>"
            f"<th>max violation{e(unit)}</th><th>Linf{e(unit)}</th>"
            "<th>max rel. error (floored)</th></tr>")
    sealed = getattr(fit.saved, "integrity", "sealed") == "sealed"
    sub = subset_of(fit.saved)
    for ch in fit.saved.channels:
        s = ch.summary
        ok = s.get("verified") is True and sealed
        said = "NO" if not ok else "yes" if sub is None else (
            f"on a subset of {sub[0]} of {sub[1]} samples" if sub[0] else "on a subset")
        diag += (f"<tr><td>{e(ch.name)}</td><td>{ch.rational.n}</td><td>{ch.rational.m}</td>"
                 f"<td>{e(said)}</td>"
                 f"<td>{_num(s.get('max_violation'))}</td><td>{_num(s.get('linf'))}</td>"
                 f"<td>{_num(max_rel.get(ch.name))}</td></tr>")
    diag += "</table>"
    if sealed:
        diag += f"<p>{e(scope_text(fit.saved, reprove_saved(fit.saved)))}</p>"
    if getattr(fit.saved, "integrity", "sealed") == "alta":
        diag += ("<p class='bad'>An ALTA function file: ratfit holds no verification record "
                 "for it; the metrics compare it with the data only.</p>")
    elif not sealed:
        diag += ("<p class='bad'>The fit file was edited after ratfit wrote it (or predates "
                 "content digests): its verification record is not trusted.</p>")
    if res.recheck is not None:
        diag += "<p>Checked again on the data's segments: " + "; ".join(
            f"{e(n)}: {met} of {tot} met" + (
                "" if met == tot else f", <b class='bad'>worst violation {_num(w)}</b>")
            for n, met, tot, w in res.recheck) + ".</p>"
    alb = ""
    if res.albedo is not None:
        mx = res.albedo["max_albedo"]
        if mx is None or not np.isfinite(mx):
            alb = ("<p>Directional albedo: not available (the fit's domain does not cover "
                   "the hemisphere; no energy check).</p>")
        else:
            alb = (f"<p>Maximum directional albedo: {mx:.4g}"
                   + (" &mdash; <b class='bad'>reflects more than it receives</b>"
                      if res.albedo["flagged"] else " (at most 1: energy check passed)")
                   + _coverage_note(res.albedo) + "</p>")
    figs = "".join(
        f"<figure><img src='{e(p.name)}' alt='{e(cap)}'><figcaption>{e(cap)}</figcaption>"
        "</figure>" for cap, p in pics)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>ratfit report: {e(Path(fit.path).name)}</title>
<style>
body {{ font-family: sans-serif; margin: 2em; max-width: 1200px; }}
table {{ border-collapse: collapse; margin: 1em 0; }}
td, th {{ border: 1px solid #bbb; padding: 3px 8px; text-align: right; }}
figure {{ margin: 1.5em 0; }} img {{ max-width: 100%; }} .bad {{ color: #b00; }}
</style></head><body>
<h1>ratfit report</h1>
<p>Fit <code>{e(str(fit.path))}</code>{f" (BRDF, parametrization {e(fit.param)})" if fit.param
    else ""}; data <code>{e(str(data_path)) if data_path else "none"}</code>;
basis {e(fit.saved.space.family.name)}, {fit.saved.space.dim} variable(s). ratfit {e(version)}.</p>
<h2>Fit diagnostics</h2>{diag}
<h2>Metrics on the data</h2>{table or "<p>No data given.</p>"}
<p>{e(_metrics_note(res, style, unit))}</p>
{alb}
<h2>Pictures</h2>{figs}
</body></html>
"""
