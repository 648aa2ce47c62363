"""Scattered measurements leave most direction pairs unsampled (every Cornell sample lies
in the plane of incidence), and a log fit's proved ceiling is its channel's highlight:
the default fits rose to 28-1 681 1/sr off the highlight (theta_h > 0.3, where no sample
exceeds 0.06) at pairs away from the plane, the renders' fireflies. The search's and the
polish's validity rows keep p / q under the samples' envelope over theta_h instead, and
the validity proof proves it (with twice the slack) on the whole evaluated region."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import above_horizon
from test_log_ceiling import _spike
from test_log_values import WIDTHS, _material

from ratfit.brdf.fitter import (
    CEILING_ROW_MARGIN,
    ENVELOPE_PROOF_SLACK,
    ENVELOPE_SLACK,
    LOG_CEILING_FACTOR,
    BRDFFitter,
    brdf_segments,
    fit_brdf,
    theta_h_column,
)
from ratfit.brdf.io import read_brdf, samples_dataset
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.brdf.validity import StepCeiling, reprove_saved
from ratfit.core.polish import _positivity_rows
from ratfit.core.positivity import prove_below
from ratfit.io.fitfile import load_fit, scope_text


def _by_hand(theta_h, top, t, slack):
    """log(2 x the largest top among the samples with theta_h >= t - slack), the
    farthest sample's past them all: the envelope, one point at a time."""
    th, top = np.asarray(theta_h, float), np.asarray(top, float)
    out = []
    for v in np.atleast_1d(t):
        near = th >= v - slack
        out.append(np.log(LOG_CEILING_FACTOR * (top[near].max() if near.any()
                                                else top[np.argmax(th)])))
    return np.array(out)


def test_the_envelope_is_the_largest_upper_end_at_least_as_far_from_the_mirror() -> None:
    env = StepCeiling.of_samples(0, [1.0, 0.0, 0.5, 0.1], [0.5, 100.0, 1.0, 10.0],
                                 ENVELOPE_SLACK, LOG_CEILING_FACTOR)
    t = np.array([0.0, 0.16, 0.3, 0.56, 2.0])
    # theta_h >= t - 0.05: all four; 0.5 and 1.0 (0.1 lies below 0.11); 0.5 and 1.0;
    # 1.0 alone; past the farthest sample, that sample's
    expect = LOG_CEILING_FACTOR * np.array([100.0, 1.0, 1.0, 0.5, 0.5])
    np.testing.assert_allclose(np.exp(env.at(t)), expect, rtol=1e-12)
    # a point within the slack of a sample counts it
    assert np.exp(env.at(0.14)) == pytest.approx(LOG_CEILING_FACTOR * 10.0)
    assert ENVELOPE_SLACK == 0.05


def test_theta_h_is_found_among_the_kept_coordinates() -> None:
    assert theta_h_column("RUSIN_TH_TD_SYM", None) == 0
    assert theta_h_column("RUSIN_TH_TD_PD", (1, 0, 2)) == 1
    assert theta_h_column("RUSIN_TH_TD_PD", (1, 2)) is None  # theta_h dropped as constant
    assert theta_h_column("ISOTROPIC_TV_TL_DPHI", None) is None


def test_the_polish_rows_take_one_ceiling_per_point() -> None:
    rf = _spike(1000.0)
    pts = np.array([[0.01, 0.6, 1.0], [1.0, 1.0, 2.0], [0.5, 0.8, 0.5]])
    ceil = np.array([2000.0, 50.0, -3.0])
    grid, inv = _positivity_rows(rf, pts, numerator=False, ceiling=ceil)
    c = np.concatenate([rf.p, rf.q])
    bound = grid[3:] @ c / inv[3:]
    np.testing.assert_allclose(bound, ceil * rf.denominator(pts) - rf.numerator(pts),
                               rtol=1e-12, atol=1e-12)
    assert bound[0] > 0  # 1000 at the spike, under its own 2000


def test_row_ceilings_are_the_envelope_under_the_channel_ceiling() -> None:
    ds = _material(200)
    f = BRDFFitter(parametrization="RUSIN_TH_TD_SYM", values="log", envelope=True)
    seg = brdf_segments(ds, dt=WIDTHS["dt"], abs_width=WIDTHS["abs_width"])
    f._ceilings = np.log(LOG_CEILING_FACTOR * seg.hi.max(axis=0))
    f._envelopes = f._theta_h_envelopes(seg, ENVELOPE_SLACK)
    pts = np.array([[0.0018, 0.5, 0.0], [0.6, 0.5, 0.0], [1.3, 0.5, 0.0]])
    rows = f._row_ceiling(0, pts)
    env = _by_hand(seg.x[:, 0], seg.hi[:, 0], pts[:, 0], ENVELOPE_SLACK)
    np.testing.assert_allclose(rows, np.minimum(env, f._ceilings[0]) - CEILING_ROW_MARGIN)
    assert rows[0] == pytest.approx(f._ceilings[0] - CEILING_ROW_MARGIN)  # the highlight
    assert rows[2] < rows[1] < rows[0]  # the lobe falls off away from the mirror
    f.envelope = False
    f._envelopes = f._theta_h_envelopes(seg, ENVELOPE_SLACK)
    assert f._row_ceiling(0, pts) == pytest.approx(f._ceilings[0] - CEILING_ROW_MARGIN)


