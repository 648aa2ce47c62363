"""`ratfit tolerance`: the smallest segment width a fixed size (n, m) still fits."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import click

from ratfit.cli.main import EXIT_NO_FIT, _fmt, _write_json
from ratfit.cli.options import FiniteFloatRange, fit_options, pop_fit_params
from ratfit.io.data import FORMATS
from ratfit.jobs.common import results_summary


@click.command("tolerance")
@click.argument("input_path", metavar="INPUT", type=click.Path(dir_okay=False, path_type=Path))
@fit_options(only=("n", "m"), required=("n", "m"),
             helps={"n": "Numerator coefficients.", "m": "Denominator coefficients."})
@click.option("--width-kind", type=click.Choice(["relative", "absolute"]), default="relative",
              show_default=True,
              help="Search a relative width [(1-w) y, (1+w) y] (as fit --dt) or an absolute "
                   "one [y-w, y+w] (as fit --abs-width).")
@click.option("--absolute", "absolute_flag", is_flag=True, hidden=True,
              help="Old spelling of --width-kind absolute.")
@click.option("--rtol", type=FiniteFloatRange(min=0, max=1, min_open=True, max_open=True),
              default=1e-3, show_default=True,
              help="Stop when the feasible width is within this ratio of an infeasible one.")
@click.option("--format", "fmt", type=click.Choice(FORMATS),
              help="Input format (default: from the file).")
@fit_options(only=("basis", "solver"))
@click.option("--channel", "channels", multiple=True, type=int,
              help="Only these channels (0-based; repeatable).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def tolerance_cmd(input_path: Path, width_kind: str, absolute_flag: bool, rtol: float,
                  fmt: str | None, channels: tuple[int, ...], as_json: bool,
                  **options: Any) -> None:
    """Smallest width at which a rational of size (n, m) fits INPUT's y values.

    Intervals in the file are ignored: segments are built from y with the
    width being searched, by bisection with feasibility QPs. The result is a
    verified fit at WIDTH and a width below it with a checked (exact) certificate
    that no rational of this size fits: the bisection's lower end when its
    certificate checks, else the largest smaller width where one does (the
    output names both).
    """
    from ratfit.errors import InputError
    from ratfit.fitting.tolerance import best_width
    from ratfit.io.data import read_data

    params = pop_fit_params(options)
    n, m, basis, solver = params["n"], params["m"], params["basis"], params["solver"]
    absolute = absolute_flag or width_kind == "absolute"
    data = read_data(input_path, fmt=fmt)
    if data.y is None:
        raise InputError(f"{input_path} has only lo/hi bounds, no y values to fit")
    k = data.y.shape[1]
    pick = list(channels) or list(range(k))
    for c in pick:
        if not 0 <= c < k:
            raise InputError(f"channel {c} out of range: {input_path} has {k} channel(s)")
    for label, v in (("--n", n), ("--m", m)):
        if v is None:
            raise click.UsageError(f"missing option {label} (a coefficient count)")
        if v > data.n_points:
            raise InputError(f"{label} {v} is more coefficients than the {data.n_points} data "
                             f"point(s) of {input_path} can determine")
    names = data.output_names or tuple(f"y{j}" for j in range(k))
    outs = []
    for c in pick:
        try:
            outs.append(best_width(data.x, data.y[:, c], n, m, absolute=absolute, rtol=rtol,
                                   basis=basis, solver=solver, name=names[c]))
        except InputError as exc:
            raise InputError(f"{input_path}: channel {names[c]}: {exc}") from None
    ok = all(o.success for o in outs)
    if as_json:
        _write_json(_widths_summary(outs))
    else:
        _print_widths([names[c] for c in pick], outs, absolute, n, m)
    if not ok:
        sys.exit(EXIT_NO_FIT)


def _widths_summary(outs: list[Any]) -> dict[str, Any]:
    """The ``--json`` object: the fits' summary with each channel's best width."""
    found = [o for o in outs if o.fit is not None]
    doc: dict[str, Any] = results_summary([o.fit for o in found], None) if found else {}
    per = [o.summary() for o in outs]
    if len(outs) == 1:
        doc.update(per[0])
    else:
        doc["width"] = [p["width"] for p in per]
        doc["width_kind"] = per[0]["width_kind"]
        for entry, p in zip(doc.get("channels", []), [p for o, p in zip(outs, per, strict=True)
                                                         if o.fit is not None], strict=True):
            entry.update(p)
        doc["widths"] = per
    doc["success"] = all(o.success for o in outs)
    return doc


def _print_widths(names: list[str], outs: list[Any], absolute: bool, n: int, m: int) -> None:
    kind = "absolute" if absolute else "relative"
    for name, o in zip(names, outs, strict=True):
        if o.fit is None:
            click.echo(f"{name}: no verified fit of size n={n}, m={m} at any width tried")
            continue
        v = o.fit.verification
        click.echo(
            f"{name}: best {kind} width {o.width:.6g} for n={n}, m={m} (verified; max rel. "
            f"error {_fmt(v.max_rel_error if v else None)}); {o.lower_statement}"
        )
