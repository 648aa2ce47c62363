"""Pictures people look at before they trust numbers (matplotlib Agg, atomic PNG).

* :func:`plot_slice`: a fit and its data along one coordinate, with the signed
  error and the allowed band below (the seed's Figures 2 and 3, in n-D on a
  slice through the data).
* :func:`plot_error`: the signed error at every data point.
* :func:`plot_brdf_slices`: BRDF against theta_h for several theta_d (phi_d = 90 deg).
* :func:`plot_polar`: BRDF in the plane of incidence, for several incidences.
* :func:`render_sphere` / :func:`plot_spheres`: a sphere under a point light seen
  by an orthographic camera, the BRDF evaluated per pixel; several BRDFs (data,
  rational fit, analytic fit) side by side with one exposure.

A BRDF here is any callable ``f(L, V) -> (N, k)`` on unit directions in the local
frame; NaN marks "unknown" (outside a fit's domain, away from data samples) and
is drawn grey. :class:`DataBRDF` turns samples into such a callable and
:func:`fit_brdf_function` a saved fit with its parametrization.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit._atomic import atomic_path
from ratfit.errors import InputError
from ratfit.io.fitfile import SavedFit
from ratfit.viz._figures import plain

__all__ = [
    "DataBRDF",
    "fit_brdf_function",
    "plot_brdf_slices",
    "plot_error",
    "PlotStyle",
    "plot_polar",
    "plot_relative_error",
    "plot_slice",
    "plot_spheres",
    "render_sphere",
    "rusin_dirs",
]

Array = NDArray[np.float64]
BRDFFunction = Callable[[Array, Array], Array]


# ---------------------------------------------------------------------------- plumbing
def _plt():
    """Figure factory on a private Agg canvas: the user's pyplot backend is left alone."""
    from ratfit.viz import _figures

    return _figures


def _save(fig, path: str | Path, dpi: int = 100) -> Path:
    plt = _plt()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)
    plt.close(fig)
    return Path(path)


def rusin_dirs(th: ArrayLike, td: ArrayLike, pd: ArrayLike) -> tuple[Array, Array]:
    """Directions for Rusinkiewicz angles (phi_h = 0); rows below the horizon are NaN."""
    th, td, pd = np.broadcast_arrays(*(np.asarray(a, dtype=float) for a in (th, td, pd)))
    th, td, pd = th.ravel(), td.ravel(), pd.ravel()
    d = np.stack([np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)], axis=1)
    c, s = np.cos(th), np.sin(th)
    L = np.stack([c * d[:, 0] + s * d[:, 2], d[:, 1], -s * d[:, 0] + c * d[:, 2]], axis=1)
    h = np.stack([s, np.zeros_like(s), c], axis=1)
    V = 2.0 * np.einsum("ij,ij->i", L, h)[:, None] * h - L
    bad = (L[:, 2] <= 0) | (V[:, 2] <= 0)
    L[bad] = np.nan
    V[bad] = np.nan
    return L, V


def _eval_masked(fn: BRDFFunction, L: Array, V: Array, k: int | None = None) -> Array:
    """fn on the rows that are valid directions above the horizon; NaN elsewhere."""
    ok = np.all(np.isfinite(L), axis=1) & np.all(np.isfinite(V), axis=1)
    ok &= (L[:, 2] > 1e-9) & (V[:, 2] > 1e-9) if L.size else ok
    out = None
    if ok.any():
        vals = np.asarray(fn(L[ok], V[ok]), dtype=float)
        if vals.ndim == 1:
            vals = vals[:, None]
        out = np.full((L.shape[0], vals.shape[1]), np.nan)
        out[ok] = vals
    if out is None:
        out = np.full((L.shape[0], k or 1), np.nan)
    return out


def fit_brdf_function(fit: Any, *, clip: bool = True, cos_factor: bool = False
                      ) -> BRDFFunction:
    """A :class:`ratfit.brdf.fitter.BRDFFit` as f(L, V), NaN outside the fit's domain.

    ``cos_factor``: the fitted values are f cos(theta_l) as the data file gives them
    (ALTA's INV_STERADIAN_COSINE_FACTOR); divide by cos(theta_l) to get the BRDF.
    """
    from ratfit.brdf.parametrizations import fold_phi_d, get_parametrization

    par = get_parametrization(fit.parametrization)
    dom = fit.saved.space.domain
    fold = bool(getattr(fit, "fold_phi_d", False)) and par.name == "RUSIN_TH_TD_PD"

    def f(L: Array, V: Array) -> Array:
        vals = np.array(fit.eval_dirs(L, V), dtype=float)
        if clip:
            x = par.from_dirs(L, V)
            if fold:
                x[:, 2] = fold_phi_d(x[:, 2], x[:, 0], x[:, 1])
            pad = 1e-9 * (dom[:, 1] - dom[:, 0])
            inside = np.all((x >= dom[:, 0] - pad) & (x <= dom[:, 1] + pad), axis=1)
            vals[~inside] = np.nan
        if cos_factor:
            vals = vals / np.maximum(np.asarray(L)[:, 2:3], 1e-6)
        return vals

    return f


