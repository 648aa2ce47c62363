"""`ratfit render`: images of a fit beside its data, one-line errors, no partial files."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ratfit.brdf.parametrizations import get_parametrization
from ratfit.cli import main
from ratfit.io.alta_function import write_alta_data
from ratfit.io.data import Dataset

from .conftest import ggx_rgb


def _one_error_line(res) -> str:
    lines = [x for x in res.output.splitlines() if x.strip()]
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    err = [x for x in lines if x.startswith("error:") or x.startswith("Error:")]
    assert len(err) == 1, res.output
    return err[0]


def test_missing_extra_is_one_error_line(rgb_fit: Path, tmp_path: Path, monkeypatch) -> None:
    from ratfit.render import mitsuba_bsdf as mb

    monkeypatch.setitem(sys.modules, "mitsuba", None)  # import mitsuba -> ImportError
    monkeypatch.setitem(mb._STATE, "variant", None)
    out = tmp_path / "x.png"
    res = CliRunner().invoke(main, ["render", str(rgb_fit), "-o", str(out)])
    line = _one_error_line(res)
    assert 'pip install ".[render]"' in line and "Mitsuba" in line
    assert not out.exists()


@pytest.mark.parametrize("args,needle", [
    (["-o", "{tmp}/x.jpg"], ".exr or .png"),
    (["-o", "{tmp}/x.png", "--spp", "0"], "--spp"),
    (["-o", "{tmp}/x.png", "--exposure", "-1"], "--exposure"),
])
def test_usage_errors(rgb_fit: Path, tmp_path: Path, args: list[str], needle: str) -> None:
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    res = CliRunner().invoke(main, ["render", str(rgb_fit), *args])
    assert needle in _one_error_line(res)
    assert not list(tmp_path.iterdir())


def test_bad_fit_files(tmp_path: Path) -> None:
    pytest.importorskip("mitsuba", reason='Mitsuba 3 not installed: pip install ".[render]"')
    out = tmp_path / "x.png"
    res = CliRunner().invoke(main, ["render", str(tmp_path / "nope.json"), "-o", str(out)])
    assert "nope.json" in _one_error_line(res)
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "ratfit.fit", "version": 2, "space": ')
    res = CliRunner().invoke(main, ["render", str(bad), "-o", str(out)])
    assert "bad.json" in _one_error_line(res)
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["bad.json"]


def _data_file(tmp_path: Path, name: str, fn) -> Path:
    """Dense ALTA data of ``fn`` in ISOTROPIC_TV_TL_DPHI (a stand-in for measurements)."""
    g = np.radians(np.arange(2.5, 88.0, 5.0))
    dp = np.radians(np.arange(0.0, 181.0, 10.0))
    TV, TL, DP = (a.ravel() for a in np.meshgrid(g, g, dp, indexing="ij"))
    x = np.stack([TV, TL, DP], 1)
    L, V = get_parametrization("ISOTROPIC_TV_TL_DPHI").to_dirs(x)
    ds = Dataset(x, fn(L, V), output_names=("R", "G", "B"),
                 meta={"param_in": "ISOTROPIC_TV_TL_DPHI"})
    path = tmp_path / name
    write_alta_data(path, ds)
    return path


@pytest.mark.slow
def test_render_fit_beside_data(rgb_fit: Path, tmp_path: Path) -> None:
    """Same camera, light, samples: the fit of a material is close to that material's data,
    far from another material's; the difference image is fit - data."""
    mi = pytest.importorskip("mitsuba", reason='Mitsuba 3 not installed: pip install ".[render]"')
    same = _data_file(tmp_path, "same.alta", ggx_rgb)
    other = _data_file(tmp_path, "other.alta", lambda L, V: np.full((len(L), 3), 0.05))
    got = {}
    for name, data in (("same", same), ("other", other)):
        out = tmp_path / f"{name}.exr"
        res = CliRunner().invoke(main, ["render", str(rgb_fit), "-o", str(out), "--size", "24",
                                        "--spp", "16", "--sampling", "cosine", "--data",
                                        str(data), "--json"])
        assert res.exit_code == 0, res.output
        info = json.loads(res.output[res.output.index("{"):])
        got[name] = info["difference"]
        panel = np.asarray(mi.Bitmap(str(out)))
        diff = np.asarray(mi.Bitmap(str(tmp_path / f"{name}-diff.exr")))
        assert panel.shape[0] == 24 and panel.shape[1] > 3 * 24 and diff.shape[:2] == (24, 24)
        assert np.all(np.isfinite(panel)) and np.abs(diff).max() > 0
    # same seeds: the noise is shared, what remains is the fit's error (measured ~0.02)
    assert got["same"]["rel_rmse"] < 0.08, got
    assert got["other"]["rel_rmse"] > 10 * got["same"]["rel_rmse"], got


