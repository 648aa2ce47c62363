"""BRDF parametrizations: coordinates of a (light, view) pair of directions.

Every parametrization converts to and from the Cartesian pivot: unit vectors
L (towards the light) and V (towards the viewer), arrays (N, 3) in the local
frame of the surface (normal = +z, tangent = +x). Converting between any two
parametrizations goes through that pivot (:func:`convert`).

Names and formulas follow ALTA (``sources/core/params.cpp``) where ALTA has
the parametrization; where ALTA's code is ambiguous the choice made here is
stated in the description. A parametrization that forgets something (the
isotropic ones forget a rotation about the normal, the 2-D ones also phi_d)
maps coordinates back to one canonical pair of directions: L in the x-z plane
(phi_l = 0) unless said otherwise.

Angles are radians. Azimuth differences are wrapped to (-pi, pi].
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.errors import InputError

__all__ = [
    "DIRECTION_TOL",
    "FOLD_SEAM_TOL",
    "PARAMETRIZATIONS",
    "Parametrization",
    "check_dirs",
    "convert",
    "determines",
    "find_parametrization",
    "fold_phi_d",
    "get_parametrization",
    "is_folded",
    "reciprocal_order",
]

Array = NDArray[np.float64]

# Unit vectors (coordinates converted back) may be off by rounding; anything further
# is a caller's error.
_UNIT_TOL = 1e-6
#: How far a direction given by a user (typed, read from a file) may be from unit
#: length and still be normalised: 4-digit components are off by up to ~1e-4.
DIRECTION_TOL = 1e-3
# A direction with z below -_HORIZON_TOL is below the surface.
_HORIZON_TOL = 1e-12


@dataclass(frozen=True)
class Parametrization:
    """One named coordinate system for (L, V) pairs.

    ``invariant`` names what the coordinates determine about the pair: "full"
    (the pair itself), "isotropic" (the pair up to a rotation about the
    normal), "reciprocal" (the pair up to that rotation and the exchange of L and V),
    "symmetric" (up to those and a mirror: what an isotropic reciprocal BRDF depends on
    when it is also mirror-symmetric), "th_td" (the half and
    difference elevations), "th" (the half
    elevation), "half" (the half vector), "tv_tl" (the two elevations).
    ``bounds`` are the natural ranges of the coordinates, (dim, 2).
    """

    name: str
    dim: int
    coords: tuple[str, ...]
    description: str
    invariant: str
    bounds: tuple[tuple[float, float], ...]
    _from: Callable[[Array, Array], Array]
    _to: Callable[[Array], tuple[Array, Array]]

    def from_dirs(self, L: ArrayLike, V: ArrayLike) -> Array:
        """Coordinates (N, dim) of unit directions L, V (N, 3) above the horizon."""
        la, va = check_dirs(L, V)
        return self._from(la, va)

    def to_dirs(self, coords: ArrayLike) -> tuple[Array, Array]:
        """Unit directions (L, V), each (N, 3), for coordinates (N, dim)."""
        c = _check_coords(coords, self)
        with np.errstate(invalid="ignore"):
            L, V = self._to(c)
        bad = ~(np.isfinite(L).all(axis=1) & np.isfinite(V).all(axis=1))
        bad |= (L[:, 2] < -_HORIZON_TOL) | (V[:, 2] < -_HORIZON_TOL)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InputError(
                f"{self.name}: {int(bad.sum())} coordinate row(s) describe no pair of directions "
                f"above the horizon; first: row {i} = {c[i].tolist()}"
            )
        return L, V

    def __repr__(self) -> str:
        return f"Parametrization({self.name!r}, dim={self.dim}, coords={self.coords})"


# --------------------------------------------------------------------------- checks
def check_dirs(L: ArrayLike, V: ArrayLike) -> tuple[Array, Array]:
    """L, V as (N, 3) unit vectors on or above the horizon, else InputError.

    Directions within :data:`DIRECTION_TOL` of unit length are normalised: a
    direction typed to 4 digits (0.7071, 0, 0.7071 has length 0.99999) is meant
    as a unit vector; one further off is a mistake, not rounding.
    """
    out = []
    for name, d in (("L", L), ("V", V)):
        try:
            a = np.asarray(d, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InputError(f"direction {name} must be numeric: {exc}") from None
        if a.ndim == 1:
            a = a[None, :]
        if a.ndim != 2 or a.shape[1] != 3:
            raise InputError(f"direction {name} must have shape (N, 3), got {np.shape(d)}")
        if not np.all(np.isfinite(a)):
            i = int(np.argwhere(~np.isfinite(a))[0][0])
            raise InputError(f"direction {name} has a non-finite value at row {i}")
        norm = np.linalg.norm(a, axis=1)
        off = np.abs(norm - 1.0) > DIRECTION_TOL
        if off.any():
            i = int(np.flatnonzero(off)[0])
            raise InputError(
                f"direction {name} row {i} is not a unit vector (length {float(norm[i]):.6g}; "
                f"directions within {DIRECTION_TOL:g} of length 1 are normalised); "
                f"{int(off.sum())} such row(s)"
            )
        a = a / norm[:, None]
        below = a[:, 2] < -_HORIZON_TOL
        if below.any():
            i = int(np.flatnonzero(below)[0])
            raise InputError(
                f"direction {name} row {i} = {a[i].tolist()} is below the horizon (z < 0); "
                f"{int(below.sum())} such row(s)"
            )
        a[:, 2] = np.maximum(a[:, 2], 0.0)
        out.append(a)
    if out[0].shape != out[1].shape:
        raise InputError(f"L has {out[0].shape[0]} rows but V has {out[1].shape[0]}")
    return out[0], out[1]


def _check_coords(coords: ArrayLike, p: Parametrization) -> Array:
    try:
        c = np.asarray(coords, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{p.name} coordinates must be numeric: {exc}") from None
    if c.ndim == 1 and p.dim == 1:
        c = c[:, None]
    elif c.ndim == 1:
        c = c[None, :]
    if c.ndim != 2 or c.shape[1] != p.dim:
        raise InputError(
            f"{p.name} has {p.dim} coordinate(s) {', '.join(p.coords)}; "
            f"got shape {np.shape(coords)}"
        )
    if not np.all(np.isfinite(c)):
        i = int(np.argwhere(~np.isfinite(c))[0][0])
        raise InputError(f"{p.name} coordinates have a non-finite value at row {i}")
    return c


# --------------------------------------------------------------------------- helpers
def _acos(x: Array) -> Array:
    return np.arccos(np.clip(x, -1.0, 1.0))


def _angle(a: Array, b: Array) -> Array:
    """Angle between unit vectors, accurate near 0 and pi (atan2 of |a x b|, a.b)."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("ij,ij->i", a, b))