class DataBRDF:
    """BRDF samples as a function of directions: linear interpolation in the data's
    coordinates (nearest sample where the simplex search fails), NaN where the nearest
    sample is farther than ``radius`` (default: 2.5 x the median sample spacing).
    """

    def __init__(self, coords: ArrayLike, values: ArrayLike, parametrization: str, *,
                 method: str = "linear", radius: float | None = None,
                 fold_phi_d: bool = False, cos_factor: bool = False) -> None:
        from scipy.spatial import cKDTree

        from ratfit.brdf.parametrizations import get_parametrization

        self.param = get_parametrization(parametrization)
        x = np.asarray(coords, dtype=float)
        y = np.asarray(values, dtype=float)
        if y.ndim == 1:
            y = y[:, None]
        if x.ndim != 2 or x.shape[1] != self.param.dim or y.shape[0] != x.shape[0]:
            raise InputError(f"data coordinates {x.shape} / values {y.shape} do not match "
                             f"{self.param.name} ({self.param.dim} coordinates)")
        if method not in ("linear", "nearest"):
            raise InputError(f"method must be 'linear' or 'nearest', got {method!r}")
        self.x, self.y, self.method = x, y, method
        self.fold = fold_phi_d
        self.cos_factor = cos_factor
        self._lo = x.min(axis=0)
        span = x.max(axis=0) - self._lo
        self._span = np.where(span > 0, span, 1.0)
        self._tree = cKDTree(self._unit(x))
        if radius is None:
            dist, _ = self._tree.query(self._unit(x), k=2)
            radius = 2.5 * float(np.median(dist[:, 1]))
        self.radius = float(radius)
        self._interp = None

    def _unit(self, x: Array) -> Array:
        return (x - self._lo) / self._span

    def _linear(self):
        if self._interp is None:
            from scipy.interpolate import LinearNDInterpolator

            self._interp = LinearNDInterpolator(self._unit(self.x), self.y)
        return self._interp

    def coords(self, L: Array, V: Array) -> Array:
        from ratfit.brdf.parametrizations import fold_phi_d

        x = self.param.from_dirs(L, V)
        if self.fold and self.param.name == "RUSIN_TH_TD_PD":
            x[:, 2] = fold_phi_d(x[:, 2], x[:, 0], x[:, 1])
        return x

    def dense(self, L: Array, V: Array) -> NDArray[np.bool_]:
        """True where a data sample lies within ``radius`` of the query."""
        d, _ = self._tree.query(self._unit(self.coords(L, V)))
        return d <= self.radius

    def __call__(self, L: Array, V: Array) -> Array:
        u = self._unit(self.coords(L, V))
        d, i = self._tree.query(u)
        if self.method == "nearest" or self.param.dim == 1:
            vals = self.y[i].copy()
        else:
            vals = np.asarray(self._linear()(u), dtype=float)
            miss = ~np.all(np.isfinite(vals), axis=1)
            vals[miss] = self.y[i[miss]]
        vals[d > self.radius] = np.nan
        if self.cos_factor:
            vals = vals / np.maximum(np.asarray(L)[:, 2:3], 1e-6)
        return vals


# ---------------------------------------------------------------------------- style
SCALES = ("auto", "linear", "log")
# "auto" draws values on a log axis when their positive part spans more than this
# ratio (two decades): a specular peak or an exponential decay then stays readable
AUTO_LOG_SPAN = 100.0
# relative errors divide by max(|y|, floor) with floor = REL_FLOOR x the channel's
# largest |y|: near-zero data (a blue paint's red channel) would otherwise turn a tiny
# absolute error into a relative one of thousands
REL_FLOOR = 1e-3


