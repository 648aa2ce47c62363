"""A default rational fit of a Cornell material beats the analytic model fitted to the
same data, on every channel and every error graphics compares BRDFs by."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ratfit.brdf.analytic_models import Model, fit_model
from ratfit.brdf.fitter import (
    DEFAULT_DT,
    HALF_VECTOR,
    HALF_VECTOR_FLOOR_REL,
    brdf_fit_of,
    brdf_metrics,
    candidate_parametrizations,
    fit_brdf_auto,
)
from ratfit.brdf.io import brdf_dataset
from ratfit.brdf.parametrizations import get_parametrization

# The polish regressions below were found in the Rusinkiewicz angles (the default
# half-vector frame before RUSIN_TH_TD_SYM); they stay pinned there.
RUSIN = "RUSIN_TH_TD_PD"
# Open (issue 28): since BRDF fits need a proof of q > 0 and p >= 0 on the whole evaluated
# region, the least-squares polish of these mystique fits in RUSIN_TH_TD_PD is refuted
# (q < 0 at a corner near the mirror direction) and the unpolished fit is kept. The
# polish's band rows are still exercised; these expectations come back when the polish
# carries the proof's points. strict: a pass is reported.
_UNPROVED_POLISH = ("the polish of this fit is not proved valid: the unpolished fit is kept "
                    "(issue 28, open)")


@pytest.mark.slow
@pytest.mark.xfail(strict=True, run=False, reason=(
    "open (issue 28): acryl_blue's default fit (log values at each channel's noise level, "
    "131 coefficients in 2.3 min, channels at +-43-65 %) has a higher cos-weighted RMSE "
    "at its samples than lambert+ggx (RMS over R, G, B 0.121 against 0.087, 2026-11-27): "
    "not run, as its failure is measured and it costs minutes"))
def test_default_fit_of_acryl_blue_beats_lambert_ggx(shared_data: Path) -> None:
    path = shared_data / "cornell" / "acryl_blue.brdf"
    iso = "ISOTROPIC_TV_TL_DPHI"  # what `ratfit brdf fit` reads Cornell's CARTESIAN as
    ds = brdf_dataset(path, iso)
    # what `ratfit brdf fit` does with no options: the half-vector frame first; no
    # time limit, so a loaded machine cannot cut the search short
    names = candidate_parametrizations(iso)
    assert names == (HALF_VECTOR, iso)
    frames = [brdf_dataset(path, p) for p in names]
    fitter, _seg, meta = fit_brdf_auto(frames, time_limit=None)
    assert meta["parametrization"] == HALF_VECTOR and meta["values"] == "log"
    assert meta["segments"]["noise_estimated"]
    assert fitter.success_ and all(str(v).startswith("proved") for v in meta["validity"])
    assert all(p["proved"] and p["q_margin"] > 0 for p in meta["proof"])
    pred = brdf_fit_of(fitter.results_, meta).eval_coords(frames[0].x)
    L, V = get_parametrization(iso).to_dirs(ds.x)
    rat = brdf_metrics(pred, ds.y, L[:, 2], ds.output_names)
    mf = fit_model(Model("lambert+ggx"), L, V, ds.y, channel_names=ds.output_names, starts=4)
    ggx = brdf_metrics(mf.eval_dirs(L, V), ds.y, L[:, 2], ds.output_names)
    for ch in ds.output_names:
        for key in ("rmse", "log_rmse", "cos_rmse"):
            assert rat[ch][key] < ggx[ch][key], (ch, key, rat[ch][key], ggx[ch][key])


@pytest.mark.slow
def test_default_width_follows_what_the_data_needs(shared_data: Path) -> None:
    from ratfit.brdf.fitter import DEFAULT_DT, default_dt, prepare_values

    exr = brdf_dataset(shared_data / "alta" / "data-example-01.exr", None)
    # nearest-neighbour resampling: neighbours jump by up to 19.8 % (B)
    assert default_dt(exr.x, prepare_values(exr)) == 0.22
    cornell = brdf_dataset(shared_data / "cornell" / "garnet_red.brdf", "ISOTROPIC_TV_TL_DPHI")
    assert default_dt(cornell.x, prepare_values(cornell)) == DEFAULT_DT  # no near pairs
    # the same point measured twice, 1.0 and 1.5: the segments must overlap
    x = np.array([[0.0, 0.0], [1e-4, 0.0], [1.0, 1.0], [0.5, 0.2]])
    y = np.array([1.0, 1.5, 1.0, 1.0])
    dt = default_dt(x, y, floor=0.0)
    assert dt == 0.22  # 1.1 x |1.5 - 1.0| / (1.5 + 1.0)
    assert (1 + dt) * 1.0 >= (1 - dt) * 1.5


@pytest.mark.slow
def test_polish_meets_the_band_on_a_specular_peak(shared_data: Path) -> None:
    """mystique G in the half-vector frame: q spans four decades over the data, so
    the polish QP (in whitened coordinates) met an active band row only to the
    solver's tolerance, 0.2 above a segment at the peak, and the polish was thrown
    away (RMSE 0.53). Raised right-hand sides make it meet the band: RMSE 0.084; its
    proof failed, and the fit half way to it (fitter.BLEND_STEPS) is proved valid."""
    ds = brdf_dataset(shared_data / "cornell" / "mystique.brdf", RUSIN, channels=["G"])
    fitter, seg, _ = fit_brdf_auto([ds], time_limit=None)
    res = fitter.result_
    assert res.success and "least-squares polish" in res.message, res.message
    r = res.rational(seg.x)
    assert np.all((r >= seg.lo[:, 0]) & (r <= seg.hi[:, 0]))
    assert float(np.sqrt(np.mean((r - seg.center[:, 0]) ** 2))) < 0.15


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=(
    "the polish of this fit is not proved valid, only the fit part of the way to it "
    "(fitter.BLEND_STEPS): RMSE 0.095, not below 0.05 (issue 28, open)"))
def test_polish_settles_when_q_spans_six_decades(shared_data: Path) -> None:
    """mystique G at a 0.05 % floor: q of the (3, 5) fit spans six decades over the
    data; rows met to rounding used to be 'missed' forever (30 rounds, no polish,
    RMSE 0.49). A row counts as missed only when the value leaves the band."""
    from ratfit.brdf.fitter import fit_brdf

    ds = brdf_dataset(shared_data / "cornell" / "mystique.brdf", RUSIN, channels=["G"])
    fitter, seg, _ = fit_brdf(ds, dt=0.05, floor_rel=0.0005, time_limit=None)
    res = fitter.result_
    assert res.success and "least-squares polish" in res.message, res.message
    r = res.rational(seg.x)
    assert np.all((r >= seg.lo[:, 0]) & (r <= seg.hi[:, 0]))
    assert float(np.sqrt(np.mean((r - seg.center[:, 0]) ** 2))) < 0.05


@pytest.mark.slow
def test_a_rejected_candidate_is_solved_again_before_it_is_repaired(shared_data: Path) -> None:
    """mystique B, default widths: the (1, 6) candidate meets every segment but its q
    changes sign between the samples. The repair (a least-squares fit under the
    validity rows, weighted by that candidate's own q) made it valid with RMSE 0.78,
    worse than lambert+ggx (0.36); solving the split again with the validity points
    gives a valid (1, 6) with RMSE 0.059. The repair now comes after that."""
    from ratfit.brdf.fitter import fit_brdf

    ds = brdf_dataset(shared_data / "cornell" / "mystique.brdf", RUSIN, channels=["B"])
    # the default widths before the floor is narrowed (a small fit: see SMALL_FIT_TOTAL)
    fitter, seg, _ = fit_brdf(ds, dt=DEFAULT_DT, floor_rel=HALF_VECTOR_FLOOR_REL,
                              time_limit=None)
    res = fitter.result_
    assert res.success and (res.n, res.m) == (1, 6), res.message
    r = res.rational(seg.x)
    assert np.all((r >= seg.lo[:, 0]) & (r <= seg.hi[:, 0]))
    assert float(np.sqrt(np.mean((r - seg.center[:, 0]) ** 2))) < 0.1


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason=_UNPROVED_POLISH)
def test_polish_falls_back_to_the_cone_program(shared_data: Path) -> None:
    """mystique at a 0.05 % floor, all three channels: G's (4, 5) fit has q over six
    decades and DAQP called every cut-off of its whitened polish QP infeasible, with
    the start strictly inside (RMSE stayed 0.59, lambert+ggx has 0.39). Clarabel's
    cone program in c polishes it (about 0.01); every channel is polished."""
    from ratfit.brdf.fitter import fit_brdf

    ds = brdf_dataset(shared_data / "cornell" / "mystique.brdf", RUSIN)
    fitter, seg, _ = fit_brdf(ds, dt=0.05, floor_rel=0.0005, time_limit=None, jobs=1)
    for j, res in enumerate(fitter.results_):
        assert res.success and "least-squares polish" in res.message, res.message
        r = res.rational(seg.x)
        assert np.all((r >= seg.lo[:, j]) & (r <= seg.hi[:, j]))
        assert float(np.sqrt(np.mean((r - seg.center[:, j]) ** 2))) < 0.05