def _elev(d: Array) -> Array:
    return np.arctan2(np.hypot(d[:, 0], d[:, 1]), d[:, 2])


def _wrap(a: Array) -> Array:
    """Angles into (-pi, pi]."""
    w = np.mod(a + np.pi, 2.0 * np.pi) - np.pi
    return np.where(w == -np.pi, np.pi, w)


def _sph(theta: Array, phi: Array) -> Array:
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=1)


def _rot_z(d: Array, a: Array) -> Array:
    c, s = np.cos(a), np.sin(a)
    return np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)


def _rot_y(d: Array, a: Array) -> Array:
    c, s = np.cos(a), np.sin(a)
    return np.stack([c * d[:, 0] + s * d[:, 2], d[:, 1], -s * d[:, 0] + c * d[:, 2]], axis=1)


def _unit(v: Array) -> Array:
    return v / np.linalg.norm(v, axis=1)[:, None]


def _half_diff(L: Array, V: Array) -> tuple[Array, Array, Array, Array]:
    """Rusinkiewicz: half vector h, its angles, and the difference vector (L in h's frame)."""
    s = L + V
    n = np.linalg.norm(s, axis=1)
    # L = -V has no half vector; it cannot happen above the horizon except at
    # grazing opposite directions, where the normal is the natural choice.
    h = np.where(n[:, None] > 1e-300, s / np.where(n > 0, n, 1.0)[:, None], [0.0, 0.0, 1.0])
    th = _elev(h)
    ph = np.arctan2(h[:, 1], h[:, 0])
    d = _rot_y(_rot_z(L, -ph), -th)
    return h, th, ph, d