def test_scattered_log_fits_keep_an_envelope_and_say_so() -> None:
    ds = _material(300)
    fitter, _seg, meta = fit_brdf(ds, values="log", **WIDTHS)
    assert fitter.success_ and fitter.envelope is True
    assert meta["envelope"] == {"coordinate": "theta_h", "slack": ENVELOPE_SLACK,
                                "proof_slack": ENVELOPE_PROOF_SLACK,
                                "factor": LOG_CEILING_FACTOR, "proved": True}
    lin = fit_brdf(ds, values="linear", **WIDTHS)
    assert lin[0].envelope is False and lin[2]["envelope"] is None
    off = fit_brdf(ds, values="log", envelope=False, **WIDTHS)
    assert off[0].envelope is False and off[2]["envelope"] is None
    assert all("envelope" not in p for p in off[2]["proof"])


def test_the_step_ceiling_falls_past_each_record_sample_by_its_slack() -> None:
    # samples at theta_h 0, 0.2, 0.2, 0.5 with upper ends 10, 1, 3, 0.1
    sc = StepCeiling.of_samples(0, [0.2, 0.0, 0.5, 0.2], [1.0, 10.0, 0.1, 3.0],
                                slack=0.1, factor=2.0)
    # the largest end at theta_h >= t - 0.1 falls from 10 past 0.1, from 3 past 0.3
    # (the two samples at 0.2 fall together) and from 0.1 never (the farthest sample)
    np.testing.assert_allclose(sc.theta_h, [0.0, 0.2])
    assert sc.slack == 0.1
    np.testing.assert_allclose(np.exp(sc.log_ceiling), [20.0, 6.0, 0.2])
    t = np.array([-1.0, 0.1, 0.1000001, 0.3, 0.31, 5.0])
    np.testing.assert_allclose(np.exp(sc.at(t)), [20.0, 20.0, 6.0, 6.0, 0.2, 0.2])
    np.testing.assert_allclose(sc.at(t), _by_hand([0.2, 0.0, 0.5, 0.2],
                                                  [1.0, 10.0, 0.1, 3.0], t, 0.1), rtol=1e-12)
    # an entry without a slack (commit a74032d wrote the steps with it added) reads as 0
    old = {"column": 0, "theta_h": [0.1, 0.3], "log_ceiling": sc.log_ceiling.tolist()}
    before = StepCeiling.from_dict({"envelope": old})
    assert before is not None and before.slack == 0.0
    np.testing.assert_array_equal(before.at(t), sc.at(t))
    # a file's entry round-trips; a rising or malformed one is no ceiling
    back = StepCeiling.from_dict({"envelope": sc.to_dict()})
    assert back is not None and back.column == 0
    np.testing.assert_array_equal(back.theta_h, sc.theta_h)
    np.testing.assert_array_equal(back.log_ceiling, sc.log_ceiling)
    bad = sc.to_dict() | {"log_ceiling": [0.0, 1.0, 2.0]}
    assert StepCeiling.from_dict({"envelope": bad}) is None
    assert StepCeiling.from_dict({"envelope": sc.to_dict() | {"column": "0"}}) is None
    assert StepCeiling.from_dict({"envelope": sc.to_dict() | {"slack": -0.1}}) is None
    assert StepCeiling.from_dict({"ceiling": 3.0}) is None


def test_a_step_bound_is_proved_piece_by_piece() -> None:
    """p = -t under C = 2 for t <= 0 and 0.1 past it: p < C everywhere. On the whole
    box the bound is C's smaller value, and the corner t = -1 (p = 1) exceeds it: only a
    piece where C is one number throughout may show a counterexample."""
    q, p = np.array([1.0, 0.0]), np.array([0.0, -1.0])  # Legendre: q = 1, p = -t

    def step(lo, hi):
        c = np.where(hi[:, 0] > 0.0, 0.1, 2.0)
        return c, np.where(lo[:, 0] >= 0.0, True, hi[:, 0] <= 0.0)

    ok = prove_below(q, p, "legendre", step)
    assert ok.proved and not ok.counterexample and ok.boxes >= 3

    # under C = 0.3 past t = -0.5, p = -t exceeds it on (-0.5, -0.3): refuted there
    def low(lo, hi):
        c = np.where(hi[:, 0] > -0.5, 0.3, 2.0)
        return c, np.where(lo[:, 0] >= -0.5, True, hi[:, 0] <= -0.5)

    no = prove_below(q, p, "legendre", low)
    assert not no.proved and no.counterexample
    assert np.all((no.points[:, 0] >= -0.5) & (no.points[:, 0] <= -0.3))


