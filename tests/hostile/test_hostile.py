"""Hostile input over every subcommand: exit 2, exactly one ``error:`` line, no traceback,
nothing on stdout, no output file. The cases come from :mod:`tests.hostile.cases`."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ratfit.cli import main

from .cases import Case, Ctx, all_cases

CASES = all_cases()


def _cli(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="session")
def good(tmp_path_factory: pytest.TempPathFactory, shared_data: Path) -> dict[str, Path]:
    """A verified 1-D fit and a verified CDF fit, made once (the cases damage copies)."""
    d = tmp_path_factory.mktemp("good")
    x = np.linspace(0.0, 2.0, 40)
    y = 1.0 / (1.0 + x * x) + 0.5
    csv = d / "data.csv"
    rows = zip(x.tolist(), y.tolist(), strict=True)
    csv.write_text("x,y\n" + "".join(f"{a!r},{b!r}\n" for a, b in rows))
    fit = d / "fit.json"
    res = _cli("fit", csv, "--dt", "0.01", "-o", fit)
    assert res.exit_code == 0, res.output
    pdf = d / "pdf.csv"
    pdf.write_text("x,y\n" + "".join(f"{float(a)!r},{float(np.exp(-a))!r}\n" for a in x))
    cdf = d / "cdf.json"
    res = _cli("cdf", pdf, "--from", "pdf", "--abs-width", "0.01", "-o", cdf)
    assert res.exit_code == 0, res.output
    brdf_data, brdf = d / "synth.alta", d / "brdf.json"
    _synthetic_brdf(brdf_data)
    res = _cli("brdf", "fit", brdf_data, "--param", "COS_TH_TD_PD", "--dt", "0.1",
               "--abs-width", "1e-4", "--max-total", "30", "-o", brdf)
    assert res.exit_code == 0, res.output
    return {"fit": fit, "cdf": cdf, "csv": csv, "data": shared_data, "brdf": brdf,
            "brdf_data": brdf_data}


def _synthetic_brdf(path: Path) -> None:
    """A dull GGX lobe on 600 random isotropic direction pairs (fits in about a second)."""
    from ratfit.brdf.parametrizations import get_parametrization
    from ratfit.io.data import write_alta

    rng = np.random.default_rng(5)
    par = get_parametrization("ISOTROPIC_TV_TL_DPHI")
    c = np.column_stack([rng.uniform(0.05, 1.3, 600), rng.uniform(0.05, 1.3, 600),
                         rng.uniform(-np.pi, np.pi, 600)])
    L, V = par.to_dirs(c)
    h = L + V
    cos_h = h[:, 2] / np.linalg.norm(h, axis=1)
    lobe = 0.1225 / (np.pi * ((0.1225 - 1.0) * cos_h * cos_h + 1.0) ** 2)
    write_alta(path, c, (0.05 + 0.12 * lobe)[:, None], param_in="ISOTROPIC_TV_TL_DPHI",
               param_out="INV_STERADIAN")


def check_bad_input(res, outs: list[Path], expect: str = "") -> str:
    """The project's contract for bad input, as one reusable assertion."""
    assert res.exception is None or isinstance(res.exception, SystemExit), (
        f"uncaught {type(res.exception).__name__}: {res.exception}")
    assert "Traceback" not in res.output
    assert res.exit_code == 2, f"exit {res.exit_code}: {res.output[-2000:]}"
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, f"expected one stderr line, got {lines[:20]}"
    assert lines[0].startswith("error: "), lines[0]
    assert "internal error" not in lines[0]
    if expect:
        assert re.search(expect, lines[0], re.IGNORECASE), f"{expect!r} not in {lines[0]!r}"
    assert res.stdout == "", f"stdout on bad input: {res.stdout[:500]!r}"
    for out in outs:
        assert not out.exists(), f"{out} was written"
    return lines[0]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_hostile_input(case: Case, good: dict[str, Path], tmp_path: Path) -> None:
    ctx = Ctx(tmp_path, good["data"], good["fit"], good["cdf"], good["csv"], good["brdf"],
              good["brdf_data"])
    args, outs = case.build(ctx)
    check_bad_input(_cli(*args), outs, case.expect)


def test_at_least_300_cases_over_every_subcommand() -> None:
    assert len(CASES) >= 300
    seen = {c.id.split("-")[1] for c in CASES if c.id.startswith(("data-", "fitfile-"))}
    ids = " ".join(c.id for c in CASES)
    for cmd in ("fit", "eval", "cdf", "sample", "tolerance", "batch", "export", "plot",
                "report", "brdf-fit", "brdf-eval", "brdf-compare", "demo"):
        assert cmd in ids, cmd
    assert seen
