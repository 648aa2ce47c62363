"""Pictures: files exist with the expected size and are not blank; the rendered sphere of a
rational fit agrees with the sphere rendered from dense data within the fit's error bound."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ratfit.brdf.analytic_models import Model
from ratfit.brdf.fitter import BRDFFit
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.cli import main
from ratfit.core.segments import Segments
from ratfit.fitting.search import RationalFitter
from ratfit.io.fitfile import fit_document, parse_fit, save_fit
from ratfit.viz import pictures as pic

DT = 0.02
PARAM = "RUSIN_TH_TD"
TRUTH = ("lambert+blinn", [0.4, 0.5, 4.0])


def _image(path):
    import matplotlib.image as mpimg

    return mpimg.imread(path)


def _check_png(path, shape):
    im = _image(path)
    assert im.shape[:2] == shape
    assert float(np.var(im[..., :3])) > 1e-4  # not blank


@pytest.fixture(scope="module")
def dense():
    """A dense (theta_h, theta_d) grid from an analytic BRDF and a verified rational fit."""
    g = np.radians(np.linspace(0.0, 88.0, 30))
    th, td = np.meshgrid(g, g, indexing="ij")
    x = np.column_stack([th.ravel(), td.ravel()])
    L, V = get_parametrization(PARAM).to_dirs(x)
    y = Model(TRUTH[0])(L, V, TRUTH[1])[:, None]
    seg = Segments.from_relative(x, y, DT)
    fitter = RationalFitter(max_total=60).fit(seg)
    assert fitter.success_
    doc = fit_document(fitter.results_, extra={"brdf": {"parametrization": PARAM}})
    saved = parse_fit(json.loads(json.dumps(doc)))
    return x, y, BRDFFit(saved, PARAM), doc


@pytest.mark.slow
def test_sphere_of_fit_matches_sphere_of_data(dense):
    x, y, bf, _ = dense
    data = pic.DataBRDF(x, y, PARAM)
    img_d = pic.render_sphere(data, size=64)
    img_f = pic.render_sphere(pic.fit_brdf_function(bf), size=64)
    on, Ll, Vl, irr = pic.sphere_geometry(64)
    lit = irr > 0
    near = np.zeros(lit.shape, bool)
    near[lit] = data.dense(Ll[lit], Vl[lit])
    dense_px = np.zeros((64, 64), bool)
    dense_px[on] = near
    assert dense_px.sum() > 1000
    d, f = img_d[dense_px, 0], img_f[dense_px, 0]
    both = np.isfinite(d) & np.isfinite(f)  # the fit is NaN outside its domain (rim pixels)
    assert both.mean() > 0.97
    d, f = d[both], f[both]
    # a verified fit is within DT * y of every sample; interpolation adds a little
    assert np.all(np.abs(f - d) <= DT * np.maximum(d, f) * 1.05)
    assert np.max(np.abs(f - d)) > 0  # two different renderings, not the same one twice


@pytest.mark.slow
def test_brdf_pictures(dense, tmp_path):
    x, y, bf, _ = dense
    truth = Model(TRUTH[0])
    funcs = {"rational": pic.fit_brdf_function(bf),
             "analytic": lambda L, V: truth(L, V, TRUTH[1])[:, None]}
    p = pic.plot_brdf_slices(funcs, tmp_path / "s.png")
    _check_png(p, (660, 1200))
    p = pic.plot_polar(funcs, tmp_path / "p.png")
    _check_png(p, (390, 1380))
    imgs = {"data": pic.render_sphere(pic.DataBRDF(x, y, PARAM), size=48)}
    imgs.update({k: pic.render_sphere(f, size=48) for k, f in funcs.items()})
    p = pic.plot_spheres(imgs, tmp_path / "sph.png")
    _check_png(p, (360, 960))


@pytest.mark.slow
def test_slice_and_error_plots(dense, tmp_path):
    x, y, bf, _ = dense
    lo, hi = (1 - DT) * y, (1 + DT) * y
    p = pic.plot_slice(bf.saved, tmp_path / "slice.png", x=x, y=y, lo=lo, hi=hi, dim=0)
    _check_png(p, (600, 800))
    p = pic.plot_error(bf.saved, tmp_path / "err.png", x, y, lo=lo, hi=hi)
    _check_png(p, (400, 800))


def _fit_and_data_files(x, y, doc, folder):
    """The dense fit saved as ``fit.json`` and its data as ALTA text ``data.dat``."""
    fit = folder / "fit.json"
    save_fit(fit, doc)
    data = folder / "data.dat"
    rows = "\n".join(" ".join(repr(float(v)) for v in r) for r in np.hstack([x, y]))
    data.write_text(f"#DIM 2 1\n#PARAM_IN {PARAM}\n#PARAM_OUT INV_STERADIAN\n{rows}\n")
    return fit, data


@pytest.mark.slow
def test_cli_plot_and_report(dense, tmp_path):
    x, y, _, doc = dense
    fit, data = _fit_and_data_files(x, y, doc, tmp_path)
    runner = CliRunner()
    for kind in ("slice", "error", "polar", "sphere"):
        out = tmp_path / f"{kind}.png"
        r = runner.invoke(main, ["plot", str(fit), "--data", str(data), "--kind", kind,
                                 "-o", str(out), "--size", "40"])
        assert r.exit_code == 0, r.output
        assert float(np.var(_image(out)[..., :3])) > 1e-4
    r = runner.invoke(main, ["report", str(fit), "--data", str(data), "-o",
                             str(tmp_path / "rep")])
    assert r.exit_code == 0, r.output
    page = (tmp_path / "rep" / "index.html").read_text()
    assert "<table>" in page and "lambert+ggx" in page and "http" not in page
    for src in ("spheres.png", "polar.png", "brdf_slices.png", "slice_0.png", "albedo.png"):
        assert f"src='{src}'" in page and (tmp_path / "rep" / src).is_file()
    r = runner.invoke(main, ["brdf", "compare", str(data), str(fit), "--model", "lambert+blinn",
                             "--json"])
    assert r.exit_code == 0, r.output
    rows = json.loads(r.stdout)["rows"]
    assert [row["name"] for row in rows] == ["fit.json", "lambert+blinn"]
    assert rows[1]["rmse"] < 1e-6 < rows[0]["rmse"]  # the true model fits exactly
    # bad input: one message, exit 2, no file
    out = tmp_path / "none.png"
    r = runner.invoke(main, ["plot", str(data), "--kind", "slice", "-o", str(out)])
    assert r.exit_code == 2 and "error:" in r.output and not out.exists()
    r = runner.invoke(main, ["plot", str(fit), "--kind", "sphere", "--model", "phong", "-o",
                             str(out)])
    assert r.exit_code == 2 and "phong" in r.output and not out.exists()


@pytest.mark.slow
def test_drawing_leaves_the_users_matplotlib_backend_alone(tmp_path: Path) -> None:
    """A notebook's backend survives importing ratfit's plotting code and saving PNGs."""
    import subprocess
    import sys

    code = f"""
