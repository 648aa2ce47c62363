"""Measured BRDF files: MERL .binary, ALTA data (text and binary), Cornell/pbrt
spectral .brdf, Cornell ASTM text and EXR 2-D slices.

Each reader returns the samples in the file's own parametrization;
:func:`brdf_dataset` turns any of them into a :class:`ratfit.io.data.Dataset`
in a chosen parametrization, going through the Cartesian (L, V) pivot of
:mod:`ratfit.params`. Errors are :class:`FileFormatError` (not the format it
claims, truncated, wrong header) or :class:`InputError` (values that cannot be
used); writers are atomic.

MERL tables follow MERL's reference reader (BRDFRead.cpp): indices are rounded
down, so cell (i, j, k) holds the BRDF at its lower edge, theta_h = (i/90)^2 pi/2,
theta_d = j/90 pi/2, phi_d = k/180 pi (:func:`merl_coords`).
"""

from __future__ import annotations

import functools
import os
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit._atomic import atomic_open
from ratfit.brdf.parametrizations import PARAMETRIZATIONS, get_parametrization
from ratfit.errors import FileFormatError, InputError
from ratfit.io.data import Dataset, read_data

__all__ = [
    "BRDF_FORMATS",
    "measured_brdf_format",
    "MERL_SCALE",
    "MERL_SHAPE",
    "BRDFSamples",
    "MERLData",
    "channel_names_of",
    "brdf_dataset",
    "cie1931_xyz",
    "merl_cell_measure",
    "merl_coords",
    "merl_from_function",
    "read_alta_binary",
    "read_astm",
    "read_brdf",
    "samples_dataset",
    "read_cornell",
    "read_exr",
    "read_merl",
    "spectrum_to_rgb",
    "write_merl",
]

Array = NDArray[np.float64]
_PathLike = str | os.PathLike[str]

BRDF_FORMATS = ("merl", "alta", "cornell", "astm", "exr")
#: How ``max_points`` draws a subset: every sample alike; (a MERL table) each cell as
#: often as uniformly random direction pairs fall in it (:func:`merl_cell_measure`); or
#: half the cells so and half as often as pairs weighted by the table's luminance fall in
#: them ("energy": where a renderer that samples the BRDF evaluates it, the highlight).
SUBSET_BY = ("samples", "pairs", "energy")
#: Share of an "energy" subset drawn by pairs weighted by the table's luminance.
ENERGY_SHARE = 0.5
# Rec. 709 luminance of linear RGB: what weighs an "energy" subset's cells
_LUMINANCE = (0.2126, 0.7152, 0.0722)

# --------------------------------------------------------------------------- samples
@dataclass(frozen=True, eq=False)
class BRDFSamples:
    """BRDF samples in the file's parametrization: coords (N, d), values (N, k)."""

    param: str
    coords: Array
    values: Array
    channel_names: tuple[str, ...]
    meta: dict[str, Any] = field(default_factory=dict)


# --------------------------------------------------------------------------- MERL
# ratfit follows the convention of MERL's own reader (BRDFRead.cpp, lookup_brdf_val):
# a direction pair's cell index is its coordinate rounded DOWN, so the value stored in
# cell (i, j, k) is the BRDF at the cell's lower edge,
#     theta_h = (i/90)^2 pi/2,  theta_d = j/90 pi/2,  phi_d = k/180 pi,
# not at its centre. Reading, writing, looking up and fitting all use these points.
MERL_SHAPE = (90, 90, 180)  # theta_h, theta_d, phi_d
MERL_SCALE = (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0)  # R, G, B
_MERL_HEADER = 12
# index rounding slack: the stored point of cell i maps back to i although
# sqrt((i/90)^2) * 90 may come out a few ulps below i
_MERL_INDEX_SLACK = 1e-9
# midpoints a cell's theta_h and theta_d are each split into by merl_cell_measure
_MEASURE_STEPS = 4


@dataclass(frozen=True, eq=False)
class MERLData:
    """A MERL table: ``rgb`` (90, 90, 180, 3) BRDF values (scale applied), NaN = missing.

    Cell (i, j, k) holds the BRDF at MERL's sample point for that cell, its lower
    edge (:func:`merl_coords`), as MERL's reference reader assumes.
    """

    rgb: Array
    source: str = "merl"

    @property
    def valid(self) -> NDArray[np.bool_]:
        """Cells where all three channels were measured (MERL stores missing as < 0)."""
        return np.all(np.isfinite(self.rgb), axis=-1)

    def samples(self) -> BRDFSamples:
        """Valid cells at MERL's sample points (lower cell edges), in RUSIN_TH_TD_PD
        (phi_d in [0, pi))."""
        ok = self.valid
        coords = merl_coords()[ok.ravel()]
        return BRDFSamples(
            "RUSIN_TH_TD_PD", coords, self.rgb[ok], ("R", "G", "B"),
            {"format": "merl", "source": self.source, "fold_phi_d": True,
             "param_out": "INV_STERADIAN", "missing": int((~ok).sum()),
             "merl_convention": "lower cell edge (MERL BRDFRead.cpp)"},
        )

    def lookup(self, L: ArrayLike, V: ArrayLike) -> Array:
        """Cell values (N, 3) at directions, with MERL's index maps (rounded down)."""
        th, td, pd = get_parametrization("RUSIN_TH_TD_PD").from_dirs(L, V).T
        i, j, k = merl_indices(th, td, pd)
        return self.rgb[i, j, k]


