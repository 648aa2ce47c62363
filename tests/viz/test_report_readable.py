"""Issue 27: pictures a researcher can put in a paper.

Units on every axis, angles in degrees, relative errors against a stated floor
(not a "rel. RMSE 882" from near-zero data), a log-scale option that changes the
axis, a theta_d = 0 panel that says why it has no fit, polar plots where the fit
is not shrunk to a dot by a data outlier.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from ratfit.viz import pictures as pic


@pytest.fixture
def figures(monkeypatch) -> list:
    """Every figure a picture function saves, kept open for inspection."""
    kept: list = []
    real = pic._save

    def keep(fig, path, dpi=100):
        kept.append(fig)
        with_path = Path(path)
        fig.savefig(with_path, format="png", dpi=40)
        return with_path

    monkeypatch.setattr(pic, "_save", keep)
    assert real is not keep
    return kept


def _fit_1d(x: np.ndarray, y: np.ndarray, dt: float = 0.02, floor: float = 0.0):
    from ratfit.core.segments import Segments
    from ratfit.fitting.search import RationalFitter
    from ratfit.io.fitfile import fit_document, parse_fit

    xs = x[:, None]
    half = np.maximum(dt * np.abs(y), floor)[:, None]
    seg = Segments(xs, y[:, None] - half, y[:, None] + half)
    f = RationalFitter(max_total=20).fit(seg)
    assert f.success_
    return parse_fit(fit_document(f.results_))


@pytest.fixture(scope="module")
def decay():
    """y = exp(-4 x) on [0, 2.5]: four decades, a fit within 2 %."""
    x = np.linspace(0.0, 2.5, 120)
    y = np.exp(-4.0 * x)
    return x, y, _fit_1d(x, y)


def test_angle_coordinates_in_degrees_and_values_with_units(decay, figures, tmp_path):
    x, y, saved = decay
    pic.plot_slice(saved, tmp_path / "a.png", x=x, y=y, names=["theta_h"],
                   style=pic.BRDF_STYLE)
    top, bottom = figures[-1].axes[:2]
    assert bottom.get_xlabel() == "theta_h (deg)"
    assert top.get_ylabel().startswith("y0: BRDF (1/sr)")
    assert "(1/sr)" in bottom.get_ylabel()
    # the x axis runs in degrees: 0 .. 2.5 rad = 143 deg (x itself is the angle here)
    assert bottom.get_xlim()[1] == pytest.approx(np.degrees(2.5), rel=0.06)
    pic.plot_slice(saved, tmp_path / "b.png", x=x, y=y, names=["x"])
    top, bottom = figures[-1].axes[:2]
    assert bottom.get_xlabel() == "x (file units)"
    assert "(file units)" in top.get_ylabel()
    pic.plot_error(saved, tmp_path / "c.png", x, y, names=["phi_d"], style=pic.BRDF_STYLE)
    ax = figures[-1].axes[0]
    assert ax.get_xlabel() == "phi_d (deg)" and "(1/sr)" in ax.get_ylabel()


def test_log_option_changes_the_scale(decay, figures, tmp_path):
    x, y, saved = decay
    for scale, want in (("auto", "log"), ("log", "log"), ("linear", "linear")):
        pic.plot_slice(saved, tmp_path / f"{scale}.png", x=x, y=y,
                       style=pic.PlotStyle(scale=scale))
        assert figures[-1].axes[0].get_yscale() == want, scale
    # auto on data spanning one decade stays linear
    assert pic.resolve_scale(np.linspace(1.0, 9.0, 50), "auto") == "linear"
    assert pic.resolve_scale(np.exp(-4.0 * x), "auto") == "log"
    with pytest.raises(Exception, match="scale must be one of"):
        pic.PlotStyle(scale="logarithmic")


def test_relative_error_has_a_stated_floor(decay, figures, tmp_path):
    x, y, saved = decay
    yz = y.copy()
    yz[100::5] = 1e-9  # near-zero tail (true y < 2.3e-4): |r - y| / |y| alone is ~1e5
    pred = saved.channels[0].rational(x[:, None]).ravel()
    assert np.max(np.abs(pred - yz) / np.abs(yz)) > 1e5
    _, floor = pic.plot_relative_error(saved, tmp_path / "r.png", x, yz)
    assert floor == pytest.approx(1e-3 * np.max(np.abs(yz)))
    rel = np.abs(pred - yz) / np.maximum(np.abs(yz), floor)
    ax = figures[-1].axes[0]
    assert ax.get_yscale() == "log" and ax.get_ylabel() == "relative error (log scale)"
    assert f"floor {floor:.3g} = 0.001 x max |y|" in ax.get_title()
    assert f"(max {rel.max():.3g})" in ax.get_title()
    assert rel.max() < 0.5  # bounded by |r - y| / floor, not by 1/1e-9
    from ratfit.viz.report import floored

    m = floored({}, pred, yz, 1e-3)
    assert m["rel_floor"] == pytest.approx(floor)
    assert m["rel_rmse"] == pytest.approx(np.sqrt(np.mean(rel**2)))
    assert m["max_rel"] == pytest.approx(rel.max())


def test_theta_d_zero_panel_says_why_it_has_no_fit(figures, tmp_path):
    def fit(L, V):  # a fit whose domain starts at theta_d = 5 deg (no data at L = V)
        cos_d = np.sum(L * (L + V) / np.linalg.norm(L + V, axis=1)[:, None], axis=1)
        out = np.full((L.shape[0], 1), 0.2)
        out[cos_d > np.cos(np.radians(5.0))] = np.nan
        return out

    pic.plot_brdf_slices({"rational": fit, "model": lambda L, V: np.full((len(L), 1), 0.3)},
                         tmp_path / "s.png")
    panels = figures[-1].axes
    text0 = " ".join(t.get_text() for t in panels[0].texts)
    assert "no value here: rational" in text0 and "outside the fit's domain" in text0
    assert not panels[1].texts  # theta_d = 15 deg: both drawn
    assert all(a.get_xlabel() == "theta_h (deg)" for a in panels[:6])
    assert panels[0].get_title() == "theta_d = 0 deg, phi_d = 90 deg"


def test_polar_range_follows_the_fit_not_a_data_outlier(figures, tmp_path):
    def fit(L, V):
        return np.full((len(L), 1), 0.1)

    def data(L, V):  # mostly the fit, one configuration 100x brighter
        v = np.full((len(L), 1), 0.1)
        v[np.abs(V[:, 0]) > 0.99] = 10.0
        return v

    pic.plot_polar({"rational": fit}, tmp_path / "p.png", data=data, scale="linear")
    ax = figures[-1].axes[0]
    assert ax.get_ylim()[1] == pytest.approx(0.108)  # the fit fills the plot
    labels = [t.get_text() for t in figures[-1].legends[0].texts]
    assert "data above the radial range (on the rim)" in labels
    assert "radius: BRDF (1/sr)" in " ".join(t.get_text() for t in ax.texts)
    pic.plot_polar({"rational": fit}, tmp_path / "q.png", data=data, scale="log")
    ax = figures[-1].axes[0]
    lo, hi = ax.get_ylim()
    assert hi >= np.log10(10.0) and lo == pytest.approx(np.log10(10.0) - 1 - 4 + 1, abs=1)


@pytest.mark.slow
def test_report_of_a_nist_fit(shared_data, tmp_path):
    """Kirby2 (y from 0.008 to 92): log axes chosen automatically, the floored
    relative error in the table and panel, a caption under every picture."""
    from conftest import run_cli

    from ratfit.io.data import read_data
    from ratfit.viz.report import LoadedFit

    data = shared_data / "nist" / "Kirby2.dat"
    fit = tmp_path / "kirby.json"
    r = run_cli("fit", data, "--dt", "0.02", "--abs-width", "0.05", "-o", fit)
    assert r.exit_code == 0, r.output
    r = run_cli("report", fit, "--data", data, "-o", tmp_path / "rep")
    assert r.exit_code == 0, r.output
    page = (tmp_path / "rep" / "index.html").read_text()
    ds = read_data(data)
    y = ds.y[:, 0]
    floor = 1e-3 * np.max(np.abs(y))
    pred = LoadedFit.load(fit).saved(ds.x)[:, 0]
    rel = np.abs(pred - y) / np.maximum(np.abs(y), floor)
    assert np.max(np.abs(pred - y) / np.abs(y)) > 2 * rel.max()  # the floor matters here
    assert f"<td>{rel.max():.4g}</td>" in page
    assert f"(y: {floor:.4g})" in page
    assert "Values on a log axis (chosen automatically" in page
    caps = re.findall(r"<figcaption>(.*?)</figcaption>", page, re.S)
    imgs = re.findall(r"<img src='([^']+)'", page)
    assert len(caps) == len(imgs) == 3 and all(len(c) > 80 for c in caps)
    assert "relerr_0.png" in imgs
    r = run_cli("report", fit, "--data", data, "-o", tmp_path / "lin", "--scale", "linear")
    assert r.exit_code == 0, r.output
    assert "Values on a linear axis." in (tmp_path / "lin" / "index.html").read_text()