def _from_half_diff(th: Array, ph: Array, td: Array, pd: Array) -> tuple[Array, Array]:
    d = _sph(td, pd)
    L = _rot_z(_rot_y(d, th), ph)
    h = _sph(th, ph)
    V = 2.0 * np.einsum("ij,ij->i", L, h)[:, None] * h - L
    return L, V


def _rusin(L: Array, V: Array) -> tuple[Array, Array, Array, Array]:
    _, th, ph, d = _half_diff(L, V)
    return th, ph, _elev(d), np.arctan2(d[:, 1], d[:, 0])


def _iso_frame(L: Array, V: Array) -> tuple[Array, Array, Array]:
    """theta_l, theta_v, dphi = phi_l - phi_v (ALTA's from_cartesian convention)."""
    dphi = np.arctan2(L[:, 1], L[:, 0]) - np.arctan2(V[:, 1], V[:, 0])
    return _elev(L), _elev(V), _wrap(dphi)


def _iso_dirs(tl: Array, tv: Array, dphi: Array) -> tuple[Array, Array]:
    """Canonical pair: L at phi = 0, V at phi = -dphi."""
    return _sph(tl, np.zeros_like(tl)), _sph(tv, -dphi)


def _stack(*cols: Array) -> Array:
    return np.stack(cols, axis=1)


def is_folded(param: str, fold_phi_d: bool) -> bool:
    """Whether a fit's phi_d is folded into [0, pi) (:func:`fold_phi_d`): always in
    RUSIN_TH_TD_FOLD, and in RUSIN_TH_TD_PD for a MERL table (its ``fold_phi_d`` flag).
    Every evaluator of such a fit takes the pair in :func:`reciprocal_order`."""
    return param == "RUSIN_TH_TD_FOLD" or (fold_phi_d and param == "RUSIN_TH_TD_PD")


def reciprocal_order(L: Array, V: Array) -> tuple[Array, Array]:
    """(L, V) and (V, L) as one ordered pair: the direction with the larger
    (z, x, y) first. A folded fit (:func:`fold_phi_d`) is reciprocal by construction,
    but at the fold itself (in-plane pairs near the mirror direction, where phi_d is
    ~1e-16 / sin(theta_h) off) a pair and its exchange could still round to opposite
    sides; evaluated in this order they are the same computation, bit for bit."""
    swap = (V[:, 2] > L[:, 2]) | ((V[:, 2] == L[:, 2]) & (
        (V[:, 0] > L[:, 0]) | ((V[:, 0] == L[:, 0]) & (V[:, 1] > L[:, 1]))))
    s = swap[:, None]
    return np.where(s, V, L), np.where(s, L, V)


# --------------------------------------------------------------------------- definitions
def _cart_from(L: Array, V: Array) -> Array:
    return np.hstack([V, L])


def _cart_to(c: Array) -> tuple[Array, Array]:
    V, L = c[:, :3], c[:, 3:]
    off = (np.abs(np.linalg.norm(V, axis=1) - 1.0) > _UNIT_TOL) | (
        np.abs(np.linalg.norm(L, axis=1) - 1.0) > _UNIT_TOL
    )
    return _nan_rows(off, _unit(L), _unit(V))


def _sph_from(L: Array, V: Array) -> Array:
    return _stack(
        _elev(L), np.arctan2(L[:, 1], L[:, 0]), _elev(V), np.arctan2(V[:, 1], V[:, 0])
    )


def _sph_to(c: Array) -> tuple[Array, Array]:
    return _sph(c[:, 0], c[:, 1]), _sph(c[:, 2], c[:, 3])


