"""Analytic isotropic BRDF models and their nonlinear fits, for comparison with rational fits.

A :class:`Model` is a sum of lobes, written as a spec string such as
``"lambert+ggx"`` or ``"lambert+lafortune*2"``. Every lobe is vectorised on
directions ``L``, ``V`` (N, 3) in the local frame (normal +z, both pointing
away from the surface) and is zero below the horizon. Lobes are normalised so
that a scale ``k <= 1`` reflects at most (about) what it receives:

* ``lambert``: k / pi.
* ``blinn``: k (e + 8) / (8 pi) cos^e theta_h (the usual energy-conserving
  normalisation of Blinn-Phong).
* ``ward``: isotropic Ward, k exp(-tan^2 theta_h / a^2) / (4 pi a^2 sqrt(cos_l cos_v)).
* ``beckmann`` / ``ggx``: Cook-Torrance k F D G / (4 cos_l cos_v) with the named
  microfacet distribution D, its Smith shadowing G and Schlick's Fresnel F(f0).
* ``lafortune``: k (e + 2) / (2 pi) max(cxy (LxVx + LyVy) + LzVz, 0)^e (cz fixed
  to 1, which removes the scale ambiguity of C against k); cxy = -1 is the Phong
  lobe around the mirror direction, cxy > 0 a retro-reflective one.

Fitting (:func:`fit_model`) uses ``scipy.optimize.least_squares`` with bounds,
a robust loss and several starts whose linear scales come from a non-negative
least-squares solve, so a bad random shape does not waste a start.
"""

from __future__ import annotations

import json
import os
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit._atomic import atomic_open
from ratfit.errors import FileFormatError, InputError

__all__ = [
    "LOBES",
    "Geometry",
    "Lobe",
    "Model",
    "ModelFit",
    "channel_metrics",
    "check_dirs",
    "fit_model",
    "is_model_file",
    "load_model_fit",
]

Array = NDArray[np.float64]
# largest lobe value used (scale 1): far beyond any BRDF, far below overflow when squared
LOBE_CAP = 1e60
FORMAT = "ratfit.model"
VERSION = 1
_EPS = 1e-12


# ---------------------------------------------------------------------------- geometry
def check_dirs(L: ArrayLike, V: ArrayLike, where: str = "directions") -> tuple[Array, Array]:
    """Validate L, V as (N, 3) finite arrays (normalised here; zero vectors are refused)."""
    La = np.asarray(L, dtype=float)
    Va = np.asarray(V, dtype=float)
    if La.ndim == 1:
        La = La[None, :]
    if Va.ndim == 1:
        Va = Va[None, :]
    if La.ndim != 2 or La.shape[1] != 3 or Va.shape != La.shape:
        raise InputError(f"{where}: L and V must both have shape (N, 3), got "
                         f"{np.shape(L)} and {np.shape(V)}")
    if not (np.all(np.isfinite(La)) and np.all(np.isfinite(Va))):
        raise InputError(f"{where}: non-finite direction components")
    nl = np.linalg.norm(La, axis=1, keepdims=True)
    nv = np.linalg.norm(Va, axis=1, keepdims=True)
    if np.any(nl == 0) or np.any(nv == 0):
        raise InputError(f"{where}: zero-length direction vector")
    return La / nl, Va / nv


@dataclass(frozen=True)
class Geometry:
    """Cosines every lobe needs, computed once per direction set."""

    cos_l: Array
    cos_v: Array
    cos_h: Array
    cos_d: Array
    lv_xy: Array  # Lx Vx + Ly Vy
    lv_z: Array  # Lz Vz
    above: NDArray[np.bool_]  # both directions strictly above the horizon

    @classmethod
    def from_dirs(cls, L: ArrayLike, V: ArrayLike) -> Geometry:
        La, Va = check_dirs(L, V)
        H = La + Va
        hn = np.linalg.norm(H, axis=1)
        hn = np.where(hn > _EPS, hn, 1.0)
        cos_h = np.clip(H[:, 2] / hn, 0.0, 1.0)
        cos_d = np.clip(np.einsum("ij,ij->i", La, H) / hn, 0.0, 1.0)
        above = (La[:, 2] > 0) & (Va[:, 2] > 0)
        return cls(
            cos_l=np.clip(La[:, 2], _EPS, 1.0), cos_v=np.clip(Va[:, 2], _EPS, 1.0),
            cos_h=np.maximum(cos_h, _EPS), cos_d=cos_d,
            lv_xy=La[:, 0] * Va[:, 0] + La[:, 1] * Va[:, 1], lv_z=La[:, 2] * Va[:, 2],
            above=above,
        )

    def tan2_h(self) -> Array:
        c2 = self.cos_h**2
        return (1.0 - c2) / c2