def merl_indices(th: ArrayLike, td: ArrayLike, pd: ArrayLike) -> tuple[NDArray, NDArray, NDArray]:
    """MERL's cell indices, as its reference reader computes them: theta_h square-root
    mapped, theta_d linear, phi_d folded into [0, pi), each rounded down and clipped."""
    th, td, pd = (np.asarray(a, dtype=float) for a in (th, td, pd))
    eps = _MERL_INDEX_SLACK
    i = np.floor(np.sqrt(np.clip(th, 0.0, None) / (0.5 * np.pi)) * 90.0 + eps).astype(int)
    j = np.floor(td / (0.5 * np.pi) * 90.0 + eps).astype(int)
    k = np.floor(np.mod(pd, np.pi) / np.pi * 180.0 + eps).astype(int)
    return np.clip(i, 0, 89), np.clip(j, 0, 89), np.clip(k, 0, 179)


def merl_coords() -> Array:
    """MERL's sample points (90*90*180, 3) in RUSIN_TH_TD_PD, table order.

    The point of cell (i, j, k) is its lower edge, theta_h = (i/90)^2 pi/2,
    theta_d = j/90 pi/2, phi_d = k/180 pi: MERL's reader rounds indices down
    (BRDFRead.cpp), so this is where each stored value belongs, and
    :func:`merl_indices` sends it back to its own cell.
    """
    th = (np.arange(90) / 90.0) ** 2 * (0.5 * np.pi)
    td = np.arange(90) / 90.0 * (0.5 * np.pi)
    pd = np.arange(180) / 180.0 * np.pi
    g = np.meshgrid(th, td, pd, indexing="ij")
    return np.stack([a.ravel() for a in g], axis=1)


@functools.cache
def _merl_cell_measure() -> Array:
    u = (np.arange(_MEASURE_STEPS) + 0.5) / _MEASURE_STEPS
    th_edges = (np.arange(91) / 90.0) ** 2 * (0.5 * np.pi)
    td_edges = np.arange(91) / 90.0 * (0.5 * np.pi)
    pd_lo = np.arange(180) / 180.0 * np.pi
    pd_hi = pd_lo + np.pi / 180.0
    out = np.zeros(MERL_SHAPE)
    for a in u:
        th = th_edges[:-1] + a * np.diff(th_edges)
        for b in u:
            td = td_edges[:-1] + b * np.diff(td_edges)
            # both directions are above the horizon where |cos phi_d| < c
            with np.errstate(divide="ignore"):
                c = 1.0 / (np.tan(th)[:, None] * np.tan(td)[None, :])
            p0 = np.arccos(np.clip(c, 0.0, 1.0))  # valid phi_d: (p0, pi - p0)
            valid = np.clip(np.minimum(pd_hi, np.pi - p0[..., None])
                            - np.maximum(pd_lo, p0[..., None]), 0.0, None)
            jac = (np.sin(th) * np.diff(th_edges))[:, None] * (
                np.sin(td) * np.cos(td) * np.diff(td_edges))[None, :]
            out += jac[..., None] * valid
    out /= out.sum()
    out.flags.writeable = False
    return out


def merl_cell_measure() -> Array:
    """Each MERL cell's share (90, 90, 180; sum 1) of direction pairs L, V drawn
    uniformly (by solid angle) on the upper hemisphere, as MERL's reader indexes them.

    Why: a table's cells are packed toward the mirror direction (theta_h is square-root
    spaced), so a uniform draw of cells leaves out the pairs a renderer meets most. In
    (theta_h, phi_h, theta_d, phi_d), dL dV = 4 cos(theta_d) dh dd; neither z depends on
    phi_h, so the density is sin(theta_h) sin(theta_d) cos(theta_d) where both z > 0,
    which is |cos phi_d| < cot(theta_h) cot(theta_d) (phi_d and phi_d + pi alike, one
    cell). Integrated exactly over phi_d and by a midpoint rule of
    :data:`_MEASURE_STEPS` points over theta_h and theta_d in each cell."""
    return _merl_cell_measure()