def _r4_from(L: Array, V: Array) -> Array:
    th, ph, td, pd = _rusin(L, V)
    return _stack(th, ph, td, pd)


def _r4_to(c: Array) -> tuple[Array, Array]:
    return _from_half_diff(c[:, 0], c[:, 1], c[:, 2], c[:, 3])


def _r3_from(L: Array, V: Array) -> Array:
    th, _, td, pd = _rusin(L, V)
    return _stack(th, td, pd)


def _r3_to(c: Array) -> tuple[Array, Array]:
    return _from_half_diff(c[:, 0], np.zeros(len(c)), c[:, 1], c[:, 2])


def _sym_from(L: Array, V: Array) -> Array:
    th, _, td, pd = _rusin(L, V)
    return _stack(th, td, np.sin(th) ** 2 * np.cos(2.0 * pd))


def _sym_to(c: Array) -> tuple[Array, Array]:
    s2 = np.sin(c[:, 0]) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        c2 = np.where(s2 > 0, c[:, 2] / np.where(s2 > 0, s2, 1.0), 0.0)
    bad = np.abs(c2) > 1.0 + 1e-12
    pd = 0.5 * np.arccos(np.clip(c2, -1.0, 1.0))
    L, V = _from_half_diff(c[:, 0], np.zeros(len(c)), c[:, 1], pd)
    return _nan_rows(bad, L, V)


def _fold_from(L: Array, V: Array) -> Array:
    th, _, td, pd = _rusin(L, V)
    return _stack(th, td, np.sin(th) * np.cos(fold_phi_d(pd, th, td)))


#: A pair whose difference vector D lies this close to the plane of H and the normal
#: is in the plane of incidence, and :func:`fold_phi_d` gives it phi_d = 0: the test is
#: |D_y| sin(theta_h) <= this, with |D_y| = sin(theta_d) |sin(phi_d)|. Rounding leaves
#: |D_y| up to ~1e-15 / sin(theta_h) in the plane (the half-vector frame turns with
#: H; measured: |D_y| sin(theta_h) <= 9e-16 at 4e5 in-plane pairs, theta_h down to
#: 1e-9), so phi_d itself is off by as much divided by sin(theta_d): no fixed
#: tolerance on the angle covers both the mirror and the retro direction.
FOLD_SEAM_TOL = 1e-12


def fold_phi_d(pd: ArrayLike, th: ArrayLike, td: ArrayLike) -> Array:
    """phi_d folded into [0, pi) as MERL's lookup folds it (phi_d and phi_d + pi are one
    value, reciprocity), with the fold's two ends made one: a pair in the plane of
    incidence (phi_d = 0 or pi up to rounding, :data:`FOLD_SEAM_TOL`) gets 0, and so
    does its exchange. Every evaluator of a folded fit (numpy here, the exported C,
    GLSL and Python) uses this rule; ``th``, ``td`` are the pair's theta_h, theta_d."""
    p, h, t = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (pd, th, td)))
    w = np.mod(p, np.pi)  # (-1e-17 % pi rounds to pi itself: the seam rule takes it)
    dy = np.abs(np.sin(t) * np.sin(w)) * np.abs(np.sin(h))
    return np.where((w >= np.pi) | ((w > 0.5 * np.pi) & (dy <= FOLD_SEAM_TOL)), 0.0, w)