# ---------------------------------------------------------------------------- lobes
def _lambert(g: Geometry, k: float) -> Array:
    return np.full(g.cos_l.shape, k / np.pi)


def _blinn(g: Geometry, k: float, e: float) -> Array:
    return k * (e + 8.0) / (8.0 * np.pi) * g.cos_h**e


def _ward(g: Geometry, k: float, a: float) -> Array:
    a2 = a * a
    return k * np.exp(-g.tan2_h() / a2) / (4.0 * np.pi * a2 * np.sqrt(g.cos_l * g.cos_v))


def _schlick(f0: float, c: Array) -> Array:
    return f0 + (1.0 - f0) * (1.0 - c) ** 5


def _smith_ggx(c: Array, a: float) -> Array:
    a2 = a * a
    return 2.0 * c / (c + np.sqrt(a2 + (1.0 - a2) * c * c))


def _smith_beckmann(c: Array, a: float) -> Array:
    t = np.sqrt(np.maximum(1.0 - c * c, 0.0)) / c
    with np.errstate(divide="ignore"):
        u = np.where(t > 0, 1.0 / (a * np.maximum(t, 1e-300)), np.inf)
    rational = (3.535 * u + 2.181 * u * u) / (1.0 + 2.276 * u + 2.577 * u * u)
    return np.where(u < 1.6, rational, 1.0)


def _ggx(g: Geometry, k: float, a: float, f0: float) -> Array:
    a2 = a * a
    c2 = g.cos_h**2
    D = a2 / (np.pi * (c2 * (a2 - 1.0) + 1.0) ** 2)
    G = _smith_ggx(g.cos_l, a) * _smith_ggx(g.cos_v, a)
    return k * _schlick(f0, g.cos_d) * D * G / (4.0 * g.cos_l * g.cos_v)


def _beckmann(g: Geometry, k: float, a: float, f0: float) -> Array:
    a2 = a * a
    D = np.exp(-g.tan2_h() / a2) / (np.pi * a2 * g.cos_h**4)
    G = _smith_beckmann(g.cos_l, a) * _smith_beckmann(g.cos_v, a)
    return k * _schlick(f0, g.cos_d) * D * G / (4.0 * g.cos_l * g.cos_v)


def _lafortune(g: Geometry, k: float, cxy: float, e: float) -> Array:
    s = np.maximum(cxy * g.lv_xy + g.lv_z, 0.0)
    return k * (e + 2.0) / (2.0 * np.pi) * s**e