def merl_from_function(f: Callable[[Array, Array], ArrayLike], *, chunk: int = 200_000) -> Array:
    """A (90, 90, 180, 3) table of ``f(L, V) -> (N, 3)`` at MERL's sample points
    (:func:`merl_coords`, the lower cell edges).

    Cells whose point puts L or V below the horizon are missing (NaN), as in
    measured MERL files.
    """
    from ratfit.brdf.parametrizations import _from_half_diff

    c = merl_coords()
    out = np.full((c.shape[0], 3), np.nan)
    for s in range(0, c.shape[0], chunk):
        cc = c[s : s + chunk]
        L, V = _from_half_diff(cc[:, 0], np.zeros(len(cc)), cc[:, 1], cc[:, 2])
        ok = (L[:, 2] > 0) & (V[:, 2] > 0)
        if ok.any():
            out[s : s + chunk][ok] = np.asarray(f(L[ok], V[ok]), dtype=float).reshape(-1, 3)
    return out.reshape(*MERL_SHAPE, 3)


def read_merl(path: _PathLike) -> MERLData:
    """Read a MERL .binary file: 3 int32 dims, then R, G, B blocks of float64."""
    src = str(path)
    data = _read_bytes(path)
    if len(data) < _MERL_HEADER:
        raise FileFormatError(f"{src}: truncated MERL file ({len(data)} bytes, no 12-byte header)")
    dims = tuple(int(v) for v in np.frombuffer(data[:_MERL_HEADER], dtype="<i4"))
    if dims != MERL_SHAPE:
        raise FileFormatError(
            f"{src}: MERL header dims {dims}, expected {MERL_SHAPE} (theta_h, theta_d, phi_d)"
        )
    n = int(np.prod(MERL_SHAPE))
    want = _MERL_HEADER + 3 * n * 8
    if len(data) != want:
        what = "truncated" if len(data) < want else "has trailing bytes"
        raise FileFormatError(
            f"{src}: {what}: a MERL file is {want} bytes (12-byte header + 3 x {n} doubles), "
            f"this one is {len(data)}"
        )
    raw = np.frombuffer(data[_MERL_HEADER:], dtype="<f8").reshape(3, *MERL_SHAPE)
    if not np.all(np.isfinite(raw)):
        raise InputError(f"{src}: MERL table holds {int((~np.isfinite(raw)).sum())} NaN/inf")
    scale = np.asarray(MERL_SCALE)[:, None, None, None]
    rgb = np.where(raw < 0, np.nan, raw * scale)
    return MERLData(np.moveaxis(rgb, 0, -1).copy(), src)


def write_merl(path: _PathLike, rgb_table: ArrayLike) -> None:
    """Write a (90, 90, 180, 3) table of BRDF values as MERL .binary (NaN/negative = missing)."""
    t = np.asarray(rgb_table, dtype=float)
    if t.shape != (*MERL_SHAPE, 3):
        raise InputError(f"{path}: a MERL table has shape {(*MERL_SHAPE, 3)}, got {t.shape}")
    if np.isinf(t).any():
        raise InputError(f"{path}: MERL table holds infinite values")
    scale = np.asarray(MERL_SCALE)
    raw = np.where(np.isnan(t) | (t < 0), -1.0, t / scale)
    with atomic_open(path, "wb") as fh:
        fh.write(np.asarray(MERL_SHAPE, dtype="<i4").tobytes())
        fh.write(np.ascontiguousarray(np.moveaxis(raw, -1, 0), dtype="<f8").tobytes())


# --------------------------------------------------------------------------- ALTA binary
def read_alta_binary(path: _PathLike) -> Dataset:
    """ALTA binary data: a text header (#FORMAT binary, #ENDIAN, #SAMPLE_COUNT) + doubles."""
    src = str(path)
    data = _read_bytes(path)
    end = data.find(b"#ALTA_END_HEADER\n")
    if end < 0:
        raise FileFormatError(f"{src}: no '#ALTA_END_HEADER' line: not an ALTA binary file")
    head: dict[str, list[str]] = {}
    for n, raw in enumerate(data[:end].split(b"\n"), start=1):
        s = raw.decode("ascii", "replace").strip()
        if s.startswith("#") and len(s) > 1:
            parts = s[1:].split()
            head[parts[0].upper()] = parts[1:]
            if parts[0].upper() == "DIM" and len(parts) != 3:
                raise FileFormatError(f"{src} line {n}: malformed #DIM header {s!r}")
    try:
        nx, ny = (int(v) for v in head["DIM"])
        count = int(head["SAMPLE_COUNT"][0])
        vs = int(head.get("VS", ["0"])[0])
    except (KeyError, ValueError, IndexError):
        raise FileFormatError(
            f"{src}: ALTA binary header needs '#DIM nx ny' and '#SAMPLE_COUNT n'"
        ) from None
    if nx < 1 or ny < 1 or count < 1 or vs not in (0, 1, 2):
        raise FileFormatError(f"{src}: bad ALTA binary header (#DIM {nx} {ny}, #VS {vs})")
    fmt = " ".join(head.get("FORMAT", ["binary"])).lower()
    if fmt != "binary":
        raise FileFormatError(f"{src}: #FORMAT {fmt!r} is not binary")
    endian = " ".join(head.get("ENDIAN", ["little"])).lower()
    if endian not in ("little", "big"):
        raise FileFormatError(f"{src}: unknown #ENDIAN {endian!r}")
    prec = " ".join(head.get("PRECISION", ["ieee754-double"])).lower()
    if prec != "ieee754-double":
        raise FileFormatError(f"{src}: unsupported #PRECISION {prec!r} (ieee754-double only)")
    width = nx + ny + ny * vs
    body = data[end + len(b"#ALTA_END_HEADER\n") :]
    want = count * width * 8
    if len(body) != want:
        raise FileFormatError(
            f"{src}: body has {len(body)} bytes but #SAMPLE_COUNT {count} x {width} doubles "
            f"(#DIM {nx} {ny}, #VS {vs}) needs {want}"
        )
    arr = np.frombuffer(body, dtype="<f8" if endian == "little" else ">f8").reshape(count, width)
    arr = arr.astype(np.float64)
    y = arr[:, nx : nx + ny]
    lo = hi = None
    if vs == 1:
        lo, hi = y - arr[:, nx + ny :], y + arr[:, nx + ny :]
    elif vs == 2:
        lo, hi = arr[:, nx + ny :: 2], arr[:, nx + ny + 1 :: 2]
    meta = {"format": "alta-binary", "source": src, "vs": vs,
            "param_in": " ".join(head.get("PARAM_IN", ["UNKNOWN"])),
            "param_out": " ".join(head.get("PARAM_OUT", ["UNKNOWN"]))}
    return Dataset(arr[:, :nx], y, lo, hi, (), (), meta)