def test_log_fits_prove_their_envelope_and_a_file_is_proved_again(tmp_path) -> None:
    from ratfit.brdf.fitter import save_brdf_fit

    ds = _material(300)
    fitter, _seg, meta = fit_brdf(ds, values="log", **WIDTHS)
    assert fitter.success_
    proof = fitter.proofs_[0]
    assert proof.proved and proof.envelope is not None
    assert "samples' envelope over theta_h" in proof.summary()
    entry = meta["proof"][0]
    assert entry["envelope"]["column"] == 0 and len(entry["envelope"]["log_ceiling"]) >= 2
    # the proved steps are the samples' envelope with the proof's slack
    seg = brdf_segments(ds, dt=WIDTHS["dt"], abs_width=WIDTHS["abs_width"])
    t = np.linspace(0.0, 1.5, 301)
    env = _by_hand(seg.x[:, 0], seg.hi[:, 0], t, ENVELOPE_PROOF_SLACK)
    np.testing.assert_allclose(proof.envelope.at(t), env, rtol=1e-12)
    path = tmp_path / "fit.json"
    save_brdf_fit(path, fitter.results_, meta)
    saved = load_fit(path)
    assert reprove_saved(saved) is True
    assert "under the samples' envelope over theta_h" in scope_text(saved, True)
    # a lower envelope than the fit's values is not proved from the same numbers
    stated = saved.extra["brdf"]["proof"][0]["envelope"]
    stated["log_ceiling"] = [min(stated["log_ceiling"]) - 8.0] * len(stated["log_ceiling"])
    assert reprove_saved(saved) is False
    # an envelope the file states but that cannot be read proves nothing, nor one
    # over another coordinate than theta_h
    saved.extra["brdf"]["proof"][0]["envelope"] = {"column": 0}
    assert reprove_saved(saved) is False
    for column in (1, 7):
        saved.extra["brdf"]["proof"][0]["envelope"] = StepCeiling(
            column, np.array([0.5]), np.array([9.0, 8.0])).to_dict()
        assert reprove_saved(saved) is False
    saved.extra["brdf"]["proof"][0]["envelope"] = StepCeiling(
        0, np.array([0.5]), np.array([50.0, 40.0])).to_dict()
    assert reprove_saved(saved) is True  # a looser one is proved from the same numbers


@pytest.mark.slow
def test_mystique_stays_under_its_samples_off_the_highlight(shared_data) -> None:
    """mystique's default fit reached 1 681 (R), 28 (G) and 12 (B) 1/sr at random pairs
    with theta_h > 0.3, where its largest sample is 0.054 (green fireflies in renders)."""
    from ratfit.brdf.fitter import brdf_fit_of
    from ratfit.jobs.brdf import fit_brdf_file

    path = shared_data / "cornell" / "mystique.brdf"
    report = fit_brdf_file(path)
    assert report.success and report.meta["envelope"] is not None
    fit = brdf_fit_of(report.results, report.meta)
    ds = samples_dataset(read_brdf(path), "RUSIN_TH_TD_SYM")
    rng = np.random.default_rng(3)
    L, V = above_horizon(rng, 200_000, z_min=0.0), above_horizon(rng, 200_000, z_min=0.0)
    th = get_parametrization("RUSIN_TH_TD_SYM").from_dirs(L, V)[:, 0]
    v = fit.eval_dirs(L, V)
    off = th > 0.3
    lo, hi = fit.saved.channels[0].rational.space.domain[0]
    for j in range(3):
        top = ds.y[ds.x[:, 0] > 0.3 - ENVELOPE_PROOF_SLACK, j].max()  # 0.05 1/sr
        assert v[off, j].max() <= LOG_CEILING_FACTOR * top * (1 + 1e-9), j
        # and everywhere under the proved steps, at theta_h as the fit clamps it
        steps = StepCeiling.from_dict(report.meta["proof"][j])
        assert steps is not None
        assert np.all(v[:, j] <= np.exp(steps.at(np.clip(th, lo, hi))) * (1 + 1e-9)), j
