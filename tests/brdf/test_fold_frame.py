"""RUSIN_TH_TD_FOLD: a frame with reciprocity and isotropy at the mirror direction built
in but not mirror symmetry (RGL's measured tables are not mirror-symmetric; see
benchmarks/rgl_symmetry.py). Every evaluator gives the same value, also at the fold
phi_d = 0 / pi where in-plane pairs lie, and a fit in it is proved valid."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
from conftest import above_horizon, exported_brdf_in_c

from ratfit.brdf.fitter import BRDFFitter, load_brdf_fit
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.brdf.validity import prove_validity
from ratfit.core.bases import PolynomialSpace
from ratfit.core.rational import RationalFunction
from ratfit.core.segments import Segments
from ratfit.export.code import export_fit
from ratfit.io.fitfile import save_fit

P = "RUSIN_TH_TD_FOLD"
FRAME = get_parametrization(P)
DOMAIN = np.array(FRAME.bounds, dtype=float)


def _truth(c: np.ndarray) -> np.ndarray:
    """A reciprocal, isotropic BRDF that is not mirror-symmetric: it grows with
    u = sin(theta_h) cos(phi_d), which the mirror phi_d -> pi - phi_d negates."""
    return (1.0 + 0.5 * c[:, 2]) / (1.0 + 0.3 * c[:, 1] ** 2)


def _pairs(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Uniform random pairs over the whole hemisphere, grazing included."""
    rng = np.random.default_rng(seed)
    return above_horizon(rng, n, 0.0), above_horizon(rng, n, 0.0)


def _fit_file(tmp_path: Path, param: str = P) -> Path:
    """The truth itself as a fit file: p = 1 + 0.5 u, q = 1 + 0.3 theta_d^2 (FOLD); or,
    in MERL's folded axes (RUSIN_TH_TD_PD with phi_d in [0, pi)), p = 1 + 0.5 cos phi_d,
    which is far from periodic: its two ends, phi_d = 0 and pi, differ by 3x."""
    frame = get_parametrization(param)
    dom = np.array(frame.bounds, dtype=float)
    fold = param == "RUSIN_TH_TD_PD"
    if fold:
        dom[2] = [0.0, np.pi]
    space = PolynomialSpace("legendre", dom, "total")
    t = np.random.default_rng(0).uniform(-1, 1, (2000, 3))
    x = space.from_window(t)
    D = space.design(t, 10, window=True)  # total degree 2
    Dp = space.design(t, 220, window=True) if fold else D  # degree 9: cos to ~1e-9
    p = np.linalg.lstsq(Dp, 1.0 + 0.5 * (np.cos(x[:, 2]) if fold else x[:, 2]), rcond=None)[0]
    q = np.linalg.lstsq(D, 1.0 + 0.3 * x[:, 1] ** 2, rcond=None)[0]
    doc = {"format": "ratfit.fit", "version": 1, "space": space.to_dict(),
           "channels": [{"name": "R", "p": p.tolist(), "q": q.tolist(),
                         "diagnostics": {"verified": True}, "monomial": None}],
           "provenance": {},
           "brdf": {"parametrization": param, "cosine_weighted": False, "fold_phi_d": fold,
                    "channel_names": ["R"], "dropped_coords": {}}}
    path = tmp_path / "fit.json"
    save_fit(path, json.loads(json.dumps(doc)))
    return path


