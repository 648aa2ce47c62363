"""A full MERL table's default fit: ratfit's table defaults (a subset drawn by direction
pairs, RUSIN_TH_TD_FOLD, log values, the networks' size) fill what a request leaves open;
among frames tried, the half-vector frame first, with log values there.

resolve_values decides "auto" from the dataset. The table here is a closed-form material
(Lambert + a Blinn-like lobe with a colour of its own) written at MERL's resolution.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import run_cli

from ratfit.brdf.fitter import (
    HALF_VECTOR,
    candidate_parametrizations,
    fit_brdf,
    resolve_values,
)
from ratfit.brdf.io import merl_from_function, read_brdf, samples_dataset, write_merl
from ratfit.brdf.options import BRDFOptions
from ratfit.errors import InputError
from ratfit.jobs.brdf import TABLE_DEFAULTS, TABLE_GROUPS, BRDFFitRequest

PD = "RUSIN_TH_TD_PD"
KD = np.array([0.12, 0.05, 0.02])
KS = np.array([2.0, 1.6, 1.2])


def material(L: np.ndarray, V: np.ndarray) -> np.ndarray:
    """Lambert + a lobe around the mirror direction (N, 3), 1/sr."""
    h = L + V
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    lobe = np.clip(h[:, 2], 0.0, 1.0) ** 40
    return KD / np.pi + KS * lobe[:, None]


@pytest.fixture(scope="module")
def table(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("merl") / "closed-form.binary"
    write_merl(path, merl_from_function(material))
    return path


def test_auto_values_are_log_for_a_table_in_the_half_vector_frame(table: Path) -> None:
    data = read_brdf(table)
    sym = samples_dataset(data, HALF_VECTOR, max_points=200)
    pd = samples_dataset(data, PD, max_points=200)
    assert resolve_values("auto", sym, HALF_VECTOR) == "log"
    assert resolve_values("auto", pd, PD) == "linear"  # no smaller there (measured)
    assert resolve_values("auto", sym, HALF_VECTOR, shared_denominator=True) == "linear"
    assert resolve_values("linear", sym, HALF_VECTOR) == "linear"  # a word given is kept
    # not a table: scattered measurements are log values at ratfit's widths (noise
    # floors) in the half-vector frame, linear at widths the caller gives
    scattered = samples_dataset(data, HALF_VECTOR, max_points=200)
    scattered = type(scattered)(**{**scattered.__dict__,
                                   "meta": {**scattered.meta, "format": "cornell"}})
    assert resolve_values("auto", scattered, HALF_VECTOR) == "log"
    assert resolve_values("auto", scattered, HALF_VECTOR, widths_given=True) == "linear"


def test_a_table_is_tried_in_the_half_vector_frame_first() -> None:
    assert candidate_parametrizations(PD, table=True) == (HALF_VECTOR, PD)
    assert candidate_parametrizations(PD) == (PD,)  # scattered data in its own angles
    # f cos(theta_l) is not reciprocal: no symmetric frame
    assert candidate_parametrizations(PD, cosine=True, table=True) == (PD,)


def test_a_bad_values_word_is_refused_before_any_fit(table: Path) -> None:
    ds = samples_dataset(read_brdf(table), HALF_VECTOR, max_points=200)
    with pytest.raises(InputError, match="unknown values 'exp'; choose one of auto, linear, log"):
        fit_brdf(ds, values="exp")


def test_a_request_left_open_takes_the_table_defaults(table: Path) -> None:
    """Each group of options a request gives replaces its part of the table defaults,
    and only that part."""
    req, filled = TABLE_DEFAULTS.apply(BRDFFitRequest(table))
    assert filled == TABLE_GROUPS
    assert (req.parametrization, req.max_points, req.subset_by, req.dt, req.abs_width) == (
        "RUSIN_TH_TD_FOLD", 5000, "pairs", 0.22, 1e-3)
    assert (req.options.values, req.options.n, req.options.m) == ("log", 113, 112)
    given = BRDFFitRequest(table, parametrization=HALF_VECTOR, max_points=800, dt=0.3,
                           options=BRDFOptions(values="linear", max_total=40))
    assert TABLE_DEFAULTS.apply(given) == (given, ())
    # a floor alone is a width given; a total a size given; energy draws stay energy
    req, filled = TABLE_DEFAULTS.apply(BRDFFitRequest(
        table, abs_width=0.01, dt=0.1, options=BRDFOptions(total=30)))
    assert filled == ("frame", "subset", "values") and (req.dt, req.abs_width) == (0.1, 0.01)
    assert (req.options.n, req.options.total) == (None, 30)
    # one denominator for all channels refuses log values and a fixed n
    req, filled = TABLE_DEFAULTS.apply(BRDFFitRequest(table, shared_denominator=True))
    assert filled == ("frame", "subset", "widths")
    assert (req.options.values, req.options.n) == ("auto", None)


def test_default_fit_of_a_table_is_a_subset_by_pairs_in_the_fold_frame(
        table: Path, tmp_path: Path) -> None:
    """``ratfit brdf fit TABLE`` with the subset smaller than the default's (CI's time):
    the other defaults fill the rest, the report says so, and the fit holds the closed
    form at random pairs it never saw."""
    out = tmp_path / "fit.json"
    t0 = time.perf_counter()
    r = run_cli("brdf", "fit", table, "--max-points", "2500", "--subset-by", "pairs",
                "--json", "-o", out)
    wall = time.perf_counter() - t0
    assert r.exit_code == 0, r.output
    summary = json.loads(r.stdout)
    assert summary["table_defaults"] == ("--param RUSIN_TH_TD_FOLD --values log --dt 0.22 "
                                         "--abs-width 0.001 --n 113 --m 112")
    assert summary["success"] is True and summary["values"] == "log"
    # the job's phases in wall seconds: within the call's own wall time
    phases = summary["phase_seconds"]
    assert {"fit", "write"} <= set(phases) and phases["fit"] > 0
    assert sum(phases.values()) <= wall
    doc = json.loads(out.read_text())
    assert doc["brdf"]["parametrization"] == "RUSIN_TH_TD_FOLD"
    assert doc["brdf"]["values"] == "log"
    assert doc["brdf"]["subset"] == {"points": 2500, "of": doc["brdf"]["subset"]["of"],
                                     "by": "pairs"}
    assert [(c["n"], c["m"]) for c in doc["channels"]] == [(113, 112)] * 3
    assert all(p["proved"] for p in doc["brdf"]["proof"])
    # away from the cells it was fitted on: the closed form within a few per cent
    rng = np.random.default_rng(5)
    dirs = tmp_path / "dirs.csv"
    th_l, th_v = rng.uniform(0.05, 1.3, (2, 400))
    ph = rng.uniform(0, 2 * np.pi, 400)
    L = np.stack([np.sin(th_l), np.zeros(400), np.cos(th_l)], axis=1)
    V = np.stack([np.sin(th_v) * np.cos(ph), np.sin(th_v) * np.sin(ph), np.cos(th_v)], axis=1)
    np.savetxt(dirs, np.hstack([L, V]), delimiter=",")
    ev = run_cli("brdf", "eval", out, "--dirs", dirs, "-o", tmp_path / "values.npy")
    assert ev.exit_code == 0, ev.output
    got = np.load(tmp_path / "values.npy")
    want = material(L, V)
    rel = np.abs(got - want) / want
    assert np.all(got > 0) and np.all(np.isfinite(got))
    # measured: 0.03 % median, 0.25 % at the 95th percentile, 1 % at most
    assert np.median(rel) < 0.005, np.median(rel, axis=0)
    assert np.percentile(rel, 95) < 0.02


def test_a_table_builds_no_envelope_and_measures_no_growth(table: Path, monkeypatch) -> None:
    """A table's cells leave no gap for an envelope to close; measuring its highlight's
    growth took minutes at MERL's 1.1e6 cells (a loop over 141 755 distinct angle pairs),
    so a table's log fit must not ask for it."""
    import ratfit.brdf.validity as validity

    def refuse(*args, **kwargs):
        raise AssertionError("theta_d_growth called for a full table")

    monkeypatch.setattr(validity, "theta_d_growth", refuse)
    ds = samples_dataset(read_brdf(table), HALF_VECTOR, max_points=1500)
    fitter, _seg, meta = fit_brdf(ds, values="log", max_total=12)
    assert fitter.envelope is False and meta["envelope"] is None
    # scattered samples of the same material do build one, with the growth
    scattered = type(ds)(**{**ds.__dict__, "meta": {**ds.meta, "format": "cornell"}})
    with pytest.raises(AssertionError, match="for a full table"):
        fit_brdf(scattered, values="log", max_total=12)


