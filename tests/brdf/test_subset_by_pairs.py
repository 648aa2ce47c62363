"""--max-points on a MERL table drawn by direction pairs (--subset-by pairs): each cell as
likely as uniformly random direction pairs make it, not as its share of the grid."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import one_error_line, run_cli

from ratfit.brdf.io import (
    MERLData,
    merl_cell_measure,
    merl_from_function,
    merl_indices,
    samples_dataset,
    write_merl,
)
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.errors import InputError


def _uniform_pairs(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """L and V uniform by solid angle on the upper hemisphere."""
    out = []
    for _ in range(2):
        z = rng.uniform(0.0, 1.0, n)
        phi = rng.uniform(0.0, 2.0 * np.pi, n)
        s = np.sqrt(1.0 - z * z)
        out.append(np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1))
    return out[0], out[1]


def _blocks(w: np.ndarray) -> np.ndarray:
    """(90, 90, 180) cell shares summed into 9 x 9 x 9 blocks."""
    return w.reshape(9, 10, 9, 10, 9, 20).sum(axis=(1, 3, 5))


@pytest.fixture(scope="module")
def table() -> MERLData:
    """A constant table: every cell above the horizon holds 1."""
    rgb = merl_from_function(lambda L, V: np.ones((len(L), 3)))
    return MERLData(rgb, "constant")


def test_the_cell_measure_is_where_random_pairs_fall() -> None:
    w = merl_cell_measure()
    assert w.shape == (90, 90, 180) and abs(w.sum() - 1.0) < 1e-12 and w.min() >= 0.0
    L, V = _uniform_pairs(np.random.default_rng(11), 1_000_000)
    i, j, k = merl_indices(*get_parametrization("RUSIN_TH_TD_PD").from_dirs(L, V).T)
    hits = np.zeros(w.shape)
    np.add.at(hits, (i, j, k), 1.0)
    hits /= hits.sum()
    # 729 blocks, 1e6 pairs: sampling noise alone gives a distance of about 0.01
    assert 0.5 * np.abs(_blocks(w) - _blocks(hits)).sum() < 0.015
    # the grid's own share (every cell above the horizon alike) is far from it: the
    # square-root spacing of theta_h packs cells toward the mirror direction
    grid = np.isfinite(merl_from_function(lambda L, V: np.ones((len(L), 3)))[..., 0])
    grid = grid / grid.sum()
    assert 0.5 * np.abs(_blocks(grid) - _blocks(hits)).sum() > 0.2


def test_a_subset_by_pairs_follows_the_measure(table: MERLData) -> None:
    samples = table.samples()
    near = merl_cell_measure()[:30].sum()  # theta_h below (1/3)^2 pi/2 = 10 degrees
    assert 0.01 < near < 0.05
    shares = {}
    for by in ("pairs", "samples"):
        ds = samples_dataset(samples, "RUSIN_TH_TD_PD", max_points=20_000, subset_by=by)
        assert ds.meta["subset"] == {"points": 20_000, "of": samples.coords.shape[0], "by": by}
        assert np.unique(ds.x, axis=0).shape[0] == 20_000  # no cell twice
        shares[by] = float(np.mean(ds.x[:, 0] < (1 / 3) ** 2 * np.pi / 2))
    assert abs(shares["pairs"] - near) < 0.006
    assert shares["samples"] > 0.3  # a third of the grid's theta_h rows
    # seeded: the same subset every run, in every frame
    a = samples_dataset(samples, "RUSIN_TH_TD_FOLD", max_points=500, subset_by="pairs")
    b = samples_dataset(samples, "RUSIN_TH_TD_FOLD", max_points=500, subset_by="pairs")
    assert np.array_equal(a.x, b.x)


def test_a_subset_by_pairs_needs_a_merl_table_and_max_points(shared_data: Path,
                                                              tmp_path: Path) -> None:
    from ratfit.brdf.io import read_brdf

    cornell = shared_data / "cornell" / "mystique.brdf"

    with pytest.raises(InputError, match="cells of a MERL table"):
        samples_dataset(read_brdf(cornell), max_points=100, subset_by="pairs")
    with pytest.raises(InputError, match="unknown subset rule"):
        samples_dataset(read_brdf(cornell), max_points=100, subset_by="cells")
    out = tmp_path / "fit.json"
    one_error_line(run_cli("brdf", "fit", cornell, "--max-points", "100", "--subset-by",
                           "pairs", "-o", out), "cells of a MERL table")
    merl = tmp_path / "t.binary"
    write_merl(merl, merl_from_function(lambda L, V: np.ones((len(L), 3))))
    one_error_line(run_cli("brdf", "fit", merl, "--subset-by", "pairs", "-o", out),
                   "give --max-points")
    assert not out.exists()


def test_a_table_without_a_fit_is_pointed_at_a_subset_by_pairs(tmp_path: Path,
                                                               monkeypatch) -> None:
    """A fit of every cell of a MERL table (``--max-points`` above its cells) with no
    verified fit (cell noise, no time to search) gets the hint of the table defaults,
    and those options make the request they say; a table's subset that fails does not
    repeat the hint."""
    import shlex

    import ratfit.jobs
    from ratfit.errors import InputError as Stop
    from ratfit.jobs.brdf import TABLE_SUBSET_OPTIONS

    rng = np.random.default_rng(5)
    merl = tmp_path / "t.binary"
    write_merl(merl, merl_from_function(lambda L, V: 10.0 ** rng.uniform(-3, 0, (len(L), 3))))
    out = tmp_path / "fit.json"
    full = run_cli("brdf", "fit", merl, "--max-points", "2000000", "--time-limit", "0",
                   "-o", out)
    said = " ".join(full.stderr.split())
    assert full.exit_code == 1 and not out.exists(), full.output
    assert "a subset of the table drawn where random direction pairs fall" in said
    assert TABLE_SUBSET_OPTIONS in said and "Traceback" not in full.output
    sub = run_cli("brdf", "fit", merl, "--max-points", "300", "--subset-by", "pairs",
                  "--time-limit", "0", "-o", out)
    assert sub.exit_code == 1 and not out.exists(), sub.output
    assert "hint:" in sub.stderr and "--subset-by" not in sub.stderr.split("hint:")[-1]
    # the table defaults' other parts filled in, R widened alone as far as they go
    assert ("no verified fit at the table defaults (n = 113, m = 112, each such channel "
            "widened alone up to y +- 0.9 y): more coefficients (--n 153 --m 152)"
            in " ".join(sub.stderr.split()))
    # the options as the hint prints them: the request a user gets by pasting them
    asked = []

    def stop_at_the_request(request):
        asked.append(request)
        raise Stop("stopped before fitting")

    monkeypatch.setattr(ratfit.jobs, "fit_brdf_file", stop_at_the_request)
    one_error_line(run_cli("brdf", "fit", merl, *shlex.split(TABLE_SUBSET_OPTIONS), "-o",
                           out), "stopped before fitting")
    (req,) = asked
    assert (req.parametrization, req.max_points, req.subset_by, req.dt, req.abs_width) == (
        "RUSIN_TH_TD_FOLD", 5000, "pairs", 0.22, 1e-3)
    assert (req.options.values, req.options.n, req.options.m) == ("log", 113, 112)


def _spike_table() -> np.ndarray:
    """A dim diffuse table (0.01 1/sr) with a narrow reflection: 300 1/sr within 0.02 rad
    of the mirror direction, where uniformly random pairs almost never fall."""
    def f(L: np.ndarray, V: np.ndarray) -> np.ndarray:
        h = L + V
        cos_h = h[:, 2] / np.linalg.norm(h, axis=1)
        spike = np.where(np.arccos(np.clip(cos_h, -1.0, 1.0)) < 0.02, 300.0, 0.0)
        return np.stack([0.01 + spike, 0.02 + spike, 0.01 + 0.5 * spike], axis=1)

    return merl_from_function(f)


def test_an_energy_subset_draws_the_highlight_renders_look_at(tmp_path: Path) -> None:
    from ratfit.brdf.io import ENERGY_SHARE, read_brdf

    merl = tmp_path / "spike.binary"
    write_merl(merl, _spike_table())
    samples = read_brdf(merl)
    cells = merl_indices(*samples.coords.T)
    in_spike = samples.values[:, 1] > 1.0
    pairs = merl_cell_measure()[cells]
    lum = samples.values @ np.array([0.2126, 0.7152, 0.0722])
    # the share of the draw the spike's cells should get: half of the energy's, none of
    # the pairs' to speak of
    expected = ((1 - ENERGY_SHARE) * pairs[in_spike].sum() / pairs.sum()
                + ENERGY_SHARE * (pairs * lum)[in_spike].sum() / (pairs * lum).sum())
    assert 0.1 < expected < 0.5 and pairs[in_spike].sum() / pairs.sum() < 1e-3
    k = 4000
    got = {}
    for by in ("pairs", "energy"):
        ds = samples_dataset(samples, "RUSIN_TH_TD_FOLD", max_points=k, subset_by=by)
        assert ds.meta["subset"] == {"points": k, "of": samples.coords.shape[0], "by": by}
        got[by] = float(np.mean(ds.y[:, 1] > 1.0))
    assert got["pairs"] < 0.005
    # sampling without replacement from a few thousand spike cells: within 3 sigma
    assert abs(got["energy"] - expected) < 3 * np.sqrt(expected * (1 - expected) / k) + 0.01
    # every channel weighs the cells: a fit of one channel draws the cells of all three
    one = samples_dataset(samples, "RUSIN_TH_TD_FOLD", max_points=k, subset_by="energy",
                          channels=["B"])
    full = samples_dataset(samples, "RUSIN_TH_TD_FOLD", max_points=k, subset_by="energy")
    assert np.array_equal(one.x, full.x) and np.array_equal(one.y[:, 0], full.y[:, 2])


def test_an_energy_subset_of_a_dark_table_is_a_subset_by_pairs(table: MERLData) -> None:
    """Nothing lit to weigh by (every cell 0): the energy half draws by pairs too."""
    samples = table.samples()
    dark = type(samples)(samples.param, samples.coords, 0.0 * samples.values,
                         samples.channel_names, dict(samples.meta))
    a = samples_dataset(dark, "RUSIN_TH_TD_PD", max_points=3000, subset_by="energy")
    b = samples_dataset(dark, "RUSIN_TH_TD_PD", max_points=3000, subset_by="pairs")
    assert np.array_equal(a.x, b.x)


def test_an_energy_subset_is_refused_where_pairs_are(shared_data: Path, tmp_path: Path) -> None:
    from ratfit.brdf.io import read_brdf

    cornell = shared_data / "cornell" / "mystique.brdf"
    with pytest.raises(InputError, match="subset by energy"):
        samples_dataset(read_brdf(cornell), max_points=100, subset_by="energy")
    out = tmp_path / "fit.json"
    one_error_line(run_cli("brdf", "fit", cornell, "--max-points", "100", "--subset-by",
                           "energy", "-o", out), "cells of a MERL table")
    assert not out.exists()
