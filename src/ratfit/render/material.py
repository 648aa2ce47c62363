"""BRDF functions a renderer calls: a ratfit fit, measured data (interpolated), a model.

Each is a callable ``f(L, V) -> (N, 3)`` (linear RGB, 1/sr) on unit directions
in the surface frame (normal +z); both directions must be above the horizon
(callers pass only such rows). Values are finite and non-negative: a fit that
dips below zero between its samples is clamped to 0 at evaluation, and the
fraction of clamped values is kept in ``negative_fraction`` (measured on the
hemisphere grid at load time) so reports can say so.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.brdf.albedo import hemisphere_quadrature
from ratfit.brdf.fitter import BRDFFit, load_brdf_fit
from ratfit.errors import InputError

__all__ = ["AnalyticMaterial", "DataMaterial", "FitMaterial", "ModelMaterial", "material_of",
           "measured_pairs", "unit_rows"]

Array = NDArray[np.float64]


def above_rows(d: ArrayLike) -> Array:
    """(N, 3) float64 vectors with z >= 0 (rounding from float32 renderers removed)."""
    a = np.atleast_2d(np.asarray(d, dtype=float)).copy()
    a[:, 2] = np.maximum(a[:, 2], 0.0)
    return a


def unit_rows(d: ArrayLike) -> Array:
    """(N, 3) float64 unit vectors with z >= 0 (rounding from float32 renderers removed)."""
    a = above_rows(d)
    n = np.linalg.norm(a, axis=1)
    return a / np.where(n > 0, n, 1.0)[:, None]


def _rgb(v: Array, what: str) -> Array:
    v = np.atleast_2d(np.asarray(v, dtype=float))
    if v.shape[1] == 1:
        v = np.repeat(v, 3, axis=1)
    elif v.shape[1] != 3:
        raise InputError(f"{what} has {v.shape[1]} channels; rendering needs 1 (grey) or 3 (RGB)")
    return v


def _negative_fraction(fn) -> float:
    V, _ = hemisphere_quadrature(16, 32)
    ti = np.radians(np.arange(2.5, 90.0, 5.0))
    neg = tot = 0
    for t in ti:
        L = np.broadcast_to([np.sin(t), 0.0, np.cos(t)], V.shape).copy()
        v = fn(L, V)
        neg += int(np.sum(~(v >= 0)))
        tot += v.size
    return neg / tot


class FitMaterial:
    """A ratfit BRDF fit file (``ratfit brdf fit`` output), clamped at 0 for rendering."""

    def __init__(self, fit: str | os.PathLike[str] | BRDFFit) -> None:
        self.fit = fit if isinstance(fit, BRDFFit) else load_brdf_fit(fit)
        self.name = Path(str(fit)).stem if not isinstance(fit, BRDFFit) else "fit"
        from ratfit.brdf.parametrizations import get_parametrization

        self.isotropic = get_parametrization(self.fit.parametrization).invariant != "full"
        if self.fit.n_channels not in (1, 3):
            raise InputError(f"the fit has {self.fit.n_channels} channels; rendering needs 1 "
                             "(grey) or 3 (RGB): fit with --color rgb")
        self.negative_fraction = _negative_fraction(self.raw)
        V, _ = hemisphere_quadrature(16, 32)
        L = np.broadcast_to([np.sin(0.6), 0.0, np.cos(0.6)], V.shape)
        #: fraction of a hemisphere of directions (theta_l = 34 deg) outside the fit's box
        self.outside_fraction = float(self.coords(L, V)[1].mean())

    def coords(self, L: ArrayLike, V: ArrayLike) -> tuple[Array, NDArray[np.bool_]]:
        """The fit's coordinates of (L, V): :meth:`ratfit.brdf.fitter.BRDFFit.coords`,
        the definition every evaluator shares (it normalises the directions: once, so
        the values are ``brdf eval``'s to the last bit). Also returns which rows needed a
        clip."""
        return self.fit.coords(above_rows(L), above_rows(V))

    def raw(self, L: ArrayLike, V: ArrayLike) -> Array:
        """The fit's own values (N, 3), negative or non-finite ones included."""
        c, _ = self.coords(L, V)
        with np.errstate(all="ignore"):
            return _rgb(self.fit.eval_coords(c), "the fit")

    def __call__(self, L: ArrayLike, V: ArrayLike) -> Array:
        v = self.raw(L, V)
        return np.where(np.isfinite(v), np.maximum(v, 0.0), 0.0)


def _dirs_of(p, coords: Array) -> tuple[Array, Array, NDArray[np.bool_]]:
    """Directions of data coordinates and which rows are a pair above the horizon
    (the others hold NaN); :meth:`Parametrization.to_dirs` refuses the whole file."""
    c = np.asarray(coords, dtype=float)
    with np.errstate(invalid="ignore"):
        L, V = p._to(c)
    ok = np.isfinite(L).all(axis=1) & np.isfinite(V).all(axis=1)
    ok &= (L[:, 2] >= -1e-12) & (V[:, 2] >= -1e-12)
    L, V = np.where(ok[:, None], L, np.nan), np.where(ok[:, None], V, np.nan)
    return L, V, ok


def measured_pairs(path: str | os.PathLike[str]) -> tuple[Array, Array, Array, int]:
    """A measured BRDF file's samples as a renderer sees them: (L, V, RGB) of the pairs
    above the horizon with finite values, and how many samples put a direction below
    it (left out). Refused: a file without values, or whose coordinates do not fix both
    directions up to a rotation."""
    from ratfit.brdf.io import brdf_dataset
    from ratfit.brdf.parametrizations import get_parametrization

    ds = brdf_dataset(path, None, color="rgb")
    if ds.y is None:
        raise InputError(f"{path}: no BRDF values")
    p = get_parametrization(str(ds.meta.get("param_in")))
    if p.invariant not in ("full", "isotropic"):
        raise InputError(f"{path}: data in {p.name} does not fix both directions up to a "
                         "rotation; it cannot be rendered as measured")
    L, V, above = _dirs_of(p, ds.x)
    y = _rgb(ds.y, f"{path}")
    keep = above & np.all(np.isfinite(y), axis=1)
    return L[keep], V[keep], y[keep], int((~above).sum())


class DataMaterial:
    """Measured BRDF samples, interpolated for rendering.

    Each (L, V) pair is embedded by its half and difference vectors (Rusinkiewicz's
    frame, in which an isotropic BRDF's highlight lies at theta_h = 0 whatever the
    incidence): H's elevation on MERL's square-root scale and D with phi_d folded into
    [0, pi/2] (reciprocity moves phi_d by pi, mirror symmetry sends it to -phi_d). A
    query takes the inverse-distance-squared average of its ``k`` nearest samples there
    (exact at a sample; samples at one embedded point are averaged): scattered
    goniometer data has no grid for multilinear interpolation, and scipy's
    Delaunay-based interpolation is very slow on such degenerate point sets.

    Why this frame, measured (``benchmarks/bench_data_interp.py``: 5-fold, each Cornell
    file's held-out samples predicted from the others): against the same average over
    the two directions' own angles (L at azimuth 0), the relative RMSE falls in all 15
    channels (cayman R 0.86 -> 0.38, acryl_blue R 0.71 -> 0.34) and the RMSE in all 15;
    the cos-weighted RMSE rises 1-3 % in 9 (garnet_red, cayman, mystique). With the
    light at 8 incidence angles in one plane, neighbours in the directions' angles
    blend samples of two incidence angles off their highlights into a broad glow.
    """

    def __init__(self, path: str | os.PathLike[str], *, k: int = 8) -> None:
        L, V, y, below = measured_pairs(path)
        self.name = Path(str(path)).stem
        #: samples whose coordinates put L or V below the horizon: a renderer never asks
        #: for such a pair, so they are left out (counted, not refused)
        self.below_horizon = below
        if len(y) < 4:
            raise InputError(f"{path}: fewer than 4 finite samples to interpolate")
        self._index(L, V, y, k)

    @classmethod
    def from_pairs(cls, L: ArrayLike, V: ArrayLike, rgb: ArrayLike, *, k: int = 8,
                   name: str = "data") -> DataMaterial:
        """Samples given as unit direction pairs above the horizon and their RGB values
        (N, 3): one fold of a file's samples, say, to predict the others."""
        la, va = unit_rows(L), unit_rows(V)
        y = _rgb(np.asarray(rgb, dtype=float), name)
        if not (len(la) == len(va) == len(y)) or len(y) < 4:
            raise InputError(f"{name}: need at least 4 pairs with one value row each, got "
                             f"{len(la)} L, {len(va)} V, {len(y)} values")
        self = cls.__new__(cls)
        self.name = name
        self.below_horizon = 0
        self._index(la, va, y, k)
        return self

    def _index(self, L: Array, V: Array, y: Array, k: int) -> None:
        from scipy.spatial import cKDTree

        y = np.maximum(y, 0.0)
        # samples at one embedded point (a pair and its reciprocal or mirror image,
        # measured twice) are one point: their mean value
        pts, group = np.unique(np.round(self._features(L, V), 9), axis=0,
                               return_inverse=True)
        group = group.ravel()
        count = np.bincount(group, minlength=len(pts)).astype(float)
        self._vals = np.stack([np.bincount(group, weights=y[:, c], minlength=len(pts))
                               for c in range(y.shape[1])], axis=1) / count[:, None]
        self._tree = cKDTree(pts)
        self._k = int(min(k, len(pts)))
        self.n_samples = int(len(y))
        self.isotropic = True
        self.negative_fraction = 0.0

    @staticmethod
    def _features(L: Array, V: Array) -> Array:
        """(N, 4): sqrt(theta_h / (pi/2)) (MERL's map, fine near the highlight) and
        D = (sin theta_d cos phi, sin theta_d sin phi, cos theta_d), phi = phi_d folded
        into [0, pi/2]: the same for (L, V), (V, L) and their mirror images."""
        from ratfit.brdf.parametrizations import get_parametrization

        th, td, pd = get_parametrization("RUSIN_TH_TD_PD").from_dirs(L, V).T
        pd = np.mod(pd, np.pi)
        pd = np.minimum(pd, np.pi - pd)
        std = np.sin(td)
        return np.stack([np.sqrt(np.clip(th, 0.0, None) / (0.5 * np.pi)), std * np.cos(pd),
                         std * np.sin(pd), np.cos(td)], axis=1)

    def __call__(self, L: ArrayLike, V: ArrayLike) -> Array:
        q = self._features(unit_rows(L), unit_rows(V))
        d, i = self._tree.query(q, k=self._k)
        d, i = d.reshape(len(q), -1), i.reshape(len(q), -1)
        w = 1.0 / np.maximum(d, 1e-9) ** 2
        out = np.einsum("nk,nkc->nc", w, self._vals[i]) / w.sum(axis=1)[:, None]
        return np.maximum(out, 0.0)


class AnalyticMaterial:
    """An analytic model of :mod:`ratfit.brdf.analytic_models` (e.g. ``"lambert+ggx"``)."""

    def __init__(self, spec: str, theta: ArrayLike, rgb: ArrayLike = (1.0, 1.0, 1.0)) -> None:
        from ratfit.brdf.analytic_models import Model

        self.model = Model(spec)
        self.theta = np.asarray(theta, dtype=float)
        self.model._split(self.theta)  # checks the parameter count
        self.rgb = np.asarray(rgb, dtype=float)
        self.name = self.model.spec
        self.negative_fraction = 0.0
        self.isotropic = True

    def __call__(self, L: ArrayLike, V: ArrayLike) -> Array:
        v = self.model(unit_rows(L), unit_rows(V), self.theta)
        return np.where(np.isfinite(v), np.maximum(v, 0.0), 0.0)[:, None] * self.rgb[None, :]


class ModelMaterial:
    """An analytic model fitted per channel (a ``ratfit.model`` file, written by
    ``ratfit brdf model``), rendered exactly as a rational fit is: its values at
    every pair above the horizon, nothing clamped (the lobes are non-negative)."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        from ratfit.brdf.analytic_models import load_model_fit

        self.fit = load_model_fit(path)
        self.name = Path(str(path)).stem
        if self.fit.n_channels not in (1, 3):
            raise InputError(f"the model has {self.fit.n_channels} channels; rendering needs 1 "
                             "(grey) or 3 (RGB)")
        self.isotropic = True
        self.negative_fraction = _negative_fraction(self.raw)
        self.outside_fraction = 0.0

    def raw(self, L: ArrayLike, V: ArrayLike) -> Array:
        with np.errstate(all="ignore"):
            return _rgb(self.fit.eval_dirs(unit_rows(L), unit_rows(V)), "the model")

    def __call__(self, L: ArrayLike, V: ArrayLike) -> Array:
        v = self.raw(L, V)
        return np.where(np.isfinite(v), np.maximum(v, 0.0), 0.0)


def material_of(path: str | os.PathLike[str]) -> FitMaterial | ModelMaterial:
    """The material a file holds: a rational BRDF fit, or an analytic model fit."""
    from ratfit.brdf.analytic_models import is_model_file

    return ModelMaterial(path) if is_model_file(path) else FitMaterial(path)