# --------------------------------------------------------------------------- colour
def _lobe(lam: Array, mu: float, s1: float, s2: float) -> Array:
    s = np.where(lam < mu, s1, s2)
    return np.exp(-0.5 * ((lam - mu) / s) ** 2)


def cie1931_xyz(wavelengths: ArrayLike) -> Array:
    """CIE 1931 2-degree colour matching functions (N, 3) at wavelengths in nm.

    Wyman, Sloan and Shirley's multi-lobe fit (JCGT 2(2), 2013) of the CIE
    tables; it matches them to about 1 % of the peak, far below the spread of
    a 31-band gonioreflectometer.
    """
    lam = np.asarray(wavelengths, dtype=float)
    x = (1.056 * _lobe(lam, 599.8, 37.9, 31.0) + 0.362 * _lobe(lam, 442.0, 16.0, 26.7)
         - 0.065 * _lobe(lam, 501.1, 20.4, 26.2))
    y = 0.821 * _lobe(lam, 568.8, 46.9, 40.5) + 0.286 * _lobe(lam, 530.9, 16.3, 31.1)
    z = 1.217 * _lobe(lam, 437.0, 11.8, 36.0) + 0.681 * _lobe(lam, 459.0, 26.0, 13.8)
    return np.stack([x, y, z], axis=-1)


# XYZ -> linear sRGB (IEC 61966-2-1, D65 primaries).
_XYZ_TO_SRGB = np.array(
    [[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415], [0.0557, -0.2040, 1.0570]]
)


def spectrum_to_rgb(wavelengths: ArrayLike, spectra: ArrayLike, *, space: str = "rgb",
                    clip: bool = True) -> Array:
    """Spectral values (N, W) -> linear sRGB (or XYZ) (N, 3) under an equal-energy light.

    Normalised so that a flat spectrum of value s has Y = s: a BRDF stays a
    BRDF. ``clip`` sets negative (out-of-gamut) sRGB components to 0.
    """
    lam = np.asarray(wavelengths, dtype=float)
    s = np.asarray(spectra, dtype=float)
    cmf = cie1931_xyz(lam)
    w = np.gradient(lam) if lam.size > 1 else np.ones(1)
    xyz = (s * w) @ cmf / float(np.sum(cmf[:, 1] * w))
    if space == "xyz":
        return xyz
    rgb = xyz @ _XYZ_TO_SRGB.T
    return np.maximum(rgb, 0.0) if clip else rgb


