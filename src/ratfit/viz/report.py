"""One static HTML page per fit: metrics table, albedo check and pictures (opens offline).

Also the shared plumbing of ``ratfit plot``, ``ratfit report`` and
``ratfit brdf compare``: loading a fit file with its parametrization (if it is a
BRDF fit), reading data in the fit's coordinates, and computing the same
metrics (:func:`ratfit.brdf.analytic_models.channel_metrics`) for rational and analytic fits.
"""

from __future__ import annotations

import html
import os
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

            return brdf_segments(ds, dt=seg.get("dt"), abs_width=seg.get("abs_width"),
                                 floor_rel=seg.get("floor_rel"),
                                 cosine=bool(meta.get("cosine_weighted")), clamp=meta.get("clamp"))
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


def rational_metrics(fit: LoadedFit, ds: Dataset) -> list[dict[str, Any]]:
    from ratfit.brdf.analytic_models import channel_metrics

    assert fit.brdf is not None and fit.param is not None and ds.y is not None
    pred = fit.brdf.eval_coords(ds.x)
    cos_l = data_dirs(fit.param, ds)[0][:, 2]
    out: list[dict[str, Any]] = []
    for j, ch in enumerate(fit.saved.channels):
        out.append({**channel_metrics(pred[:, j], ds.y[:, j], cos_l), "name": "rational",
                    "channel": ch.name, "coefficients": ch.rational.total,
                    "detail": f"n={ch.rational.n}, m={ch.rational.m}"})
    return out


def model_fit_for(param: str, ds: Dataset, spec: str, *, starts: int = 6, seed: int = 0):
    """Fit an analytic model to the data (BRDF values; a cosine factor is divided out)."""
    from ratfit.brdf.analytic_models import Model, fit_model

    L, V = data_dirs(param, ds)
    y = np.asarray(ds.y, dtype=float)
    if cos_factor(ds):
        y = y / np.maximum(L[:, 2:3], 1e-6)
    return fit_model(Model(spec), L, V, y, channel_names=ds.output_names, starts=starts,
                     seed=seed)


def model_metrics(mf, param: str, ds: Dataset) -> list[dict[str, Any]]:
    """Metrics of an analytic fit on the data values as the file gives them."""
    from ratfit.brdf.analytic_models import channel_metrics

    assert ds.y is not None
    L, V = data_dirs(param, ds)
    pred = mf.eval_dirs(L, V)
    if cos_factor(ds):
        pred = pred * L[:, 2:3]
    out: list[dict[str, Any]] = []
    for j in range(ds.n_channels):
        m = channel_metrics(pred[:, min(j, pred.shape[1] - 1)], ds.y[:, j], L[:, 2])
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
                 size: int = 96) -> ReportResult:
    """index.html and its PNGs in ``outdir``; everything is read and checked first."""
    from ratfit._version import __version__

    fit = LoadedFit.load(fit_path)
    ds = load_data_for(fit, data_path) if data_path is not None else None
    out = Path(outdir)
    res = ReportResult(out / "index.html")
    seg = segments_of(fit, ds) if ds is not None else None
    lo = None if seg is None else seg.lo
    hi = None if seg is None else seg.hi
    # metrics first: a failure here leaves no folder behind
    model_fits = []
    if ds is not None:
        if fit.param is not None:
            res.metrics = rational_metrics(fit, ds)
            for spec in models:
                mf = model_fit_for(fit.param, ds, spec)
                model_fits.append(mf)
                res.metrics += model_metrics(mf, fit.param, ds)
        else:
            res.metrics = _plain_metrics(fit, ds)
    if seg is not None:
        res.recheck = recheck(fit, seg)
    # every picture and the page are written into a folder beside ``outdir`` that
    # moves into place only when all of them are written: a full disk midway leaves
    # nothing (an error naming ``outdir``), never half a report
    with atomic_dir(out) as work:
        pics = _pictures(fit, ds, lo, hi, model_fits, res, work, size)
        res.pictures = [out / p.name for _, p in pics]
        page = _html(fit, data_path, res, pics, __version__)
        (work / res.index.name).write_text(page)
    return res


