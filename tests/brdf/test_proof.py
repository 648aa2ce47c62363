"""Physical validity proved, not sampled: a BRDF fit with a pole or a negative value
anywhere it is evaluated (near the mirror direction too) is never a success, and every
evaluator (``BRDFFit``, the C and Python exports, the renderer's material) computes the
same non-negative number at every pair of directions above the horizon."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import above_horizon, exported_brdf_in_c

from ratfit.brdf.fitter import BRDFFitter, load_brdf_fit
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.brdf.validity import check_validity, prove_validity
from ratfit.core.bases import PolynomialSpace
from ratfit.core.rational import RationalFunction
from ratfit.core.segments import Segments
from ratfit.export.code import export_fit
from ratfit.io.fitfile import save_fit

P = "RUSIN_TH_TD_PD"
# a box like a Cornell file's: theta_h from just off the mirror direction
DOMAIN = np.array([[0.0018, 1.385], [0.15, 1.388], [0.0, np.pi]])


def _poly(space: PolynomialSpace, f, count: int) -> np.ndarray:
    """Coefficients (graded, the space's family) of the polynomial f(t) of the window
    variables t, exact up to rounding: least squares on many points."""
    t = np.random.default_rng(0).uniform(-1, 1, (4000, space.dim))
    return np.linalg.lstsq(space.design(t, count, window=True), f(t), rcond=None)[0]


def _rational(q_dip: float) -> RationalFunction:
    """p / q with p > 0 and q = |t - c|^2 + q_dip, c a valid configuration 0.01 rad off
    the mirror direction, between any reasonable sampling grid's points."""
    space = PolynomialSpace("legendre", DOMAIN, "total")
    c = space.to_window(np.array([[0.01, 0.6, 1.0]]))[0]
    q = _poly(space, lambda t: np.sum((t - c) ** 2, axis=1) + q_dip, 10)
    p = _poly(space, lambda t: 1.0 + 0.25 * t[:, 0] + 0.1 * t[:, 1] ** 2, 10)
    return RationalFunction(space, p, q)


def _samples(rf: RationalFunction) -> Segments:
    """A coarse gonioreflectometer-like set of samples, far from the dip."""
    g = [np.linspace(lo + 0.2 * (hi - lo), hi, 6) for lo, hi in DOMAIN]
    x = np.stack([a.ravel() for a in np.meshgrid(*g, indexing="ij")], axis=1)
    y = rf(x)
    return Segments.from_bounds(x, 0.5 * y, 2.0 * y, y)


def test_a_negative_dip_near_the_mirror_is_never_a_success() -> None:
    rf = _rational(-1e-7)
    seg = _samples(rf)
    fitter = BRDFFitter(parametrization=P)
    ver = fitter._verify(rf, seg, 0)
    assert ver.n_violations == 0  # every segment is met ...
    assert not ver.verified  # ... and the fit is still refused
    proof = prove_validity(rf, P)
    assert not proof.proved and proof.q.counterexample
    # the counterexample is the dip, 0.01 rad from the mirror direction
    assert np.min(np.abs(proof.bad_points[:, 0] - 0.01)) < 0.01
    assert np.all(rf.denominator(proof.bad_points[:1]) < 0)


def test_the_dense_check_alone_misses_what_the_proof_finds() -> None:
    rf = _rational(-1e-9)
    chk = check_validity(rf, P)
    proof = prove_validity(rf, P)
    assert chk is not None and chk.valid  # the grid and compass search see nothing
    assert not proof.proved  # the proof does


def test_a_positive_fit_is_proved_with_its_margin() -> None:
    rf = _rational(1e-3)
    proof = prove_validity(rf, P)
    assert proof.proved
    assert 0 < proof.q.margin <= 1e-3 / 1.0  # min q = 1e-3, max |q| >= 1
    assert proof.to_dict()["proved"] is True


def _fit_file(tmp_path: Path, q_dip: float = 1e-3, claim: bool = False) -> Path:
    rf = _rational(q_dip)
    space = rf.space
    doc = {"format": "ratfit.fit", "version": 1, "space": space.to_dict(),
           "channels": [{"name": "R", "p": rf.p.tolist(), "q": rf.q.tolist(),
                         "diagnostics": {"verified": True}, "monomial": None}],
           "provenance": {},
           "brdf": {"parametrization": P, "cosine_weighted": False, "fold_phi_d": False,
                    "channel_names": ["R"], "dropped_coords": {},
                    **({"proof": [{"proved": True}]} if claim else {})}}
    path = tmp_path / "fit.json"
    save_fit(path, json.loads(json.dumps(doc)))
    return path


def _hemisphere(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Uniform random pairs over the whole hemisphere (grazing and mirror included)."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(2):
        ct, ph = rng.uniform(0.0, 1.0, n), rng.uniform(-np.pi, np.pi, n)
        st = np.sqrt(1 - ct**2)
        out.append(np.stack([st * np.cos(ph), st * np.sin(ph), ct], 1))
    L, V = out
    V[:200] = L[:200] * [-1, -1, 1]  # exact mirror pairs: theta_h = 0
    return L, V


def test_every_evaluator_gives_the_same_nonnegative_value(tmp_path: Path) -> None:
    from ratfit.render.material import FitMaterial

    fit = load_brdf_fit(_fit_file(tmp_path))
    L, V = _hemisphere(100_000, 4)
    ref = fit.eval_dirs(L, V)[:, 0]
    assert np.all(np.isfinite(ref)) and np.all(ref >= 0)
    # the renderer's material
    mat = FitMaterial(fit)
    np.testing.assert_allclose(mat.raw(L, V)[:, 0], ref, rtol=1e-12)
    # the exported Python, on a subset (a Python loop)
    py = tmp_path / "fit_export.py"
    export_fit(tmp_path / "fit.json", "python", py)
    spec = importlib.util.spec_from_file_location("fit_export", py)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    got = np.array([mod.ratfit_brdf(a, b)[0] for a, b in zip(L[:3000], V[:3000],
                                                               strict=True)])
    np.testing.assert_allclose(got, ref[:3000], rtol=1e-6)
    # the exported C, on all of them
    src = tmp_path / "f.c"
    export_fit(tmp_path / "fit.json", "c", src)
    c_vals = exported_brdf_in_c(src, L, V, tmp_path)[:, 0]
    np.testing.assert_allclose(c_vals, ref, rtol=1e-6)
    assert np.all(c_vals >= 0)
    # theta_h = 0 is clipped to the box like any other pair outside it
    assert get_parametrization(P).from_dirs(L[:200], V[:200])[:, 0].max() < 1e-7


@pytest.mark.parametrize("name", ["RUSIN_TH_TD_PD", "RUSIN_TH_TD_SYM", "RUSIN_TH_TD_FOLD",
                                  "STARK_2D"])
def test_no_evaluated_point_lies_in_an_excluded_piece(name: str) -> None:
    """The proof leaves out pieces of the box that no pair above the horizon reaches; every
    point where a fit is evaluated (random pairs over the whole hemisphere, through
    BRDFFit.coords' symmetries and clip) must lie outside every excluded piece, here
    tested with a small piece around each point."""
    from ratfit.brdf.fitter import BRDFFit
    from ratfit.brdf.validity import _EXCLUDERS

    p = get_parametrization(name)
    L, V = _hemisphere(200_000, 11)
    box = {"RUSIN_TH_TD_PD": DOMAIN, "STARK_2D": np.array([[0.05, 0.95], [0.1, 0.99]]),
           "RUSIN_TH_TD_SYM": np.array([[0.0018, 1.385], [0.15, 1.388], [-0.7, 0.9]]),
           "RUSIN_TH_TD_FOLD": np.array([[0.0018, 1.385], [0.15, 1.388], [-0.8, 0.95]])}[name]
    space = PolynomialSpace("legendre", box, "total")
    # BRDFFit.coords reads only the saved fit's box
    fit = BRDFFit(SimpleNamespace(space=space), p.name)  # type: ignore[arg-type]
    coords = fit.coords(L, V)[0]
    t = space.to_window(coords)
    exclude = _EXCLUDERS[name](space)
    for h in (0.0, 1e-3, 0.05):
        lo, hi = np.clip(t - h, -1, 1), np.clip(t + h, -1, 1)
        assert not exclude(lo, hi).any()
    # and the exclusion does drop a real part of the box (pairs below the horizon)
    g = np.linspace(-1, 1, 9)
    c = np.stack([a.ravel() for a in np.meshgrid(*([g] * p.dim), indexing="ij")], axis=1)
    assert exclude(c, c).mean() > 0.05



def test_a_stored_proof_is_proved_again_before_an_export_claims_it(tmp_path: Path) -> None:
    """A digest can be recomputed by anyone: a file that says "proved" while its q dips
    below zero near the mirror direction gets no proof claim in its exported code; the
    same claim on a valid fit is kept."""
    for dip, claimed in ((-1e-7, False), (1e-3, True)):
        path = _fit_file(tmp_path, dip, claim=True)
        out = tmp_path / "f.py"
        export_fit(path, "python", out)
        head = out.read_text().split("\n\n")[0]
        assert ("q > 0 and p >= 0 proved" in head) is claimed, head


@pytest.mark.parametrize("name", ["RUSIN_TH_TD_PD", "RUSIN_TH_TD_SYM", "RUSIN_TH_TD_FOLD"])
def test_validity_rows_cover_the_retro_face(name: str) -> None:
    """At theta_d = 0 (L = V) phi_d is undefined, so a round trip through directions moves
    every point of that face to phi_d = 0; pairs with theta_d -> 0 still reach them all.
    The box's validity rows hold that face, and each row is within a hair of a pair."""
    from ratfit.brdf.validity import box_configurations

    p = get_parametrization(name)
    dom = np.array(p.bounds, dtype=float)
    dom[0, 1], dom[1, 1] = 1.50, 1.55  # as far up as a MERL table's cells
    if name == "RUSIN_TH_TD_PD":
        dom[2] = [0.0, np.pi]
    rows = box_configurations(name, dom, 8000)
    face = rows[rows[:, 1] == 0.0]
    assert len(face) > 150  # 20 x 20 grid points on the face, of which ~half are pairs' limits
    assert len(np.unique(np.round(face[:, 2], 9))) > 10  # many phi_d (or u, s), not one
    # every row is a limit of valid pairs: a pair exists within 1e-5 of it
    L, V = p.to_dirs(face + 1e-6 * (dom.mean(axis=1) - face))
    back = p.from_dirs(L, V)
    np.testing.assert_allclose(back, face, atol=1e-5)


def test_the_proof_takes_q_sign_where_pairs_are() -> None:
    """q positive wherever the fit is evaluated but negative on average over its box
    (its constant coefficient < 0: pieces no pair reaches carry much of the box) is
    proved positive, not "refuted" by a proof of -q > 0. In RUSIN_TH_TD_FOLD no pair has
    |u| > sin(theta_h), and on this box's faces the clipped images keep |u| <= theta_h,
    so q = 1 + 400 u^2 (theta_h^2 - u^2) >= 1 where the fit is evaluated; its mean over
    the box is 1 + 400 * 0.5^4 (1/9 - 1/5) = -1.2."""
    fold = "RUSIN_TH_TD_FOLD"
    dom = np.array([[0.0, 0.5], [0.0, 0.5], [-0.5, 0.5]])  # every pair above the horizon
    space = PolynomialSpace("legendre", dom, "total")

    def q_of(t: np.ndarray) -> np.ndarray:
        x = space.from_window(t)
        return 1.0 + 400.0 * x[:, 2] ** 2 * (x[:, 0] ** 2 - x[:, 2] ** 2)

    rf = RationalFunction(space, _poly(space, lambda t: np.ones(len(t)), 1),
                          _poly(space, q_of, 35))
    assert rf.to_family().q[0] < -1.0  # the mean over the box
    rng = np.random.default_rng(1)
    L, V = above_horizon(rng, 20_000, 0.0), above_horizon(rng, 20_000, 0.0)
    x = np.clip(get_parametrization(fold).from_dirs(L, V), dom[:, 0], dom[:, 1])
    assert np.all(rf.denominator(x) >= 1.0 - 1e-9)  # where the fit is evaluated
    proof = prove_validity(rf, fold, values="log")
    assert proof.proved and proof.q.margin > 0, proof.summary()
    # a q that does dip below 0 where pairs are is still refuted
    bad = RationalFunction(space, rf.p, _poly(space, lambda t: q_of(t) - 1.5, 35))
    assert not prove_validity(bad, fold, values="log").proved
