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
    assert BRDFFitter().options().polish_error == "relative"
    with pytest.raises(InputError, match="polish_error"):
        BRDFFitter(polish_error="log").options()
    res = CliRunner().invoke(main, ["brdf", "fit", str(tmp_path / "x.brdf"),
                                    "--polish-error", "log"])
    assert res.exit_code == 2 and "--polish-error" in res.output