# --------------------------------------------------------------------------- Cornell
def read_cornell(path: _PathLike) -> BRDFSamples:
    """Cornell spectral BRDF in pbrt's .brdf layout: wavelengths, then rows of
    theta_i phi_i theta_s phi_s and one value per wavelength (radians, 1/sr)."""
    src = str(path)
    data = _read_bytes(path)
    toks: list[tuple[int, str]] = []
    comments: list[str] = []
    for n, s in _text_lines(src, data):
        if s.startswith("#"):
            comments.append(s[1:].strip())
            continue
        toks.extend((n, t) for t in s.split())
    if not toks:
        raise FileFormatError(f"{src}: no numbers: not a Cornell/pbrt .brdf file")
    vals = _floats(src, toks)
    nw = vals[0]
    if nw != int(nw) or not 1 <= nw <= 10_000:
        raise FileFormatError(
            f"{src} line {toks[0][0]}: first number {nw!r} should be the count of wavelengths"
        )
    nw = int(nw)
    if len(vals) < 1 + nw:
        raise FileFormatError(f"{src}: truncated: {nw} wavelengths announced, fewer given")
    lam = vals[1 : 1 + nw]
    if np.any(np.diff(lam) <= 0) or lam[0] < 200 or lam[-1] > 2000:
        raise FileFormatError(f"{src}: wavelengths {lam[0]}..{lam[-1]} are not increasing nm")
    rest = vals[1 + nw :]
    width = 4 + nw
    if rest.size == 0 or rest.size % width:
        k = rest.size // width
        line = toks[1 + nw + k * width][0] if rest.size % width else toks[-1][0]
        raise FileFormatError(
            f"{src} line {line}: {rest.size} numbers after the wavelengths is not a whole number "
            f"of rows of {width} (4 angles + {nw} spectral values): truncated or wrong count"
        )
    rows = rest.reshape(-1, width)
    _check_angles(src, rows[:, [0, 2]])
    L = _sph_dirs(rows[:, 0], rows[:, 1])
    V = _sph_dirs(rows[:, 2], rows[:, 3])
    name = next((c for c in comments[1:2] if c), Path(src).stem)
    return BRDFSamples(
        "CARTESIAN", np.hstack([V, L]), rows[:, 4:], tuple(f"{w:g}nm" for w in lam),
        {"format": "cornell", "source": src, "wavelengths": lam.tolist(), "material": name,
         "param_out": "INV_STERADIAN"},
    )


def read_astm(path: _PathLike) -> BRDFSamples:
    """Cornell's ASTM E1392-style text: keyword lines (``VARS`` names the columns,
    ``NUM_POINTS`` the row count), then comma- or blank-separated rows with
    theta_i, phi_i, theta_s, phi_s and one column per channel. Angles are radians
    unless some exceed 2 pi (then degrees)."""
    src = str(path)
    data = _read_bytes(path)
    names: list[str] | None = None
    npts: int | None = None
    rows: list[list[str]] = []
    lines: list[int] = []
    for n, s in _text_lines(src, data):
        if not s or s.startswith("#"):
            continue
        first = s.replace(",", " ").split()[0]
        if not _is_num(first):
            key = first.upper()
            rest = s[len(first):].strip()
            if key == "VARS":
                names = [t.strip() for t in re.split(r"[,\s]+", rest) if t.strip()]
            elif key == "NUM_POINTS":
                try:
                    npts = int(rest.split()[0])
                except (ValueError, IndexError):
                    raise FileFormatError(f"{src} line {n}: malformed NUM_POINTS {s!r}") from None
            elif rows:
                raise FileFormatError(f"{src} line {n}: keyword line {first!r} after data rows")
            continue
        if names is None:
            raise FileFormatError(f"{src} line {n}: data row before the VARS line")
        t = s.replace(",", " ").split()
        if len(t) != len(names):
            raise FileFormatError(
                f"{src} line {n}: expected {len(names)} values (VARS {','.join(names)}), "
                f"got {len(t)}"
            )
        rows.append(t)
        lines.append(n)
    if names is None:
        raise FileFormatError(f"{src}: no VARS line: not an ASTM BRDF file")
    if not rows:
        raise FileFormatError(f"{src}: no data rows")
    if npts is not None and npts != len(rows):
        what = "truncated" if len(rows) < npts else "has extra rows"
        raise FileFormatError(f"{src}: {what}: NUM_POINTS {npts}, found {len(rows)} rows")
    low = [v.lower() for v in names]
    need = ["theta_i", "phi_i", "theta_s", "phi_s"]
    miss = [v for v in need if v not in low]
    if miss:
        raise FileFormatError(f"{src}: VARS lacks {', '.join(miss)} (has {', '.join(names)})")
    arr = _floats(src, [(n, t) for n, r in zip(lines, rows, strict=True) for t in r])
    arr = arr.reshape(len(rows), len(names))
    ang = arr[:, [low.index(v) for v in need]]
    if np.abs(ang).max() > 2 * np.pi + 1e-9:
        ang = np.radians(ang)
    _check_angles(src, ang[:, [0, 2]])
    chans = [j for j, v in enumerate(low) if v not in need]
    if not chans:
        raise FileFormatError(f"{src}: VARS names no value column besides the four angles")
    L, V = _sph_dirs(ang[:, 0], ang[:, 1]), _sph_dirs(ang[:, 2], ang[:, 3])
    return BRDFSamples("CARTESIAN", np.hstack([V, L]), arr[:, chans],
                       tuple(names[j] for j in chans),
                       {"format": "astm", "source": src, "param_out": "INV_STERADIAN"})


