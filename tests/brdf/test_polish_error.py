"""The BRDF polish can minimise relative errors (``polish_error="relative"``): the diffuse
part of a glossy material, far below its peak, then counts as much as the peak."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import above_horizon

from ratfit.brdf.analytic_models import Model
from ratfit.brdf.fitter import BRDFFitter, brdf_fit_of, fit_brdf
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.cli.main import main
from ratfit.errors import InputError
from ratfit.io.data import Dataset

FRAME = "RUSIN_TH_TD_SYM"


def _glossy(n: int = 400, seed: int = 1):
    """A known lambert + ggx material whose diffuse part is ~1 % of its peak."""
    rng = np.random.default_rng(seed)
    L, V = above_horizon(rng, n), above_horizon(rng, n)
    y = Model("lambert+ggx")(L, V, [0.01, 1.0, 0.25, 0.04])
    x = get_parametrization(FRAME)._from(L, V)
    ds = Dataset(x, y[:, None], None, None, ("theta_h", "theta_d", "s"), ("Y",),
                 {"param_in": FRAME, "source": "glossy"})
    return ds, L, V, y, x[:, 0] > 0.5


def test_relative_polish_keeps_the_diffuse_part_closer_to_the_data():
    ds, L, V, y, diffuse = _glossy()
    assert np.median(y[diffuse]) < 0.02 * y.max()  # the floor (0.2 % of the peak) matters
    spread = {}
    for how in ("absolute", "relative"):
        fitter, _seg, meta = fit_brdf(ds, dt=0.05, floor_rel=0.002, polish_error=how)
        assert fitter.success_
        assert meta["polish_error"] == how
        assert ("relative RMSE" in fitter.results_[0].message) == (how == "relative")
        f = brdf_fit_of(fitter.results_, meta).eval_dirs(L, V)[:, 0]
        ratio = f[diffuse] / y[diffuse]
        spread[how] = float(np.percentile(np.abs(np.log(ratio)), 90))
        if how == "relative":
            assert 0.9 <= float(np.median(ratio)) <= 1.1
    # measured: 90th percentile of |log(fit/data)| over diffuse pairs 0.26 -> 0.17
    assert spread["relative"] < 0.8 * spread["absolute"]


def test_polish_error_is_checked_and_offered_on_the_command_line(tmp_path):
    assert BRDFFitter().options().polish_error == "auto"
    with pytest.raises(InputError, match="polish_error"):
        BRDFFitter(polish_error="log").options()
    res = CliRunner().invoke(main, ["brdf", "fit", str(tmp_path / "x.brdf"),
                                    "--polish-error", "log"])
    assert res.exit_code == 2 and "--polish-error" in res.output


def test_auto_polish_is_relative_only_under_an_absolute_floor():
    """"auto" (the default): relative errors where the segments have a noise-level floor
    (--abs-width, a MERL table's default), plain ones under a floor that is a fraction of
    the peak; the fit file records which ran."""
    g = np.linspace(0.0, 1.0, 5)
    x = np.stack([c.ravel() for c in np.meshgrid(g, g)], axis=1)
    y = (0.01 + np.exp(-8.0 * x[:, 0]))[:, None]
    ds = Dataset(x, y, None, None, ("u", "v"), ("a",), {"param_in": "UNKNOWN"})
    runs = {}
    for kw in ({"dt": 0.05, "abs_width": 1e-3}, {"dt": 0.05, "floor_rel": 0.002},
               {"dt": 0.05, "abs_width": 1e-3, "polish_error": "absolute"}):
        _, _, meta = fit_brdf(ds, max_total=12, **kw)
        runs[tuple(sorted(kw))] = meta["polish_error"]
    assert runs[("abs_width", "dt")] == "relative"
    assert runs[("dt", "floor_rel")] == "absolute"
    assert runs[("abs_width", "dt", "polish_error")] == "absolute"
