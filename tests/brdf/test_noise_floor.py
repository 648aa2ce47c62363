"""``--abs-width auto``: each channel's floor is its noise level, estimated from pairs of
samples measured at nearly the same point; a dt of ratfit's choice is widened channel by
channel; the floors are recorded, printed and used again when the fit file is read."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import one_error_line, run_cli

from ratfit.brdf.fitter import (
    NOISE_QUANTILE,
    brdf_segments,
    close_pairs,
    fit_brdf,
    load_brdf_fit,
    noise_floors,
)
from ratfit.brdf.options import NOISE_FLOOR
from ratfit.errors import InputError
from ratfit.io.data import Dataset

PARAM = "RUSIN_TH_TD"
SIGMA = np.array([4e-3, 3e-3])
# half the 90th percentile of |e1 - e2| for e ~ N(0, s^2): 1.6449 * sqrt(2) * s / 2
HALF_P90 = 1.6448536269514722 * np.sqrt(2.0) / 2


def _measured_twice(k: int = 24, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Every point of a k x k grid of (theta_h, theta_d) measured twice (1e-4 rad apart)
    with Gaussian noise SIGMA: R = 1 + 0.3 theta_h (smooth), G = 1 +- 0.15 alternating
    between neighbours (no rational of up to 100 coefficients follows it below +-15 %)."""
    g = np.radians(np.linspace(1.0, 80.0, k))
    th, td = (a.ravel() for a in np.meshgrid(g, g, indexing="ij"))
    sign = (-1.0) ** (np.arange(k)[:, None] + np.arange(k)[None, :]).ravel()
    x = np.stack([th, td], axis=1)
    x = np.vstack([x, x + 1e-4])
    clean = np.stack([1.0 + 0.3 * x[:, 0], 1.0 + 0.15 * np.tile(sign, 2)], axis=1)
    noise = np.random.default_rng(seed).normal(size=clean.shape) * SIGMA
    return x, clean + noise


def _write(path: Path, x: np.ndarray, y: np.ndarray) -> Path:
    rows = "\n".join(" ".join(f"{v:.17g}" for v in (*xi, *yi)) for xi, yi in zip(x, y, strict=True))
    path.write_text(f"#DIM 2 2\n#PARAM_IN {PARAM}\n#PARAM_OUT INV_STERADIAN\n{rows}\n")
    return path


def test_noise_floors_estimate_a_known_noise() -> None:
    rng = np.random.default_rng(1)
    x = rng.uniform(0.0, 1.0, (4000, 2))
    x = np.vstack([x, x + 1e-4])
    sigma = np.array([2e-3, 5e-3, 1e-5])
    y = (0.05 + 0.02 * np.sin(3 * x[:, 0]))[:, None] + rng.normal(size=(8000, 3)) * sigma
    got = noise_floors(x, y)
    want = np.maximum(HALF_P90 * sigma, NOISE_FLOOR)
    np.testing.assert_allclose(got, want, rtol=0.05)
    assert got[2] == NOISE_FLOOR  # a quieter channel keeps the level relative errors use
    assert NOISE_QUANTILE == 0.9
    # no two samples within 1 % of each axis: nothing to estimate from
    grid = np.stack(np.meshgrid(np.linspace(0, 1, 20), np.linspace(0, 1, 20)), -1).reshape(-1, 2)
    assert close_pairs(grid, 0.01)[0].size == 0
    np.testing.assert_array_equal(noise_floors(grid, np.ones((400, 2))), [NOISE_FLOOR] * 2)


def test_auto_floor_segments_use_the_estimate() -> None:
    x, y = _measured_twice()
    ds = Dataset(x, y, None, None, ("th", "td"), ("R", "G"), {"param_in": PARAM})
    floors = noise_floors(x, y)
    np.testing.assert_allclose(floors, HALF_P90 * SIGMA, rtol=0.15)
    seg = brdf_segments(ds, dt=0.05, abs_width="auto")
    half = np.maximum(0.05 * np.abs(y), floors)
    np.testing.assert_allclose(seg.hi - seg.center, half, rtol=1e-12)
    np.testing.assert_allclose(seg.center - seg.lo, half, rtol=1e-12)
    with pytest.raises(InputError, match="abs_width must be a number >= 0 or 'auto'"):
        brdf_segments(ds, dt=0.05, abs_width="noise")


