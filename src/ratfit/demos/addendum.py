"""The seed's section 2 example, reproduced: the table, Figures 1-3, the minimal fit.

f(x) = 1000 e^{-x^2} x^2 + 0.1 e^{-100 (x-9)^2} x^3 + 0.1 on 1000 uniform points
of [0, 10], segments +-10 %, n = m = 20, for Legendre, Chebyshev and centered
monomials (powers of the scaled variable t in [-1, 1]).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ratfit.core.options import FitOptions
from ratfit.core.results import FitResult
from ratfit.core.segments import Segments
from ratfit.fitting.search import RationalFitter

__all__ = ["PAPER_TABLE", "addendum_function", "addendum_segments", "run_addendum"]

# The seed's table: delta, sigma_min, sigma_max for n = m = 20.
PAPER_TABLE = {
    "legendre": (1.4e-05, 0.10, 7160.0),
    "chebyshev": (1.0e-05, 0.11, 11023.0),
    "monomial": (1.8e-10, 1.5e-06, 8173.0),
}


def addendum_function(x: NDArray[np.float64]) -> NDArray[np.float64]:
    return 1000 * np.exp(-(x**2)) * x**2 + 0.1 * np.exp(-100 * (x - 9) ** 2) * x**3 + 0.1


def addendum_segments(points: int = 1000, dt: float = 0.1) -> Segments:
    x = np.linspace(0.0, 10.0, points)
    return Segments.from_relative(x, addendum_function(x), dt, names=("f",))


def run_addendum(
    *, solver: str = "quadprog", cross_check: str = "orth", jobs: int | None = None
) -> dict[str, Any]:
    """Fit the three bases at 20 + 20 in the seed's formulation (its table), and
    search the minimal Legendre total in both the seed's and the well-conditioned
    (Arnoldi) formulation."""
    seg = addendum_segments()
    fits: dict[str, FitResult] = {}
    common = FitOptions(solver=solver, cross_check=cross_check, jobs=jobs)
    for basis in PAPER_TABLE:
        fits[basis] = RationalFitter.from_options(common.replace(
            basis=basis, n=20, m=20, formulation="basis")).fit(seg).result_
    seed_form = RationalFitter.from_options(
        common.replace(basis="legendre", formulation="basis")).fit(seg).result_
    minimal = RationalFitter.from_options(
        common.replace(basis="legendre", formulation="arnoldi")).fit(seg).result_
    return {"segments": seg, "fits": fits, "minimal": minimal, "minimal_seed_form": seed_form}


def addendum_json(run: dict[str, Any]) -> dict[str, Any]:
    bases = {}
    for basis, r in run["fits"].items():
        v = r.verification
        bases[basis] = {
            "delta": r.delta,
            "sigma_min": r.sigma_min,
            "sigma_max": r.sigma_max,
            "verified": r.success,
            "poles_in_domain": v.poles_in_domain if v else None,
            "max_violation": v.max_violation if v else None,
            "max_rel_error": v.max_rel_error if v else None,
            "solver_status": r.solver_status,
            "decided_by": r.decided_by or r.solver,
            "paper": dict(zip(("delta", "sigma_min", "sigma_max"), PAPER_TABLE[basis],
                              strict=True)),
        }
    from ratfit.fitting.dense import dense_check, dense_grid

    seg: Segments = run["segments"]
    xd = dense_grid(seg.x[:, 0], 10)

    def brief(mn: FitResult) -> dict[str, Any]:
        out = {
            "n": mn.n, "m": mn.m, "total": mn.total, "verified": mn.success,
            "basis": mn.basis, "max_violation": mn.max_violation,
            "qp_solves": mn.qp_solves, "seconds": mn.seconds,
            "formulation": mn.formulation,
        }
        if mn.rational is not None:  # between the samples: a 10x denser grid
            chk = dense_check(mn.rational, addendum_function, xd, dt=0.1)
            out["dense_max_rel_error"] = chk.max_rel_error
            out["dense_inside"] = chk.inside
        return out

    return {
        "bases": bases,
        "minimal": brief(run["minimal"]),
        "minimal_seed_form": brief(run["minimal_seed_form"]),
    }


def write_figures(run: dict[str, Any], outdir: str | Path) -> list[Path]:
    """Figures 1-3 of the seed as PNG files in ``outdir`` (all three, or none)."""
    from ratfit._atomic import atomic_dir
    from ratfit.viz.plots import plot_errors, plot_fits, plot_function

    outdir = Path(outdir)
    seg: Segments = run["segments"]
    x = seg.x[:, 0]
    y = seg.center[:, 0]
    fits = {b: r.rational for b, r in run["fits"].items()}
    fits["minimal legendre " + f"({run['minimal'].n}+{run['minimal'].m})"] = run["minimal"].rational
    with atomic_dir(outdir) as work:
        made = [
            plot_function(x, y, work / "figure1_function.png"),
            plot_fits(seg, fits, work / "figure2_fits.png"),
            plot_errors(seg, fits, work / "figure3_errors.png"),
        ]
    return [outdir / p.name for p in made]