def _fold_to(c: Array) -> tuple[Array, Array]:
    s = np.sin(c[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        cp = np.where(s > 0, c[:, 2] / np.where(s > 0, s, 1.0), 0.0)
    bad = np.abs(c[:, 2]) > np.abs(s) * (1.0 + 1e-12) + 1e-15  # |u| <= sin(theta_h)
    L, V = _from_half_diff(c[:, 0], np.zeros(len(c)), c[:, 1], np.arccos(np.clip(cp, -1.0, 1.0)))
    return _nan_rows(bad, L, V)


def _c3_from(L: Array, V: Array) -> Array:
    th, _, td, pd = _rusin(L, V)
    return _stack(np.cos(th), np.cos(td), pd)


def _c3_to(c: Array) -> tuple[Array, Array]:
    bad = np.any(np.abs(c[:, :2]) > 1.0, axis=1)
    L, V = _from_half_diff(_acos(c[:, 0]), np.zeros(len(c)), _acos(c[:, 1]), c[:, 2])
    return _nan_rows(bad, L, V)


def _r2_from(L: Array, V: Array) -> Array:
    th, _, td, _ = _rusin(L, V)
    return _stack(th, td)


def _r2_to(c: Array) -> tuple[Array, Array]:
    z = np.zeros(len(c))
    return _from_half_diff(c[:, 0], z, c[:, 1], z + 0.5 * np.pi)


def _c2_from(L: Array, V: Array) -> Array:
    th, _, td, _ = _rusin(L, V)
    return _stack(np.cos(th), np.cos(td))


def _c2_to(c: Array) -> tuple[Array, Array]:
    L, V = _r2_to(_acos(c))
    return _nan_rows(np.any(np.abs(c) > 1.0, axis=1), L, V)


def _r1_from(L: Array, V: Array) -> Array:
    return _rusin(L, V)[0][:, None]


def _r1_to(c: Array) -> tuple[Array, Array]:
    z = np.zeros(len(c))
    return _from_half_diff(c[:, 0], z, z, z)


def _c1_from(L: Array, V: Array) -> Array:
    return np.cos(_rusin(L, V)[0])[:, None]


def _c1_to(c: Array) -> tuple[Array, Array]:
    L, V = _r1_to(_acos(c))
    return _nan_rows(np.abs(c[:, 0]) > 1.0, L, V)


def _nan_rows(bad: NDArray[np.bool_], L: Array, V: Array) -> tuple[Array, Array]:
    """Mark rows that describe no configuration; to_dirs reports them."""
    L[bad] = np.nan
    V[bad] = np.nan
    return L, V


def _vhvd_from(L: Array, V: Array) -> Array:
    h, _, _, d = _half_diff(L, V)
    return np.hstack([h, d])


def _vhvd_to(c: Array) -> tuple[Array, Array]:
    h, d = _unit(c[:, :3]), _unit(c[:, 3:])
    th, ph = _elev(h), np.arctan2(h[:, 1], h[:, 0])
    return _from_half_diff(th, ph, _elev(d), np.arctan2(d[:, 1], d[:, 0]))


def _vh_from(L: Array, V: Array) -> Array:
    return _half_diff(L, V)[0]


def _vh_to(c: Array) -> tuple[Array, Array]:
    h = _unit(c)
    z = np.zeros(len(c))
    return _from_half_diff(_elev(h), np.arctan2(h[:, 1], h[:, 0]), z, z)


def _tvtl_dphi_from(L: Array, V: Array) -> Array:
    tl, tv, dphi = _iso_frame(L, V)
    return _stack(tv, tl, dphi)


def _tvtl_dphi_to(c: Array) -> tuple[Array, Array]:
    return _iso_dirs(c[:, 1], c[:, 0], c[:, 2])


def _tvtl_from(L: Array, V: Array) -> Array:
    tl, tv, _ = _iso_frame(L, V)
    return _stack(tv, tl)


def _tvtl_to(c: Array) -> tuple[Array, Array]:
    return _iso_dirs(c[:, 1], c[:, 0], np.full(len(c), np.pi))


def _proj_from(L: Array, V: Array) -> Array:
    tl, tv, dphi = _iso_frame(L, V)
    return _stack(tl, tv * np.cos(dphi), tv * np.sin(dphi))


def _proj_to(c: Array) -> tuple[Array, Array]:
    tv = np.hypot(c[:, 1], c[:, 2])
    return _iso_dirs(c[:, 0], tv, np.arctan2(c[:, 2], c[:, 1]))


def _retro_from(L: Array, V: Array) -> Array:
    # Rotate the pair so that L lies in the x-z plane (phi_l = 0).
    V = _rot_z(V, -np.arctan2(L[:, 1], L[:, 0]))
    tl = _elev(L)
    Lc = _sph(tl, np.zeros_like(tl))
    towards_n = np.stack([-np.cos(tl), np.zeros_like(tl), np.sin(tl)], axis=1)
    side = np.array([0.0, -1.0, 0.0])
    tvl = _angle(Lc, V)
    d = V - np.einsum("ij,ij->i", V, Lc)[:, None] * Lc
    phi = np.arctan2(d @ side, np.einsum("ij,ij->i", d, towards_n))
    return _stack(tl, tvl * np.cos(phi), tvl * np.sin(phi))


def _retro_to(c: Array) -> tuple[Array, Array]:
    tl = c[:, 0]
    tvl = np.hypot(c[:, 1], c[:, 2])
    phi = np.arctan2(c[:, 2], c[:, 1])
    L = _sph(tl, np.zeros_like(tl))
    towards_n = np.stack([-np.cos(tl), np.zeros_like(tl), np.sin(tl)], axis=1)
    side = np.array([0.0, -1.0, 0.0])
    t = np.cos(phi)[:, None] * towards_n + np.sin(phi)[:, None] * side
    V = np.cos(tvl)[:, None] * L + np.sin(tvl)[:, None] * t
    return L, V


def _retro_v_from(L: Array, V: Array) -> Array:
    return _retro_from(V, L)


def _retro_v_to(c: Array) -> tuple[Array, Array]:
    V, L = _retro_to(c)
    return L, V


def _stark2_from(L: Array, V: Array) -> Array:
    h = 0.5 * (L + V)
    b = 0.5 * (L - V)
    return _stack(np.hypot(h[:, 0], h[:, 1]), np.linalg.norm(b, axis=1))


def _stark2_to(c: Array) -> tuple[Array, Array]:
    hx, b = c[:, 0], c[:, 1]
    # Valid configurations: hp >= 0, b >= 0, hp^2 + b^2 <= 1 (a quarter disk).
    bad = (hx < 0) | (b < 0) | (hx * hx + b * b > 1.0 + 1e-12)
    hz = np.sqrt(np.maximum(1.0 - hx * hx - b * b, 0.0))
    H = np.stack([hx, np.zeros_like(hx), hz], axis=1)
    B = np.stack([np.zeros_like(hx), b, np.zeros_like(hx)], axis=1)
    return _nan_rows(bad, _unit(H + B), _unit(H - B))


_PI = float(np.pi)
_HALF = 0.5 * _PI


def _p(name: str, coords: tuple[str, ...], inv: str, bounds: tuple, frm, to, desc: str):
    return Parametrization(name, len(coords), coords, desc, inv, bounds, frm, to)


_ALL = (
    _p("CARTESIAN", ("vx", "vy", "vz", "lx", "ly", "lz"), "full",
       ((-1, 1), (-1, 1), (0, 1)) * 2, _cart_from, _cart_to,
       "The pivot as ALTA stores it: view vector V, then light vector L (6 numbers)."),
    _p("SPHERICAL_TL_PL_TV_PV", ("theta_l", "phi_l", "theta_v", "phi_v"), "full",
       ((0, _HALF), (-_PI, _PI), (0, _HALF), (-_PI, _PI)), _sph_from, _sph_to,
       "Classical spherical angles of L and V."),
    _p("RUSIN_TH_PH_TD_PD", ("theta_h", "phi_h", "theta_d", "phi_d"), "full",
       ((0, _HALF), (-_PI, _PI), (0, _HALF), (-_PI, _PI)), _r4_from, _r4_to,
       "Rusinkiewicz half/difference angles. The difference vector is L expressed in the "
       "half vector's frame (Rusinkiewicz 1998, MERL); ALTA's code rotates its first "
       "Cartesian vector (V) instead, which moves phi_d by pi: equal for reciprocal BRDFs."),
    _p("RUSIN_VH_VD", ("hx", "hy", "hz", "dx", "dy", "dz"), "full",
       ((-1, 1), (-1, 1), (0, 1), (-1, 1), (-1, 1), (0, 1)), _vhvd_from, _vhvd_to,
       "Half vector h = (L+V)/|L+V| and difference vector d (L in h's frame), as vectors."),
    _p("RUSIN_TH_TD_PD", ("theta_h", "theta_d", "phi_d"), "isotropic",
       ((0, _HALF), (0, _HALF), (-_PI, _PI)), _r3_from, _r3_to,
       "Isotropic Rusinkiewicz angles (MERL's table axes); canonical phi_h = 0."),
    _p("RUSIN_TH_TD_SYM", ("theta_h", "theta_d", "sin2_theta_h_cos_2phi_d"), "symmetric",
       ((0, _HALF), (0, _HALF), (-1, 1)), _sym_from, _sym_to,
       "Rusinkiewicz angles with the symmetries of an isotropic, reciprocal BRDF built in "
       "(ratfit's own name): theta_h, theta_d and sin^2(theta_h) cos(2 phi_d). Any function "
       "of these is reciprocal (phi_d -> phi_d + pi), mirror-symmetric (phi_d -> -phi_d) "
       "and independent of phi_d at the mirror direction theta_h = 0; canonical phi_d in "
       "[0, pi/2]."),
    _p("RUSIN_TH_TD_FOLD", ("theta_h", "theta_d", "sin_theta_h_cos_phi_d"), "reciprocal",
       ((0, _HALF), (0, _HALF), (-1, 1)), _fold_from, _fold_to,
       "Rusinkiewicz angles with reciprocity and isotropy at the mirror direction built in, "
       "but not mirror symmetry (ratfit's own name): theta_h, theta_d and "
       "sin(theta_h) cos(phi_d), phi_d folded into [0, pi) as a MERL table folds it. Any "
       "function of these is reciprocal (phi_d -> phi_d + pi) and independent of phi_d at "
       "theta_h = 0, and may differ between phi_d and -phi_d, as RGL's measured tables do; "
       "it jumps where a MERL table does, at the fold phi_d = 0 / pi."),
    _p("COS_TH_TD_PD", ("cos_theta_h", "cos_theta_d", "phi_d"), "isotropic",
       ((0, 1), (0, 1), (-_PI, _PI)), _c3_from, _c3_to,
       "Cosine variant of RUSIN_TH_TD_PD (ratfit's own name; ALTA has only COS_TH_TD)."),
    _p("ISOTROPIC_TV_TL_DPHI", ("theta_v", "theta_l", "delta_phi"), "isotropic",
       ((0, _HALF), (0, _HALF), (-_PI, _PI)), _tvtl_dphi_from, _tvtl_dphi_to,
       "Elevations of V and L and delta_phi = phi_l - phi_v (ALTA's from_cartesian); "
       "canonical L at phi = 0."),
    _p("ISOTROPIC_TL_TV_PROJ_DPHI", ("theta_l", "tv_cos_dphi", "tv_sin_dphi"), "isotropic",
       ((0, _HALF), (-_HALF, _HALF), (-_HALF, _HALF)), _proj_from, _proj_to,
       "ALTA's retro-reflection files: theta_l, then theta_v (cos, sin)(delta_phi) with "
       "delta_phi = phi_l - phi_v, i.e. V's elevation projected on the plane; canonical L at "
       "phi = 0."),
    _p("RETRO_TL_TVL_PROJ_DPHI", ("theta_l", "tvl_cos_phi", "tvl_sin_phi"), "isotropic",
       ((0, _HALF), (-_PI, _PI), (-_PI, _PI)), _retro_from, _retro_to,
       "theta_l, then the angle theta_vl between L and V projected on the tangent plane at L "
       "(phi measured at L from the arc towards the normal, ALTA's sign); (0, 0) is exact "
       "retro-reflection."),
    _p("RETRO_TV_TVL_PROJ_DPHI", ("theta_v", "tvl_cos_phi", "tvl_sin_phi"), "isotropic",
       ((0, _HALF), (-_PI, _PI), (-_PI, _PI)), _retro_v_from, _retro_v_to,
       "RETRO_TL_TVL_PROJ_DPHI with the roles of L and V exchanged (ratfit's own name): "
       "the same values for a reciprocal BRDF. Gonioreflectometers such as the ALTA retro "
       "files fix a few light elevations and sweep the viewer, so theta_l takes a handful "
       "of values and cannot carry a polynomial of higher degree; theta_v varies freely."),
    _p("RUSIN_VH", ("hx", "hy", "hz"), "half",
       ((-1, 1), (-1, 1), (0, 1)), _vh_from, _vh_to,
       "The half vector only; canonical theta_d = 0 (L = V = h)."),
    _p("ISOTROPIC_TV_TL", ("theta_v", "theta_l"), "tv_tl",
       ((0, _HALF), (0, _HALF)), _tvtl_from, _tvtl_to,
       "Elevations only; canonical delta_phi = pi (V in L's plane of incidence, opposite)."),
    _p("RUSIN_TH_TD", ("theta_h", "theta_d"), "th_td",
       ((0, _HALF), (0, _HALF)), _r2_from, _r2_to,
       "Half and difference elevations; canonical phi_h = 0, phi_d = pi/2 (ALTA)."),
    _p("COS_TH_TD", ("cos_theta_h", "cos_theta_d"), "th_td",
       ((0, 1), (0, 1)), _c2_from, _c2_to,
       "Cosines of the half and difference elevations."),
    _p("STARK_2D", ("hp", "b"), "th_td",
       ((0, 1), (0, 1)), _stark2_from, _stark2_to,
       "Stark et al. 2005 as in ALTA: hp = |projection of H = (L+V)/2 on the plane|, "
       "b = |B|, B = (L-V)/2; hp = cos(theta_d) sin(theta_h), b = sin(theta_d)."),
    _p("RUSIN_TH", ("theta_h",), "th", ((0, _HALF),), _r1_from, _r1_to,
       "Half-vector elevation only; canonical L = V."),
    _p("COS_TH", ("cos_theta_h",), "th", ((0, 1),), _c1_from, _c1_to,
       "Cosine of the half-vector elevation; canonical L = V."),
)

PARAMETRIZATIONS: dict[str, Parametrization] = {p.name: p for p in _ALL}

# What each invariant determines (for round trips: src -> dst -> src is exact
# when dst determines src's invariant).
_DETERMINES = {
    "full": {"full", "isotropic", "reciprocal", "symmetric", "th_td", "th", "half", "tv_tl"},
    "isotropic": {"isotropic", "reciprocal", "symmetric", "th_td", "th", "tv_tl"},
    "reciprocal": {"reciprocal", "symmetric", "th_td", "th"},
    "symmetric": {"symmetric", "th_td", "th"},
    "th_td": {"th_td", "th"},
    "half": {"half", "th"},
    "tv_tl": {"tv_tl"},
    "th": {"th"},
}


def find_parametrization(name: str | Parametrization) -> Parametrization | None:
    """The parametrization called ``name`` (ALTA spelling, case-insensitive), or None."""
    if isinstance(name, Parametrization):
        return name
    return PARAMETRIZATIONS.get(str(name).strip().upper())


def get_parametrization(name: str | Parametrization) -> Parametrization:
    """The parametrization called ``name``; an unknown name is an InputError."""
    p = find_parametrization(name)
    if p is None:
        raise InputError(
            f"unknown parametrization {name!r}; valid names: {', '.join(PARAMETRIZATIONS)}"
        )
    return p


def determines(src: str | Parametrization, dst: str | Parametrization) -> bool:
    """True when coordinates in ``src`` fix the coordinates in ``dst`` (convert is lossless)."""
    a, b = get_parametrization(src), get_parametrization(dst)
    return b.invariant in _DETERMINES[a.invariant]


def convert(coords: ArrayLike, src: str | Parametrization, dst: str | Parametrization) -> Array:
    """Coordinates in ``src`` -> directions (the pivot) -> coordinates in ``dst``."""
    a, b = get_parametrization(src), get_parametrization(dst)
    L, V = a.to_dirs(coords)
    return b.from_dirs(L, V)