def _pictures(fit: LoadedFit, ds: Dataset | None, lo: Any, hi: Any, model_fits: list,
              res: ReportResult, out: Path, size: int) -> list[tuple[str, Path]]:
    """The report's pictures written into ``out``: (caption, path) each."""
    from ratfit.viz import pictures as pic

    pics: list[tuple[str, Path]] = []
    dx = None if ds is None else ds.x
    dy = None if ds is None else ds.y
    names = coordinate_names(fit, ds)
    for j in range(len(fit.saved.channels)):
        pics.append((f"channel {fit.channel_names[j]}: fit and data along {names[0]}, "
                     "signed error", pic.plot_slice(fit.saved, out / f"slice_{j}.png", x=dx,
                                                    y=dy, lo=lo, hi=hi, channel=j,
                                                    names=names)))
        if ds is not None:
            assert ds.y is not None
            pics.append((f"channel {fit.channel_names[j]}: signed error at every data point",
                         pic.plot_error(fit.saved, out / f"error_{j}.png", ds.x, ds.y, lo=lo,
                                        hi=hi, channel=j, names=names)))
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
        pics.append(("BRDF against theta_h for several theta_d (phi_d = 90 deg)",
                     pic.plot_brdf_slices(funcs, out / "brdf_slices.png")))
        pics.append(("BRDF in the plane of incidence (dots: nearest data samples)"
                     if data_fn is not None else "BRDF in the plane of incidence",
                     pic.plot_polar(funcs, out / "polar.png", data=data_fn)))
        imgs = {}
        if data_fn is not None:
            imgs["data"] = pic.render_sphere(data_fn, size=size)
        imgs.update({k: pic.render_sphere(f, size=size) for k, f in funcs.items()})
        pics.append(("Sphere under a point light (grey: unknown)",
                     pic.plot_spheres(imgs, out / "spheres.png")))
        from ratfit.brdf.albedo import directional_albedo

        alb = directional_albedo(funcs["rational"], n_mu=48, n_phi=96)
        res.albedo = alb.to_dict()
        if np.any(np.isfinite(alb.albedo)):  # else the page says why, with no empty plot
            pics.append(("Directional albedo of the rational fit",
                         _plot_albedo(alb, fit.channel_names, out / "albedo.png")))
    return pics


def _plain_metrics(fit: LoadedFit, ds: Dataset) -> list[dict[str, Any]]:
    from ratfit.brdf.analytic_models import channel_metrics

    assert ds.y is not None
    pred = fit.saved(ds.x)
    out: list[dict[str, Any]] = []
    for j, ch in enumerate(fit.saved.channels):
        out.append({**channel_metrics(pred[:, j], ds.y[:, j]), "name": "rational",
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
    ax.set_ylabel("directional albedo")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def _html(fit: LoadedFit, data_path, res: ReportResult, pics, version: str) -> str:
    e = html.escape
    rows = compare_table(res.metrics)
    head = ["fit", "channel", "coefficients", "RMSE", "rel. RMSE", "log RMSE", "Linf",
            "cos RMSE", "parameters"]
    table = ""
    if rows:
        table = ("<table><tr>" + "".join(f"<th>{e(h)}</th>" for h in head) + "</tr>"
                 + "".join("<tr>" + "".join(f"<td>{e(c)}</td>" for c in r) + "</tr>"
                           for r in rows) + "</table>")
    diag = ("<table><tr><th>channel</th><th>n</th><th>m</th><th>verified</th>"
            "<th>max violation</th><th>Linf</th><th>max rel. error</th></tr>")
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
                 f"<td>{_num(s.get('max_rel_error'))}</td></tr>")
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
<p>RMSE = sqrt(mean((fit - data)^2)); rel. RMSE = sqrt(mean(((fit - data) / data)^2))
over the samples where data != 0; log RMSE: the RMSE of log(1 + fit) - log(1 + data);
cos RMSE weighs each error by cos(theta_l); Linf = max |fit - data|.</p>
{alb}
<h2>Pictures</h2>{figs}
</body></html>
"""
