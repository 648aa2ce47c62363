"""The CDF demonstration: a Beckmann lobe's pdf -> monotone rational CDF -> samples -> PNG."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["run_demo_cdf"]


def run_demo_cdf(outdir: Path, *, alpha: float = 0.3, samples: int = 100_000,
                 seed: int = 0) -> dict[str, Any]:
    """Beckmann lobe: tabulated pdf of cos(theta_h) -> monotone CDF fit -> samples -> PNG."""
    from scipy import stats

    from ratfit._atomic import atomic_dir
    from ratfit.cdf.monotone import MonotoneFitter, cdf_from_pdf
    from ratfit.cdf.sampling import RationalCDF, beckmann_cos_cdf, beckmann_cos_pdf

    mu = np.linspace(0.0, 1.0, 513)
    seg = cdf_from_pdf(mu, beckmann_cos_pdf(mu, alpha), abs_width=5e-4)
    fitter = MonotoneFitter(grid=200).fit(seg)
    res = fitter.result_
    out: dict[str, Any] = {"fitter": fitter, "result": res}
    if not res.success or res.rational is None:
        return out
    model = RationalCDF(res.rational)
    draws = model.sample(samples, np.random.default_rng(seed))
    ks = stats.kstest(draws, lambda v: beckmann_cos_cdf(v, alpha))
    outdir = Path(outdir)
    with atomic_dir(outdir) as work:  # the figure and the fit file, or neither
        _write_demo_files(work, model, seg, draws, fitter, alpha)
    fig, fit_file = outdir / "cdf_beckmann.png", outdir / "cdf_beckmann.json"
    out.update(ks_statistic=float(ks.statistic), ks_pvalue=float(ks.pvalue), figure=fig,
               fit_file=fit_file, samples=samples, seed=seed, alpha=alpha)
    return out


def _write_demo_files(work: Path, model: Any, seg: Any, draws: Any, fitter: Any,
                      alpha: float) -> None:
    from ratfit.cdf.sampling import beckmann_cos_cdf, beckmann_cos_pdf
    from ratfit.io.fitfile import fit_document, save_fit
    from ratfit.viz.plots_cdf import plot_cdf_fit

    res = fitter.result_
    plot_cdf_fit(
        model, seg, draws, work / "cdf_beckmann.png",
        true_pdf=lambda v: beckmann_cos_pdf(v, alpha),
        true_cdf=lambda v: beckmann_cos_cdf(v, alpha),
        xlabel="cos(theta_h)",
        title=f"Beckmann lobe, alpha = {alpha}: cos(theta_h), rational CDF "
              f"n={res.n}, m={res.m}",
    )
    save_fit(work / "cdf_beckmann.json", fit_document(fitter.results_, provenance={
        "input": f"demo: Beckmann pdf of cos(theta_h), alpha={alpha}, 513 points",
        "cdf": {"from": "pdf", "dt": None, "abs_width": 5e-4, "confidence": None,
                "form": "two-row", "grid": 200, "domain": [model.a, model.b],
                "r_domain": [model.r_a, model.r_b]},
    }))
