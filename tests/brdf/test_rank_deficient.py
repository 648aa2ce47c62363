"""ALTA's retro file: theta_l takes three values, so basis columns are dependent on the data."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ratfit.brdf.fitter import fit_brdf
from ratfit.brdf.io import brdf_dataset


def test_retro_own_parametrization_is_decided_not_lost_in_rounding(shared_data: Path) -> None:
    ds = brdf_dataset(shared_data / "alta" / "retro-3M-jaune.dat", None)
    assert ds.meta["param_in"] == "ISOTROPIC_TL_TV_PROJ_DPHI"
    fitter, seg, _ = fit_brdf(ds, abs_width=0.5, n=12, m=11)
    res = fitter.result_
    assert fitter.space_.max_degree[0] == 2  # three light elevations carry degree 2 at most
    # Before the caps: delta 1.4e-17 and "missed by up to inf"; now a well-posed QP
    # whose answer is an infeasibility the certificate proves in exact arithmetic.
    assert res.delta > 1e-3
    assert res.status == 1 and not res.success
    assert res.infeasible_proof is not None and res.infeasible_proof["checked"]
    assert np.isfinite(res.delta)
