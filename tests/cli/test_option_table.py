"""Every CLI fit option of every mode is honoured or refused: never silently dropped.

One row per (mode, option of the spec that the mode's command exposes): the option
is given a value other than its default; the run either reaches the search engine
with that value in its checked options (honoured; the test stops the run there) or
exits 2 with one error line naming the option (refused). Which options a mode
refuses is stated below: a new option, or one that stops reaching the engine,
fails here. Issue 25: ``ratfit fit --shared-denominator`` dropped --time-limit,
--strategy, --split-rule, --variable, --formulation, --min-total and --total.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import click
import numpy as np
import pytest
from conftest import run_cli, shared_data_dir

from ratfit.core.options import FIT_OPTIONS
from ratfit.io.data import write_csv

# (CLI arguments, the value the engine's options must hold) per option.
VALUES: dict[str, tuple[list[str], Any]] = {
    "basis": (["--basis", "chebyshev"], "chebyshev"),
    "index_set": (["--index-set", "tensor"], "tensor"),
    "domain": (["--domain", "-0.5", "1.5"], ((-0.5, 1.5),)),
    "n": (["--n", "2", "--m", "3"], 2),
    "m": (["--n", "2", "--m", "3"], 3),
    "total": (["--total", "5"], 5),
    "min_total": (["--min-total", "3"], 3),
    "max_total": (["--max-total", "30"], 30),
    "strategy": (["--strategy", "exhaustive"], "exhaustive"),
    "split_rule": (["--split-rule", "error"], "error"),
    "solver": (["--solver", "clarabel"], "clarabel"),
    "cross_check": (["--cross-check", "lp"], "lp"),
    "jobs": (["--jobs", "2"], 2),
    "formulation": (["--formulation", "basis"], "basis"),
    "time_limit": (["--time-limit", "7"], 7.0),
    "work_limit": (["--work-limit", "900"], 900),
    "variable": (["--variable", "x"], "x"),
}
# What each mode refuses (exit 2, one line naming it); everything else is honoured.
REFUSED: dict[str, set[str]] = {
    "fit": set(),
    "fit --shared-denominator": {"n", "total", "min_total", "strategy", "split_rule",
                                 "formulation"},
    "brdf fit": set(),
    "cdf": set(),
}
# Where an option arrives under another name (the shared search's largest numerator).
ARRIVES_AS = {("fit --shared-denominator", "max_total"): "max_n"}
# Where a mode takes an option alone (--m fixes the shared denominator).
ARGS = {("fit --shared-denominator", "m"): ["--m", "3"]}


def _inputs(folder: Path) -> dict[str, list[str]]:
    x = np.linspace(0.0, 1.0, 12)
    two = folder / "two.csv"
    write_csv(two, x[:, None], np.stack([1 / (2 + x), np.exp(x)], axis=1))
    pdf = folder / "pdf.csv"
    write_csv(pdf, x[:, None], (1 + x)[:, None])
    cayman = shared_data_dir() / "cornell" / "cayman.brdf"
    return {
        "fit": ["fit", str(two), "--dt", "0.01"],
        "fit --shared-denominator": ["fit", str(two), "--dt", "0.01", "--shared-denominator"],
        "brdf fit": ["brdf", "fit", str(cayman), "--max-points", "40", "--channel", "R"],
        "cdf": ["cdf", str(pdf)],
    }


def _flags(mode: str) -> set[str]:
    from ratfit.cli import main

    cmd: Any = main
    for part in mode.split():
        if part.startswith("--"):
            break
        cmd = cmd.get_command(click.Context(cmd), part)  # imports its module on first use
    return {p.name for p in cmd.params if p.name}


ROWS = [(mode, name) for mode in REFUSED for name, opt in FIT_OPTIONS.items()
        if opt.cli and name in _flags(mode)]


def test_the_table_covers_every_cli_option_of_the_spec() -> None:
    assert set(VALUES) == {k for k, o in FIT_OPTIONS.items() if o.cli}
    for mode, refused in REFUSED.items():
        assert refused <= _flags(mode), mode


class _Reached(KeyboardInterrupt):
    """Raised where the search starts: the options it got are recorded."""


@pytest.fixture
def engine_options(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    from ratfit.fitting import search, shared_denominator

    seen: list[Any] = []

    def record(self: Any, options: Any, *args: Any, **kw: Any) -> None:
        seen.append(options)
        raise _Reached

    monkeypatch.setattr(search.SearchEngine, "__init__", record)
    monkeypatch.setattr(shared_denominator._SharedSearch, "__init__", record)
    return seen


@pytest.mark.parametrize(("mode", "name"), ROWS, ids=lambda v: str(v))
def test_every_cli_option_is_honoured_or_refused(mode: str, name: str, tmp_path: Path,
                                                 engine_options: list[Any]) -> None:
    if mode == "brdf fit" and not (shared_data_dir() / "cornell").is_dir():
        pytest.skip("no shared data")
    args, value = VALUES[name]
    args = ARGS.get((mode, name), args)
    res = run_cli(*_inputs(tmp_path)[mode], *args)
    assert "Traceback" not in res.output, res.output
    if name in REFUSED[mode]:
        assert res.exit_code == 2, f"{mode} {args}: exit {res.exit_code}\n{res.output}"
        err = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
        assert len(err) == 1, res.stderr
        flag = "--" + name.replace("_", "-")
        assert re.search(rf"{flag}|\b{name}\b", err[0]), err[0]
        assert not engine_options, "a refused option must stop the run before any search"
        return
    assert res.exit_code == 130, f"{mode} {args}: exit {res.exit_code}\n{res.output}"
    assert engine_options, f"{mode}: the search was not reached"
    got = getattr(engine_options[0], ARRIVES_AS.get((mode, name), name))
    assert got == value, f"{mode} {args}: the engine got {name}={got!r}"


def test_shared_denominator_refuses_a_log_variable(tmp_path: Path) -> None:
    res = run_cli(*_inputs(tmp_path)["fit --shared-denominator"], "--variable", "log")
    assert res.exit_code == 2 and "not log x" in res.stderr


def test_shared_denominator_at_min_total_30_is_refused_not_ignored(tmp_path: Path) -> None:
    """The reproduction: --min-total 30 returned totals below 30 with exit 0."""
    out = tmp_path / "f.json"
    res = run_cli(*_inputs(tmp_path)["fit --shared-denominator"], "--min-total", "30",
                  "-o", out)
    assert res.exit_code == 2 and not out.exists()
    assert "a shared denominator does not take min_total" in res.stderr


def test_shared_denominator_honours_the_time_limit(tmp_path: Path) -> None:
    """A budget that ends after the first QPs: the smallest verified fit so far, marked
    as not proven minimal, or none with no claim of impossibility."""
    from ratfit import Segments
    from ratfit.fitting import SharedDenominatorFitter

    x = np.linspace(-1.0, 1.0, 40)
    seg = Segments.from_relative(x, np.stack([1 / (2 + x), x / (2 + x)], axis=1), 0.01)
    free = SharedDenominatorFitter(max_n=8, max_m=4, time_limit=60).fit(seg).result_
    cut = SharedDenominatorFitter(max_n=8, max_m=4, time_limit=1e-9).fit(seg).result_
    assert free.success and free.proven and not any(r.time_limited for r in free.results)
    assert len(free.history) > 1
    # the first QP runs, then the budget is spent: no further test, no claim
    assert len(cut.history) == 1 and not cut.proven
    assert all(r.time_limited for r in cut.results)
    assert "time limit of 1e-09 s reached after 1 QP test(s)" in cut.results[0].message


# The BRDF fitter's own options (its spec extends the base one), as `brdf fit` spells them.
BRDF_ROWS = [
    ("parametrization", ["--param", "isotropic_tv_tl_dphi"], "ISOTROPIC_TV_TL_DPHI"),
    ("positive_q", ["--positive-q"], True),
    ("polish", ["--no-polish"], False),
    ("polish_error", ["--polish-error", "absolute"], "absolute"),
    ("values", ["--values", "log"], "log"),
    ("envelope", ["--no-envelope"], False),
    ("held_out_size", ["--smallest-size"], False),
]


def test_brdf_rows_cover_the_brdf_spec() -> None:
    from ratfit.brdf.options import BRDF_OPTIONS

    own = set(BRDF_OPTIONS) - set(FIT_OPTIONS)
    # physical: always on from the command; used_coords: what the job finds in the file
    assert {r[0] for r in BRDF_ROWS} == own - {"physical", "used_coords"}


@pytest.mark.parametrize(("name", "args", "value"), BRDF_ROWS, ids=lambda v: str(v))
def test_brdf_fit_options_reach_the_engine(name: str, args: list[str], value: Any,
                                           tmp_path: Path, engine_options: list[Any]) -> None:
    if not (shared_data_dir() / "cornell").is_dir():
        pytest.skip("no shared data")
    res = run_cli(*_inputs(tmp_path)["brdf fit"], *args)
    assert res.exit_code == 130, res.output
    assert getattr(engine_options[0], name) == value