# --------------------------------------------------------------------------- EXR
def read_exr(path: _PathLike, param: str = "STARK_2D") -> BRDFSamples:
    """A 2-D BRDF slice stored as an image (ALTA's EXR output): pixel (row i, column j)
    holds the value at coordinates ((j + 0.5)/W, (i + 0.5)/H) of ``param``."""
    src = str(path)
    try:
        import OpenEXR
    except ImportError:  # pragma: no cover - installed with the 'exr' extra
        raise InputError('reading EXR needs the OpenEXR package: pip install ".[exr]" '
                         "(from the ratfit checkout)") \
            from None
    if not Path(path).is_file():
        raise FileFormatError(f"{src}: no such file")
    with open(path, "rb") as fh:
        magic = fh.read(4)
    if magic != b"\x76\x2f\x31\x01":
        raise FileFormatError(f"{src}: not an OpenEXR file (bad magic number)")
    from ratfit._quiet import quiet_output

    said = ""
    try:
        with quiet_output() as cap, OpenEXR.File(str(path)) as f:
            chans = {k: np.asarray(v.pixels, dtype=np.float64) for k, v in f.channels().items()}
        said = cap.first_line
    except Exception as exc:  # OpenEXR raises plain RuntimeError/ValueError on bad files
        raise FileFormatError(f"{src}: unreadable EXR: {exc}") from None
    if said:  # OpenEXR warns (and returns partial pixels) on a damaged file
        raise FileFormatError(f"{src}: damaged EXR (OpenEXR: {said})")
    planes: dict[str, Array] = {}
    for k, v in chans.items():
        if v.ndim == 3:
            for i, c in enumerate(k if len(k) == v.shape[2] else [f"{k}{i}" for i in
                                                                  range(v.shape[2])]):
                planes[c] = v[:, :, i]
        else:
            planes[k] = v
    order: list[str] = [c for c in ("R", "G", "B") if c in planes] or sorted(planes)
    h, w = planes[order[0]].shape
    p = get_parametrization(param)
    if p.dim != 2:
        raise InputError(f"an EXR slice is 2-D; {p.name} has {p.dim} coordinates")
    jj, ii = np.meshgrid(np.arange(w), np.arange(h))
    coords = np.stack([(jj.ravel() + 0.5) / w, (ii.ravel() + 0.5) / h], axis=1)
    vals = np.stack([planes[c].ravel() for c in order], axis=1)
    bad = ~np.isfinite(vals)
    if bad.any():
        raise InputError(f"{src}: {int(bad.sum())} non-finite pixel value(s)")
    return BRDFSamples(p.name, coords, vals, tuple(order),
                       {"format": "exr", "source": src, "width": w, "height": h})


# --------------------------------------------------------------------------- dispatch
def _sniff(p: Path, head: bytes) -> str:
    suf = p.suffix.lower()
    if head.startswith(b"\x76\x2f\x31\x01"):
        return "exr"
    if suf == ".binary" or (len(head) >= 12 and head[:12] == np.asarray(MERL_SHAPE, "<i4")
                            .tobytes()):
        return "merl"
    if b"#ALTA_BEGIN_HEADER" in head[:64] or head.lstrip().startswith(b"#DIM") or suf in (
        ".alta", ".dat"
    ):
        return "alta"
    if b"VARS" in head[:4096] or suf == ".astm":
        return "astm"
    return "cornell"


def measured_brdf_format(path: _PathLike) -> str | None:
    """The BRDF-only format of ``path`` ("merl", "exr", "cornell", "astm") when its
    content or name says so clearly, else None (ALTA text, CSV and the rest are
    read by ``ratfit fit`` too). ``ratfit fit`` names ``ratfit brdf fit`` for these."""
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return None
    suf = p.suffix.lower()
    if head.startswith(b"\x76\x2f\x31\x01") or suf == ".exr":
        return "exr"
    if suf == ".binary" or head[:12] == np.asarray(MERL_SHAPE, "<i4").tobytes():
        return "merl"
    if suf == ".astm" or b"VARS" in head:
        return "astm"
    if suf == ".brdf" and b"Cornell" in head and b"wls" in head:
        return "cornell"
    return None


def read_brdf(path: _PathLike, *, fmt: str | None = None) -> BRDFSamples:
    """Read any supported BRDF file into samples in its own parametrization."""
    src = str(path)
    p = Path(path)
    if fmt is not None and fmt not in BRDF_FORMATS:
        raise InputError(f"unknown BRDF format {fmt!r}; valid: {', '.join(BRDF_FORMATS)}")
    if not p.is_file():
        raise FileFormatError(f"{src}: no such file")
    with open(p, "rb") as fh:
        head = fh.read(65536)
    key = fmt or _sniff(p, head)
    if key == "merl":
        return read_merl(p).samples()
    if key == "cornell":
        return read_cornell(p)
    if key == "astm":
        return read_astm(p)
    if key == "exr":
        return read_exr(p)
    if b"#FORMAT binary" in head:
        ds = read_alta_binary(p)
    else:
        ds = read_data(p, fmt="alta")
    if ds.y is None:  # pragma: no cover - ALTA data always has y
        raise InputError(f"{src}: no values")
    param = str(ds.meta.get("param_in", "UNKNOWN")).strip().upper()
    meta = dict(ds.meta)
    if ds.lo is not None:
        meta["lo"], meta["hi"] = ds.lo, ds.hi
    return BRDFSamples(param, np.asarray(ds.x), np.asarray(ds.y), tuple(ds.output_names), meta)