def test_a_table_in_merl_axes_keeps_every_cell(table: Path) -> None:
    """A MERL table in RUSIN_TH_TD_PD has its cells' own coordinates, phi_d in [0, pi):
    the seam rule of a pair of directions (fold_phi_d: in-plane pairs get phi_d = 0)
    does not apply to them, or the cells at theta_h = 0 and theta_d = 0 with phi_d >
    pi / 2 would merge with phi_d = 0: 15 931 of the 1 458 000 cells)."""
    data = read_brdf(table)
    assert np.sum((data.coords[:, 0] == 0.0) & (data.coords[:, 2] > 0.5 * np.pi)) > 1000
    ds = samples_dataset(data, PD)
    np.testing.assert_array_equal(ds.x, data.coords)
    assert ds.meta["fold_phi_d"] is True


def test_a_channel_at_ratfits_widths_is_widened_alone_at_a_fixed_size(table: Path) -> None:
    """A table's default widths are ratfit's, its size fixed: a channel with no fit at
    them is widened alone at that size (fit_brdf's ``widen_alone``); widths a caller
    gives are not."""
    ds = samples_dataset(read_brdf(table), "RUSIN_TH_TD_FOLD", channels=["G"],
                         max_points=1500, subset_by="pairs")
    kept, _, meta = fit_brdf(ds, values="log", dt=0.02, abs_width=1e-3, n=4, m=4)
    assert not kept.success_ and kept.results_[0].status == 1
    assert meta["segments"]["channel_dt"] is None
    widened, seg, meta = fit_brdf(ds, values="log", dt=0.02, abs_width=1e-3, n=4, m=4,
                                  widen_alone=True)
    (width,) = meta["segments"]["channel_dt"]
    res = widened.results_[0]
    assert widened.success_ and 0.02 < width <= 0.9 and (res.n, res.m) == (4, 4)
    assert f"segments widened to +- {width:.3g} y for this channel alone" in res.message
    assert "at n = 4, m = 4" in res.message
    # the segments the fit met are the widened ones
    y = seg.center[:, 0]
    np.testing.assert_allclose(seg.hi[:, 0], np.maximum((1 + width) * y, y + 1e-3))
