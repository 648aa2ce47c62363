"""K-fold held-out errors of BRDF fits (ratfit.brdf.holdout, `brdf fit --holdout K`)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import above_horizon

from ratfit.brdf.analytic_models import Model
from ratfit.brdf.holdout import REL_FLOOR, cross_validate, fold_indices, holdout_metrics
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.cli.main import main
from ratfit.errors import InputError
from ratfit.io.data import Dataset

FRAME = "RUSIN_TH_TD_SYM"


def test_folds_partition_the_samples_the_same_way_every_run():
    folds = fold_indices(103, 5, seed=3)
    joined = np.sort(np.concatenate(folds))
    assert np.array_equal(joined, np.arange(103))
    assert sorted(f.size for f in folds) == [20, 20, 21, 21, 21]
    again = fold_indices(103, 5, seed=3)
    assert all(np.array_equal(a, b) for a, b in zip(folds, again, strict=True))
    other = fold_indices(103, 5, seed=4)
    assert not all(np.array_equal(a, b) for a, b in zip(folds, other, strict=True))
    with pytest.raises(InputError, match="K >= 2"):
        fold_indices(10, 1)
    with pytest.raises(InputError, match="at least 5 samples"):
        fold_indices(4, 5)


def test_holdout_metrics_are_the_stated_formulas():
    pred = np.array([[1.0], [3.0], [0.0]])
    ref = np.array([[1.0], [1.0], [0.0]])
    cos_l = np.array([1.0, 0.5, 1.0])
    m = holdout_metrics(pred, ref, cos_l, ("R",))["R"]
    assert m["rmse"] == pytest.approx(np.sqrt(4.0 / 3.0))
    assert m["cos_rmse"] == pytest.approx(np.sqrt(1.0 / 3.0))
    rel = np.log((3.0 + REL_FLOOR) / (1.0 + REL_FLOOR))
    assert m["rel_rmse"] == pytest.approx(np.sqrt(rel**2 / 3.0))


def _smooth_material(n: int, seed: int = 0) -> Dataset:
    """A known lambert + wide ggx material at random direction pairs, in the frame."""
    rng = np.random.default_rng(seed)
    L, V = above_horizon(rng, n), above_horizon(rng, n)
    y = Model("lambert+ggx")(L, V, [0.5, 0.2, 0.6, 0.04])
    x = get_parametrization(FRAME)._from(L, V)
    return Dataset(x=x, y=y[:, None], output_names=("R",),
                   meta={"param_in": FRAME, "source": "smooth"})


def test_cross_validation_predicts_unseen_samples_of_a_smooth_material():
    ds = _smooth_material(160)
    res = cross_validate([ds], 4, dt=0.05, floor_rel=0.01, time_limit=60)
    assert res.folds_verified == 4 and res.held_out == 160
    assert [f["held_out"] for f in res.folds] == [40, 40, 40, 40]
    assert all(f["parametrization"] == FRAME and f["coefficients"] >= 2 for f in res.folds)
    m = res.metrics["R"]
    # each sample predicted by a fit that never saw it: close, but not the training error
    assert 0.0 < m["rel_rmse"] < 0.1
    assert np.all(np.isfinite(res.predictions))
    y = np.asarray(ds.y)
    assert np.median(np.abs(res.predictions - y) / y) < 0.05
    doc = res.to_dict()
    assert doc["k"] == 4 and doc["folds_verified"] == 4 and doc["rel_floor"] == REL_FLOOR


def test_folds_in_separate_processes_give_the_same_predictions():
    # each fold's fit is bounded by counted work, not a clock: workers change nothing
    ds = _smooth_material(90, seed=3)
    one = cross_validate([ds], 3, dt=0.05, floor_rel=0.01, seed=2)
    two = cross_validate([ds], 3, dt=0.05, floor_rel=0.01, seed=2, workers=2)
    assert one.folds_verified == 3
    assert one.folds == two.folds
    assert np.array_equal(one.predictions, two.predictions, equal_nan=True)
    assert one.metrics == two.metrics


def test_cli_records_the_holdout_in_the_fit_file(tmp_path: Path, shared_data: Path):
    out = tmp_path / "fit.json"
    r = CliRunner().invoke(main, [
        "brdf", "fit", str(shared_data / "cornell" / "garnet_red.brdf"), "--channel", "R",
        "--max-points", "80", "--dt", "0.3", "--floor-rel", "0.01", "--holdout", "2",
        "--param", FRAME, "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "held-out (2-fold, seed 0)" in r.output
    block = json.loads(out.read_text())["brdf"]["holdout"]
    assert block["k"] == 2 and block["n_points"] == 80
    assert block["metrics"]["R"]["rmse"] > 0
    r = CliRunner().invoke(main, [
        "brdf", "fit", str(shared_data / "cornell" / "garnet_red.brdf"), "--holdout", "1",
        "-o", str(tmp_path / "no.json")])
    assert r.exit_code == 2 and "--holdout must be >= 2" in r.output
    assert not (tmp_path / "no.json").exists()


def test_one_sample_that_carries_the_held_out_error_is_named():
    from ratfit.brdf.holdout import WORST_SHARE, HoldoutResult

    y = np.array([[1.0, 1.0], [2.0, 2.0], [39.0, 3.0], [0.5, 0.5]])
    pred = np.array([[1.1, 1.1], [1.9, 2.2], [1.0, 3.1], [np.nan, 0.4]])
    names = ("R", "G")
    seen = np.isfinite(pred).all(axis=1)
    m = holdout_metrics(pred[seen], y[seen], None, names)
    res = HoldoutResult(5, 0, m, [], int(seen.sum()), 4, pred, y)
    worst = res.worst()
    assert worst["R"]["row"] == 2 and worst["R"]["y"] == 39.0 and worst["R"]["predicted"] == 1.0
    assert worst["R"]["share"] == pytest.approx(38.0**2 / (0.01 + 0.01 + 38.0**2))
    # G's worst sample (row 1: errors 0.1, 0.2, 0.1, 0.1) carries 4/7 of its squared error
    assert worst["G"]["row"] == 1
    assert worst["G"]["share"] == pytest.approx(0.04 / (0.01 + 0.04 + 0.01 + 0.01))
    lines = res.lines()
    named = [ln for ln in lines if "of the held-out squared error is one sample" in ln]
    assert [ln.split(":")[0] for ln in named] == [n for n in names
                                                  if worst[n]["share"] >= WORST_SHARE]
    assert "row 3: data 39, predicted 1)" in named[0]
    # no predictions kept (a result read back from a fit file): nothing to name
    assert HoldoutResult(5, 0, m, [], 3, 4).worst() == {}