@pytest.mark.slow
def test_render_png_with_fit_sampling_and_progress(rgb_fit: Path, tmp_path: Path) -> None:
    pytest.importorskip("mitsuba", reason='Mitsuba 3 not installed: pip install ".[render]"')
    out = tmp_path / "f.png"
    res = CliRunner().invoke(main, ["render", str(rgb_fit), "-o", str(out), "--size", "16",
                                    "--spp", "4", "--incidence-nodes", "2",
                                    "--conditional-nodes", "3"])
    assert res.exit_code == 0, res.output
    assert "verified rational CDFs" in res.output
    # the last pass ends the estimate (one pass on LLVM, one per sample on scalar_rgb)
    assert re.search(r"fit: pass (\d+)/\1, 4/4 spp, [\d.]+ s, done", res.stderr), res.stderr
    # the sampler's CDF fits (2 incidence nodes x (marginal + 3 conditionals)) report
    # their count and an estimate like the render passes; each step ends once
    assert re.search(r"sampler: CDF 1/8, [\d.]+ s, about \d+ (s|min) left", res.stderr), \
        res.stderr
    assert "sampler: CDF 8/8, " in res.stderr and res.stderr.count(", done") == 2
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_an_analytic_model_renders_like_a_fit(tmp_path: Path) -> None:
    """`brdf model` fits the model `brdf compare` fits and saves it; `render` draws it in
    the same scene as a fit: a model of the very material it was fitted to is close to
    the data's render, and it recovers the material's parameters."""
    pytest.importorskip("mitsuba", reason='Mitsuba 3 not installed: pip install ".[render]"')
    from ratfit.brdf.analytic_models import load_model_fit

    from .conftest import GGX

    data = _data_file(tmp_path, "ggx.alta", ggx_rgb)
    model = tmp_path / "model.json"
    res = CliRunner().invoke(main, ["brdf", "model", str(data), "--model", GGX[0],
                                    "-o", str(model), "--starts", "2"])
    assert res.exit_code == 0, res.output
    mf = load_model_fit(model)
    assert mf.model.spec == GGX[0] and mf.n_channels == 3
    alpha = mf.model.param_names.index("ggx1.alpha")
    assert np.allclose(mf.params[:, alpha], GGX[1][alpha], rtol=0.02)
    out = tmp_path / "model.exr"
    res = CliRunner().invoke(main, ["render", str(model), "-o", str(out), "--size", "24",
                                    "--spp", "16", "--sampling", "cosine", "--data", str(data),
                                    "--json"])
    assert res.exit_code == 0, res.output
    info = json.loads(res.output[res.output.index("{"):])
    assert info["difference"]["rel_rmse"] < 0.08, info
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "ratfit.model", "model": "lambert", "channels": []}')
    res = CliRunner().invoke(main, ["render", str(bad), "-o", str(tmp_path / "x.exr")])
    assert _one_error_line(res) and not (tmp_path / "x.exr").exists()
