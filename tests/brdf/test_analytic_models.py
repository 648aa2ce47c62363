"""Analytic BRDF models: recovery of known parameters, energy (albedo) checks, model files."""

from __future__ import annotations

import numpy as np
import pytest

from ratfit.brdf.albedo import directional_albedo
from ratfit.brdf.analytic_models import Model, fit_model, load_model_fit
from ratfit.errors import InputError


def _hemi(rng, n):
    u = rng.uniform(0, 1, (n, 2))
    ct = np.sqrt(1 - 0.97 * u[:, 0])
    st = np.sqrt(1 - ct**2)
    ph = 2 * np.pi * u[:, 1]
    return np.stack([st * np.cos(ph), st * np.sin(ph), ct], axis=1)


@pytest.mark.parametrize("spec,theta", [
    ("lambert+ggx", [0.3, 0.5, 0.2, 0.6]),
    ("lambert+beckmann", [0.3, 0.5, 0.25, 0.4]),
    ("lambert+blinn", [0.4, 0.3, 50.0]),
    ("ward", [0.6, 0.2]),
    ("lafortune", [0.5, -0.9, 20.0]),
])
@pytest.mark.slow
def test_fit_recovers_parameters(spec, theta):
    rng = np.random.default_rng(1)
    L, V = _hemi(rng, 1500), _hemi(rng, 1500)
    model = Model(spec)
    y = model(L, V, theta)
    noisy = y * (1 + 0.002 * rng.standard_normal(y.shape))
    fit = fit_model(model, L, V, noisy, starts=4, seed=2)
    np.testing.assert_allclose(fit.params[0], theta, rtol=0.03)
    assert fit.metrics[0]["rmse"] < 0.01 * np.sqrt(np.mean(y**2))


def test_two_channels_and_model_file(tmp_path):
    rng = np.random.default_rng(4)
    L, V = _hemi(rng, 800), _hemi(rng, 800)
    model = Model("lambert+ggx")
    y = np.column_stack([model(L, V, [0.2, 0.4, 0.3, 0.5]), model(L, V, [0.6, 0.4, 0.3, 0.5])])
    fit = fit_model(model, L, V, y, channel_names=("R", "G"), starts=3)
    assert fit.params.shape == (2, 4)
    np.testing.assert_allclose(fit.params[:, 0], [0.2, 0.6], rtol=1e-3)
    fit.save(tmp_path / "m.json")
    back = load_model_fit(tmp_path / "m.json")
    np.testing.assert_array_equal(back.params, fit.params)
    np.testing.assert_array_equal(back.eval_dirs(L, V), fit.eval_dirs(L, V))


def test_zero_below_horizon_and_bad_specs():
    m = Model("lambert+ggx")
    L = np.array([[0.0, 0.6, -0.8], [0.0, 0.6, 0.8]])
    V = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    v = m(L, V, [1.0, 1.0, 0.3, 0.5])
    assert v[0] == 0.0 and v[1] > 0
    for bad in ("", "lambert+phong", "ggx*0", "ggx*99"):
        with pytest.raises(InputError):
            Model(bad)
    with pytest.raises(InputError, match="parameters"):
        m(L, V, [1.0])


def test_albedo_lambert_and_energy_flag():
    lam = Model("lambert")
    for rho in (0.25, 0.8):
        res = directional_albedo(lambda L, V, r=rho: lam(L, V, [r])[:, None])
        np.testing.assert_allclose(res.albedo[:, 0], rho, atol=1e-3)
        assert res.ok
    hot = directional_albedo(lambda L, V: lam(L, V, [1.3])[:, None])
    assert hot.flagged.all() and hot.max_albedo == pytest.approx(1.3, abs=1e-3)
    # an energy-sensible specular lobe stays below 1 at every incidence
    ggx = Model("ggx")
    res = directional_albedo(lambda L, V: ggx(L, V, [1.0, 0.3, 1.0])[:, None])
    assert res.ok and 0.5 < res.max_albedo <= 1.0


def test_albedo_partial_coverage_is_not_reported():
    lam = Model("lambert")

    def half(L, V):
        out = lam(L, V, [0.5])[:, None].copy()
        out[V[:, 0] < 0] = np.nan
        return out

    res = directional_albedo(half, np.radians([10.0, 40.0]))
    assert np.all(np.isnan(res.albedo)) and np.allclose(res.coverage, 0.5, atol=0.02)
