"""`ratfit demo`: its group, and `ratfit demo addendum`: the seed's section 2 reproduced."""

from __future__ import annotations

import sys
from pathlib import Path

import click
from rich.markup import escape

from ratfit.cli.main import EXIT_NO_FIT, LazyGroup, _write_json, console, fit_table
from ratfit.cli.options import aliased_option, fit_options


@click.group("demo", cls=LazyGroup, lazy={"cdf": "ratfit.cli.cdf:demo_cdf"})
def demo_group() -> None:
    """Built-in demonstrations on built-in data."""


@demo_group.command("addendum")
@aliased_option("-o", "--output", "outdir", hidden=["--outdir"],
                type=click.Path(file_okay=False, path_type=Path),
                default=Path("ratfit-addendum"), show_default=True,
                help="Folder for Figures 1-3 (PNG).")
@fit_options(only=("solver", "cross_check", "jobs"), helps={
    "solver": "QP solver (try clarabel: interior point, like the paper's Matlab).",
    "cross_check": "'none' shows what the solver alone returns (the paper's setting).",
})
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def demo_addendum(outdir: Path, solver: str, cross_check: str, jobs: int | None,
                  as_json: bool) -> None:
    """Reproduce section 2 of the seed: table, figures, and the minimal-total fit."""
    from ratfit.core.solvers import check_solver
    from ratfit.demos.addendum import PAPER_TABLE, addendum_json, run_addendum, write_figures

    check_solver(solver)
    run = run_addendum(solver=solver, cross_check=cross_check, jobs=jobs)
    figs = write_figures(run, outdir)
    doc = addendum_json(run)
    doc["figures"] = [str(p) for p in figs]
    if as_json:
        _write_json(doc)
    else:
        con = console(110)
        cols = ["basis", "delta (paper)", "sigma_min (paper)", "sigma_max (paper)", "verified",
                "poles", "decided by"]
        rows = []
        for basis, b in doc["bases"].items():
            pd, ps, pS = PAPER_TABLE[basis]
            rows.append([
                basis, f"{b['delta']:.2g} ({pd:.2g})", f"{b['sigma_min']:.2g} ({ps:.2g})",
                f"{b['sigma_max']:.0f} ({pS:.0f})", "yes" if b["verified"] else "NO",
                str(b["poles_in_domain"]), b["decided_by"],
            ])
        table, _ = fit_table(con, f"Seed section 2: n = m = 20, +-10 % segments, solver {solver}",
                             cols, rows, optional=("decided by", "poles"), left=("basis",))
        con.print(table)
        for key, label in (("minimal_seed_form", "seed's formulation"),
                           ("minimal", "orthonormal (Arnoldi) formulation")):
            mn = doc[key]
            dense = mn.get("dense_max_rel_error", float("nan"))
            con.print(
                f"minimal total with Legendre, {label}: n={mn['n']} + m={mn['m']} = "
                f"{mn['total']} (paper used 40), verified: {'yes' if mn['verified'] else 'NO'}, "
                f"{mn['qp_solves']} QPs in {mn['seconds']:.3f} s; between the samples "
                f"(10x denser grid): max rel. error {dense:.3g}"
            )
        for p in figs:
            con.print(f"wrote {escape(str(p))}")
    if not (doc["minimal"]["verified"] and doc["minimal_seed_form"]["verified"]):
        sys.exit(EXIT_NO_FIT)
