"""A fit of log values is exp(p / q): positive wherever q > 0, and otherwise bounded by
nothing its samples say (default log fits of Cornell files reached 1e71 and overflowed to
inf between their samples). The search, the polish, the dense check and the proof keep
p / q <= C, C the log of twice the channel's largest segment end, so every evaluated
value is at most exp(C), proved by Bernstein bounds on the stored coefficients."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import above_horizon
from test_log_values import WIDTHS, _material

from ratfit.brdf.fitter import (
    LOG_CEILING_FACTOR,
    fit_brdf,
    load_brdf_fit,
    log_ceilings,
    save_brdf_fit,
)
from ratfit.brdf.io import read_brdf, samples_dataset
from ratfit.brdf.validity import check_validity, prove_validity, reprove_saved
from ratfit.core.bases import PolynomialSpace
from ratfit.core.polish import _positivity_rows
from ratfit.core.rational import RationalFunction
from ratfit.core.systems import AppendedRows
from ratfit.io.fitfile import scope_text

P = "RUSIN_TH_TD_PD"
DOMAIN = np.array([[0.0018, 1.385], [0.15, 1.388], [0.0, np.pi]])


def _spike(height: float) -> RationalFunction:
    """p / q = 1 / (|t - c|^2 + 1 / height): ``height`` at c, a valid configuration
    0.01 rad off the mirror direction, and at most ~1 at the box's far corners."""
    space = PolynomialSpace("legendre", DOMAIN, "total")
    c = space.to_window(np.array([[0.01, 0.6, 1.0]]))[0]
    t = np.random.default_rng(0).uniform(-1, 1, (4000, 3))
    q = np.linalg.lstsq(space.design(t, 10, window=True),
                        np.sum((t - c) ** 2, axis=1) + 1.0 / height, rcond=None)[0]
    p = np.zeros(10)
    p[0] = 1.0
    return RationalFunction(space, p, q)


def test_the_proof_refutes_a_log_fit_that_passes_its_ceiling_between_samples() -> None:
    rf = _spike(1000.0)  # exp(1000) overflows: a value no evaluator can return
    low = prove_validity(rf, P, values="log", ceiling=50.0)
    assert not low.proved and low.refuted and low.ceiling == 50.0
    assert "at most" in low.summary() and "NOT PROVED" in low.summary()
    near = np.linalg.norm(rf.space.to_window(low.bad_points)
                          - rf.space.to_window(np.array([[0.01, 0.6, 1.0]])), axis=1)
    # the rows go where the spike is: points past the ceiling, beside it
    assert len(near) and near.min() < 0.25 and rf(low.bad_points).max() > 50.0
    high = prove_validity(rf, P, values="log", ceiling=1100.0)
    assert high.proved and high.p.margin > 0
    d = high.to_dict()  # exp(1100) is past float64: no bound a file could store
    assert d["ceiling"] == 1100.0 and d["value_bound"] is None
    assert "at most inf" in high.summary()
    # without a ceiling only q > 0 is proved, as for files written before it
    assert prove_validity(rf, P, values="log").proved


def test_the_dense_check_finds_where_p_over_q_passes_the_ceiling() -> None:
    rf = _spike(1000.0)
    chk = check_validity(rf, P, values="log", ceiling=50.0)
    assert chk is not None and not chk.valid and chk.min_r < 0
    ratio = rf(chk.bad_points)
    assert len(ratio) and np.all(ratio > 50.0)
    ok = check_validity(rf, P, values="log", ceiling=1100.0)
    assert ok is not None and ok.valid


class _NoRows:
    """A base system with no rows of its own (only appended ones)."""

    n_rows, n_points = 0, 0
    space = t = None

    def rows(self, n, m, ridx):
        return np.zeros((len(ridx), n + m))

    def residuals(self, n, m, c):
        return np.zeros(0)

    def row_norms(self, n, m):
        return np.zeros(0)