@dataclass(frozen=True)
class PlotStyle:
    """How a picture labels and scales what it shows.

    ``value_label``: the y axis (with its unit); ``coord_unit``: the unit of
    coordinates that are not angles (angles, coordinates named theta_* or phi_*,
    are stored in radians and always drawn in degrees); ``scale``: "linear", "log"
    or "auto" (log when the positive values span more than :data:`AUTO_LOG_SPAN`);
    ``rel_floor``: relative errors are |r - y| / max(|y|, rel_floor x max |y|).
    """

    value_label: str = "y (file units)"
    coord_unit: str = "file units"
    scale: str = "auto"
    rel_floor: float = REL_FLOOR

    def __post_init__(self) -> None:
        if self.scale not in SCALES:
            raise InputError(f"scale must be one of {', '.join(SCALES)}, got {self.scale!r}")
        if not (np.isfinite(self.rel_floor) and 0.0 < self.rel_floor < 1.0):
            raise InputError(f"the relative-error floor must be in (0, 1), got {self.rel_floor!r}")


DEFAULT_STYLE = PlotStyle()
BRDF_STYLE = PlotStyle(value_label="BRDF (1/sr)", coord_unit="unitless")


def is_angle(name: str) -> bool:
    """Coordinates named theta_*, phi_* or delta_phi are angles in radians."""
    n = str(name).lower()
    return n.startswith(("theta", "phi", "delta_phi"))


def coord_axis(name: str, style: PlotStyle) -> tuple[float, str]:
    """(factor from stored to drawn values, axis label with unit) of a coordinate."""
    if is_angle(name):
        return 180.0 / np.pi, f"{plain(name)} (deg)"
    return 1.0, f"{plain(name)} ({plain(style.coord_unit)})"


def resolve_scale(values: ArrayLike, scale: str) -> str:
    """The scale "auto" stands for on these values: "log" when their positive part
    spans more than :data:`AUTO_LOG_SPAN`, else "linear"."""
    if scale != "auto":
        return scale
    v = np.asarray(values, dtype=float)
    pos = v[np.isfinite(v) & (v > 0)]
    if pos.size < 2:
        return "linear"
    return "log" if float(pos.max()) > AUTO_LOG_SPAN * float(pos.min()) else "linear"


def rel_floor_value(y: ArrayLike, rel_floor: float = REL_FLOOR) -> float:
    """The absolute floor of relative errors: ``rel_floor`` x max |y| (1 if y is all 0)."""
    a = np.abs(np.asarray(y, dtype=float))
    a = a[np.isfinite(a)]
    top = float(a.max()) if a.size else 0.0
    return rel_floor * top if top > 0 else 1.0


def relative_error(pred: ArrayLike, y: ArrayLike, floor: float) -> Array:
    """|pred - y| / max(|y|, floor), elementwise."""
    p = np.asarray(pred, dtype=float)
    t = np.asarray(y, dtype=float)
    return np.abs(p - t) / np.maximum(np.abs(t), floor)


def _log_safe(v: Array) -> Array:
    """Values for a log axis: those <= 0 become NaN (not drawn)."""
    v = np.asarray(v, dtype=float)
    return np.where(v > 0, v, np.nan)


# ---------------------------------------------------------------------------- 1-D slices
# A slice shows data "on the line" when at least this many samples share the other
# coordinates exactly; scattered data (a goniometer's Cornell samples in the
# half-vector frame) has one or two there, and gets the samples of a slab instead.
SLICE_MIN_POINTS = 8
SLICE_SLAB = 0.05  # half-width of that slab, as a fraction of each other axis's span


def _slice_rows(x: Array, dim: int,
                at: Array | None) -> tuple[NDArray[np.bool_], Array, float]:
    """Data rows on the line through ``at`` along ``dim`` (n-D), that point, and the
    slab's half-width (a fraction of each other axis's span; 0: exactly on the line).

    Without ``at``: the line the most samples lie on (ties: nearest the median
    point); where no line holds :data:`SLICE_MIN_POINTS`, the slab of half-width
    :data:`SLICE_SLAB` around a sample that holds the most samples."""
    if x.shape[1] == 1:
        return np.ones(x.shape[0], bool), x[0], 0.0
    others = [k for k in range(x.shape[1]) if k != dim]
    span = np.ptp(x, axis=0)
    span[span == 0] = 1.0
    t = x[:, others] / span[others]
    if at is not None:
        close = np.all(np.abs(t - at[others] / span[others]) <= 1e-6, axis=1)
        return close, at, 0.0
    centre = np.median(t, axis=0)
    key = np.round(t * 1e6).astype(np.int64)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    size = counts[inverse]  # how many samples share each sample's line
    dist = np.sum((t - centre) ** 2, axis=1)
    if size.max() >= SLICE_MIN_POINTS:
        i = int(np.lexsort((dist, -size))[0])
        return inverse == inverse[i], x[i], 0.0
    # scattered: the slab around a sample (the 256 nearest the median point tried)
    cand = np.argsort(dist)[:256]
    inside = [np.all(np.abs(t - t[i]) <= SLICE_SLAB, axis=1) for i in cand]
    best = int(np.argmax([int(m.sum()) for m in inside]))
    return inside[best], x[cand[best]], SLICE_SLAB