@pytest.mark.slow
def test_auto_floor_fit_widens_one_channel_and_records_the_floors(tmp_path: Path) -> None:
    x, y = _measured_twice()
    data = _write(tmp_path / "twice.dat", x, y)
    out = tmp_path / "f.json"
    r = run_cli("brdf", "fit", data, "--abs-width", "auto", "-o", out, "--jobs", "1")
    assert r.exit_code == 0, r.output
    saved = json.loads(out.read_text())["brdf"]
    seg = saved["segments"]
    floors = noise_floors(x, y)
    np.testing.assert_allclose(seg["abs_width"], floors, rtol=1e-12)
    assert seg["noise_estimated"] is True and seg["default"] is False
    # y0 fits at the dt the duplicates need (0.05); y1 alone is widened until a constant fits
    assert seg["dt"] == 0.05 and seg["channel_dt"] == [0.05, 0.18]
    assert saved["polish_error"] == "relative"
    said = " ".join(r.stderr.split())
    assert (f"segments: y0 +- 0.05 y, floor {floors[0]:.3g}; y1 +- 0.18 y, floor "
            f"{floors[1]:.3g} (floor: each channel's noise level") in said
    fit = load_brdf_fit(out)
    v = fit.eval_coords(x)
    for j, d in enumerate((0.05, 0.18)):
        half = np.maximum(d * np.abs(y[:, j]), floors[j])
        # every sample inside its segment, or inside the hull of a nearby sample's one
        # (consistent segments join the disjoint segments of a point measured twice)
        inside = np.abs(v[:, j] - y[:, j]) <= half * (1 + 1e-9)
        assert inside.mean() > 0.97, (j, inside.mean())
    # the report draws each channel's segments at its own width
    from ratfit.brdf.io import brdf_dataset
    from ratfit.viz.report import LoadedFit, segments_of

    drawn = segments_of(LoadedFit.load(str(out)), brdf_dataset(data, PARAM))
    assert drawn is not None
    for j, d in enumerate((0.05, 0.18)):
        np.testing.assert_allclose(drawn.hi[:, j] - drawn.center[:, j],
                                   np.maximum(d * np.abs(y[:, j]), floors[j]), rtol=1e-9)


def test_auto_floor_refuses_other_words(tmp_path: Path) -> None:
    x, y = _measured_twice(k=4)
    data = tmp_path / "small.dat"
    data.write_text(f"#DIM 2 2\n#PARAM_IN {PARAM}\n"
                    + "\n".join(" ".join(f"{v:.17g}" for v in (*a, *b))
                                for a, b in zip(x, y, strict=True)) + "\n")
    out = tmp_path / "f.json"
    r = run_cli("brdf", "fit", data, "--abs-width", "noise", "-o", out)
    assert r.exit_code == 2
    one_error_line(r, "'noise' is neither a number nor 'auto'")
    assert not out.exists()


def test_fit_brdf_records_per_channel_floors() -> None:
    x, y = _measured_twice(k=6)
    ds = Dataset(x, y[:, :1], None, None, ("th", "td"), ("R",), {"param_in": PARAM})
    _fitter, seg, meta = fit_brdf(ds, dt=0.05, abs_width="auto", max_total=6, jobs=1)
    floors = noise_floors(x, y[:, :1])
    assert meta["segments"]["abs_width"] == floors.tolist()
    assert meta["segments"]["noise_estimated"] is True
    assert meta["polish_error"] == "relative"
    # a dt the caller gave is never widened
    assert meta["segments"]["dt"] == 0.05 and meta["segments"]["channel_dt"] is None
    # each segment holds y +- max(0.05 |y|, floor) (a hull of a nearby one's only widens it)
    half = np.maximum(0.05 * np.abs(y[:, 0]), floors[0])
    assert np.all(seg.lo[:, 0] <= y[:, 0] - half * (1 - 1e-12))
    assert np.all(seg.hi[:, 0] >= y[:, 0] + half * (1 - 1e-12))


@pytest.mark.slow
def test_auto_floor_starts_each_channel_at_its_own_need(tmp_path: Path) -> None:
    """One point of y0 measured 1.0 and 1.3: y0 starts at the width that pair needs
    over its floor (1.1 x (0.3 - 2 x 0.0048) / 2.3, rounded up: 0.14); y1 starts at 0.05
    and is widened alone to 0.18."""
    x, y = _measured_twice()
    y[0, 0], y[len(y) // 2, 0] = 1.0, 1.3  # the same grid point, measured twice
    floors = noise_floors(x, y)
    assert np.isclose(floors[0], noise_floors(*_measured_twice())[0], rtol=0.05)
    out = tmp_path / "f.json"
    r = run_cli("brdf", "fit", _write(tmp_path / "d.dat", x, y), "--abs-width", "auto",
                "-o", out, "--jobs", "1")
    assert r.exit_code == 0, r.output
    seg = json.loads(out.read_text())["brdf"]["segments"]
    assert seg["channel_dt"] == [0.14, 0.18] and seg["dt"] == 0.05
    v = load_brdf_fit(out).eval_coords(x)[:, 0]
    # the two measurements' segments overlap, and the fit lies in both
    for i in (0, len(y) // 2):
        assert abs(v[i] - y[i, 0]) <= max(0.14 * y[i, 0], floors[0]) * (1 + 1e-9)


@pytest.mark.slow
def test_auto_floor_widens_a_single_channel() -> None:
    """One channel that alternates +-15 %: no candidate at 0.05, 0.08, 0.12; a constant
    at 0.18, recorded as that channel's width."""
    x, y = _measured_twice()
    ds = Dataset(x, y[:, 1:], None, None, ("th", "td"), ("G",), {"param_in": PARAM})
    fitter, seg, meta = fit_brdf(ds, abs_width="auto", jobs=1)
    assert fitter.success_ and meta["segments"]["channel_dt"] == [0.18]
    r = fitter.results_[0]
    assert r.n + r.m == 2
    v = r.rational(x)
    assert np.all((v >= seg.lo[:, 0]) & (v <= seg.hi[:, 0]))