def _in_plane(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Pairs in the plane of incidence (phi_d on the fold, 0 or pi up to rounding): a
    third at random, a third within 1e-5 of the mirror direction and a third within
    1e-5 of L = V, where rounding moves phi_d most (~1e-16 / sin(theta_h or theta_d))."""
    rng = np.random.default_rng(seed)
    az = rng.uniform(-np.pi, np.pi, n)
    a = rng.uniform(0.05, 1.5, n)
    near = a + rng.uniform(-1e-5, 1e-5, n)
    b = np.concatenate([rng.uniform(0.05, 1.5, n - 2 * (n // 3)), near[: 2 * (n // 3)]])
    side = np.where(np.arange(n) < n - n // 3, -1.0, 1.0)  # the last third: V beside L
    L = np.stack([np.sin(a) * np.cos(az), np.sin(a) * np.sin(az), np.cos(a)], 1)
    V = np.stack([side * np.sin(b) * np.cos(az), side * np.sin(b) * np.sin(az), np.cos(b)], 1)
    return L, V


def test_coordinates_are_reciprocal_and_free_of_phi_d_at_the_mirror() -> None:
    L, V = _pairs(20_000, 1)
    c = FRAME.from_dirs(L, V)
    np.testing.assert_allclose(FRAME.from_dirs(V, L), c, atol=1e-12)
    assert np.all(np.abs(c[:, 2]) <= np.sin(c[:, 0]) + 1e-15)
    # theta_h = 0: V is L's mirror image; u = 0 whatever the azimuth
    m = FRAME.from_dirs(L, L * [-1, -1, 1])
    assert np.abs(m[:, 2]).max() < 1e-7
    # the mirror image y -> -y is a different point: phi_d -> pi - phi_d negates u
    flip = np.array([1.0, -1.0, 1.0])
    cm = FRAME.from_dirs(L * flip, V * flip)
    away = np.abs(c[:, 2]) > 0.1
    np.testing.assert_allclose(cm[away, 2], -c[away, 2], atol=1e-9)
    # the fold's two sides, phi_d = 0 and pi (u = +-sin theta_h), are one in-plane pair:
    # both convert back to phi_d = 0, and so does the exchanged pair
    th = np.linspace(0.1, 1.2, 5)
    for sign in (1.0, -1.0):
        edge = np.stack([th, np.full(5, 0.3), sign * np.sin(th)], axis=1)
        la, va = FRAME.to_dirs(edge)
        for a, b in ((la, va), (va, la)):
            np.testing.assert_allclose(FRAME.from_dirs(a, b)[:, 2], np.sin(th), atol=1e-12)


def test_every_evaluator_agrees_and_the_mirror_images_differ(tmp_path: Path) -> None:
    fit = load_brdf_fit(_fit_file(tmp_path))
    L, V = _pairs(50_000, 2)
    inplane_l, inplane_v = _in_plane(3000, 3)
    L, V = np.vstack([L, inplane_l]), np.vstack([V, inplane_v])
    ref = fit.eval_dirs(L, V)[:, 0]
    np.testing.assert_allclose(ref, _truth(FRAME.from_dirs(L, V)), rtol=1e-9)
    # reciprocal: the exchanged pair is the same computation (bit for bit)
    np.testing.assert_array_equal(fit.eval_dirs(V, L)[:, 0], ref)
    flip = np.array([1.0, -1.0, 1.0])
    mirrored = fit.eval_dirs(L * flip, V * flip)[:, 0]
    assert np.mean(np.abs(mirrored - ref) > 0.05 * ref) > 0.3
    # the mirror direction: one value over phi_d
    t = np.linspace(0.05, 1.4, 7)
    spread = []
    for td in t:
        ph = np.linspace(-np.pi, np.pi, 37)
        lm = np.stack([np.sin(td) * np.cos(ph), np.sin(td) * np.sin(ph), np.full(37, np.cos(td))],
                      1)
        vals = fit.eval_dirs(lm, lm * [-1, -1, 1])[:, 0]
        spread.append(vals.max() / vals.min() - 1.0)
    assert max(spread) < 1e-6
    py = tmp_path / "fit_export.py"
    export_fit(tmp_path / "fit.json", "python", py)
    spec = importlib.util.spec_from_file_location("fit_export", py)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    idx = np.r_[0:2000, len(L) - 3000:len(L)]
    got = np.array([mod.ratfit_brdf(a, b)[0] for a, b in zip(L[idx], V[idx], strict=True)])
    np.testing.assert_allclose(got, ref[idx], rtol=1e-6)
    src = tmp_path / "f.c"
    export_fit(tmp_path / "fit.json", "c", src)
    np.testing.assert_allclose(exported_brdf_in_c(src, L, V, tmp_path)[:, 0], ref, rtol=1e-6)


def test_a_fit_of_mirror_asymmetric_data_is_proved() -> None:
    rng = np.random.default_rng(5)
    L, V = _pairs(4000, 6)
    x = FRAME.from_dirs(L, V)
    x = x[rng.permutation(len(x))[:400]]
    y = _truth(x)
    seg = Segments.from_bounds(x, 0.97 * y, 1.03 * y, y)
    fitter = BRDFFitter(parametrization=P, max_total=30).fit(seg)
    res = fitter.results_[0]
    assert res.success and res.n + res.m <= 30
    rf: RationalFunction = res.rational
    proof = prove_validity(rf, P)
    assert proof.proved and proof.q.margin > 0
    # held-out pairs: the fit follows the asymmetric truth, within the segments' width
    L2, V2 = _pairs(5000, 7)
    x2 = FRAME.from_dirs(L2, V2)
    inside = np.all((x2 >= rf.space.domain[:, 0]) & (x2 <= rf.space.domain[:, 1]), axis=1)
    rel = np.abs(rf(x2[inside]) / _truth(x2[inside]) - 1.0)
    assert np.median(rel) < 0.03 and np.percentile(rel, 99) < 0.1


def test_merl_folded_axes_are_reciprocal_at_the_fold(tmp_path: Path) -> None:
    """A fit in MERL's axes with phi_d folded into [0, pi) (how a MERL table is fitted
    in RUSIN_TH_TD_PD) is reciprocal through the fold: phi_d and phi_d + pi are one
    value. In the plane of incidence phi_d is 0 or pi up to rounding, and folding it by
    np.mod sent a pair and its exchange to opposite ends (21 % of random in-plane pairs;
    in this box, which holds phi_d = pi, values 1.5 against 0.5). Every evaluator gives
    one value for both."""
    fit = load_brdf_fit(_fit_file(tmp_path, "RUSIN_TH_TD_PD"))
    L, V = _in_plane(3000, 8)
    ref = fit.eval_dirs(L, V)[:, 0]
    np.testing.assert_array_equal(fit.eval_dirs(V, L)[:, 0], ref)
    # in the plane phi_d counts as 0 (the fold's lower end): p = 1.5 there
    c = get_parametrization("RUSIN_TH_TD_PD").from_dirs(L, V)
    np.testing.assert_allclose(ref, 1.5 / (1.0 + 0.3 * c[:, 1] ** 2), rtol=1e-6)
    # off the plane, a pair and its exchange still agree (phi_d + pi folds onto phi_d)
    L2, V2 = _pairs(5000, 9)
    np.testing.assert_allclose(fit.eval_dirs(V2, L2), fit.eval_dirs(L2, V2), rtol=1e-9)
    py = tmp_path / "fit_export.py"
    export_fit(tmp_path / "fit.json", "python", py)
    spec = importlib.util.spec_from_file_location("fit_export_pd", py)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    for a, b in ((L, V), (V, L)):
        got = np.array([mod.ratfit_brdf(u, v)[0] for u, v in zip(a, b, strict=True)])
        np.testing.assert_allclose(got, ref, rtol=1e-6)
    src = tmp_path / "f.c"
    export_fit(tmp_path / "fit.json", "c", src)
    both = exported_brdf_in_c(src, np.vstack([L, V]), np.vstack([V, L]), tmp_path)[:, 0]
    np.testing.assert_allclose(both, np.r_[ref, ref], rtol=1e-6)
