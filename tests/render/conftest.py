"""Fixtures for the renderer tests: a small RGB BRDF fit file of a known material."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ratfit.brdf.analytic_models import Model
from ratfit.brdf.fitter import fit_brdf, save_brdf_fit
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.io.data import Dataset

GGX = ("lambert+ggx", [0.4, 1.0, 0.3, 0.04])
TINT = np.array([1.0, 0.7, 0.4])


def ggx_rgb(L: np.ndarray, V: np.ndarray) -> np.ndarray:
    return Model(GGX[0])(L, V, GGX[1])[:, None] * TINT[None, :]


@pytest.fixture(scope="session")
def rgb_fit(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A verified 3-channel COS_TH_TD fit of a tinted lambert+GGX (rough, alpha 0.3)."""
    rng = np.random.default_rng(3)
    n = 600
    tl, tv = np.arccos(rng.uniform(0.15, 1.0, n)), np.arccos(rng.uniform(0.15, 1.0, n))
    dphi = rng.uniform(-np.pi, np.pi, n)
    L = np.stack([np.sin(tl), np.zeros(n), np.cos(tl)], 1)
    V = np.stack([np.sin(tv) * np.cos(dphi), np.sin(tv) * np.sin(dphi), np.cos(tv)], 1)
    P = get_parametrization("COS_TH_TD")
    ds = Dataset(P.from_dirs(L, V), ggx_rgb(L, V), output_names=("R", "G", "B"),
                 meta={"param_in": "COS_TH_TD"})
    fitter, _, meta = fit_brdf(ds, dt=0.05, max_total=30)
    assert fitter.success_, [r.message for r in fitter.results_]
    path = tmp_path_factory.mktemp("render") / "ggx_fit.json"
    save_brdf_fit(path, fitter.results_, meta)
    return path