import matplotlib
matplotlib.use("pdf")
import numpy as np
import ratfit.viz.plots, ratfit.viz.pictures, ratfit.viz.plots_cdf, ratfit.viz.report
from ratfit.viz.plots import plot_function
from ratfit.viz.pictures import plot_spheres
p = plot_function(np.linspace(0, 1, 50), np.linspace(0, 1, 50) ** 2, {str(tmp_path / 'f.png')!r})
q = plot_spheres({{"a": np.full((16, 16, 3), 0.5)}}, {str(tmp_path / 's.png')!r})
import sys
print(matplotlib.get_backend(), "matplotlib.pyplot" in sys.modules)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["pdf", "False"], out.stdout + out.stderr
    for name in ("f.png", "s.png"):
        data = (tmp_path / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 1000, name


@pytest.mark.slow
def test_report_without_albedo_has_no_empty_albedo_plot(dense, tmp_path, monkeypatch):
    """Where the fit's domain leaves no incidence with a directional albedo (cayman in
    the half-vector frame), the page says so in words and shows no empty plot."""
    import ratfit.brdf.albedo as albedo_mod

    real = albedo_mod.directional_albedo

    def nowhere(*args, **kw):
        alb = real(*args, **kw)
        alb.albedo[:] = np.nan
        return alb

    monkeypatch.setattr(albedo_mod, "directional_albedo", nowhere)
    x, y, _, doc = dense
    fit, data = _fit_and_data_files(x, y, doc, tmp_path)
    r = CliRunner().invoke(main, ["report", str(fit), "--data", str(data), "-o",
                                  str(tmp_path / "rep")])
    assert r.exit_code == 0, r.output
    page = (tmp_path / "rep" / "index.html").read_text()
    assert "Directional albedo: not available" in page
    assert "albedo.png" not in page and not (tmp_path / "rep" / "albedo.png").exists()
    assert "src='spheres.png'" in page


def test_slice_rows_pick_the_fullest_line_or_a_slab_on_scattered_data():
    """A slice through the median sample of scattered data (Cornell in the half-vector
    frame) held one or two samples. On a grid the line with the most samples is
    taken; on scattered data the samples within 5 % of the span of the other axes."""
    rng = np.random.default_rng(0)
    g = np.linspace(0.0, 1.0, 12)
    grid = np.array([(a, b) for a in g for b in g])
    grid = np.vstack([grid, [[0.5, 0.123]]])  # one odd sample: its line holds one point
    rows, at, slab = pic._slice_rows(grid, 0, None)
    assert slab == 0.0 and rows.sum() == 12 and np.all(grid[rows, 1] == at[1])
    pts = rng.uniform(size=(1439, 3))
    rows, at, slab = pic._slice_rows(pts, 1, None)
    assert slab == pic.SLICE_SLAB
    assert any(np.array_equal(at, p) for p in pts)  # centred on a sample
    assert rows.sum() >= 8  # about 1439 x 0.1 x 0.1 = 14 on average, the fullest of 256
    assert np.all(np.abs(pts[rows][:, [0, 2]] - at[[0, 2]]) <= pic.SLICE_SLAB + 1e-12)
    # a given point keeps the exact line through it
    rows, at2, slab = pic._slice_rows(pts, 1, pts[7])
    assert slab == 0.0 and rows.sum() == 1 and np.array_equal(at2, pts[7])


# ---------------------------------------------------------------------------- names as text
NAMES_WITH_DOLLARS = ["$\\oops$", "a$b$c", "$x^2$", "cost $5 and $6", "\\$x$"]


@pytest.mark.parametrize("name", NAMES_WITH_DOLLARS)
def test_names_from_files_are_never_mathtext(tmp_path: Path, monkeypatch, name: str) -> None:
    """A channel or column name holding `$` is drawn as written: never parsed as mathtext
    (a malformed formula such as $\\oops$ stopped the picture with exit 3 before)."""
    from matplotlib import cbook
    from matplotlib.text import Text

    from ratfit.viz import _figures

    x = np.linspace(0.0, 2.0, 40).tolist()
    data = tmp_path / "d.csv"
    data.write_text(f"x{name},y_{name}\n" + "".join(f"{a!r},{1 / (1 + a * a) + 0.5!r}\n"
                                                     for a in x))
    fit = tmp_path / "fit.json"
    run = CliRunner()
    res = run.invoke(main, ["fit", str(data), "--dt", "0.01", "-o", str(fit)])
    assert res.exit_code == 0, res.output
    assert json.loads(fit.read_text())["channels"][0]["name"] == name
    shown: list[str] = []
    real_close = _figures.close

    def keep_texts(fig) -> None:
        for t in fig.findobj(Text):
            raw = t.get_text()
            if raw.startswith("$\\mathdefault{"):
                continue  # matplotlib's own log-axis tick labels (10^k), not file text
            if raw:
                assert not cbook.is_math_text(raw), raw
                shown.append(t._preprocess_math(raw)[0])  # what is drawn
        real_close(fig)

    monkeypatch.setattr(_figures, "close", keep_texts)
    for args in (["plot", str(fit), "--data", str(data), "-o", str(tmp_path / "p.png")],
                 ["plot", str(fit), "--data", str(data), "--kind", "error", "-o",
                  str(tmp_path / "e.png")],
                 ["report", str(fit), "--data", str(data), "-o", str(tmp_path / "r")]):
        res = run.invoke(main, args)
        assert res.exit_code == 0, res.output
    assert any(name in s for s in shown)  # the channel name, drawn verbatim
    assert any(f"x{name}" in s for s in shown)  # the column name too
