"""A default rational fit of a Cornell material beats the analytic model fitted to the
same data, on every channel and every error graphics compares BRDFs by."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ratfit.brdf.analytic_models import Model, fit_model
from ratfit.brdf.fitter import DEFAULT_DT, DEFAULT_FLOOR_REL, brdf_metrics, fit_brdf
from ratfit.brdf.io import brdf_dataset
from ratfit.brdf.parametrizations import get_parametrization


def test_default_fit_of_acryl_blue_beats_lambert_ggx(shared_data: Path) -> None:
    param = "ISOTROPIC_TV_TL_DPHI"  # what `ratfit brdf fit` picks for Cornell's CARTESIAN
    ds = brdf_dataset(shared_data / "cornell" / "acryl_blue.brdf", param)
    # no widths: the defaults; no time limit, so a loaded machine cannot cut the
    # search short and hand back a larger, not minimal fit
    fitter, seg, meta = fit_brdf(ds, time_limit=None)
    assert meta["segments"] == {"dt": DEFAULT_DT, "abs_width": None,
                                "floor_rel": DEFAULT_FLOOR_REL, "default": True}
    assert fitter.success_ and all(str(v).startswith("valid on") for v in meta["validity"])
    pred = np.stack([r.rational(seg.x) for r in fitter.results_], axis=1)
    L, V = get_parametrization(param).to_dirs(ds.x)
    rat = brdf_metrics(pred, ds.y, L[:, 2], ds.output_names)
    mf = fit_model(Model("lambert+ggx"), L, V, ds.y, channel_names=ds.output_names, starts=4)
    ggx = brdf_metrics(mf.eval_dirs(L, V), ds.y, L[:, 2], ds.output_names)
    for ch in ds.output_names:
        for key in ("rmse", "log_rmse", "cos_rmse"):
            assert rat[ch][key] < ggx[ch][key], (ch, key, rat[ch][key], ggx[ch][key])
    # ...with a few dozen coefficients per channel, not hundreds
    assert all(8 <= r.total <= 60 for r in fitter.results_)


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
    dt = default_dt(x, y, floor_rel=0.0)
    assert dt == 0.22  # 1.1 x |1.5 - 1.0| / (1.5 + 1.0)
    assert (1 + dt) * 1.0 >= (1 - dt) * 1.5