def test_appended_bound_rows_act_on_both_blocks() -> None:
    rng = np.random.default_rng(1)
    n, m = 3, 4
    psi, phi, chi = rng.normal(size=(2, m)), rng.normal(size=(5, n)), rng.normal(size=(6, n + m))
    sys_ = AppendedRows(_NoRows(), n, m, psi=psi, phi=phi, chi=chi)
    c = rng.normal(size=n + m)
    assert sys_.n_rows == 13
    np.testing.assert_allclose(sys_.rows(n, m) @ c, sys_.residuals(n, m, c))
    np.testing.assert_allclose(sys_.residuals(n, m, c)[7:], chi @ c)
    np.testing.assert_array_equal(sys_.rows(n, m, np.array([12]))[0], chi[5])


def test_the_polish_rows_keep_p_over_q_below_the_ceiling() -> None:
    rf = _spike(1000.0)
    pts = np.array([[0.01, 0.6, 1.0], [1.0, 1.0, 2.0]])
    grid, inv = _positivity_rows(rf, pts, numerator=False, ceiling=50.0)
    c = np.concatenate([rf.p, rf.q])
    assert grid.shape == (4, 20)
    np.testing.assert_array_equal(inv[:2], 0.0)
    bound = grid[2:] @ c / inv[2:]  # the rows as C q - p at each point
    np.testing.assert_allclose(bound, 50.0 * rf.denominator(pts) - rf.numerator(pts),
                               rtol=1e-12, atol=1e-12)
    assert bound[0] < 0 < bound[1]  # p / q = 1000 at the spike, below 50 far from it


@pytest.fixture(scope="module")
def fitted():
    ds = _material(300)
    return ds, fit_brdf(ds, values="log", **WIDTHS)


def test_a_log_fit_is_proved_below_twice_its_largest_segment_end(fitted, tmp_path) -> None:
    ds, (fitter, seg, meta) = fitted
    assert fitter.success_
    proof = fitter.proofs_[0]
    top = float(np.max(seg.hi[:, 0]))
    assert proof.proved and proof.ceiling == pytest.approx(np.log(LOG_CEILING_FACTOR * top))
    np.testing.assert_allclose(log_ceilings(seg), [proof.ceiling])
    assert meta["proof"][0]["value_bound"] == pytest.approx(LOG_CEILING_FACTOR * top)
    path = tmp_path / "fit.json"
    save_brdf_fit(path, fitter.results_, meta)
    fit = load_brdf_fit(path)
    rng = np.random.default_rng(5)
    L, V = above_horizon(rng, 200_000, z_min=0.0), above_horizon(rng, 200_000, z_min=0.0)
    v = fit.eval_dirs(L, V)[:, 0]
    assert np.all(np.isfinite(v)) and v.max() <= LOG_CEILING_FACTOR * top
    assert reprove_saved(fit.saved) is True
    assert f"exp(p/q) <= {LOG_CEILING_FACTOR * top:.4g}" in scope_text(fit.saved, True)
    # a stored bound below the fit's own values is not proved again
    brdf = dict(fit.saved.extra["brdf"])
    brdf["proof"] = [{**brdf["proof"][0], "ceiling": float(np.log(0.5 * v.max()))}]
    assert reprove_saved(replace(fit.saved, extra={**fit.saved.extra, "brdf": brdf})) is False


@pytest.mark.slow
def test_a_cornell_log_fit_stays_finite_and_bounded_everywhere(shared_data) -> None:
    """garnet_red's log fit reached 1.2e71 (G) and 7e135 (B) between its samples before
    the ceiling; now its 1e5 random pairs over the hemisphere stay below the bound."""
    from ratfit.brdf.fitter import candidate_parametrizations, fit_brdf_auto

    s = read_brdf(shared_data / "cornell" / "garnet_red.brdf")
    frames = [samples_dataset(s, p) for p in candidate_parametrizations("ISOTROPIC_TV_TL_DPHI")]
    fitter, seg, meta = fit_brdf_auto(frames, values="log")
    assert fitter.success_
    from ratfit.brdf.fitter import brdf_fit_of

    fit = brdf_fit_of(fitter.results_, meta)
    rng = np.random.default_rng(2)
    L, V = above_horizon(rng, 100_000, z_min=0.0), above_horizon(rng, 100_000, z_min=0.0)
    v = fit.eval_dirs(L, V)
    bounds = np.array([p["value_bound"] for p in meta["proof"]])
    assert np.all(np.isfinite(v)) and np.all(v.max(axis=0) <= bounds)
    np.testing.assert_allclose(bounds, LOG_CEILING_FACTOR * np.max(seg.hi, axis=0))
