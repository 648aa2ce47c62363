"""MERL's reference convention: a cell's value belongs to its lower edge.

MERL's reader (BRDFRead.cpp, lookup_brdf_val) rounds each index down, so the
value of cell (i, j, k) is the BRDF at theta_h = (i/90)^2 pi/2, theta_d = j/90 pi/2,
phi_d = k/180 pi. A file written that way (valid exactly where those points are
above the horizon) was accepted by ``brdf fit`` but refused by ``render --data``
("15 261 rows below the horizon") while ratfit placed values at cell centres.
The table here is written byte by byte with the test's own direction formulas.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ratfit.brdf.io import MERL_SCALE, merl_from_function, read_merl

TH = (np.arange(90) / 90.0) ** 2 * (np.pi / 2)
TD = np.arange(90) / 90.0 * (np.pi / 2)
PD = np.arange(180) / 180.0 * np.pi


def reference_dirs(th: np.ndarray, td: np.ndarray, pd: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Rusinkiewicz (phi_h = 0) to directions: D rotated by theta_h about y is L;
    V is L mirrored about the half vector."""
    d = np.stack([np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)], axis=1)
    c, s = np.cos(th), np.sin(th)
    L = np.stack([c * d[:, 0] + s * d[:, 2], d[:, 1], -s * d[:, 0] + c * d[:, 2]], axis=1)
    h = np.stack([s, np.zeros_like(s), c], axis=1)
    V = 2.0 * np.sum(L * h, axis=1)[:, None] * h - L
    return L, V


def brdf(L: np.ndarray, V: np.ndarray) -> np.ndarray:
    h = L + V
    c = h[:, 2] / np.linalg.norm(h, axis=1)
    g = 0.3 * np.exp(-((1.0 - c) / 0.02))
    return np.stack([0.2 + g, 0.1 + g, 0.05 + g], axis=1)


@pytest.fixture(scope="module")
def merl_reference(tmp_path_factory: pytest.TempPathFactory
                   ) -> tuple[Path, np.ndarray, np.ndarray, np.ndarray]:
    g = np.meshgrid(TH, TD, PD, indexing="ij")
    th, td, pd = (a.ravel() for a in g)
    L, V = reference_dirs(th, td, pd)
    ok = (L[:, 2] > 0) & (V[:, 2] > 0)
    vals = np.full((th.size, 3), -1.0)
    vals[ok] = brdf(L[ok], V[ok]) / np.asarray(MERL_SCALE)
    path = tmp_path_factory.mktemp("merl") / "reference.binary"
    path.write_bytes(np.array([90, 90, 180], "<i4").tobytes()
                     + np.ascontiguousarray(vals.T, dtype="<f8").tobytes())
    return path, np.stack([th, td, pd], axis=1), ok, brdf(L[ok], V[ok])


def test_samples_sit_at_lower_cell_edges(merl_reference) -> None:
    path, coords, ok, values = merl_reference
    s = read_merl(path).samples()
    assert s.coords.shape == (int(ok.sum()), 3)
    np.testing.assert_allclose(s.coords, coords[ok], rtol=0, atol=1e-15)
    np.testing.assert_allclose(s.values, values, rtol=1e-14)


def test_lookup_rounds_down_like_merl(merl_reference) -> None:
    path, coords, ok, values = merl_reference
    m = read_merl(path)
    rows = np.flatnonzero(ok)[::997]
    # at the sample point itself and just inside the cell (above the lower edge)
    for bump in (0.0, 0.3):
        th = ((np.sqrt(coords[rows, 0] / (np.pi / 2)) * 90 + bump) / 90) ** 2 * (np.pi / 2)
        td = coords[rows, 1] + bump * (np.pi / 2) / 90
        pd = coords[rows, 2] + bump * np.pi / 180
        L, V = reference_dirs(th, td, pd)
        keep = (L[:, 2] > 0) & (V[:, 2] > 0)
        got = m.lookup(L[keep], V[keep])
        want = values[np.searchsorted(np.flatnonzero(ok), rows[keep])]
        np.testing.assert_allclose(got, want, rtol=1e-14)


def test_render_data_accepts_a_reference_merl_file(merl_reference) -> None:
    from ratfit.render.material import DataMaterial

    path, coords, ok, values = merl_reference
    # 15 261 valid cells have their centre below the horizon: the old reading refused them
    c = np.stack([((np.sqrt(coords[:, 0] / (np.pi / 2)) * 90 + 0.5) / 90) ** 2 * (np.pi / 2),
                  coords[:, 1] + 0.25 * np.pi / 90, coords[:, 2] + 0.5 * np.pi / 180], axis=1)
    Lc, Vc = reference_dirs(*c.T)
    assert int((ok & ~((Lc[:, 2] > 0) & (Vc[:, 2] > 0))).sum()) == 15261
    mat = DataMaterial(path)
    assert mat.below_horizon == 0
    assert mat.n_samples == int(ok.sum())
    rows = np.flatnonzero(ok)[::5003]
    L, V = reference_dirs(*coords[rows].T)
    np.testing.assert_allclose(mat(L, V), values[np.searchsorted(np.flatnonzero(ok), rows)],
                               rtol=1e-9)


def test_writer_samples_at_the_same_points(merl_reference) -> None:
    path, coords, ok, values = merl_reference
    table = merl_from_function(brdf)
    assert np.array_equal(np.isfinite(table[..., 0]).ravel(), ok)
    np.testing.assert_allclose(table.reshape(-1, 3)[ok], values, rtol=1e-13)
