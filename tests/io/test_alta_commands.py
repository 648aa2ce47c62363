"""Issue 27: ALTA fit files through every command that takes a fit (one loader seam:
``load_fit`` reads ``#ALTA FUNC HEADER`` files as unverified fits)."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from conftest import one_error_line, run_cli

from ratfit.io.alta_function import read_alta_function
from ratfit.io.data import read_data
from ratfit.io.fitfile import load_fit


@pytest.fixture(scope="module")
def alta(shared_data: Path) -> Path:
    return shared_data / "alta"


def test_eval_reproduces_altas_own_errors(alta: Path) -> None:
    # said "not valid JSON (truncated or corrupt)"
    r = run_cli("eval", alta / "fits" / "Kirby2.brdf", alta / "Kirby2.dat")
    assert r.exit_code == 0, r.output
    vals = np.loadtxt(io.StringIO(r.stdout), delimiter=",", skiprows=1)
    data = read_data(alta / "Kirby2.dat")
    assert np.array_equal(vals[:, 0], data.x[:, 0])
    err = vals[:, 1] - data.y[:, 0]
    # the L2 (RMS) and Linf ALTA wrote in the file's #CMD line
    assert np.sqrt(np.mean(err**2)) == pytest.approx(0.0279415, rel=1e-5)
    assert np.max(np.abs(err)) == pytest.approx(0.27124, rel=1e-5)
    ref = read_alta_function(alta / "fits" / "Kirby2.brdf")(data.x)[:, 0]
    assert np.allclose(vals[:, 1], ref, rtol=1e-10, atol=0)


def test_load_fit_marks_alta_files_unverified(alta: Path) -> None:
    saved = load_fit(alta / "fits" / "Kirby2.brdf")
    assert saved.integrity == "alta" and not saved.verified
    r = saved.channels[0].rational
    assert (r.n, r.m, r.space.family.name) == (10, 10, "monomial")
    assert saved.space.domain.tolist() == [[9.65, 371.3]]
    stark = load_fit(alta / "fits" / "rational-example-01.brdf")
    assert stark.provenance["param_in"] == "STARK_2D"
    # the BRDF seam makes it a BRDF fit of its parametrization
    from ratfit.export.code import load_any_fit

    saved, bf = load_any_fit(alta / "fits" / "rational-example-01.brdf")
    assert bf is not None and bf.parametrization == "STARK_2D"
    assert saved.extra == {"brdf": {"parametrization": "STARK_2D"}}
    assert stark.space.family.name == "chebyshev" and len(stark.channels) == 3
    x = np.random.default_rng(1).uniform(0.01, 0.99, size=(200, 2))
    ref = read_alta_function(alta / "fits" / "rational-example-01.brdf")(x)
    assert np.allclose(stark(x), ref, rtol=1e-10, atol=0)


def test_export_writes_code_that_says_not_verified(alta: Path, tmp_path: Path) -> None:
    out = tmp_path / "kirby2.py"
    r = run_cli("export", alta / "fits" / "Kirby2.brdf", "--lang", "python", "-o", out)
    assert r.exit_code == 0, r.output
    text = out.read_text()
    assert "NOT VERIFIED: an ALTA function file" in text
    ns: dict = {}
    exec(compile(text, str(out), "exec"), ns)  # noqa: S102 -- the code ratfit wrote
    data = read_data(alta / "Kirby2.dat")
    got = np.array([ns["ratfit_eval"]([v])[0] for v in data.x[:, 0]])
    ref = read_alta_function(alta / "fits" / "Kirby2.brdf")(data.x)[:, 0]
    assert np.allclose(got, ref, rtol=1e-9, atol=0)
    c = run_cli("export", alta / "fits" / "rational-example-01.brdf", "--lang", "glsl",
                "-o", tmp_path / "stark.glsl")
    assert c.exit_code == 0, c.output
    assert "STARK_2D" in c.output and "NOT VERIFIED" in (tmp_path / "stark.glsl").read_text()


def test_plot_and_report(alta: Path, tmp_path: Path) -> None:
    png = tmp_path / "slice.png"
    r = run_cli("plot", alta / "fits" / "Kirby2.brdf", "--data", alta / "Kirby2.dat", "-o", png)
    assert r.exit_code == 0, r.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the STARK_2D function is a BRDF fit: polar lobes work
    polar = tmp_path / "polar.png"
    p = run_cli("plot", alta / "fits" / "rational-example-01.brdf", "--kind", "polar",
                "-o", polar)
    assert p.exit_code == 0, p.output
    assert polar.stat().st_size > 1000
    rep = run_cli("report", alta / "fits" / "Kirby2.brdf", "--data", alta / "Kirby2.dat",
                  "-o", tmp_path / "rep")
    assert rep.exit_code == 0, rep.output
    html = (tmp_path / "rep" / "index.html").read_text()
    assert "An ALTA function file: ratfit holds no verification record" in html
    assert "edited after ratfit wrote it" not in html


def test_nonlinear_alta_functions_are_refused_in_one_line(alta: Path) -> None:
    r = run_cli("eval", alta / "fits" / "nonlinear-example-01.brdf", alta / "Kirby2.dat")
    one_error_line(r, r"ALTA diffuse \+ Blinn function", "rational functions only")
