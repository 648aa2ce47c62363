"""The size of a default fit of scattered measurements is chosen by held-out error.

The search finds the fewest coefficients that meet every segment; at that size the
feasible set is thin, the fit runs along the segments' edges, and a least-squares polish
cannot move it (acryl_blue's B at +-65 %: diffuse fit / data 0.62). The default also
polishes the smallest fit at larger sizes, scores each by cross-validation, and keeps
the best one when it is proved valid like any fit."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import above_horizon

from ratfit.brdf.analytic_models import Model
from ratfit.brdf.fitter import (
    GROWTH_FACTORS,
    GROWTH_FOLDS,
    GROWTH_MIN_GAIN,
    _padded,
    brdf_fit_of,
    fit_brdf,
)
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.io.data import Dataset

FRAME = "RUSIN_TH_TD_SYM"
PARAMS = [0.02, 1.0, 0.2, 0.05]  # lambert+ggx: values 7e-3 .. 0.54 at these pairs


def _truth(L, V):
    return Model("lambert+ggx")(L, V, PARAMS)


def _noisy(n: int, noise: float, seed: int = 0) -> Dataset:
    """``n`` scattered measurements of a glossy lobe, each off by a random factor
    exp(N(0, noise)) (a gonioreflectometer's scatter)."""
    rng = np.random.default_rng(seed)
    L, V = above_horizon(rng, n), above_horizon(rng, n)
    y = _truth(L, V) * np.exp(rng.normal(0.0, noise, n))
    x = get_parametrization(FRAME)._from(L, V)
    return Dataset(x=x, y=y[:, None], output_names=("Y",),
                   meta={"param_in": FRAME, "source": "noisy lobe"})


def _rel_rms_to_truth(fitter, meta, seed: int = 7) -> float:
    """RMS of log((f + e) / (t + e)), e = 1e-3, against the material itself at pairs no
    sample was taken at."""
    rng = np.random.default_rng(seed)
    L, V = above_horizon(rng, 4000), above_horizon(rng, 4000)
    f = brdf_fit_of(fitter.results_, meta).eval_dirs(L, V)[:, 0]
    return float(np.sqrt(np.mean(np.log((f + 1e-3) / (_truth(L, V) + 1e-3)) ** 2)))


@pytest.fixture(scope="module")
def both():
    ds = _noisy(400, 0.2)
    grown = fit_brdf(ds, time_limit=None)
    smallest = fit_brdf(ds, time_limit=None, held_out_size=False)
    return ds, grown, smallest


def test_padding_a_fit_keeps_the_function():
    ds = _noisy(60, 0.0)
    fitter, _seg, _meta = fit_brdf(ds, dt=0.2, abs_width=1e-3, values="log",
                                   time_limit=None, held_out_size=False)
    rf = fitter.results_[0].rational.to_family()
    big = _padded(rf, rf.n + 7, rf.m + 3)
    assert (big.n, big.m) == (rf.n + 7, rf.m + 3)
    assert np.max(np.abs(big(ds.x) - rf(ds.x))) < 1e-12 * np.max(np.abs(rf(ds.x)))


def test_a_default_fit_of_scattered_data_records_its_held_out_sizes(both):
    _ds, (fitter, _seg, meta), _small = both
    assert fitter.success_
    rec = meta["held_out_size"][0]
    n, m = rec["searched"]
    assert rec["sizes"][0] == [n, m] and len(rec["sizes"]) == 1 + len(GROWTH_FACTORS)
    for g, (n2, m2) in zip(GROWTH_FACTORS, rec["sizes"][1:], strict=True):
        assert (n2, m2) == (int(np.ceil(g * n)), int(np.ceil(g * m)))
    assert rec["folds"] == GROWTH_FOLDS and rec["qp_solves"] > 0
    scores = rec["held_out_rel_rmse"]
    best = int(np.argmin(scores))
    res = fitter.results_[0]
    # the kept size is the best-scored one when it wins by the margin, else the smallest
    if best > 0 and scores[best] < (1 - GROWTH_MIN_GAIN) * scores[0]:
        assert rec["chosen"] == rec["sizes"][best] == [res.n, res.m]
        assert "lowest held-out relative RMSE" in res.message
    else:
        assert rec["chosen"] == [n, m] == [res.n, res.m]
    # proved like any fit
    assert meta["proof"][0]["proved"] is True


def test_noisy_measurements_get_a_larger_fit_that_is_closer_to_the_material(both):
    """Measurements scattered +-20 % around a lobe: the smallest fit meets their
    segments along the edges; the size chosen on held-out samples is larger and closer
    to the material itself at pairs no sample was taken at."""
    _ds, (grown, _s1, meta_g), (small, _s2, meta_s) = both
    assert grown.success_ and small.success_
    assert "held_out_size" not in meta_s
    rec = meta_g["held_out_size"][0]
    assert rec["chosen"] != rec["searched"]
    assert grown.results_[0].n + grown.results_[0].m > small.results_[0].n + small.results_[0].m
    # the same search underneath: the smallest fit's size is the searched one
    assert [small.results_[0].n, small.results_[0].m] == rec["searched"]
    e_grown, e_small = _rel_rms_to_truth(grown, meta_g), _rel_rms_to_truth(small, meta_s)
    # 0.114 against 0.124 under the envelope over (theta_h, theta_d) (2026-11-29); over
    # theta_h alone 0.143 against 0.162
    assert e_grown < 0.95 * e_small and e_grown < 0.13


def test_a_size_the_caller_gives_is_kept():
    ds = _noisy(120, 0.2)
    fitter, _seg, meta = fit_brdf(ds, max_total=30, time_limit=None)
    assert "held_out_size" not in meta
    assert fitter.results_[0].n + fitter.results_[0].m <= 30


def test_the_fit_says_which_sizes_held_out_samples_chose(both):
    from ratfit.jobs.brdf import _held_out_size_note

    _ds, (_fitter, _seg, meta), _small = both
    rec = meta["held_out_size"][0]
    note = _held_out_size_note(meta["held_out_size"], ["Y"])
    assert note.startswith(f"size: Y {sum(rec['searched'])} -> {sum(rec['chosen'])} ")
    assert "5-fold held-out relative error" in note and "--smallest-size" in note
    kept = dict(rec, chosen=rec["searched"])
    assert _held_out_size_note([kept, None], ["Y", "Z"]).startswith(
        f"size: the smallest verified (Y {sum(rec['searched'])}) had the lowest")


def test_held_out_size_is_refused_where_it_means_nothing():
    """It chooses the size of a fit of log values: asked for with p / q or a shared
    denominator it is an error, not an option silently dropped."""
    from ratfit.errors import InputError

    ds = _noisy(60, 0.1)
    chooses = r"held_out_size \(--held-out-size\) chooses the size of a fit of log values"
    with pytest.raises(InputError, match=chooses + r".*\(p / q\): drop it, or fit log"):
        fit_brdf(ds, values="linear", held_out_size=True, time_limit=None)
    with pytest.raises(InputError, match=chooses + ".*shared denominator: drop it$"):
        fit_brdf(ds, shared_denominator=True, held_out_size=True, time_limit=None)