def plot_slice(saved: SavedFit, path: str | Path, *, x: ArrayLike | None = None,
               y: ArrayLike | None = None, lo: ArrayLike | None = None,
               hi: ArrayLike | None = None, dim: int = 0, channel: int = 0,
               at: ArrayLike | None = None, title: str | None = None,
               names: Sequence[str] | None = None, style: PlotStyle = PlotStyle()) -> Path:
    """Fit vs data along coordinate ``dim`` and the signed error (r - y) with the band.

    ``names``: the coordinates' names (a parametrization's, or the data's columns);
    ``style``: labels, units and the value axis's scale (see :class:`PlotStyle`)."""
    return _slice(saved, path, x, y, lo, hi, dim, channel, at, title, names, style)[0]


def _slice(saved: SavedFit, path: str | Path, x: ArrayLike | None, y: ArrayLike | None,
           lo: ArrayLike | None, hi: ArrayLike | None, dim: int, channel: int,
           at: ArrayLike | None, title: str | None, names: Sequence[str] | None,
           style: PlotStyle) -> tuple[Path, str]:
    """:func:`plot_slice`, also returning the value scale drawn ("linear" or "log")."""
    plt = _plt()
    d = saved.space.dim
    if not 0 <= dim < d:
        raise InputError(f"slice dimension {dim} out of range for a {d}-D fit")
    if not 0 <= channel < len(saved.channels):
        raise InputError(f"channel {channel} out of range ({len(saved.channels)} channel(s))")
    dom = saved.space.domain
    xa = None if x is None else np.asarray(x, dtype=float).reshape(-1, d)
    at_pt = None if at is None else np.asarray(at, dtype=float)
    slab = 0.0
    if xa is not None:
        rows, at_pt, slab = _slice_rows(xa, dim, at_pt)
    else:
        rows = None
        at_pt = dom.mean(axis=1) if at_pt is None else at_pt
    cnames = _names(names, d)
    factor, xlabel = coord_axis(cnames[dim], style)
    grid = np.linspace(dom[dim, 0], dom[dim, 1], 600)
    pts = np.tile(at_pt, (grid.size, 1))
    pts[:, dim] = grid
    curve = np.asarray(saved.channel_values(channel, pts), dtype=float).ravel()
    fig, axes = plt.subplots(2, 1, figsize=(8, 6), sharex=True,
                             gridspec_kw={"height_ratios": [3, 2]})
    shown = [curve]
    hidden = 0
    ya_rows = None
    if xa is not None and y is not None and rows is not None:
        ya = np.asarray(y, dtype=float).reshape(xa.shape[0], -1)[:, channel]
        ya_rows = ya[rows]
        shown.append(ya_rows)
    scale = resolve_scale(np.concatenate(shown), style.scale)
    draw = _log_safe if scale == "log" else (lambda v: v)
    axes[0].plot(grid * factor, draw(curve), lw=1.6, color="C1", label="rational fit", zorder=3)
    if xa is not None and ya_rows is not None and rows is not None:
        xs = xa[rows, dim]
        order = np.argsort(xs)
        xs, ys = xs[order], ya_rows[order]
        if lo is not None and hi is not None:
            la = np.asarray(lo, dtype=float).reshape(xa.shape[0], -1)[rows, channel][order]
            ha = np.asarray(hi, dtype=float).reshape(xa.shape[0], -1)[rows, channel][order]
            lshow = la
            if scale == "log":  # a segment reaching 0 is drawn down to the axis's bottom
                pos = ys[ys > 0]
                lshow = np.maximum(la, 0.5 * float(pos.min())) if pos.size else la
            axes[0].vlines(xs * factor, lshow, ha, color="0.6", lw=1,
                           label="segments (allowed values)")
            axes[1].fill_between(xs * factor, la - ys, ha - ys, color="0.85", step="mid",
                                 label="allowed")
        if scale == "log":
            hidden = int(np.sum(~(ys > 0)))
        what = (f"data within {slab:.0%} of the line ({xs.size})" if slab
                else f"data ({xs.size})")
        if hidden:
            what += f"; {hidden} at or below 0 not drawn"
        axes[0].plot(xs * factor, draw(ys), ".", ms=3, color="C0", label=what)
        err = np.asarray(saved.channel_values(channel, xa[rows][order]), dtype=float).ravel() - ys
        axes[1].plot(xs * factor, err, ".-", ms=3, lw=0.8, color="C3", label="r - y")
        axes[1].axhline(0.0, color="k", lw=0.5)
        axes[1].legend(fontsize=8)
    if scale == "log":
        axes[0].set_yscale("log")
    names_p = [plain(n) for n in cnames]  # text from files: never mathtext
    chan = plain(saved.channels[channel].name)

    def at_text(k: int) -> str:
        f, _ = coord_axis(cnames[k], style)
        return f"{names_p[k]} = {at_pt[k] * f:.4g}" + (" deg" if is_angle(cnames[k]) else "")

    where = ", ".join(at_text(k) for k in range(d) if k != dim)
    axes[0].set_title(plain(title) if title else f"channel {chan}"
                      + (f" along {names_p[dim]} at {where}" if where else "")
                      + ("\n(fit on the line; data and errors of the samples near it)"
                         if slab else ""), fontsize=10)
    axes[0].set_ylabel(f"{chan}: {plain(style.value_label)}"
                       + (" (log scale)" if scale == "log" else ""))
    axes[0].legend(fontsize=8)
    axes[1].set_xlabel(xlabel)
    axes[1].set_ylabel(f"signed error r - y\n{_unit_of(style)}")
    fig.tight_layout()
    return _save(fig, path), scale