def brdf_dataset(
    path: _PathLike,
    param: str | None = None,
    *,
    fmt: str | None = None,
    channels: Sequence[str | int] | None = None,
    color: str = "rgb",
    max_points: int | None = None,
    seed: int = 0,
    subset_by: str = "samples",
) -> Dataset:
    """Any supported BRDF file as a Dataset in parametrization ``param``.

    ``param`` None keeps the file's own. Spectral files are converted with
    ``color``: "rgb" (linear sRGB), "xyz" or "spectral" (the bands as they
    are). ``channels`` then picks output channels by name or index.
    ``max_points`` takes a random subset, drawn as ``subset_by`` says
    (:func:`samples_dataset`).
    """
    return samples_dataset(read_brdf(path, fmt=fmt), param, channels=channels, color=color,
                           max_points=max_points, seed=seed, subset_by=subset_by)


def samples_dataset(
    s: BRDFSamples,
    param: str | None = None,
    *,
    channels: Sequence[str | int] | None = None,
    color: str = "rgb",
    max_points: int | None = None,
    seed: int = 0,
    subset_by: str = "samples",
) -> Dataset:
    """Samples read once (:func:`read_brdf`) as a Dataset in parametrization ``param``:
    :func:`brdf_dataset` without reading the file again (one read, several frames).

    ``max_points`` keeps a seeded random subset of that many samples: with ``subset_by``
    "samples" every sample alike; with "pairs" (a MERL table) each cell as likely as
    uniformly random direction pairs make it (:func:`merl_cell_measure`), so the subset
    stands for the pairs a fit is evaluated at rather than for the table's grid, which
    packs its cells toward the mirror direction; with "energy" a mixture, half by pairs
    and half (:data:`ENERGY_SHARE`) by pairs weighted by the table's luminance, so a
    narrow highlight, which uniformly random pairs almost never reach and renders
    sample most, is in the subset too. Every channel of the file weighs the cells, so
    a fit of some channels draws the same cells as a fit of all."""
    if subset_by not in SUBSET_BY:
        raise InputError(f"unknown subset rule {subset_by!r}; choose {' or '.join(SUBSET_BY)}")
    src = str(s.meta.get("source", "data"))
    values, names = s.values, channel_names_of(s, color)
    meta = dict(s.meta)
    if meta.get("format") == "cornell":
        if color != "spectral":
            values = spectrum_to_rgb(meta["wavelengths"], values, space=color)
        meta["color"] = color
    keep = pick_channels(names, channels, src)
    values = values[:, keep]
    names = tuple(names[j] for j in keep)
    lo = meta.pop("lo", None)
    hi = meta.pop("hi", None)
    coords = s.coords
    n = coords.shape[0]
    idx = np.arange(n)
    if subset_by != "samples" and not (meta.get("format") == "merl"
                                       and s.param == "RUSIN_TH_TD_PD"):
        raise InputError(
            f"{src}: a subset by {subset_by} (--subset-by {subset_by}) draws the cells of a "
            f"MERL table; this is {meta.get('format', 'other')} data: draw its samples alike "
            "(--subset-by samples)")
    if max_points is not None and max_points < n:
        rng = np.random.default_rng(seed)
        if subset_by != "samples":
            share = merl_cell_measure()[merl_indices(*coords.T)]
            # cells no pair reaches by the midpoint rule (edges of the horizon) come last
            share = share + 1e-3 * np.min(share[share > 0], initial=1.0) / n
            p = share / share.sum()
            if subset_by == "energy":
                p = (1.0 - ENERGY_SHARE) * p + ENERGY_SHARE * _energy_share(share, s.values)
            idx = np.sort(rng.choice(n, size=max_points, replace=False, p=p / p.sum()))
        else:
            idx = np.sort(rng.choice(n, size=max_points, replace=False))
        meta["subset"] = {"points": int(max_points), "of": int(n), "by": subset_by}
    coords, values = coords[idx], values[idx]
    if lo is not None:
        lo, hi = lo[idx][:, keep], hi[idx][:, keep]
    src_param = s.param
    meta["file_param"] = src_param
    target = src_param if param is None else get_parametrization(param).name
    if target != src_param:
        if src_param not in PARAMETRIZATIONS:
            raise InputError(
                f"{src}: the file's parametrization {src_param!r} is unknown, so it cannot be "
                f"converted to {target}; valid names: {', '.join(PARAMETRIZATIONS)}"
            )
        try:
            L, V = get_parametrization(src_param).to_dirs(coords)
            coords = get_parametrization(target).from_dirs(L, V)
        except InputError as exc:
            raise InputError(f"{src}: {exc}") from None
        meta["fold_phi_d"] = False
    if meta.get("fold_phi_d") and target == "RUSIN_TH_TD_PD":
        # a table's own cells (phi_d exact in [0, pi)), not a pair of directions: no
        # seam rule (:func:`fold_phi_d` would merge the cells at theta_h = 0 or
        # theta_d = 0, where every phi_d is a pair in the plane of incidence)
        coords = coords.copy()
        coords[:, 2] = np.mod(coords[:, 2], np.pi)
    meta["param_in"] = target
    meta["source"] = src
    p = PARAMETRIZATIONS.get(target)
    inames = p.coords if p is not None else ()
    return Dataset(coords, values, lo, hi, inames, names, meta)


