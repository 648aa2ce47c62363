"""`ratfit brdf compare` (issue 27): every column when written to a file, no stray
overflow warning from the analytic fits, progress with an estimate on stderr."""

from __future__ import annotations

import importlib
import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import run_cli

from ratfit.brdf.analytic_models import fit_model
from ratfit.brdf.io import brdf_dataset
from ratfit.brdf.parametrizations import get_parametrization

cli_main = importlib.import_module("ratfit.cli.main")


def _model_file(tmp_path: Path) -> Path:
    """A lambert+lafortune*2 model file: long parameter text, a table wider than 160."""
    params = [0.05633, 3.833e-08, -1.134, 146.1, 0.0009982, 0.8503, 1128.0]
    doc = {"format": "ratfit.model", "version": 1, "model": "lambert+lafortune*2",
           "channels": [{"name": n, "params": params} for n in ("R", "G", "B")]}
    path = tmp_path / "lafortune.json"
    path.write_text(json.dumps(doc))
    return path


def test_compare_to_a_file_keeps_every_column(shared_data: Path, tmp_path: Path,
                                              monkeypatch) -> None:
    monkeypatch.delenv("COLUMNS", raising=False)
    data = shared_data / "cornell" / "krylon_blue.brdf"
    r = run_cli("brdf", "compare", data, _model_file(tmp_path))
    assert r.exit_code == 0, r.output
    lines = r.stdout.splitlines()
    head = next(ln for ln in lines if ln.strip().startswith("fit"))
    assert head.split() == ["fit", "channel", "coefs", "rmse", "rel_rmse", "log_rmse", "linf",
                            "cos_rmse", "parameters"]
    assert "narrow terminal" not in r.stdout
    row = next(ln for ln in lines if ln.strip().startswith("lafortune.json") and " R " in ln)
    assert "lafortune2.e=1128" in row  # the parameters on the row's own line, not wrapped
    # the relative error's floor is stated and is 0.001 x the channel's largest value
    ds = brdf_dataset(data, None, color="rgb")
    floors = 1e-3 * np.max(np.abs(ds.y), axis=0)
    assert f"(R {floors[0]:.4g}, G {floors[1]:.4g}, B {floors[2]:.4g})" in r.stdout
    r = run_cli("brdf", "compare", data, _model_file(tmp_path), "--json")
    rows = json.loads(r.stdout)["rows"]
    assert [row["rel_floor"] for row in rows] == pytest.approx(list(floors))
    assert all(row["rel_rmse"] <= row["linf"] / row["rel_floor"] for row in rows)


@pytest.mark.slow
def test_lafortune_fit_prints_no_overflow_warning(shared_data: Path) -> None:
    """cayman's red channel: the optimiser's trial steps overflowed in its loss
    ("overflow encountered in square") before lobe values were capped."""
    ds = brdf_dataset(shared_data / "cornell" / "cayman.brdf", None, color="rgb")
    L, V = get_parametrization(str(ds.meta["param_in"])).to_dirs(ds.x)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mf = fit_model("lambert+lafortune*2", L, V, ds.y[:, :1], starts=2, seed=0)
    assert [str(w.message) for w in caught] == []
    # the same parameters as before the cap (the capped values are never the optimum)
    assert np.all(np.isfinite(mf.params)) and np.isfinite(mf.metrics[0]["rmse"])


def test_compare_shows_progress_with_an_estimate(shared_data: Path, monkeypatch) -> None:
    monkeypatch.setattr(cli_main, "PROGRESS_EVERY", 0.0)
    data = shared_data / "cornell" / "krylon_blue.brdf"
    r = run_cli("brdf", "compare", data, "--model", "lambert", "--starts", "2", "--json")
    assert r.exit_code == 0, r.output
    json.loads(r.stdout)  # stdout: one JSON object, the progress went to stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("ratfit: compare")]
    assert len(lines) == 6  # 3 channels x 2 starts
    assert "about" in lines[0] and "s left" in lines[0] and "(lambert R start 1/2)" in lines[0]
    assert lines[-1].startswith("ratfit: compare 6/6,")
