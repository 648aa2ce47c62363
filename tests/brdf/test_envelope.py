"""Scattered measurements leave most direction pairs unsampled (every Cornell sample lies
in the plane of incidence), and a log fit's proved ceiling is its channel's highlight:
the default fits rose to 28-1 681 1/sr off the highlight (theta_h > 0.3, where no sample
exceeds 0.06) at pairs away from the plane, the renders' fireflies. The search's and the
polish's validity rows keep p / q under the samples' envelope over theta_h instead."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import above_horizon
from test_log_ceiling import _spike
from test_log_values import WIDTHS, _material

from ratfit.brdf.fitter import (
    CEILING_ROW_MARGIN,
    ENVELOPE_SLACK,
    LOG_CEILING_FACTOR,
    BRDFFitter,
    ThetaHEnvelope,
    brdf_segments,
    fit_brdf,
    theta_h_column,
)
from ratfit.brdf.io import read_brdf, samples_dataset
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.core.polish import _positivity_rows


def test_the_envelope_is_the_largest_upper_end_at_least_as_far_from_the_mirror() -> None:
    env = ThetaHEnvelope([1.0, 0.0, 0.5, 0.1], [0.5, 100.0, 1.0, 10.0], slack=0.05)
    t = np.array([0.0, 0.16, 0.3, 0.56, 2.0])
    # theta_h >= t - 0.05: all four; 0.5 and 1.0 (0.1 lies below 0.11); 0.5 and 1.0;
    # 1.0 alone; past the farthest sample, that sample's
    expect = LOG_CEILING_FACTOR * np.array([100.0, 1.0, 1.0, 0.5, 0.5])
    np.testing.assert_allclose(np.exp(env.log_ceiling(t)), expect, rtol=1e-12)
    # a point within the slack of a sample counts it
    assert np.exp(env.log_ceiling(0.14)) == pytest.approx(LOG_CEILING_FACTOR * 10.0)
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
    f._envelopes = f._theta_h_envelopes(seg)
    pts = np.array([[0.0018, 0.5, 0.0], [0.6, 0.5, 0.0], [1.3, 0.5, 0.0]])
    rows = f._row_ceiling(0, pts)
    env = ThetaHEnvelope(seg.x[:, 0], seg.hi[:, 0]).log_ceiling(pts[:, 0])
    np.testing.assert_allclose(rows, np.minimum(env, f._ceilings[0]) - CEILING_ROW_MARGIN)
    assert rows[0] == pytest.approx(f._ceilings[0] - CEILING_ROW_MARGIN)  # the highlight
    assert rows[2] < rows[1] < rows[0]  # the lobe falls off away from the mirror
    f.envelope = False
    f._envelopes = f._theta_h_envelopes(seg)
    assert f._row_ceiling(0, pts) == pytest.approx(f._ceilings[0] - CEILING_ROW_MARGIN)


def test_scattered_log_fits_keep_an_envelope_and_say_so() -> None:
    ds = _material(300)
    fitter, _seg, meta = fit_brdf(ds, values="log", **WIDTHS)
    assert fitter.success_ and fitter.envelope is True
    assert meta["envelope"] == {"coordinate": "theta_h", "slack": ENVELOPE_SLACK,
                                "factor": LOG_CEILING_FACTOR, "proved": False}
    lin = fit_brdf(ds, values="linear", **WIDTHS)
    assert lin[0].envelope is False and lin[2]["envelope"] is None
    off = fit_brdf(ds, values="log", envelope=False, **WIDTHS)
    assert off[0].envelope is False and off[2]["envelope"] is None


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
    for j in range(3):
        top = ds.y[ds.x[:, 0] > 0.3 - ENVELOPE_SLACK, j].max()  # 0.05 1/sr
        # the envelope holds at the rows' points; between them a little over it
        assert v[off, j].max() < 2 * LOG_CEILING_FACTOR * top, j
