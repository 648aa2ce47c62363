"""ALTA's retro file: theta_l takes three values, so basis columns are dependent on the data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ratfit.brdf.fitter import fit_brdf
from ratfit.brdf.io import brdf_dataset


@pytest.mark.slow
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


@pytest.mark.slow
def test_retro_at_alta_width_has_no_22_term_polynomial_fit(shared_data: Path) -> None:
    """The issue's "a 22-term Legendre numerator and a constant denominator fits it"
    does not hold: proved in exact arithmetic, and HiGHS agrees by a wide margin."""
    from numpy.polynomial import legendre
    from scipy.optimize import linprog

    from ratfit.brdf.fitter import brdf_segments, nonnegative_segments
    from ratfit.core.bases import PolynomialSpace
    from ratfit.core.columns import axis_degree_caps
    from ratfit.fitting.certificate import certify

    ds = brdf_dataset(shared_data / "alta" / "retro-3M-jaune.dat", None)
    seg = nonnegative_segments(brdf_segments(ds, abs_width=0.5))
    space = PolynomialSpace("legendre", seg.bounds(), "total", axis_degree_caps(seg.x))
    cert = certify(space, seg, 0, 22, 1, exact=True)
    assert cert.exact and cert.checked
    # independent: the best polynomial of total degree <= 4 (31 terms, more than 22)
    # misses some sample by more than 9, where +-0.5 would be needed.
    x, y = seg.x, seg.center[:, 0]
    t = 2 * (x - x.min(0)) / (x.max(0) - x.min(0)) - 1
    V = [legendre.legvander(t[:, k], 4) for k in range(3)]
    idx = [(a, b, c) for a in range(3) for b in range(5) for c in range(5) if a + b + c <= 4]
    A = np.stack([V[0][:, a] * V[1][:, b] * V[2][:, c] for a, b, c in idx], axis=1)
    k, ones = A.shape[1], np.ones((len(y), 1))
    lp = linprog(np.r_[np.zeros(k), 1.0], A_ub=np.block([[A, -ones], [-A, -ones]]),
                 b_ub=np.r_[y, -y], bounds=[(None, None)] * k + [(0, None)], method="highs")
    assert lp.status == 0 and len(idx) == 31
    assert lp.fun > 9.0
