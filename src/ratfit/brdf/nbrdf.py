"""Neural BRDF encodings (Sztrajman et al. 2021) as functions of directions.

Each network (6 -> 21 -> 21 -> 3, 675 weights) stands in for one measured
isotropic material: it can be evaluated at any pair of directions, so it can be
written as a full MERL table (:func:`ratfit.brdf.io.merl_from_function`) and
the fits of that table compared with the material between the table's cells.
The weights come as an ``.npz`` with arrays W1 (6x21), b1, W2 (21x21), b2,
W3 (21x3), b3 (see the data's SOURCES.md, section nbrdf-rgl).
"""

from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.brdf.parametrizations import get_parametrization
from ratfit.errors import FileFormatError, InputError

__all__ = ["NeuralBRDF", "load_nbrdf"]

Array = NDArray[np.float64]

_SHAPES = {"W1": (6, 21), "b1": (21,), "W2": (21, 21), "b2": (21,), "W3": (21, 3), "b3": (3,)}


@dataclass(frozen=True, eq=False)
class NeuralBRDF:
    """One network: RGB in 1/sr at Rusinkiewicz angles or at direction pairs."""

    W1: Array
    b1: Array
    W2: Array
    b2: Array
    W3: Array
    b3: Array
    name: str = "nbrdf"

    @property
    def n_weights(self) -> int:
        """Numbers the network stores (675 for the published ones)."""
        return sum(int(np.asarray(getattr(self, k)).size) for k in _SHAPES)

    def eval_angles(self, coords: ArrayLike) -> Array:
        """RGB (N, 3) at (theta_h, theta_d, phi_d) rows, as the network takes them.

        phi_d is used as given (no fold): this is the network itself.
        """
        c = np.asarray(coords, dtype=float).reshape(-1, 3)
        th, td, pd = c[:, 0], c[:, 1], c[:, 2]
        std = np.sin(td)
        x = np.stack([np.sin(th), np.zeros_like(th), np.cos(th),
                      std * np.cos(pd), std * np.sin(pd), np.cos(td)], axis=1)
        h1 = np.maximum(x @ self.W1 + self.b1, 0.0)
        h2 = np.maximum(h1 @ self.W2 + self.b2, 0.0)
        out: Array = np.expm1(h2 @ self.W3 + self.b3)
        return out

    def eval_dirs(self, L: ArrayLike, V: ArrayLike) -> Array:
        """RGB (N, 3) for unit directions L, V (N, 3); zero where either is below the horizon.

        phi_d is folded into [0, pi) as MERL tables fold it, so the function is the
        one a MERL table of it samples, and reciprocal (L <-> V moves phi_d by pi);
        phi_h = 0 makes it isotropic. The network's slightly negative outputs (a few
        percent of pairs, down to about -0.7 1/sr) are clipped to 0: a BRDF is not
        negative. (A measured MERL file stores such cells as missing; a table written of
        this function with :func:`~ratfit.brdf.io.merl_from_function` holds the 0, which
        a fit must then meet: spectralon's has 5 537 such cells, in patches near the
        horizon.)
        """
        la = np.asarray(L, dtype=float).reshape(-1, 3)
        va = np.asarray(V, dtype=float).reshape(-1, 3)
        if la.shape != va.shape:
            raise InputError(f"L has {la.shape[0]} rows but V has {va.shape[0]}")
        out = np.zeros((la.shape[0], 3))
        up = (la[:, 2] > 0.0) & (va[:, 2] > 0.0)
        if up.any():
            c = get_parametrization("RUSIN_TH_TD_PD").from_dirs(la[up], va[up])
            c[:, 2] = np.mod(c[:, 2], np.pi)
            out[up] = np.maximum(self.eval_angles(c), 0.0)
        return out

    __call__ = eval_dirs


def load_nbrdf(path: str | os.PathLike[str]) -> NeuralBRDF:
    """Read one network's ``.npz`` (W1, b1, W2, b2, W3, b3), checking the shapes."""
    src = str(path)
    try:
        with np.load(src, allow_pickle=False) as z:
            arrays = {k: np.asarray(z[k], dtype=float) for k in _SHAPES if k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise FileFormatError(f"{src}: not a readable .npz: {exc}") from None
    for k, shape in _SHAPES.items():
        if k not in arrays:
            raise FileFormatError(f"{src}: no array {k!r} (a neural BRDF needs {list(_SHAPES)})")
        if arrays[k].shape != shape:
            raise FileFormatError(f"{src}: {k} has shape {arrays[k].shape}, expected {shape}")
        if not np.all(np.isfinite(arrays[k])):
            raise FileFormatError(f"{src}: {k} holds non-finite values")
    name = os.path.basename(src).removesuffix(".npz")
    return NeuralBRDF(name=name, **arrays)
