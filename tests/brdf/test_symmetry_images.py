"""Which image of a direction pair a BRDF fit is evaluated at, when several lie in its box.

An isotropic material is exactly mirror-symmetric (y -> -y); a measured one is not
always reciprocal. A fit in ISOTROPIC_TV_TL_DPHI whose samples all have delta_phi >= 0
(Cornell's light in one plane) is evaluated at a pair with delta_phi < 0 through its
mirror image, whose theta_v and theta_l are the pair's own: with the exchanged pair
first, acryl_blue's fit had a seam at delta_phi = 0. ``brdf eval`` and the exports
compute the same number (one definition, ``BRDFFit.coords``).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import exported_brdf_in_c

from ratfit.brdf.fitter import brdf_fit_of, fit_brdf, save_brdf_fit
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.export.code import export_fit
from ratfit.io.data import Dataset

P = "ISOTROPIC_TV_TL_DPHI"


@pytest.fixture(scope="module")
def non_reciprocal(tmp_path_factory):
    """f = 1 + theta_v on delta_phi in [0, pi]: not reciprocal, so f(V, L) = 1 + theta_l."""
    rng = np.random.default_rng(4)
    x = np.column_stack([rng.uniform(0, 1.3, 300), rng.uniform(0, 1.3, 300),
                         rng.uniform(0, np.pi, 300)])
    ds = Dataset(x=x, y=(1.0 + x[:, 0])[:, None], output_names=("R",),
                 meta={"param_in": P, "source": "non-reciprocal"})
    fitter, _seg, meta = fit_brdf(ds, dt=0.01, floor_rel=1e-3, jobs=1)
    assert fitter.success_
    path = tmp_path_factory.mktemp("sym") / "fit.json"
    save_brdf_fit(path, fitter.results_, meta)
    return brdf_fit_of(fitter.results_, meta), path


def _pairs():
    """Pairs with delta_phi < 0 and theta_v far from theta_l, and their mirror images."""
    tv, tl, dphi = np.array([0.3, 1.1, 0.6]), np.array([1.1, 0.2, 1.2]), np.array([-0.4, -1.5,
                                                                                   -2.8])
    p = get_parametrization(P)
    L, V = p.to_dirs(np.column_stack([tv, tl, dphi]))
    Lm, Vm = p.to_dirs(np.column_stack([tv, tl, -dphi]))
    return tv, tl, (L, V), (Lm, Vm)


def test_a_pair_outside_the_box_is_evaluated_at_its_mirror_image(non_reciprocal):
    fit, _path = non_reciprocal
    tv, tl, (L, V), (Lm, Vm) = _pairs()
    got = fit.eval_dirs(L, V)[:, 0]
    np.testing.assert_allclose(got, fit.eval_dirs(Lm, Vm)[:, 0], rtol=1e-12)
    np.testing.assert_allclose(got, 1.0 + tv, rtol=0.011)
    # the exchanged pair would give 1 + theta_l: 30-60 % away here
    assert np.all(np.abs(got - (1.0 + tl)) > 0.25 * (1.0 + tl))
    # continuous across delta_phi = 0
    p = get_parametrization(P)
    a, b = p.to_dirs(np.array([[0.3, 1.1, -1e-6], [0.3, 1.1, 1e-6]]))
    v = fit.eval_dirs(a, b)[:, 0]
    assert abs(v[0] - v[1]) < 1e-6 * v[1]


def test_the_exports_take_the_same_image(non_reciprocal, tmp_path):
    fit, path = non_reciprocal
    _tv, _tl, (L, V), _ = _pairs()
    ref = fit.eval_dirs(L, V)[:, 0]
    py = tmp_path / "fit.py"
    export_fit(path, "python", py)
    ns: dict = {}
    exec(compile(py.read_text(), str(py), "exec"), ns)
    got = np.array([ns["ratfit_brdf"](list(a), list(b))[0] for a, b in zip(L, V, strict=True)])
    np.testing.assert_allclose(got, ref, rtol=1e-9)
    c = tmp_path / "fit.c"
    export_fit(path, "c", c)
    np.testing.assert_allclose(exported_brdf_in_c(c, L, V, tmp_path)[:, 0], ref, rtol=1e-9)