def _energy_share(share: Array, values: Array) -> Array:
    """Each cell's share of random pairs weighted by the table's luminance (every channel,
    negative values as 0); the pair share alone where the table is all 0."""
    v = np.maximum(np.nan_to_num(np.asarray(values, dtype=float), nan=0.0), 0.0)
    lum = v @ np.asarray(_LUMINANCE) if v.shape[1] == 3 else v.mean(axis=1)
    w = share * lum
    total = float(w.sum())
    return w / total if total > 0 and np.isfinite(total) else share / share.sum()


def channel_names_of(s: BRDFSamples, color: str = "rgb") -> tuple[str, ...]:
    """Every channel a fit of ``s`` can ask for, in the file's order: a Cornell file's
    spectra become R, G, B (or X, Y, Z) unless ``color`` is "spectral"."""
    if s.meta.get("format") == "cornell":
        if color not in ("rgb", "xyz", "spectral"):
            raise InputError(f"unknown colour conversion {color!r}; choose rgb, xyz or spectral")
        return (tuple(s.channel_names) if color == "spectral" else
                ("R", "G", "B") if color == "rgb" else ("X", "Y", "Z"))
    if color != "rgb":
        raise InputError(
            f"{s.meta.get('source', 'data')}: --color {color} converts spectral (Cornell) "
            f"data; this {s.meta.get('format', 'BRDF')} file has channels "
            f"{', '.join(s.channel_names)} already")
    return tuple(s.channel_names)


def pick_channels(names: Sequence[str], channels: Sequence[str | int] | None,
                  src: str = "data") -> list[int]:
    """Indices of ``channels`` (names, case-insensitive, or 0-based indices) in ``names``."""
    if not channels:
        return list(range(len(names)))
    low = [n.lower() for n in names]
    out = []
    for c in channels:
        if isinstance(c, (int, np.integer)) or (isinstance(c, str) and c.strip().isdigit()):
            j = int(c)
            if not 0 <= j < len(names):
                raise InputError(f"{src}: channel {j} out of range: channels are {list(names)}")
        elif str(c).strip().lower() in low:
            j = low.index(str(c).strip().lower())
        else:
            raise InputError(f"{src}: no channel {c!r}; channels are {', '.join(names)}")
        out.append(j)
    return out


# --------------------------------------------------------------------------- helpers
def _read_bytes(path: _PathLike) -> bytes:
    p = Path(path)
    if not p.is_file():
        raise FileFormatError(f"{path}: no such file")
    try:
        return p.read_bytes()
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read: {exc.strerror or exc}") from None


def _text_lines(src: str, data: bytes):
    for n, raw in enumerate(data.split(b"\n"), start=1):
        try:
            yield n, raw.decode("utf-8").strip()
        except UnicodeDecodeError:
            raise FileFormatError(f"{src} line {n}: not a text file") from None


def _is_num(t: str) -> bool:
    try:
        float(t)
    except ValueError:
        return False
    return True


def _floats(src: str, toks: list[tuple[int, str]]) -> Array:
    try:
        arr = np.array([float(t) for _, t in toks])
    except ValueError:
        for n, t in toks:
            if not _is_num(t):
                raise FileFormatError(f"{src} line {n}: non-numeric value {t[:40]!r}") from None
        raise
    bad = ~np.isfinite(arr)
    if bad.any():
        n, t = toks[int(np.flatnonzero(bad)[0])]
        raise InputError(f"{src} line {n}: non-finite value {t!r}")
    return arr


def _check_angles(src: str, thetas: Array) -> None:
    bad = (thetas < -1e-9) | (thetas > 0.5 * np.pi + 1e-9)
    if bad.any():
        i, j = (int(v) for v in np.argwhere(bad)[0])
        which = "theta_i" if j == 0 else "theta_s"
        raise InputError(
            f"{src}: sample {i}: {which} = {float(thetas[i, j])!r} rad is below the horizon "
            f"(must lie in [0, pi/2]); {int(bad.sum())} such value(s)"
        )


def _sph_dirs(theta: Array, phi: Array) -> Array:
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=1)
