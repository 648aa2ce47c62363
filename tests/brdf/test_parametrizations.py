"""BRDF parametrizations: exact round trips through the (L, V) pivot, known values, errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from ratfit.brdf.parametrizations import (
    PARAMETRIZATIONS,
    convert,
    determines,
    get_parametrization,
)
from ratfit.errors import InputError

NAMES = sorted(PARAMETRIZATIONS)
PAIRS = [(a, b) for a in NAMES for b in NAMES if determines(b, a)]
ANGLES = {"phi_l", "phi_v", "phi_h", "phi_d", "delta_phi"}


def _dirs(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    v[:, 2] = np.abs(v[:, 2])
    return v


def _gap(a: np.ndarray, b: np.ndarray, coords: tuple[str, ...]) -> float:
    """Largest difference, azimuths compared modulo 2 pi."""
    d = np.abs(a - b)
    for j, c in enumerate(coords):
        if c in ANGLES:
            d[:, j] = np.minimum(d[:, j], 2 * np.pi - d[:, j])
    return float(d.max())


@pytest.mark.parametrize(("src", "dst"), PAIRS)
def test_round_trip_between_any_two(src: str, dst: str) -> None:
    """src -> dst -> src is exact (1e-12) whenever dst keeps what src describes."""
    rng = np.random.default_rng(len(src) * 31 + len(dst))
    L, V = _dirs(rng, 500), _dirs(rng, 500)
    c = get_parametrization(src).from_dirs(L, V)
    back = convert(convert(c, src, dst), dst, src)
    assert _gap(back, c, get_parametrization(src).coords) < 1e-12


def test_lossy_pairs_are_really_lossy() -> None:
    """determines() is not vacuous: dropping phi_d changes the coordinates back."""
    rng = np.random.default_rng(1)
    L, V = _dirs(rng, 200), _dirs(rng, 200)
    c = get_parametrization("RUSIN_TH_TD_PD").from_dirs(L, V)
    back = convert(convert(c, "RUSIN_TH_TD_PD", "RUSIN_TH_TD"), "RUSIN_TH_TD", "RUSIN_TH_TD_PD")
    assert not determines("RUSIN_TH_TD", "RUSIN_TH_TD_PD")
    assert np.allclose(back[:, :2], c[:, :2], atol=1e-12)
    assert np.abs(back[:, 2] - c[:, 2]).max() > 0.5


_unit_pair = st.tuples(
    st.floats(0.01, 1.56), st.floats(-3.1, 3.1), st.floats(0.01, 1.56), st.floats(-3.1, 3.1)
)


@settings(max_examples=60, deadline=None)
@given(_unit_pair)
def test_full_parametrizations_recover_the_pair(angles: tuple[float, ...]) -> None:
    tl, pl, tv, pv = angles
    L = np.array([[np.sin(tl) * np.cos(pl), np.sin(tl) * np.sin(pl), np.cos(tl)]])
    V = np.array([[np.sin(tv) * np.cos(pv), np.sin(tv) * np.sin(pv), np.cos(tv)]])
    for name in NAMES:
        p = get_parametrization(name)
        if p.invariant != "full":
            continue
        L2, V2 = p.to_dirs(p.from_dirs(L, V))
        assert np.abs(L2 - L).max() < 1e-12 and np.abs(V2 - V).max() < 1e-12, name


@settings(max_examples=40, deadline=None)
@given(_unit_pair, st.floats(-3.1, 3.1))
def test_isotropic_coordinates_ignore_rotation(angles: tuple[float, ...], rot: float) -> None:
    tl, pl, tv, pv = angles
    L = np.array([[np.sin(tl) * np.cos(pl), np.sin(tl) * np.sin(pl), np.cos(tl)]])
    V = np.array([[np.sin(tv) * np.cos(pv), np.sin(tv) * np.sin(pv), np.cos(tv)]])
    Lr = np.array([[np.sin(tl) * np.cos(pl + rot), np.sin(tl) * np.sin(pl + rot), np.cos(tl)]])
    Vr = np.array([[np.sin(tv) * np.cos(pv + rot), np.sin(tv) * np.sin(pv + rot), np.cos(tv)]])
    assume(np.linalg.norm(L - V) > 1e-3)  # phi_d is undefined for L = V
    for name in NAMES:
        p = get_parametrization(name)
        if p.invariant == "full" or name == "RUSIN_VH":
            continue
        a, b = p.from_dirs(L, V), p.from_dirs(Lr, Vr)
        assert _gap(a, b, p.coords) < 1e-9, name


def test_known_values() -> None:
    th, td, pd = 0.3, 0.5, 1.1
    P = get_parametrization("RUSIN_TH_TD_PD")
    L, V = P.to_dirs([[th, td, pd]])
    # The half vector has elevation theta_h, L and V are 2 theta_d apart.
    h = (L + V) / np.linalg.norm(L + V)
    assert np.arccos(h[0, 2]) == pytest.approx(th, abs=1e-14)
    assert np.arccos(np.dot(L[0], V[0])) == pytest.approx(2 * td, abs=1e-14)
    # Stark's 2-D coordinates are cos(td) sin(th) and sin(td) (Stark et al. 2005).
    s = get_parametrization("STARK_2D").from_dirs(L, V)[0]
    assert s == pytest.approx([np.cos(td) * np.sin(th), np.sin(td)], abs=1e-15)
    assert get_parametrization("COS_TH_TD").from_dirs(L, V)[0] == pytest.approx(
        [np.cos(th), np.cos(td)], abs=1e-15
    )
    # Mirror configuration: theta_h = 0, delta_phi = pi, projected coordinate -theta_v.
    t = 0.7
    Lm = np.array([[np.sin(t), 0.0, np.cos(t)]])
    Vm = np.array([[-np.sin(t), 0.0, np.cos(t)]])
    assert get_parametrization("RUSIN_TH_TD").from_dirs(Lm, Vm)[0] == pytest.approx([0, t])
    iso = get_parametrization("ISOTROPIC_TV_TL_DPHI").from_dirs(Lm, Vm)[0]
    assert iso == pytest.approx([t, t, np.pi])
    proj = get_parametrization("ISOTROPIC_TL_TV_PROJ_DPHI").from_dirs(Lm, Vm)[0]
    assert proj == pytest.approx([t, -t, 0.0], abs=1e-15)
    # Retro-reflection (V = L) is the origin of ALTA's retro coordinates.
    retro = get_parametrization("RETRO_TL_TVL_PROJ_DPHI").from_dirs(Lm, Lm)[0]
    assert retro == pytest.approx([t, 0.0, 0.0], abs=1e-15)
    # ALTA's CARTESIAN stores V first.
    assert get_parametrization("CARTESIAN").from_dirs(Lm, Vm)[0].tolist() == [
        *Vm[0].tolist(), *Lm[0].tolist()
    ]


def test_alta_retro_file_convention() -> None:
    """ALTA's to_cartesian for ISOTROPIC_TL_TV_PROJ_DPHI (params.cpp) maps back here."""
    tl, a, b = 0.4, 0.3, -0.2
    theta = np.hypot(a, b)
    V = np.array([[a / theta * np.sin(theta), b / theta * np.sin(theta), np.cos(theta)]])
    L = np.array([[np.sin(tl), 0.0, np.cos(tl)]])
    c = get_parametrization("ISOTROPIC_TL_TV_PROJ_DPHI").from_dirs(L, V)[0]
    # ALTA's from_cartesian uses dphi = phi_l - phi_v, so the sine part flips sign;
    # isotropic data are symmetric in it.
    assert c == pytest.approx([tl, a, -b], abs=1e-15)


