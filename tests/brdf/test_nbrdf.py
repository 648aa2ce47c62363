"""Neural BRDF encodings of RGL materials: the network as a BRDF of directions and as a
MERL table (issue 28: the RGL materials are fitted through their MERL tables)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ratfit.brdf.io import merl_coords, merl_from_function, read_merl, write_merl
from ratfit.brdf.nbrdf import NeuralBRDF, load_nbrdf
from ratfit.errors import FileFormatError

FELT = "acrylic_felt_white_rgb.npz"


@pytest.fixture(scope="module")
def felt(shared_data: Path) -> NeuralBRDF:
    return load_nbrdf(shared_data / "nbrdf-rgl" / FELT)


def _hemisphere(rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniform directions on the upper hemisphere (z > 0)."""
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 1e-9
    return v / np.linalg.norm(v, axis=1)[:, None]


def _by_hand(npz: Path, th: float, td: float, pd: float) -> np.ndarray:
    """The network written out directly from SOURCES.md, for one (theta_h, theta_d, phi_d)."""
    w = np.load(npz)
    x = np.array([np.sin(th), 0.0, np.cos(th),
                  np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)])
    h1 = np.maximum(x @ w["W1"] + w["b1"], 0.0)
    h2 = np.maximum(h1 @ w["W2"] + w["b2"], 0.0)
    return np.exp(h2 @ w["W3"] + w["b3"]) - 1.0


def test_size_is_the_published_675(felt: NeuralBRDF) -> None:
    assert felt.n_weights == 675


def test_reciprocal_and_isotropic(felt: NeuralBRDF) -> None:
    rng = np.random.default_rng(7)
    L, V = _hemisphere(rng, 20_000), _hemisphere(rng, 20_000)
    f = felt.eval_dirs(L, V)
    assert f.shape == (20_000, 3)
    assert np.all(np.isfinite(f)) and np.all(f >= 0.0)
    assert f.max() > 1.0  # not trivially zero: the felt has a grazing sheen
    np.testing.assert_allclose(felt.eval_dirs(V, L), f, rtol=1e-9, atol=1e-12)
    a = rng.uniform(-np.pi, np.pi, size=len(L))
    c, s = np.cos(a), np.sin(a)

    def rot(d: np.ndarray) -> np.ndarray:
        return np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)

    np.testing.assert_allclose(felt.eval_dirs(rot(L), rot(V)), f, rtol=1e-9, atol=1e-12)


def test_zero_below_the_horizon(felt: NeuralBRDF) -> None:
    L = np.array([[0.6, 0.0, 0.8], [0.6, 0.0, -0.8], [0.0, 0.0, 1.0]])
    V = np.array([[0.0, 0.6, -0.8], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    f = felt.eval_dirs(L, V)
    assert np.all(f[:2] == 0.0)
    assert np.all(f[2] > 0.0)


def test_matches_the_network_written_out(felt: NeuralBRDF, shared_data: Path) -> None:
    """The Rusinkiewicz convention: a pair built by hand from (theta_h, theta_d, phi_d)."""
    npz = shared_data / "nbrdf-rgl" / FELT
    for th, td, pd in [(0.0, 0.0, 0.0), (0.3, 0.5, 1.0), (0.1, 1.2, 2.5), (0.7, 0.2, 0.4)]:
        d = np.array([np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)])
        h = np.array([np.sin(th), 0.0, np.cos(th)])
        # rotate d by theta_h about the binormal (y): the normal goes to h
        L = np.array([np.cos(th) * d[0] + np.sin(th) * d[2], d[1],
                      -np.sin(th) * d[0] + np.cos(th) * d[2]])
        V = 2.0 * (L @ h) * h - L
        assert L[2] > 0 and V[2] > 0
        want = np.maximum(_by_hand(npz, th, td, pd), 0.0)
        np.testing.assert_allclose(felt.eval_dirs(L[None], V[None])[0], want, rtol=1e-9)


def test_white_felt_at_normal_incidence(felt: NeuralBRDF, shared_data: Path) -> None:
    """pi f(n, n) of the white felt, an albedo-like number: 0.676 / 0.707 / 0.851 from the
    network written out by hand (once), so a white, slightly bluish diffuse surface."""
    n = np.array([[0.0, 0.0, 1.0]])
    pif = np.pi * felt.eval_dirs(n, n)[0]
    np.testing.assert_allclose(pif, np.pi * _by_hand(shared_data / "nbrdf-rgl" / FELT, 0, 0, 0),
                               rtol=1e-12)
    assert np.all((pif > [0.66, 0.69, 0.83]) & (pif < [0.69, 0.72, 0.87]))


def test_merl_table_holds_the_network_at_its_cells(felt: NeuralBRDF, tmp_path: Path) -> None:
    path = tmp_path / "felt.binary"
    write_merl(path, merl_from_function(felt))
    back = read_merl(path)
    ok = back.valid.ravel()
    assert 0.6 < ok.mean() < 0.9  # the cells above the horizon, no more
    want = np.maximum(felt.eval_angles(merl_coords()[ok]), 0.0)
    got = back.rgb.reshape(-1, 3)[ok]
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9)
    assert np.all(np.isfinite(got)) and np.all(got >= 0.0)


def test_bad_npz_is_a_file_format_error(tmp_path: Path) -> None:
    p = tmp_path / "bad.npz"
    np.savez(p, W1=np.zeros((6, 21)))
    with pytest.raises(FileFormatError, match="no array 'b1'"):
        load_nbrdf(p)
    q = tmp_path / "text.npz"
    q.write_text("not a zip")
    with pytest.raises(FileFormatError, match="not a readable"):
        load_nbrdf(q)