def _unit_of(style: PlotStyle) -> str:
    """The unit in a value label "name (unit)", in parentheses; "" when it names none."""
    lab = plain(style.value_label)
    i = lab.rfind("(")
    return lab[i:] if i >= 0 and lab.endswith(")") else ""


def plot_error(saved: SavedFit, path: str | Path, x: ArrayLike, y: ArrayLike, *,
               lo: ArrayLike | None = None, hi: ArrayLike | None = None, dim: int = 0,
               channel: int = 0, names: Sequence[str] | None = None,
               style: PlotStyle = PlotStyle()) -> Path:
    """Signed error r - y at every data point against coordinate ``dim``, with the band."""
    plt = _plt()
    d = saved.space.dim
    xa = np.asarray(x, dtype=float).reshape(-1, d)
    ya = np.asarray(y, dtype=float).reshape(xa.shape[0], -1)[:, channel]
    err = np.asarray(saved.channel_values(channel, xa), dtype=float).ravel() - ya
    factor, xlabel = coord_axis(_names(names, d)[dim], style)
    fig, ax = plt.subplots(figsize=(8, 4))
    xs = xa[:, dim] * factor
    if lo is not None and hi is not None:
        la = np.asarray(lo, dtype=float).reshape(xa.shape[0], -1)[:, channel] - ya
        ha = np.asarray(hi, dtype=float).reshape(xa.shape[0], -1)[:, channel] - ya
        ax.vlines(xs, la, ha, color="0.8", lw=2, label="allowed (segment - y)")
    ax.plot(xs, err, ".", ms=3, color="C3", label="r - y")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(f"signed error r - y {_unit_of(style)}")
    ax.set_title(f"channel {plain(saved.channels[channel].name)}: signed error at "
                 f"{xa.shape[0]} points "
                 f"(max |r - y| = {np.max(np.abs(err)):.3g})")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def plot_relative_error(saved: SavedFit, path: str | Path, x: ArrayLike, y: ArrayLike, *,
                        lo: ArrayLike | None = None, hi: ArrayLike | None = None,
                        dim: int = 0, channel: int = 0, names: Sequence[str] | None = None,
                        style: PlotStyle = PlotStyle()) -> tuple[Path, float]:
    """Relative error |r - y| / max(|y|, floor) at every data point (log axis), with
    the allowed relative half-width; floor = ``style.rel_floor`` x max |y|, stated in
    the title. Returns the path and the floor."""
    plt = _plt()
    d = saved.space.dim
    xa = np.asarray(x, dtype=float).reshape(-1, d)
    ya = np.asarray(y, dtype=float).reshape(xa.shape[0], -1)[:, channel]
    floor = rel_floor_value(ya, style.rel_floor)
    rel = relative_error(saved.channel_values(channel, xa), ya, floor)
    factor, xlabel = coord_axis(_names(names, d)[dim], style)
    xs = xa[:, dim] * factor
    fig, ax = plt.subplots(figsize=(8, 4))
    if lo is not None and hi is not None:
        la = np.asarray(lo, dtype=float).reshape(xa.shape[0], -1)[:, channel]
        ha = np.asarray(hi, dtype=float).reshape(xa.shape[0], -1)[:, channel]
        band = np.maximum(ha - ya, ya - la) / np.maximum(np.abs(ya), floor)
        ax.plot(xs, _log_safe(band), "_", ms=6, color="0.55",
                label="allowed: segment half-width / max(|y|, floor)")
    exact = int(np.sum(rel == 0))
    ax.plot(xs, _log_safe(rel), ".", ms=3, color="C3",
            label="|r - y| / max(|y|, floor)" + (f" ({exact} exact, not drawn)" if exact
                                                 else ""))
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("relative error (log scale)")
    ax.set_title(f"channel {plain(saved.channels[channel].name)}: relative error, floor "
                 f"{floor:.3g} = {style.rel_floor:g} x max |y| (max {np.max(rel):.3g})",
                 fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path), floor