def test_unknown_name_lists_valid_ones() -> None:
    with pytest.raises(InputError, match="unknown parametrization 'NOPE'") as exc:
        get_parametrization("NOPE")
    assert "RUSIN_TH_TD_PD" in str(exc.value) and "STARK_2D" in str(exc.value)
    assert get_parametrization("rusin_th_td").name == "RUSIN_TH_TD"


def test_bad_directions() -> None:
    P = get_parametrization("RUSIN_TH_TD_PD")
    up = [[0.0, 0.0, 1.0]]
    with pytest.raises(InputError, match=r"direction V row 0 .* below the horizon"):
        P.from_dirs(up, [[0.6, 0.0, -0.8]])
    with pytest.raises(InputError, match="not a unit vector"):
        P.from_dirs(up, [[0.0, 0.0, 2.0]])
    with pytest.raises(InputError, match=r"shape \(N, 3\)"):
        P.from_dirs(up, [[0.0, 1.0]])
    with pytest.raises(InputError, match="non-finite"):
        P.from_dirs(up, [[np.nan, 0.0, 1.0]])
    # Coordinates that describe no pair above the horizon.
    with pytest.raises(InputError, match="above the horizon; first: row 1"):
        P.to_dirs([[0.1, 0.1, 0.0], [1.4, 1.4, 0.0]])
    with pytest.raises(InputError, match="STARK_2D"):
        get_parametrization("STARK_2D").to_dirs([[0.9, 0.9]])
    with pytest.raises(InputError, match="COS_TH_TD"):
        get_parametrization("COS_TH_TD").to_dirs([[1.5, 0.5]])
    with pytest.raises(InputError, match="3 coordinate"):
        P.to_dirs([[0.1, 0.2]])


def test_retro_at_v_is_retro_with_l_and_v_exchanged() -> None:
    """RETRO_TV_TVL_PROJ_DPHI(L, V) = RETRO_TL_TVL_PROJ_DPHI(V, L); theta_v comes first."""
    rng = np.random.default_rng(8)
    L, V = _dirs(rng, 300), _dirs(rng, 300)
    a = get_parametrization("RETRO_TV_TVL_PROJ_DPHI").from_dirs(L, V)
    b = get_parametrization("RETRO_TL_TVL_PROJ_DPHI").from_dirs(V, L)
    assert np.allclose(a, b, atol=1e-13)
    assert np.allclose(a[:, 0], np.arccos(np.clip(V[:, 2], -1, 1)), atol=1e-12)
    assert not np.allclose(a, get_parametrization("RETRO_TL_TVL_PROJ_DPHI").from_dirs(L, V))
