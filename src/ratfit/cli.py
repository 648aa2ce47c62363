"""Command-line interface: parse, call the library, print or write. No fitting logic.

Exit codes: 0 success, 1 a run that found no verified fit, 2 bad input or usage.
"""

from __future__ import annotations

import json
import os
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click
import numpy as np

from .errors import RatfitError

EXIT_NO_FIT = 1
EXIT_BAD_INPUT = 2


class _Main(click.Group):
    """Maps library errors to one-line messages and exit codes, without tracebacks."""

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except (click.exceptions.Exit, click.ClickException, click.Abort):
            raise
        except BrokenPipeError:
            # The reader went away (``ratfit eval ... | head``): not an input error.
            # Point stdout at devnull so the interpreter's final flush stays quiet.
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            ctx.exit(141)
        except RatfitError as exc:
            click.echo(f"error: {exc}", err=True)
            ctx.exit(EXIT_BAD_INPUT)
        except OSError as exc:
            name = exc.filename if exc.filename else ""
            click.echo(f"error: {name}: {exc.strerror or exc}", err=True)
            ctx.exit(EXIT_BAD_INPUT)
        except MemoryError:
            click.echo("error: out of memory (try fewer points or a smaller max total)", err=True)
            ctx.exit(EXIT_BAD_INPUT)
        except Exception as exc:  # an internal bug: say so, keep the trace behind a variable
            if os.environ.get("RATFIT_DEBUG"):
                raise
            click.echo(
                f"internal error: {type(exc).__name__}: {exc} (set RATFIT_DEBUG=1 for a trace)",
                err=True,
            )
            ctx.exit(3)


@click.group(cls=_Main, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="ratfit")
def main() -> None:
    """Verified rational fits of vertical segments (interval data)."""
    warnings.simplefilter("default")


# ---------------------------------------------------------------------------- helpers
def _progress(enabled: bool) -> tuple[Callable | None, Callable[[], None]]:
    """A rich status line on stderr while a search runs (terminals only)."""
    if not enabled or not sys.stderr.isatty():
        return None, lambda: None
    from rich.console import Console

    status = Console(stderr=True).status("searching ...")
    status.start()
    seen = {"qps": 0}

    def cb(att) -> None:
        seen["qps"] += 1
        status.update(
            f"tested {seen['qps']} splits; last (n={att.n}, m={att.m}): {att.status}"
        )

    return cb, status.stop


def _write_json(obj: Any) -> None:
    click.echo(json.dumps(obj, indent=1, allow_nan=False))


def _print_report(results, out: Path | None) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title="ratfit fit")
    for col in ("channel", "n", "m", "total", "verified", "max viol.", "Linf", "RMSE",
                "max rel.", "delta", "QPs", "s"):
        table.add_column(col, justify="right")
    for r in results:
        s = r.summary()
        table.add_row(
            s["channel"], str(s["n"]), str(s["m"]), str(s["total"]),
            "yes" if s["verified"] else "NO", _fmt(s["max_violation"]), _fmt(s["linf"]),
            _fmt(s["l2"]), _fmt(s["max_rel_error"]), _fmt(s["delta"]), str(s["qp_solves"]),
            f"{s['seconds']:.3f}",
        )
    con = Console(width=None if sys.stdout.isatty() else 120)
    con.print(table)
    for r in results:
        if not r.success:
            con.print(f"[bold red]{r.channel}[/]: {r.message}")
        for d in r.disagreements:
            con.print(f"[yellow]{r.channel} solver disagreement[/] {d}")
    if out is not None:
        con.print(f"wrote {out}")


def _fmt(v: float | None) -> str:
    return "-" if v is None else f"{v:.3g}"