@dataclass(frozen=True)
class Lobe:
    """One term of a model: parameter names, bounds, a sampler of starting shapes.

    The first parameter is always the linear scale ``k``; the others are the
    shape, drawn by ``sample_shape`` (log-uniform where the range spans decades).
    """

    name: str
    params: tuple[str, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    fn: Callable[..., Array]
    sample_shape: Callable[[np.random.Generator], tuple[float, ...]]

    @property
    def size(self) -> int:
        return len(self.params)


def _logu(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


LOBES: dict[str, Lobe] = {
    "lambert": Lobe("lambert", ("k",), (0.0,), (np.inf,), _lambert, lambda r: ()),
    "blinn": Lobe("blinn", ("k", "e"), (0.0, 0.0), (np.inf, 1e5), _blinn,
                  lambda r: (_logu(r, 1.0, 2000.0),)),
    "ward": Lobe("ward", ("k", "alpha"), (0.0, 1e-3), (np.inf, 1.5), _ward,
                 lambda r: (_logu(r, 0.02, 0.8),)),
    "beckmann": Lobe("beckmann", ("k", "alpha", "f0"), (0.0, 1e-3, 0.0), (np.inf, 1.5, 1.0),
                     _beckmann, lambda r: (_logu(r, 0.02, 0.8), r.uniform(0.02, 0.9))),
    "ggx": Lobe("ggx", ("k", "alpha", "f0"), (0.0, 1e-3, 0.0), (np.inf, 1.5, 1.0), _ggx,
                lambda r: (_logu(r, 0.02, 0.8), r.uniform(0.02, 0.9))),
    "lafortune": Lobe("lafortune", ("k", "cxy", "e"), (0.0, -2.0, 0.0), (np.inf, 2.0, 1e4),
                      _lafortune, lambda r: (r.choice([-1.0, 1.0]) * r.uniform(0.6, 1.2),
                                             _logu(r, 1.0, 500.0))),
}


class Model:
    """A sum of lobes, parsed from a spec such as ``"lambert+ggx"`` or ``"lafortune*2"``."""

    def __init__(self, spec: str) -> None:
        terms: list[Lobe] = []
        text = str(spec).strip().lower()
        if not text:
            raise InputError("empty model spec; e.g. 'lambert+ggx'")
        for part in text.split("+"):
            mt = re.fullmatch(r"\s*([a-z]+)\s*(?:\*\s*(\d+))?\s*", part)
            if not mt or mt.group(1) not in LOBES:
                raise InputError(
                    f"unknown lobe {part.strip()!r} in model {spec!r}; lobes: {', '.join(LOBES)}"
                    " (combine with '+', repeat with '*N')"
                )
            count = int(mt.group(2) or 1)
            if not 1 <= count <= 8:
                raise InputError(f"lobe count must be 1..8 in model {spec!r}, got {count}")
            terms.extend([LOBES[mt.group(1)]] * count)
        self.spec = "+".join(_compact([t.name for t in terms]))
        self.lobes = tuple(terms)

    @property
    def n_params(self) -> int:
        return sum(lb.size for lb in self.lobes)

    @property
    def param_names(self) -> list[str]:
        return [f"{lb.name}{i}.{p}" for i, lb in enumerate(self.lobes) for p in lb.params]

    def bounds(self) -> tuple[Array, Array]:
        lo = np.concatenate([lb.lower for lb in self.lobes])
        hi = np.concatenate([lb.upper for lb in self.lobes])
        return lo, hi

    def _split(self, theta: ArrayLike) -> list[Array]:
        th = np.asarray(theta, dtype=float).ravel()
        if th.size != self.n_params:
            raise InputError(f"model {self.spec} takes {self.n_params} parameters, got {th.size}")
        out, i = [], 0
        for lb in self.lobes:
            out.append(th[i:i + lb.size])
            i += lb.size
        return out

    def lobe_values(self, g: Geometry, theta: ArrayLike) -> Array:
        """Matrix (N, lobes) of each lobe's value with its scale set to 1."""
        cols = []
        for lb, th in zip(self.lobes, self._split(theta), strict=True):
            with np.errstate(over="ignore", invalid="ignore", under="ignore"):
                cols.append(lb.fn(g, 1.0, *th[1:]))
        M = np.stack(cols, axis=1)
        M[~g.above] = 0.0
        # a lobe at a trial shape far from the data (a Lafortune exponent of 1e3 at
        # grazing angles) overflows; capped at LOBE_CAP its residual, squared by the
        # optimiser's loss, stays finite (1e300 squared was "overflow in square")
        return np.clip(np.nan_to_num(M, nan=0.0, posinf=LOBE_CAP), -LOBE_CAP, LOBE_CAP)

    def evaluate(self, g: Geometry, theta: ArrayLike) -> Array:
        scales = np.array([th[0] for th in self._split(theta)])
        return self.lobe_values(g, theta) @ scales

    def __call__(self, L: ArrayLike, V: ArrayLike, theta: ArrayLike) -> Array:
        return self.evaluate(Geometry.from_dirs(L, V), theta)

    def __repr__(self) -> str:
        return f"Model({self.spec!r})"


def _compact(names: Sequence[str]) -> list[str]:
    out: list[str] = []
    i = 0
    while i < len(names):
        j = i
        while j < len(names) and names[j] == names[i]:
            j += 1
        out.append(names[i] if j - i == 1 else f"{names[i]}*{j - i}")
        i = j
    return out


# ---------------------------------------------------------------------------- metrics
def channel_metrics(pred: ArrayLike, y: ArrayLike,
                    cos_l: ArrayLike | None = None) -> dict[str, float]:
    """One channel's metrics, as for rational fits (:func:`ratfit.brdf.fitter.brdf_metrics`)."""
    from ratfit.brdf.fitter import brdf_metrics as _metrics

    f = np.asarray(pred, dtype=float).reshape(-1, 1)
    t = np.asarray(y, dtype=float).reshape(-1, 1)
    return _metrics(f, t, cos_l, ("y",))["y"]


# ---------------------------------------------------------------------------- fitting
@dataclass
class ModelFit:
    """Parameters (k, P) of a model fitted per channel, with the metrics on its data."""

    model: Model
    params: Array
    channel_names: tuple[str, ...]
    metrics: list[dict[str, float]] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def n_channels(self) -> int:
        return int(self.params.shape[0])

    @property
    def name(self) -> str:
        return self.model.spec

    def eval_dirs(self, L: ArrayLike, V: ArrayLike) -> Array:
        g = Geometry.from_dirs(L, V)
        return np.stack([self.model.evaluate(g, p) for p in self.params], axis=1)

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT, "version": VERSION, "model": self.model.spec,
            "param_names": self.model.param_names,
            "channels": [
                {"name": n, "params": p.tolist(), "metrics": m}
                for n, p, m in zip(self.channel_names, self.params,
                                   self.metrics or [{}] * self.n_channels, strict=True)
            ],
            "info": self.info,
        }

    def save(self, path: str | os.PathLike[str]) -> None:
        with atomic_open(path, "w") as fh:
            fh.write(json.dumps(self.to_dict(), indent=1, allow_nan=False) + "\n")


def is_model_file(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a JSON file that says it is a ratfit model file."""
    p = Path(path)
    if p.suffix.lower() != ".json" or not p.is_file():
        return False
    try:
        with open(p, "rb") as fh:
            head = fh.read(4000).decode("utf-8", errors="replace")
    except OSError:
        return False
    return f'"{FORMAT}"' in head


def load_model_fit(path: str | os.PathLike[str]) -> ModelFit:
    """Read a file written by :meth:`ModelFit.save`."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text())
    except FileNotFoundError:
        raise FileFormatError(f"{p}: no such model file") from None
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise FileFormatError(f"{p}: not a ratfit model file (not JSON)") from None
    return parse_model_fit(doc, str(p))


def parse_model_fit(doc: Any, where: str = "model") -> ModelFit:
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise FileFormatError(f"{where}: not a ratfit model file (missing format {FORMAT!r})")
    try:
        model = Model(doc["model"])
        chans = doc["channels"]
        params = np.array([c["params"] for c in chans], dtype=float).reshape(len(chans), -1)
        if params.shape[1] != model.n_params or not np.all(np.isfinite(params)):
            raise FileFormatError(f"{where}: parameters do not match model {model.spec}")
        return ModelFit(model, params, tuple(str(c["name"]) for c in chans),
                        [c.get("metrics", {}) for c in chans], doc.get("info", {}))
    except (KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, FileFormatError):
            raise
        raise FileFormatError(f"{where}: malformed model file ({exc})") from None


def _initial(model: Model, g: Geometry, y: Array, w: Array, rng: np.random.Generator) -> Array:
    """A random shape with the scales from non-negative least squares on the data."""
    from scipy.optimize import nnls

    theta = []
    for lb in model.lobes:
        theta.extend([1.0, *lb.sample_shape(rng)])
    th = np.array(theta)
    M = model.lobe_values(g, th) * w[:, None]
    M = np.where(np.isfinite(M), M, 0.0)
    colmax = np.max(np.abs(M), axis=0)
    colmax[colmax == 0] = 1.0
    try:
        k, _ = nnls(M / colmax, y * w, maxiter=50 * M.shape[1])
        k = k / colmax
    except RuntimeError:
        k = np.full(len(model.lobes), float(np.mean(np.abs(y))))
    i = 0
    for j, lb in enumerate(model.lobes):
        th[i] = max(k[j], 1e-6 * (float(np.max(np.abs(y))) or 1.0))
        i += lb.size
    return th


def fit_model(
    model: Model | str,
    L: ArrayLike,
    V: ArrayLike,
    y: ArrayLike,
    *,
    channel_names: Sequence[str] | None = None,
    loss: str = "soft_l1",
    weight: str = "none",
    starts: int = 8,
    seed: int = 0,
    max_nfev: int = 400,
    progress: Callable[[str], None] | None = None,
) -> ModelFit:
    """Fit ``model`` to values y (N,) or (N, k) at directions L, V, each channel on its own.

    ``loss`` is least_squares' loss (robust ``soft_l1`` by default, scale = rms(y));
    ``weight="cos"`` weighs residuals by cos theta_l (radiance-like errors).
    The best of ``starts`` runs (by the unweighted RMSE) is kept. ``progress`` is
    called after each run with what it was ("G start 2/8").
    """
    from scipy.optimize import least_squares

    mdl = model if isinstance(model, Model) else Model(model)
    if weight not in ("none", "cos"):
        raise InputError(f"weight must be 'none' or 'cos', got {weight!r}")
    if starts < 1:
        raise InputError(f"starts must be >= 1, got {starts}")
    g = Geometry.from_dirs(L, V)
    Y = np.asarray(y, dtype=float)
    if Y.ndim == 1:
        Y = Y[:, None]
    if Y.shape[0] != g.cos_l.size:
        raise InputError(f"{Y.shape[0]} values for {g.cos_l.size} direction pairs")
    if not np.all(np.isfinite(Y)):
        raise InputError("non-finite BRDF values")
    keep = g.above
    if not np.any(keep):
        raise InputError("no direction pair above the horizon")
    names = tuple(channel_names) if channel_names else tuple(f"y{j}" for j in range(Y.shape[1]))
    gk = Geometry(*(getattr(g, f)[keep] for f in (
        "cos_l", "cos_v", "cos_h", "cos_d", "lv_xy", "lv_z", "above")))
    w = gk.cos_l if weight == "cos" else np.ones_like(gk.cos_l)
    lo, hi = mdl.bounds()
    hi_in = np.where(np.isfinite(hi), hi - 1e-9, 1e300)  # strictly inside for least_squares
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    params, mets, nfev = [], [], 0
    for j in range(Y.shape[1]):
        yj = Y[keep, j]
        scale = float(np.sqrt(np.mean((yj * w) ** 2))) or 1.0
        best, best_rmse = None, np.inf
        for start in range(starts):
            x0 = np.clip(_initial(mdl, gk, yj, w, rng), lo + 1e-9, hi_in)

            def resid(th: Array, yj: Array = yj) -> Array:
                return (mdl.evaluate(gk, th) - yj) * w

            try:
                # trial steps far off (a scale of 1e40 times a capped lobe) may still
                # overflow inside the loss: the step is rejected, no warning is news
                with np.errstate(over="ignore"):
                    res = least_squares(resid, x0, bounds=(lo, hi), loss=loss, f_scale=scale,
                                        max_nfev=max_nfev, x_scale="jac")
            except ValueError as exc:
                raise InputError(f"model fit failed to start: {exc}") from None
            nfev += int(res.nfev)
            rmse = float(np.sqrt(np.mean((mdl.evaluate(gk, res.x) - yj) ** 2)))
            if rmse < best_rmse:
                best, best_rmse = res.x, rmse
            if progress is not None:
                progress(f"{names[j]} start {start + 1}/{starts}")
        assert best is not None
        params.append(best)
        mets.append(channel_metrics(mdl.evaluate(g, best), Y[:, j], g.cos_l))
    info = {"loss": loss, "weight": weight, "starts": starts, "seed": seed, "nfev": nfev,
            "seconds": time.perf_counter() - t0, "n_points": int(Y.shape[0])}
    return ModelFit(mdl, np.array(params), names, mets, info)