def _names(names: Sequence[str] | None, d: int) -> list[str]:
    if names is not None and len(names) == d:
        return [str(n) for n in names]
    return [f"x{k}" for k in range(d)]


# ---------------------------------------------------------------------------- BRDF views
def plot_brdf_slices(funcs: dict[str, BRDFFunction], path: str | Path, *,
                     theta_d_deg: Sequence[float] = (0, 15, 30, 45, 60, 75),
                     channel: int = 0, scale: str = "log", value_label: str = "BRDF (1/sr)",
                     data: BRDFFunction | None = None) -> Path:
    """BRDF vs theta_h for several theta_d (phi_d = 90 deg), one panel per theta_d.

    ``scale``: "log", "linear" or "auto" (:func:`resolve_scale` on all values drawn).
    A function with no value in a panel (outside a fit's domain: measured data rarely
    reach theta_d = 0, where L = V) is named in that panel, not silently left out.
    ``data``: measured samples (a :class:`DataBRDF`), dots where a sample lies near."""
    plt = _plt()
    th_deg = np.linspace(0.0, 89.5, 300)
    th = np.radians(th_deg)
    n = len(theta_d_deg)
    cols = min(3, n)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 3.3 * rows), squeeze=False)
    styles = ["-", "--", ":", "-."]
    panels = []
    for tdd in theta_d_deg:
        L, V = rusin_dirs(th, np.radians(tdd), np.pi / 2)
        vals = {name: _eval_masked(fn, L, V)[:, min(channel, _nch(fn, L, V) - 1)]
                for name, fn in funcs.items()}
        dv = None
        if data is not None:
            dv = _eval_masked(data, L, V)
            dv = dv[:, min(channel, dv.shape[1] - 1)]
        panels.append((tdd, vals, dv))
    allv = np.concatenate([v for _, vals, dv in panels
                           for v in [*vals.values(), *([] if dv is None else [dv])]])
    scale = resolve_scale(allv, scale)
    draw = _log_safe if scale == "log" else (lambda v: v)
    handles: dict[str, Any] = {}
    for a, (tdd, vals, dv) in zip(axes.flat, panels, strict=False):
        missing = []
        for i, (name, v) in enumerate(vals.items()):
            if not np.any(np.isfinite(draw(v))):
                missing.append(plain(name))
            (h,) = a.plot(th_deg, draw(v), styles[i % 4], lw=1.6 if i == 0 else 1.2,
                          color=f"C{i}", label=plain(name))
            handles.setdefault(plain(name), h)
        if dv is not None and np.any(np.isfinite(draw(dv))):
            (h,) = a.plot(th_deg[::6], draw(dv)[::6], ".", ms=3, color="k",
                          label="data (nearest sample)")
            handles.setdefault("data (nearest sample)", h)
        if missing:
            a.text(0.5, 0.04, "no value here: " + ", ".join(missing)
                   + "\n(outside the fit's domain: no data at this theta_d)",
                   transform=a.transAxes, ha="center", va="bottom", fontsize=7, color="0.25")
        a.set_title(f"theta_d = {tdd:g} deg, phi_d = 90 deg", fontsize=9)
        a.set_xlabel("theta_h (deg)")
        a.set_xlim(0, 90)
        if scale == "log":
            a.set_yscale("log")
    for a in list(axes.flat)[n:]:
        a.set_visible(False)
    for a in axes[:, 0]:
        a.set_ylabel(plain(value_label) + (" (log scale)" if scale == "log" else ""))
    fig.legend(list(handles.values()), list(handles), loc="lower center",
               ncol=max(1, len(handles)), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    return _save(fig, path)


def _nch(fn: BRDFFunction, L: Array, V: Array) -> int:
    ok = np.all(np.isfinite(L), axis=1) & np.all(np.isfinite(V), axis=1)
    if not ok.any():
        return 1
    i = int(np.flatnonzero(ok)[0])
    v = np.asarray(fn(L[i:i + 1], V[i:i + 1]))
    return 1 if v.ndim == 1 else int(v.shape[1])


POLAR_DECADES = 4  # decades of a log radius below the largest value drawn


def plot_polar(funcs: dict[str, BRDFFunction], path: str | Path, *,
               theta_i_deg: Sequence[float] = (0, 30, 60), channel: int = 0,
               data: BRDFFunction | None = None, scale: str = "auto",
               value_label: str = "BRDF (1/sr)") -> Path:
    """BRDF in the plane of incidence: V from -90 (light side) to +90 deg (mirror side).

    The radius is the BRDF ("linear") or its decades ("log": log10 of the value,
    :data:`POLAR_DECADES` decades below the largest value drawn, so a diffuse floor
    and a specular peak both show); "auto" picks log when the fitted values span
    more than :data:`AUTO_LOG_SPAN`. On a linear radius the range comes from the
    fitted curves (a data outlier would shrink them to a dot): a data sample beyond
    it is drawn on the rim as an open circle. ``data``: the measured
    samples (e.g. a :class:`DataBRDF`), drawn as dots where a sample lies near the
    plane."""
    from matplotlib.ticker import FixedLocator, MaxNLocator

    plt = _plt()
    tv_deg = np.linspace(-89.0, 89.0, 357)
    tv = np.radians(tv_deg)
    fig, axes = plt.subplots(1, len(theta_i_deg), figsize=(4.6 * len(theta_i_deg), 3.9),
                             subplot_kw={"projection": "polar"}, squeeze=False)
    styles = ["-", "--", ":", "-."]
    rows = []
    for tid in theta_i_deg:
        ti = np.radians(tid)
        L = np.tile([np.sin(ti), 0.0, np.cos(ti)], (tv.size, 1))
        V = np.stack([-np.sin(tv), np.zeros_like(tv), np.cos(tv)], axis=1)
        vals = {}
        for name, fn in funcs.items():
            v = _eval_masked(fn, L, V)
            vals[name] = v[:, min(channel, v.shape[1] - 1)]
        dv = None
        if data is not None:
            dv = _eval_masked(data, L, V)
            dv = dv[:, min(channel, dv.shape[1] - 1)]
        rows.append((tid, vals, dv))
    fitted = np.concatenate([v for _, vals, _ in rows for v in vals.values()])
    fin = fitted[np.isfinite(fitted)]
    if not fin.size and data is not None:
        fin = np.concatenate([dv[np.isfinite(dv)] for _, _, dv in rows if dv is not None])
    scale = resolve_scale(fin, scale)
    top = float(fin.max()) if fin.size and fin.max() > 0 else 1.0
    if scale == "log" and data is not None:  # decades are cheap: the data fits in too
        dall = np.concatenate([dv[np.isfinite(dv)] for _, _, dv in rows if dv is not None])
        if dall.size:
            top = max(top, float(dall.max()))
    bottom = 10.0 ** (np.floor(np.log10(top)) - POLAR_DECADES)

    def radius(v: Array) -> Array:
        if scale == "log":
            return np.log10(np.clip(_log_safe(v), bottom, None))
        return v

    r_lo, r_hi = (np.log10(bottom), np.log10(top) + 0.05) if scale == "log" else (0.0,
                                                                                  1.08 * top)
    handles: dict[str, Any] = {}
    for a, (tid, vals, dv) in zip(axes.flat, rows, strict=True):
        shown = False
        for i, (name, v) in enumerate(vals.items()):
            shown = shown or bool(np.any(np.isfinite(v)))
            (h,) = a.plot(tv, np.minimum(radius(v), r_hi), styles[i % 4],
                          lw=2.2 if i == 0 else 1.4, color=f"C{i}", label=plain(name))
            handles.setdefault(plain(name), h)
        if dv is not None:
            rv = radius(dv[::6])
            inside = rv <= r_hi
            (h,) = a.plot(tv[::6][inside], rv[inside], ".", ms=4, color="k",
                          label="data (nearest sample)")
            handles.setdefault("data (nearest sample)", h)
            if np.any(~inside & np.isfinite(rv)):
                (h,) = a.plot(tv[::6][~inside], np.full(int(np.sum(~inside)), r_hi), "o",
                              ms=5, mfc="none", color="k",
                              label="data above the radial range (on the rim)")
                handles.setdefault("data above the radial range (on the rim)", h)
        a.set_theta_zero_location("N")
        a.set_thetamin(-90)
        a.set_thetamax(90)
        a.set_ylim(r_lo, r_hi)
        if scale == "log":
            ticks = np.arange(np.ceil(r_lo), np.floor(r_hi) + 1)
            a.yaxis.set_major_locator(FixedLocator(ticks.tolist()))
            a.set_yticklabels([f"1e{int(t)}" for t in ticks])
        else:
            a.yaxis.set_major_locator(MaxNLocator(3))
        a.tick_params(axis="y", labelsize=7)
        a.set_rlabel_position(90)
        a.plot([-np.radians(tid)], [r_hi], "o", color="gold", ms=9, clip_on=False)
        a.set_title(f"incidence theta_i = {tid:g} deg (gold dot: light)", fontsize=9)
        a.text(0.5, -0.06, "radius: " + plain(value_label)
               + (", log scale" if scale == "log" else ""), transform=a.transAxes,
               ha="center", va="top", fontsize=8, color="0.2")
        if not shown:
            a.text(0.0, r_lo + 0.5 * (r_hi - r_lo), "outside the fit's domain", ha="center",
                   va="center", fontsize=9, color="0.3")
    fig.legend(list(handles.values()), list(handles), loc="lower center",
               ncol=max(1, len(handles)), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    return _save(fig, path)


# ---------------------------------------------------------------------------- spheres
def sphere_geometry(size: int = 128, light: Sequence[float] = (2.0, 1.5, 3.0)
                    ) -> tuple[NDArray[np.bool_], Array, Array, Array]:
    """Pixels on the sphere, local L and V per pixel, and the irradiance factor cos/d^2.

    Orthographic camera along -z (V = +z), unit sphere at the origin, point light at
    ``light``. The tangent frame per pixel is arbitrary: the BRDFs are isotropic.
    """
    if size < 8:
        raise InputError(f"image size must be >= 8, got {size}")
    u = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    X, Y = np.meshgrid(u, -u)
    r2 = X**2 + Y**2
    on = r2 < 1.0
    n = np.stack([X[on], Y[on], np.sqrt(1.0 - r2[on])], axis=1)
    P = n
    lp = np.asarray(light, dtype=float)
    dl = lp - P
    dist2 = np.sum(dl * dl, axis=1)
    Lw = dl / np.sqrt(dist2)[:, None]
    Vw = np.tile([0.0, 0.0, 1.0], (n.shape[0], 1))
    ref = np.where(np.abs(n[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    t = np.cross(ref, n)
    t /= np.linalg.norm(t, axis=1)[:, None]
    b = np.cross(n, t)

    def local(w: Array) -> Array:
        return np.stack([np.sum(w * t, 1), np.sum(w * b, 1), np.sum(w * n, 1)], axis=1)

    Ll, Vl = local(Lw), local(Vw)
    irr = np.maximum(Ll[:, 2], 0.0) / dist2 * float(np.dot(lp, lp))
    return on, Ll, Vl, irr


def render_sphere(fn: BRDFFunction, *, size: int = 128,
                  light: Sequence[float] = (2.0, 1.5, 3.0)) -> Array:
    """Linear radiance image (size, size, k): f(L, V) cos(theta_l) E; NaN = unknown.

    Background pixels are 0; pixels the light does not reach are 0.
    """
    on, Ll, Vl, irr = sphere_geometry(size, light)
    lit = irr > 0
    Lq = np.where(lit[:, None], Ll, np.nan)
    vals = _eval_masked(fn, Lq, Vl)
    vals[~lit] = 0.0
    img = np.zeros((size, size, vals.shape[1]))
    img[on] = vals * irr[:, None]
    return img


def plot_spheres(images: dict[str, Array], path: str | Path, *, exposure: float | None = None,
                 title: str | None = None) -> Path:
    """Rendered spheres side by side with one exposure (99th percentile -> white)."""
    plt = _plt()
    allv = np.concatenate([im[np.isfinite(im)].ravel() for im in images.values()])
    if exposure is None:
        pos = allv[allv > 0]
        exposure = 1.0 / float(np.percentile(pos, 99.0)) if pos.size else 1.0
    fig, axes = plt.subplots(1, len(images), figsize=(3.2 * len(images), 3.6), squeeze=False)
    for a, (name, im) in zip(axes.flat, images.items(), strict=True):
        k = im.shape[2]
        rgb = im[..., :3] if k >= 3 else np.repeat(im[..., :1], 3, axis=2)
        unknown = ~np.all(np.isfinite(rgb), axis=2)
        disp = np.clip(np.nan_to_num(rgb, nan=0.0) * exposure, 0.0, 1.0) ** (1.0 / 2.2)
        disp[unknown] = (0.45, 0.45, 0.5)
        a.imshow(disp, interpolation="nearest")
        a.set_title(plain(name), fontsize=9)
        a.axis("off")
    if title:
        fig.suptitle(plain(title), fontsize=10)
    fig.tight_layout()
    return _save(fig, path)