# ---------------------------------------------------------------------------- fit
@main.command("fit")
@click.argument("input_path", metavar="INPUT", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Fit file to write (JSON); written only when every channel is verified.")
@click.option("--format", "fmt", type=click.Choice(["alta", "csv", "npz", "nist"]),
              help="Input format (default: from the file).")
@click.option("--basis", type=click.Choice(["legendre", "chebyshev", "monomial"]),
              default="legendre", show_default=True)
@click.option("--index-set", type=click.Choice(["total", "tensor"]), default="total",
              show_default=True, help="n-D graded order of basis functions.")
@click.option("--dt", type=float, help="Relative segment width: [(1-dt) y, (1+dt) y].")
@click.option("--abs-width", type=float, help="Absolute segment half-width: [y-w, y+w].")
@click.option("--n", "n", type=int, help="Numerator coefficients (fixes the split).")
@click.option("--m", "m", type=int, help="Denominator coefficients (fixes the split).")
@click.option("--total", type=int, help="Try every split of this total.")
@click.option("--min-total", type=int, default=2, show_default=True)
@click.option("--max-total", type=int, default=None, help="Default 100.")
@click.option("--strategy", type=click.Choice(["staircase", "exhaustive"]), default="staircase",
              show_default=True)
@click.option("--split-rule", type=click.Choice(["min-m", "error"]), default="min-m",
              show_default=True, help="Which feasible split of the minimal total to keep.")
@click.option("--solver", default="quadprog", show_default=True,
              help="QP solver: quadprog, daqp, clarabel.")
@click.option("--cross-check", type=click.Choice(["orth", "lp", "none"]), default="orth",
              show_default=True, help="How a solver's 'infeasible' is checked.")
@click.option("--jobs", type=int, default=None, help="Threads for independent QPs.")
@click.option("--formulation", type=click.Choice(["auto", "arnoldi", "basis"]), default="auto",
              show_default=True,
              help="arnoldi: data-orthonormal bases (smallest fits); basis: the seed's matrix.")
@click.option("--domain", "domain", type=(float, float), multiple=True, metavar="LO HI",
              help="Bounds mapped to [-1, 1], one per input dimension, in order "
                   "(default: the data bounds).")
@click.option("--channel", "channels", multiple=True, type=int,
              help="Fit only these channels (0-based; repeatable).")
@click.option("--monomial/--no-monomial", default=True, show_default=True,
              help="Store the monomial form (original variables) in the fit file.")
@click.option("--shared-denominator", "shared", is_flag=True,
              help="One q for every channel, one p per channel; minimises sum(n) + m "
                   "(--m fixes the denominator size).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def fit_cmd(input_path: Path, output: Path | None, fmt: str | None, basis: str, index_set: str,
            dt: float | None, abs_width: float | None, n: int | None, m: int | None,
            total: int | None, min_total: int, max_total: int | None, strategy: str,
            split_rule: str, solver: str, cross_check: str, jobs: int | None,
            formulation: str, domain: tuple[tuple[float, float], ...],
            channels: tuple[int, ...], monomial: bool, as_json: bool,
            shared: bool = False) -> None:
    """Fit INPUT (ALTA text data, CSV, .npz or NIST StRD) with the fewest coefficients."""
    from .dataio import read_data
    from .fitfile import file_sha256, fit_document, save_fit
    from .search import RationalFitter

    if shared and (n is not None or total is not None):
        raise click.UsageError("--shared-denominator searches the numerator sizes itself: "
                               "drop --n/--total (--m fixes the shared denominator)")
    if (n is None) != (m is None) and not shared:
        raise click.UsageError("give both --n and --m, or neither")
    if n is not None and total is not None:
        raise click.UsageError("--n/--m and --total are exclusive")
    data = read_data(input_path, fmt=fmt)
    try:
        seg = data.segments(dt=dt, abs_width=abs_width)
    except RatfitError as exc:
        msg = str(exc)
        raise type(exc)(msg if str(input_path) in msg else f"{input_path}: {msg}") from None
    if channels:
        from .segments import Segments

        for c in channels:
            seg.channel(c)  # validates the index
        pick = list(channels)
        seg = Segments(seg.x, seg.lo[:, pick], seg.hi[:, pick],
                       None if seg.y is None else seg.y[:, pick],
                       tuple(seg.names[c] for c in pick))
    cb, stop = _progress(not as_json)
    shared_fit = None
    try:
        if shared:
            from .shared import SharedDenominatorFitter

            shared_fit = SharedDenominatorFitter(
                basis=basis, index_set=index_set, domain=list(domain) or None, m=m,
                max_n=max_total or 60, solver=solver, cross_check=cross_check, jobs=jobs or 1,
                callback=cb,
            ).fit(seg)
            results = shared_fit.results
        else:
            results = RationalFitter(
                basis=basis, index_set=index_set, n=n, m=m, total=total, min_total=min_total,
                max_total=max_total, strategy=strategy, split_rule=split_rule, solver=solver,
                cross_check=cross_check, jobs=jobs, callback=cb, domain=list(domain) or None,
                formulation=formulation,
            ).fit(seg).results_
    finally:
        stop()
    ok = all(r.success for r in results)
    if output is not None and ok:
        mono = _monomials(results, seg) if monomial else None
        segdesc: dict[str, Any] = {"dt": dt, "abs_width": abs_width,
                                   "explicit": dt is None and abs_width is None}
        doc = fit_document(results, monomial=mono, provenance={
            "input": str(input_path), "input_sha256": file_sha256(input_path),
            "n_points": seg.n_points, "segments": segdesc, "solver": solver,
        })
        save_fit(output, doc)
    if as_json:
        # "infeasible_proof" (null when feasible) comes with each channel's summary:
        # top level for one channel, under "channels" for several.
        doc = _fit_json(results, output if ok else None)
        if shared_fit is not None:
            doc.update(shared_denominator=True, m_shared=shared_fit.m, total=shared_fit.total,
                       proven_minimal=shared_fit.proven)
        _write_json(doc)
    else:
        _print_report(results, output if ok and output else None)
        if shared_fit is not None:
            click.echo(f"shared denominator: n = {list(shared_fit.n)}, m = {shared_fit.m}, "
                       f"total {shared_fit.total} coefficients")
        if output is not None and not ok:
            click.echo(f"no fit file written: not every channel is verified ({output})", err=True)
    if not ok:
        sys.exit(EXIT_NO_FIT)


def _monomials(results, seg) -> list[dict | None]:
    from .errors import AccuracyWarning
    from .monomial import to_monomial

    out = []
    for r in results:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", AccuracyWarning)
            mf = to_monomial(r.rational, seg.x)
        for w in caught:
            click.echo(f"warning: channel {r.channel}: {w.message}", err=True)
        out.append(mf.to_dict())
    return out


def _fit_json(results, output: Path | None) -> dict[str, Any]:
    per = [r.summary() for r in results]
    if len(per) == 1:
        doc = dict(per[0])
    else:
        doc = {
            "n": [p["n"] for p in per],
            "m": [p["m"] for p in per],
            "total": sum(p["total"] for p in per),
            "basis": per[0]["basis"],
            "verified": all(p["verified"] for p in per),
            "success": all(p["success"] for p in per),
            "max_violation": _worst(per, "max_violation"),
            "linf": _worst(per, "linf"),
            "l2": _worst(per, "l2"),
            "max_rel_error": _worst(per, "max_rel_error"),
            "delta": min((p["delta"] for p in per if p["delta"] is not None), default=None),
            "sigma_min": min((p["sigma_min"] for p in per if p["sigma_min"] is not None),
                             default=None),
            "sigma_max": max((p["sigma_max"] for p in per if p["sigma_max"] is not None),
                             default=None),
            "seconds": sum(p["seconds"] for p in per),
        }
        # one certificate per channel (null where that channel has a fit)
        doc["infeasible_proof"] = [p.get("infeasible_proof") for p in per]
    doc["channels"] = per
    doc["output"] = str(output) if output else None
    return doc


def _worst(vals: list[dict], key: str) -> float | None:
    xs = [p[key] for p in vals]
    return None if any(v is None for v in xs) else max(xs)


# ---------------------------------------------------------------------------- eval
@main.command("eval")
@click.argument("fit_path", metavar="FIT.json", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("input_path", metavar="INPUT", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="Write values to .csv or .npy (default: CSV on stdout).")
@click.option("--format", "fmt", type=click.Choice(["alta", "csv", "npz", "nist"]))
def eval_cmd(fit_path: Path, input_path: Path, output: Path | None, fmt: str | None) -> None:
    """Values of a saved fit at the points of INPUT."""
    from ._atomic import atomic_open
    from .dataio import read_data
    from .errors import InputError
    from .fitfile import load_fit

    saved = load_fit(fit_path)
    data = read_data(input_path, fmt=fmt)
    if data.dim != saved.space.dim:
        raise InputError(
            f"{input_path} has {data.dim} input dimension(s) but the fit has {saved.space.dim}"
        )
    vals = saved(data.x)
    names = [c.name for c in saved.channels]
    if output is not None and output.suffix.lower() == ".npy":
        with atomic_open(output, "wb") as fh:
            np.save(fh, vals)
        return
    header = ",".join([f"x{k}" for k in range(data.dim)] + names)
    body = np.hstack([data.x, vals])
    if output is None:
        click.echo(header)
        for row in body:
            click.echo(",".join(repr(float(v)) for v in row))
    else:
        with atomic_open(output, "w") as fh:
            fh.write(header + "\n")
            for row in body:
                fh.write(",".join(repr(float(v)) for v in row) + "\n")


# ---------------------------------------------------------------------------- demo
@main.group("demo")
def demo_group() -> None:
    """Built-in demonstrations on built-in data."""


@demo_group.command("addendum")
@click.option("-o", "--outdir", type=click.Path(file_okay=False, path_type=Path),
              default=Path("ratfit-addendum"), show_default=True,
              help="Folder for Figures 1-3 (PNG).")
@click.option("--solver", default="quadprog", show_default=True,
              help="QP solver (try clarabel: interior point, like the paper's Matlab).")
@click.option("--cross-check", type=click.Choice(["orth", "lp", "none"]), default="orth",
              show_default=True,
              help="'none' shows what the solver alone returns (the paper's setting).")
@click.option("--jobs", type=int, default=None)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def demo_addendum(outdir: Path, solver: str, cross_check: str, jobs: int | None,
                  as_json: bool) -> None:
    """Reproduce section 2 of the seed: table, figures, and the minimal-total fit."""
    from .demo import PAPER_TABLE, addendum_json, run_addendum, write_figures
    from .solvers import check_solver

    check_solver(solver)
    run = run_addendum(solver=solver, cross_check=cross_check, jobs=jobs)
    figs = write_figures(run, outdir)
    doc = addendum_json(run)
    doc["figures"] = [str(p) for p in figs]
    if as_json:
        _write_json(doc)
    else:
        from rich.console import Console
        from rich.table import Table

        con = Console(width=None if sys.stdout.isatty() else 110)
        table = Table(title=f"Seed section 2: n = m = 20, +-10 % segments, solver {solver}")
        for col in ("basis", "delta (paper)", "sigma_min (paper)", "sigma_max (paper)",
                    "verified", "poles", "decided by"):
            table.add_column(col, justify="right")
        for basis, b in doc["bases"].items():
            pd, ps, pS = PAPER_TABLE[basis]
            table.add_row(
                basis, f"{b['delta']:.2g} ({pd:.2g})", f"{b['sigma_min']:.2g} ({ps:.2g})",
                f"{b['sigma_max']:.0f} ({pS:.0f})", "yes" if b["verified"] else "NO",
                str(b["poles_in_domain"]), b["decided_by"],
            )
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
            con.print(f"wrote {p}")
    if not (doc["minimal"]["verified"] and doc["minimal_seed_form"]["verified"]):
        sys.exit(EXIT_NO_FIT)


if __name__ == "__main__":  # pragma: no cover
    main()


# Commands kept in their own modules register themselves on ``main`` when imported.
from . import cli_batch, cli_brdf, cli_cdf  # noqa: E402,F401  isort: skip
from . import cli_tolerance  # noqa: E402,F401  isort: skip
from . import cli_export  # noqa: E402,F401
