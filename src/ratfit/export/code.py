"""Source code of a saved rational fit, in C, GLSL or Python, for renderers and other tools.

Per channel the exporter picks one of two forms and says which in the code:

* ``horner``: nested Horner on the monomial form in the ORIGINAL variables
  (:mod:`ratfit.monomial`), the cheapest to evaluate; chosen only when that
  form reproduces the fit to ``rtol`` POINTWISE (|h(x) - r(x)| <= rtol |r(x)| at
  every check point: the data when given, else a seeded sample of the domain and
  its corners), which is also the figure the generated code's header states.
* ``clenshaw``: the variables are mapped to [-1, 1]^d and p, q are summed in
  their orthogonal basis (Legendre or Chebyshev) by Clenshaw's recurrence, one
  dimension at a time on the dense coefficient tensor; always as accurate as
  the fit itself.

n-D tensors are reduced one axis at a time (last axis first), the same order
as :func:`ratfit.core.monomial.horner`. For a BRDF fit (a fit file that records a
parametrization) the code also computes the coordinates from unit directions
L and V in the local frame (normal +z), with the same formulas as
:mod:`ratfit.params`.
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit._atomic import atomic_open
from ratfit.brdf.parametrizations import FOLD_SEAM_TOL, is_folded
from ratfit.errors import AccuracyWarning, InputError, RatfitError
from ratfit.io.fitfile import SavedFit

__all__ = ["LANGS", "ChannelForm", "ExportResult", "FormCheck", "UnverifiedExport", "check_forms",
           "eval_forms", "export_fit", "export_source", "plan_forms"]

#: :data:`~ratfit.brdf.parametrizations.FOLD_SEAM_TOL` in single precision (GLSL):
#: there |D_y| sin(theta_h) of an in-plane pair is ~1e-7 after rounding, not ~1e-15.
FOLD_SEAM_TOL_F32 = 1e-5


Array = NDArray[np.float64]
LANGS = ("c", "glsl", "python")
FORMS = ("auto", "horner", "clenshaw", "recurrence")
HORNER_RTOL = 1e-13
_PI = "3.141592653589793"


@dataclass(frozen=True)
class ChannelForm:
    """How one channel is written: its series family, coefficient tensors and affine map."""

    name: str
    form: str  # "horner" or "clenshaw"
    family: str  # series evaluated per axis: "power", "legendre" or "chebyshev"
    P: Array
    Q: Array
    scale: Array | None  # t = scale * x + shift (clenshaw); None: series in x itself
    shift: Array | None
    reason: str
    monomial_rel_diff: float
    # "recurrence": p and q in data-orthonormal (Arnoldi) bases, as the fit stores them
    p_rec: Any = None  # ratfit.core.arnoldi.ArnoldiBasis
    q_rec: Any = None
    p_coef: Array | None = None
    q_coef: Array | None = None


@dataclass(frozen=True)
class FormCheck:
    """One channel's segments checked with the exported formula itself (float64, the
    generated code's operations in its order): ``met`` of ``total`` segments, the
    largest miss ``worst`` (0 when every one is met) and the smallest margin."""

    name: str
    met: int
    total: int
    worst: float
    min_margin: float
    source: str  # where the segments came from

    @property
    def ok(self) -> bool:
        return self.met == self.total

    def describe(self) -> str:
        if self.ok:
            return (f"channel {self.name}: the exported formula meets all {self.total} "
                    f"segments of {self.source} (smallest margin {self.min_margin:.3g})")
        return (f"channel {self.name}: the exported formula MISSES {self.total - self.met} of "
                f"{self.total} segments of {self.source}, worst by {self.worst:.3g}")


class UnverifiedExport(RatfitError):
    """The exported formula, evaluated as the generated code evaluates it, misses
    segments the fit met: the export is refused (exit 1 in the CLI)."""


@dataclass(frozen=True)
class ExportResult:
    text: str
    lang: str
    forms: tuple[ChannelForm, ...]
    parametrization: str | None
    checks: tuple[FormCheck, ...] = ()

    @property
    def success(self) -> bool:
        """True unless a checked channel misses a segment (such exports are refused)."""
        return all(c.ok for c in self.checks)

    @property
    def message(self) -> str:
        return "; ".join(self.describe())

    def describe(self) -> list[str]:
        """One line per channel: the form used and why, then the re-check (CLI output)."""
        return ([f"channel {f.name}: {f.form} ({f.reason})" for f in self.forms]
                + [c.describe() for c in self.checks])


# ---------------------------------------------------------------------------- planning
def _check_points(saved: SavedFit, points: ArrayLike | None, count: int = 2000) -> Array:
    dom = saved.space.domain
    rng = np.random.default_rng(12345)
    pts = dom[:, 0] + (dom[:, 1] - dom[:, 0]) * rng.random((count, dom.shape[0]))
    corners = np.array(np.meshgrid(*dom, indexing="ij")).reshape(dom.shape[0], -1).T
    pts = np.vstack([pts, corners])
    if points is not None:
        x = np.asarray(points, dtype=float)
        if x.ndim == 1:
            x = x[:, None]
        if x.ndim != 2 or x.shape[1] != dom.shape[0]:
            raise InputError(f"check points must have shape (N, {dom.shape[0]}), got {x.shape}")
        pts = np.vstack([pts, x])
    return pts


def _unverified(saved: SavedFit) -> list[str]:
    """Channels recorded as failed. An ALTA function file records nothing either way:
    it is exported with a header that says ratfit never verified it."""
    if getattr(saved, "integrity", "sealed") == "alta":
        return []
    return [c.name for c in saved.channels if c.summary.get("verified") is not True]


def plan_forms(
    saved: SavedFit, *, form: str = "auto", points: ArrayLike | None = None,
    rtol: float = HORNER_RTOL,
) -> tuple[ChannelForm, ...]:
    """Choose Horner or Clenshaw per channel (see the module docstring)."""
    from ratfit.core.monomial import to_monomial

    if form not in FORMS:
        raise InputError(f"unknown form {form!r}; choose one of {', '.join(FORMS)}")
    if getattr(saved.space, "variable", "x") != "x":
        raise InputError("code export of fits in log x is not supported yet "
                         "(ratfit eval and the Python API evaluate them)")
    bad = _unverified(saved)
    if bad:
        raise InputError(
            f"refusing to export unverified channel(s) {', '.join(bad)} "
            "(the fit file does not record a verified fit)"
        )
    space = saved.space
    pts = _check_points(saved, points)
    a, b = space._scale
    out = []
    for ch in saved.channels:
        rf = ch.rational
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", AccuracyWarning)
            mf = to_monomial(rf, pts, warn_rtol=np.inf)
        ref = rf(pts)
        with np.errstate(all="ignore"):
            err = pointwise_rel_diff(mf(pts), ref)
        horner_ok = err <= rtol
        if form == "horner" or (form == "auto" and horner_ok):
            reason = (f"monomial form differs from the fit by at most {err:.1e} relative, "
                      f"pointwise at {len(pts)} check points")
            if not horner_ok:
                reason += f", ABOVE the {rtol:.0e} accuracy target (forced by the user)"
            out.append(ChannelForm(ch.name, "horner", "power", np.array(mf.p), np.array(mf.q),
                                   None, None, reason, err))
        elif rf.p_basis is not None and rf.q_basis is not None and (
            form == "recurrence" or (form == "auto" and (fam_err := _family_error(rf, pts))
                                     > rtol)
        ):
            # The fit's own representation: the Arnoldi recurrence, evaluated as stored.
            why = ("chosen by the user" if form == "recurrence" else
                   f"monomial ({err:.1e}) and {space.family.name} "
                   f"({fam_err:.1e}) conversions lose accuracy")
            out.append(ChannelForm(
                ch.name, "recurrence", space.family.name, np.zeros(1), np.zeros(1),
                np.array(a), np.array(b), f"data-orthonormal recurrence, {why}", err,
                rf.p_basis, rf.q_basis, np.array(rf.p), np.array(rf.q)))
        else:
            if form == "recurrence":
                raise InputError(f"channel {ch.name!r} has no stored recurrence; use "
                                 "--form clenshaw or horner")
            fam = space.family.name
            why = ("chosen by the user" if form == "clenshaw" else
                   f"monomial conversion loses accuracy: {err:.1e} > {rtol:.0e}")
            if rf.orthonormal:
                why += (f"; {fam} coefficients differ from the fit by at most "
                        f"{_family_error(rf, pts):.1e} relative, pointwise at {len(pts)} "
                        "check points")
            rf = rf.to_family()
            out.append(ChannelForm(
                ch.name, "clenshaw", "power" if fam == "monomial" else fam,
                space.tensor_coef(rf.p), space.tensor_coef(rf.q), np.array(a), np.array(b),
                f"{fam} basis, {why}", err))
    return tuple(out)


def _family_error(rf: Any, pts: Array) -> float:
    """Max relative difference, on the check points, of the fit converted to its
    family's coefficients (exact for family fits, rounding-limited for Arnoldi)."""
    if not rf.orthonormal:
        return 0.0
    ref = rf(pts)
    with np.errstate(all="ignore"):
        return pointwise_rel_diff(rf.to_family()(pts), ref)


def pointwise_rel_diff(approx: ArrayLike, ref: ArrayLike) -> float:
    """max_i |approx_i - ref_i| / |ref_i|: the accuracy claim a header can make.

    At a point where r itself is (nearly) zero the relative difference is
    measured against 1e-12 max|r| instead (a zero is hit to rounding either way)."""
    a = np.asarray(approx, dtype=float).ravel()
    r = np.asarray(ref, dtype=float).ravel()
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(r))):
        return float("inf")
    if r.size == 0:
        return 0.0
    floor = 1e-12 * float(np.max(np.abs(r))) or np.finfo(float).tiny
    return float(np.max(np.abs(a - r) / np.maximum(np.abs(r), floor)))


def eval_forms(forms: tuple[ChannelForm, ...], x: ArrayLike) -> Array:
    """Values of the planned forms in float64, by the same operations in the same order as
    the generated C and Python (one IEEE operation at a time, no BLAS, no numpy series
    helper), so that they equal what the exported code computes bit for bit."""
    xa = np.asarray(x, dtype=float)
    if xa.ndim == 1:
        xa = xa[:, None]
    cols = []
    for f in forms:
        t = xa if f.scale is None or f.shift is None else xa * f.scale + f.shift
        with np.errstate(all="ignore"):
            if f.form == "recurrence":
                cols.append(f.p_rec.evaluate(t, f.p_coef, window=True)
                            / f.q_rec.evaluate(t, f.q_coef, window=True))
                continue
            cols.append(_tensor_series(f.P, f.family, t) / _tensor_series(f.Q, f.family, t))
    return np.stack(cols, axis=1)


def _tensor_series(T: Array, family: str, t: Array) -> Array:
    """The generated ``_poly_function``: the last axis first, row o of the flattened
    tensor summed as a series in that coordinate into w[o]."""
    npts = t.shape[0]
    w = np.broadcast_to(np.ravel(T), (npts, T.size))
    for k in range(T.ndim - 1, -1, -1):
        kk = int(T.shape[k])
        w = _series(np.reshape(w, (npts, -1, kk)), family, t[:, k, None])
    return np.asarray(w[:, 0])


def _series(a: Array, family: str, v: Array) -> Array:
    """The generated ``_series_lines``: a[..., i] summed as a series in v, per row."""
    n = a.shape[-1]
    if family == "power":
        s = np.zeros(a.shape[:-1])
        for i in range(n - 1, -1, -1):
            s = s * v + a[..., i]
        return s
    b1 = np.zeros(a.shape[:-1])
    b2 = np.zeros(a.shape[:-1])
    for i in range(n - 1, 0, -1):
        if family == "legendre":
            alpha, beta = (2.0 * i + 1.0) / (i + 1.0), (i + 1.0) / (i + 2.0)
        else:
            alpha, beta = 2.0, 1.0
        b0 = a[..., i] + alpha * v * b1 - beta * b2
        b2 = b1
        b1 = b0
    tail = 0.5 * b2 if family == "legendre" else b2
    return a[..., 0] + v * b1 - tail


def check_forms(forms: tuple[ChannelForm, ...], seg: Any, source: str) -> tuple[FormCheck, ...]:
    """Every segment of ``seg`` checked with the exported formula (:func:`eval_forms`),
    not with the fit's own evaluation: the verdict holds for the code the user runs."""
    if seg.n_channels != len(forms):
        raise InputError(f"{source} has {seg.n_channels} channel(s) but the fit has "
                         f"{len(forms)}")
    vals = np.concatenate([eval_forms(forms, seg.x[s:s + _CHECK_BLOCK])
                           for s in range(0, seg.n_points, _CHECK_BLOCK)])
    out = []
    for j, f in enumerate(forms):
        v = vals[:, j]
        with np.errstate(invalid="ignore"):
            signed = np.maximum(seg.lo[:, j] - v, v - seg.hi[:, j])
        signed = np.where(np.isfinite(v), signed, np.inf)
        worst = float(np.max(signed)) if signed.size else 0.0
        out.append(FormCheck(f.name, int(np.sum(signed <= 0)), int(signed.size),
                             max(worst, 0.0), -worst, source))
    return tuple(out)


_CHECK_BLOCK = 2048  # points per block of the check (n-D tensors broadcast per point)


# ---------------------------------------------------------------------------- languages
@dataclass(frozen=True)
class _Lang:
    name: str
    real: str
    comment: str

    def lit(self, v: float) -> str:
        if not math.isfinite(v):
            raise InputError(f"cannot export non-finite coefficient {v!r}")
        s = repr(float(v))
        return s


# Characters a comment may hold as they are: printable ASCII without the backslash (a C or
# GLSL line splice when it ends a line), "?" (C trigraphs), "*" (the end of a block comment)
# and "%" (the escape character below). Everything else is written as %XX of its UTF-8 bytes.
_COMMENT_SAFE = frozenset(
    chr(c) for c in range(0x20, 0x7F) if chr(c) not in "\\?*%"
)


def comment_text(text: str) -> str:
    """``text`` made inert inside a one-line comment of C, GLSL and Python.

    File names, channel names and every other string that came from a file reach the
    generated code only through here (or as a Python ``repr`` literal): a newline, a
    carriage return or a line splice in them would end the comment and turn the rest into
    code. Unsafe characters become %XX of their UTF-8 bytes (a lone surrogate from an
    undecodable file name too), so the comment still says what the name was.
    """
    out = []
    for ch in text:
        if ch in _COMMENT_SAFE:
            out.append(ch)
        else:
            out.extend(f"%{b:02X}" for b in ch.encode("utf-8", "surrogateescape"))
    return "".join(out)


_C = _Lang("c", "double", "//")
_GLSL = _Lang("glsl", "float", "//")
_PY = _Lang("python", "float", "#")


def _series_lines(lang: _Lang, family: str, arr: str, base: str, n: int, var: str,
                  dst: str, ind: str) -> list[str]:
    """Code summing arr[base .. base+n-1] as a series in ``var`` into ``dst``."""
    r = lang.real
    py = lang.name == "python"
    lines: list[str] = []
    if family == "power":
        if py:
            lines += ["s = 0.0",
                      f"for i in range({n - 1}, -1, -1):",
                      f"    s = s * {var} + {arr}[{base} + i]",
                      f"{dst} = s"]
        else:
            lines += [f"{r} s = 0.0;",
                      f"for (int i = {n - 1}; i >= 0; --i) s = s * {var} + {arr}[{base} + i];",
                      f"{dst} = s;"]
        return [ind + ln for ln in lines]
    if family == "legendre":
        # phi_{k+1} = (2k+1)/(k+1) t phi_k - k/(k+1) phi_{k-1}
        a_py = "(2.0 * i + 1.0) / (i + 1.0)"
        b_py = "(i + 1.0) / (i + 2.0)"
        a_c = f"{r}(2 * i + 1) / {r}(i + 1)"
        b_c = f"{r}(i + 1) / {r}(i + 2)"
        tail = "0.5 * b2"
    else:  # chebyshev: phi_{k+1} = 2 t phi_k - phi_{k-1}
        a_py = a_c = "2.0"
        b_py = b_c = "1.0"
        tail = "b2"
    if lang.name == "c":
        a_c = a_c.replace("double(", "(double)(")
        b_c = b_c.replace("double(", "(double)(")
    if py:
        lines += ["b1 = 0.0",
                  "b2 = 0.0",
                  f"for i in range({n - 1}, 0, -1):",
                  f"    b0 = {arr}[{base} + i] + {a_py} * {var} * b1 - {b_py} * b2",
                  "    b2 = b1",
                  "    b1 = b0",
                  f"{dst} = {arr}[{base}] + {var} * b1 - {tail}"]
    else:
        lines += [f"{r} b1 = 0.0, b2 = 0.0;",
                  f"for (int i = {n - 1}; i >= 1; --i) {{",
                  f"    {r} b0 = {arr}[{base} + i] + {a_c} * {var} * b1 - {b_c} * b2;",
                  "    b2 = b1;",
                  "    b1 = b0;",
                  "}",
                  f"{dst} = {arr}[{base}] + {var} * b1 - {tail};"]
    return [ind + ln for ln in lines]


def _array_decl(lang: _Lang, name: str, values: Array) -> list[str]:
    vals = [lang.lit(v) for v in np.ravel(values)]
    rows = [", ".join(vals[i:i + 4]) for i in range(0, len(vals), 4)]
    body = ",\n    ".join(rows)
    n = len(vals)
    if lang.name == "c":
        return [f"static const double {name}[{n}] = {{", f"    {body}", "};"]
    if lang.name == "glsl":
        return [f"const float {name}[{n}] = float[{n}](", f"    {body}", ");"]
    return [f"{name} = (", f"    {body},", ")"]


def _recurrence_function(lang: _Lang, fname: str, arr: str, basis: Any,
                         coef: Array) -> list[str]:
    """A function of t[0..d-1]: the Arnoldi recurrence phi_0 .. phi_{k-1}, then
    sum coef_i phi_i. Column i of H (rows 0..i) is packed at offset i (i + 1) / 2."""
    k = int(coef.size)
    H = basis.H
    packed = np.concatenate([H[: i + 1, i] for i in range(k)])
    par = [int(v) for v in basis.parents[:k]]
    dims = [int(v) for v in basis.dims[:k]]
    r = lang.real
    out = _array_decl(lang, f"{arr}_H", packed)
    out += _array_decl(lang, f"{arr}_C", coef)
    if lang.name == "python":
        out += [f"{arr}_PARENT = {tuple(par)!r}", f"{arr}_DIM = {tuple(dims)!r}", "", "",
                f"def {fname}(t):",
                f"    f = [0.0] * {k}",
                f"    f[0] = 1.0 / {arr}_H[0]",
                f"    s = {arr}_C[0] * f[0]",
                f"    for i in range(1, {k}):",
                "        off = i * (i + 1) // 2",
                f"        v = t[{arr}_DIM[i]] * f[{arr}_PARENT[i]]",
                "        for j in range(i):",
                f"            v -= {arr}_H[off + j] * f[j]",
                f"        f[i] = v / {arr}_H[off + i]",
                f"        s = s + {arr}_C[i] * f[i]",
                "    return s"]
        return out
    ints = ", ".join(str(v) for v in par)
    intd = ", ".join(str(v) for v in dims)
    if lang.name == "c":
        out += [f"static const int {arr}_PARENT[{k}] = {{{ints}}};",
                f"static const int {arr}_DIM[{k}] = {{{intd}}};",
                f"static double {fname}(const double *t)", "{"]
    else:
        out += [f"const int {arr}_PARENT[{k}] = int[{k}]({ints});",
                f"const int {arr}_DIM[{k}] = int[{k}]({intd});",
                f"float {fname}(float t[RATFIT_DIM])", "{"]
    out += [f"    {r} f[{k}];",
            f"    f[0] = 1.0 / {arr}_H[0];",
            f"    {r} s = {arr}_C[0] * f[0];",
            f"    for (int i = 1; i < {k}; ++i) {{",
            "        int off = i * (i + 1) / 2;",
            f"        {r} v = t[{arr}_DIM[i]] * f[{arr}_PARENT[i]];",
            f"        for (int j = 0; j < i; ++j) v -= {arr}_H[off + j] * f[j];",
            f"        f[i] = v / {arr}_H[off + i];",
            f"        s += {arr}_C[i] * f[i];",
            "    }", "    return s;", "}"]
    return out


def _poly_function(lang: _Lang, fname: str, arr: str, T: Array, family: str) -> list[str]:
    """A function of t[0..d-1] summing the tensor series T, last axis first."""
    K = T.shape
    d = len(K)
    r = lang.real
    py = lang.name == "python"
    out: list[str] = []
    if py:
        out.append(f"def {fname}(t):")
    elif lang.name == "c":
        out.append(f"static double {fname}(const double *t)")
        out.append("{")
    else:
        out.append(f"float {fname}(float t[RATFIT_DIM])")
        out.append("{")
    src = arr
    ind = "    "
    for k in range(d - 1, -1, -1):
        n_out = int(np.prod(K[:k])) if k > 0 else 1
        kk = int(K[k])
        dst_arr = f"w{k}"
        if py:
            out.append(f"{ind}{dst_arr} = [0.0] * {n_out}")
            out.append(f"{ind}for o in range({n_out}):")
        else:
            out.append(f"{ind}{r} {dst_arr}[{n_out}];")
            out.append(f"{ind}for (int o = 0; o < {n_out}; ++o) {{")
        out += _series_lines(lang, family, src, f"o * {kk}", kk, f"t[{k}]", f"{dst_arr}[o]",
                             ind + "    ")
        if not py:
            out.append(f"{ind}}}")
        src = dst_arr
    out.append(f"{ind}return {src}[0]" + ("" if py else ";"))
    if not py:
        out.append("}")
    return out


# ---------------------------------------------------------------------------- parametrizations
# Statements in a syntax shared by the three languages (helpers rf_* are defined in each
# prelude); they mirror ratfit.brdf.parametrizations. Inputs: unit lx, ly, lz, vx, vy, vz (z >= 0).
_RUSIN = [
    ("sx", "lx + vx"), ("sy", "ly + vy"), ("sz", "lz + vz"),
    ("sn", "rf_max(rf_sqrt(sx * sx + sy * sy + sz * sz), 1e-300)"),
    ("hx", "sx / sn"), ("hy", "sy / sn"), ("hz", "sz / sn"),
    ("th", "rf_atan2(rf_hypot(hx, hy), hz)"), ("ph", "rf_atan2(hy, hx)"),
    ("x1", "rf_cos(ph) * lx + rf_sin(ph) * ly"), ("y1", "rf_cos(ph) * ly - rf_sin(ph) * lx"),
    ("dx", "rf_cos(th) * x1 - rf_sin(th) * lz"), ("dy", "y1"),
    ("dz", "rf_sin(th) * x1 + rf_cos(th) * lz"),
    ("td", "rf_atan2(rf_hypot(dx, dy), dz)"), ("pd", "rf_atan2(dy, dx)"),
]
_ISO = [
    ("tl", "rf_atan2(rf_hypot(lx, ly), lz)"), ("tv", "rf_atan2(rf_hypot(vx, vy), vz)"),
    ("dphi", "rf_wrap(rf_atan2(ly, lx) - rf_atan2(vy, vx))"),
]
_RETRO = [
    ("al", "rf_atan2(ly, lx)"),
    ("wx", "rf_cos(al) * vx + rf_sin(al) * vy"), ("wy", "rf_cos(al) * vy - rf_sin(al) * vx"),
    ("wz", "vz"),
    ("tl", "rf_atan2(rf_hypot(lx, ly), lz)"), ("cl", "rf_cos(tl)"), ("sl", "rf_sin(tl)"),
    ("ex", "0.0 * wz - cl * wy"), ("ey", "cl * wx - sl * wz"), ("ez", "sl * wy"),
    ("dot", "sl * wx + cl * wz"),
    ("tvl", "rf_atan2(rf_sqrt(ex * ex + ey * ey + ez * ez), dot)"),
    ("qx", "wx - dot * sl"), ("qy", "wy"), ("qz", "wz - dot * cl"),
    ("phi", "rf_atan2(0.0 - qy, 0.0 - cl * qx + sl * qz)"),
]
def _swap_lv(stmts: list[tuple[str, str]]) -> list[tuple[str, str]]:
    """The same statements with the roles of L and V exchanged."""
    import re

    sw = {"lx": "vx", "ly": "vy", "lz": "vz", "vx": "lx", "vy": "ly", "vz": "lz"}
    pat = re.compile(r"\b(lx|ly|lz|vx|vy|vz)\b")
    return [(a, pat.sub(lambda mt: sw[mt.group(1)], b)) for a, b in stmts]


_PARAM_CODE: dict[str, tuple[list[tuple[str, str]], list[str]]] = {
    "CARTESIAN": ([], ["vx", "vy", "vz", "lx", "ly", "lz"]),
    "SPHERICAL_TL_PL_TV_PV": (
        [("tl", "rf_atan2(rf_hypot(lx, ly), lz)"), ("tv", "rf_atan2(rf_hypot(vx, vy), vz)")],
        ["tl", "rf_atan2(ly, lx)", "tv", "rf_atan2(vy, vx)"]),
    "RUSIN_TH_PH_TD_PD": (_RUSIN, ["th", "ph", "td", "pd"]),
    "RUSIN_VH_VD": (_RUSIN, ["hx", "hy", "hz", "dx", "dy", "dz"]),
    "RUSIN_TH_TD_PD": (_RUSIN, ["th", "td", "pd"]),
    "COS_TH_TD_PD": (_RUSIN, ["rf_cos(th)", "rf_cos(td)", "pd"]),
    "RUSIN_TH_TD_SYM": (_RUSIN, ["th", "td", "rf_sin(th) * rf_sin(th) * rf_cos(2.0 * pd)"]),
    "RUSIN_TH_TD_FOLD": (_RUSIN, ["th", "td", "rf_sin(th) * rf_cos(rf_fold(pd, th, td))"]),
    "ISOTROPIC_TV_TL_DPHI": (_ISO, ["tv", "tl", "dphi"]),
    "ISOTROPIC_TL_TV_PROJ_DPHI": (_ISO, ["tl", "tv * rf_cos(dphi)", "tv * rf_sin(dphi)"]),
    "RETRO_TL_TVL_PROJ_DPHI": (_RETRO, ["tl", "tvl * rf_cos(phi)", "tvl * rf_sin(phi)"]),
    # theta_v first: tl below is then V's elevation (statements with L and V exchanged)
    "RETRO_TV_TVL_PROJ_DPHI": (_swap_lv(_RETRO),
                               ["tl", "tvl * rf_cos(phi)", "tvl * rf_sin(phi)"]),
    "RUSIN_VH": (_RUSIN, ["hx", "hy", "hz"]),
    "ISOTROPIC_TV_TL": (_ISO, ["tv", "tl"]),
    "RUSIN_TH_TD": (_RUSIN, ["th", "td"]),
    "COS_TH_TD": (_RUSIN, ["rf_cos(th)", "rf_cos(td)"]),
    "STARK_2D": ([("hx", "0.5 * (lx + vx)"), ("hy", "0.5 * (ly + vy)"),
                  ("bx", "0.5 * (lx - vx)"), ("by", "0.5 * (ly - vy)"), ("bz", "0.5 * (lz - vz)")],
                 ["rf_hypot(hx, hy)", "rf_sqrt(bx * bx + by * by + bz * bz)"]),
    "RUSIN_TH": (_RUSIN, ["th"]),
    "COS_TH": (_RUSIN, ["rf_cos(th)"]),
}
SUPPORTED_PARAMETRIZATIONS = tuple(_PARAM_CODE)

_PRELUDE = {
    "c": f"""static inline double rf_max(double a, double b) {{ return a > b ? a : b; }}
static inline double rf_sqrt(double a) {{ return sqrt(a > 0.0 ? a : 0.0); }}
static inline double rf_hypot(double a, double b) {{ return hypot(a, b); }}
static inline double rf_atan2(double y, double x) {{ return atan2(y, x); }}
static inline double rf_cos(double a) {{ return cos(a); }}
static inline double rf_sin(double a) {{ return sin(a); }}
static inline double rf_wrap(double a)
{{
    double w = fmod(a + {_PI}, 2.0 * {_PI});
    if (w < 0.0) w += 2.0 * {_PI};
    w -= {_PI};
    return w == -{_PI} ? {_PI} : w;
}}
static inline double rf_fold(double a, double th, double td)
{{
    double w = fmod(a, {_PI});
    if (w < 0.0) w += {_PI};
    double dy = fabs(sin(td) * sin(w) * sin(th));
    return (w >= {_PI} || (w > 0.5 * {_PI} && dy <= {FOLD_SEAM_TOL!r})) ? 0.0 : w;
}}""",
    "glsl": f"""float rf_max(float a, float b) {{ return max(a, b); }}
float rf_sqrt(float a) {{ return sqrt(max(a, 0.0)); }}
float rf_hypot(float a, float b) {{ return sqrt(a * a + b * b); }}
float rf_atan2(float y, float x) {{ return (x == 0.0 && y == 0.0) ? 0.0 : atan(y, x); }}
float rf_cos(float a) {{ return cos(a); }}
float rf_sin(float a) {{ return sin(a); }}
float rf_wrap(float a)
{{
    float w = mod(a + {_PI}, 2.0 * {_PI}) - {_PI};
    return w == -{_PI} ? {_PI} : w;
}}
float rf_fold(float a, float th, float td)
{{
    float w = mod(a, {_PI});
    float dy = abs(sin(td) * sin(w) * sin(th));
    return (w >= {_PI} || (w > 0.5 * {_PI} && dy <= {FOLD_SEAM_TOL_F32!r})) ? 0.0 : w;
}}""",
    "python": f"""def rf_max(a, b):
    return a if a > b else b


def rf_sqrt(a):
    return math.sqrt(a if a > 0.0 else 0.0)


rf_hypot = math.hypot
rf_atan2 = math.atan2
rf_cos = math.cos
rf_sin = math.sin


def rf_wrap(a):
    w = math.fmod(a + {_PI}, 2.0 * {_PI})
    if w < 0.0:
        w += 2.0 * {_PI}
    w -= {_PI}
    return {_PI} if w == -{_PI} else w


def rf_fold(a, th, td):
    w = math.fmod(a, {_PI})
    if w < 0.0:
        w += {_PI}
    dy = abs(math.sin(td) * math.sin(w) * math.sin(th))
    return 0.0 if w >= {_PI} or (w > 0.5 * {_PI} and dy <= {FOLD_SEAM_TOL!r}) else w""",
}


def _param_lines(lang: _Lang, pname: str, prefix: str, nch: int, cosine: bool,
                 fold: bool, domain: Array) -> list[str]:
    stmts, outs = _PARAM_CODE[pname]
    if fold and pname == "RUSIN_TH_TD_PD":
        outs = [outs[0], outs[1], "rf_fold(pd, th, td)"]
    py = lang.name == "python"
    r = lang.real
    out: list[str] = []
    if py:
        out += [f"def {prefix}_coords(L, V):",
                f'    """Coordinates ({pname}) of unit directions L, V (normal +z)."""',
                "    ln = math.sqrt(L[0] * L[0] + L[1] * L[1] + L[2] * L[2])",
                "    vn = math.sqrt(V[0] * V[0] + V[1] * V[1] + V[2] * V[2])",
                "    lx, ly, lz = L[0] / ln, L[1] / ln, max(L[2] / ln, 0.0)",
                "    vx, vy, vz = V[0] / vn, V[1] / vn, max(V[2] / vn, 0.0)"]
        out += [f"    {v} = {e}" for v, e in stmts]
        out.append(f"    return [{', '.join(outs)}]")
        out += ["", ""]
    else:
        if lang.name == "c":
            out += [f"/* Coordinates ({pname}) of directions L, V (local frame, normal +z). */",
                    f"void {prefix}_coords(const double L[3], const double V[3], "
                    f"double x[RATFIT_DIM])", "{"]
        else:
            out += [f"// Coordinates ({pname}) of directions L, V (local frame, normal +z).",
                    f"void {prefix}_coords(vec3 L, vec3 V, out float x[RATFIT_DIM])", "{"]
        out += [f"    {r} ln = sqrt(L[0] * L[0] + L[1] * L[1] + L[2] * L[2]);",
                f"    {r} vn = sqrt(V[0] * V[0] + V[1] * V[1] + V[2] * V[2]);",
                f"    {r} lx = L[0] / ln, ly = L[1] / ln, lz = rf_max(L[2] / ln, 0.0);",
                f"    {r} vx = V[0] / vn, vy = V[1] / vn, vz = rf_max(V[2] / vn, 0.0);"]
        out += [f"    {r} {v} = {e};" for v, e in stmts]
        if stmts and lang.name == "c":  # not every intermediate is an output
            out.append("    " + " ".join(f"(void){v};" for v, _ in stmts))
        out += [f"    x[{i}] = {e};" for i, e in enumerate(outs)]
        out += ["}", ""]
    out += _brdf_lines(lang, pname, prefix, cosine, domain, is_folded(pname, fold))
    return out


#: :func:`~ratfit.brdf.parametrizations.reciprocal_order`'s test (V comes first), in
#: Python and in C / GLSL.
_PY_LATER = "V[2] > L[2] or (V[2] == L[2] and (V[0] > L[0] or (V[0] == L[0] and V[1] > L[1])))"
_C_LATER = "V[2] > L[2] || (V[2] == L[2] && (V[0] > L[0] || (V[0] == L[0] && V[1] > L[1])))"


def _brdf_lines(lang: _Lang, pname: str, prefix: str, cosine: bool,
                domain: Array, canon: bool = False) -> list[str]:
    """The BRDF at directions L, V by the one definition of
    :meth:`ratfit.brdf.fitter.BRDFFit.coords`: of the pair and its images (for all but
    full parametrizations the mirror y -> -y, then L <-> V and its mirror; for full
    ones L <-> V), the first nearest to the domain box, clipped into it; the fit's
    validity proof covers those points. ``canon`` (folded fits): the pair is first put
    in :func:`~ratfit.brdf.parametrizations.reciprocal_order`."""
    from ratfit.brdf.parametrizations import get_parametrization

    ncand = 2 if get_parametrization(pname).invariant == "full" else 4
    lo = ", ".join(lang.lit(v) for v in domain[:, 0])
    hi = ", ".join(lang.lit(v) for v in domain[:, 1])
    tol = lang.lit(1e-12 * (1.0 + float(np.abs(domain).max())))
    doc = "BRDF values (one per channel) for unit directions L, V above the horizon."
    if lang.name == "python":
        out = [f"def {prefix}_brdf(L, V):", f'    """{doc}"""',
               f"    lo = ({lo},)", f"    hi = ({hi},)",
               (f"    p, q = (V, L) if {_PY_LATER} else (L, V)" if canon else
                "    p, q = L, V"),
               "    lf, vf = (p[0], -p[1], p[2]), (q[0], -q[1], q[2])",
               "    best, gap = None, math.inf",
               ("    for a, b in ((p, q), (q, p)):" if ncand == 2 else
                "    for a, b in ((p, q), (lf, vf), (q, p), (vf, lf)):"),
               f"        x = {prefix}_coords(a, b)",
               "        g = 0.0",
               "        for i in range(RATFIT_DIM):",
               "            g += max(lo[i] - x[i], 0.0) + max(x[i] - hi[i], 0.0)",
               "            if x[i] != x[i]:",
               "                g = math.inf",
               f"        if best is None or g < gap - {tol}:",
               "            best, gap = x, g",
               "    x = [min(max(best[i], lo[i]), hi[i]) for i in range(RATFIT_DIM)]",
               f"    vals = {prefix}_eval(x)"]
        if cosine:
            out += ["    lz = L[2] / math.sqrt(L[0] * L[0] + L[1] * L[1] + L[2] * L[2])",
                    "    vals = [v / lz for v in vals]"]
        return out + ["    return vals"]
    c = lang.name == "c"
    r = lang.real
    big = "1e300" if c else "3.0e38"
    out = [f"/* {doc} */" if c else f"// {doc}",
           (f"void {prefix}_brdf(const double L[3], const double V[3], "
            "double out[RATFIT_NCHANNELS])") if c else
           f"void {prefix}_brdf(vec3 L, vec3 V, out float res[RATFIT_NCHANNELS])", "{"]
    if c:
        out += [f"    static const double lo[RATFIT_DIM] = {{{lo}}};",
                f"    static const double hi[RATFIT_DIM] = {{{hi}}};",
                "    double best[RATFIT_DIM], x[RATFIT_DIM], a[3], b[3], gap = 1e300;"]
    else:
        out += [f"    float lo[RATFIT_DIM] = float[RATFIT_DIM]({lo});",
                f"    float hi[RATFIT_DIM] = float[RATFIT_DIM]({hi});",
                "    float best[RATFIT_DIM]; float x[RATFIT_DIM]; vec3 a; vec3 b;",
                f"    float gap = {big};"]
    nan = "x[i] != x[i]" if c else "isnan(x[i])"
    out += [f"    for (int k = 0; k < {ncand}; ++k) {{",
            # images in BRDFFit.coords' order: (L, V), mirror, (V, L), its mirror (4);
            # (L, V), (V, L) (2)
            (f"        {r} s = (k % 2 == 1) ? -1.0 : 1.0;" if ncand == 4 else
             f"        {r} s = 1.0;"),
            f"        {'int' if c else 'bool'} swap = {'k >= 2' if ncand == 4 else 'k == 1'};",
            *([f"        if ({_C_LATER}) swap = !swap;"] if canon else []),
            "        for (int i = 0; i < 3; ++i) {",
            "            a[i] = swap ? V[i] : L[i];",
            "            b[i] = swap ? L[i] : V[i];",
            "        }",
            "        a[1] *= s;", "        b[1] *= s;",
            f"        {prefix}_coords(a, b, x);",
            f"        {r} g = 0.0;",
            "        for (int i = 0; i < RATFIT_DIM; ++i) {",
            f"            {r} below = lo[i] - x[i], above = x[i] - hi[i];",
            "            g += (below > 0.0 ? below : 0.0) + (above > 0.0 ? above : 0.0);",
            f"            if ({nan}) g = {big};",
            "        }",
            f"        if (k == 0 || g < gap - {tol}) {{",
            "            gap = g;",
            "            for (int i = 0; i < RATFIT_DIM; ++i) best[i] = x[i];",
            "        }",
            "    }",
            "    for (int i = 0; i < RATFIT_DIM; ++i)",
            "        best[i] = best[i] < lo[i] ? lo[i] : (best[i] > hi[i] ? hi[i] : best[i]);"]
    dst = "out" if c else "res"
    out.append(f"    {prefix}_eval(best, {dst});")
    if cosine:
        if c:
            out += ["    double lz = L[2] / sqrt(L[0] * L[0] + L[1] * L[1] + L[2] * L[2]);",
                    "    for (int j = 0; j < RATFIT_NCHANNELS; ++j) out[j] /= lz;"]
        else:
            out += ["    float lz = normalize(L).z;",
                    "    for (int j = 0; j < RATFIT_NCHANNELS; ++j) res[j] /= lz;"]
    return out + ["}"]


# ---------------------------------------------------------------------------- assembly
def _ident(s: str) -> bool:
    return s.isidentifier() and s.isascii()


def export_source(
    saved: SavedFit, lang: str, *, parametrization: str | None = None, form: str = "auto",
    points: ArrayLike | None = None, prefix: str = "ratfit", source: str = "",
    rtol: float = HORNER_RTOL, cosine_weighted: bool = False, fold_phi_d: bool = False,
    segments: Any = None, segments_source: str = "the data", log_values: bool = False,
) -> ExportResult:
    """Source text of ``saved`` in ``lang`` (c, glsl, python).

    C and Python use double precision; GLSL uses float (the usual shader type),
    so expect single-precision rounding there. ``cosine_weighted``: the fit models
    f cos(theta_l), so *_brdf divides by L.z; ``fold_phi_d``: phi_d is folded into
    [0, pi) before evaluation (MERL tables), as :class:`ratfit.brdf.fitter.BRDFFit` does;
    ``log_values``: each channel's value is exp(p / q) (a BRDF fit of log values).

    ``segments`` (:class:`~ratfit.core.segments.Segments` in the fit's variables): every
    one is checked with the exported formula as the C/Python code evaluates it
    (:func:`check_forms`); if one is missed the export is refused with
    :class:`UnverifiedExport`. The header says which check was made.
    """
    from ratfit._version import __version__

    lang_key = str(lang).lower()
    if lang_key not in LANGS:
        raise InputError(f"unknown language {lang!r}; choose one of {', '.join(LANGS)}")
    if not _ident(prefix) or prefix.startswith("_"):
        raise InputError(f"prefix {prefix!r} is not a valid identifier")
    pname = None
    if parametrization is not None:
        pname = str(getattr(parametrization, "name", parametrization)).upper()
        if pname not in _PARAM_CODE:
            raise InputError(
                f"export of parametrization {pname!r} is not supported; supported: "
                f"{', '.join(_PARAM_CODE)}"
            )
        pdim = len(_PARAM_CODE[pname][1])
        if pdim != saved.space.dim:
            raise InputError(f"parametrization {pname} has {pdim} coordinates but the fit has "
                             f"{saved.space.dim} input dimension(s)")
    forms = plan_forms(saved, form=form, points=points, rtol=rtol)
    checks: tuple[FormCheck, ...] = ()
    if segments is not None and lang_key != "glsl":
        if log_values:
            raise InputError("the segments of a fit of log values are checked on exp(p / q): "
                             "not in the exported form yet")
        checks = check_forms(forms, segments, segments_source)
        bad = [c for c in checks if not c.ok]
        # An edited or legacy file exported with --trust-edited is NOT VERIFIED anyway (the
        # header says so, with the check's result); a sealed verified fit is refused.
        if bad and getattr(saved, "integrity", "sealed") == "sealed":
            raise UnverifiedExport(
                "; ".join(c.describe() for c in bad) + f" (evaluated as the exported {lang_key} "
                "code evaluates it, float64): export refused, no file written; try "
                "another --form or a fit with more margin")
    lg = {"c": _C, "glsl": _GLSL, "python": _PY}[lang_key]
    d, k = saved.space.dim, len(forms)
    cm = lg.comment
    head = [
        f"{cm} Generated by ratfit {__version__} from {source or 'a fit file'}.",
        f"{cm} Rational fit: {k} channel(s) of {d} variable(s); basis "
        f"{saved.space.family.name}, domain {saved.space.domain.tolist()}.",
        f"{cm} {_validity(saved)}",
    ]
    for f in forms:
        head.append(f"{cm} channel {f.name!r}: {f.form} ({f.reason}).")
    if log_values:
        head.append(f"{cm} Each channel's value is exp(p / q): p / q fits the logarithm of "
                    "the values (positive by construction).")
    head += [f"{cm} {line}" for line in _exactness_lines(lang_key, forms, checks,
                                                                 log_values)]
    if pname:
        head.append(f"{cm} Input coordinates: {pname}, computed from directions by the "
                    "coords function.")
    if lang_key == "glsl":
        head.append(f"{cm} GLSL 3.30+; float precision. Include in a shader (no #version here).")
    lines = [cm + " " + comment_text(h[len(cm) + 1:]) for h in head]
    lines.append("")
    py = lang_key == "python"
    if py:
        lines += ['"""ratfit export (see the comments above)."""', "", "import math", "",
                  f"RATFIT_DIM = {d}", f"RATFIT_NCHANNELS = {k}",
                  f"CHANNELS = {ascii(tuple(f.name for f in forms))}", ""]
    elif lang_key == "c":
        lines += ["#include <math.h>", "", *_C_EXACT, "", f"#define RATFIT_DIM {d}",
                  f"#define RATFIT_NCHANNELS {k}", ""]
    else:
        lines += [f"#define RATFIT_DIM {d}", f"#define RATFIT_NCHANNELS {k}", ""]
    if pname:
        lines += _PRELUDE[lang_key].splitlines()
        lines += ["", ""] if py else [""]
    for j, f in enumerate(forms):
        for tag, T in (("p", f.P), ("q", f.Q)):
            arr = f"{prefix.upper()}_{tag.upper()}{j}"
            if f.form == "recurrence":
                basis, coef = (f.p_rec, f.p_coef) if tag == "p" else (f.q_rec, f.q_coef)
                assert coef is not None  # a recurrence form always carries its coefficients
                lines += _recurrence_function(lg, f"{prefix}_{tag}{j}", arr, basis, coef)
                lines += ["", ""] if py else [""]
                continue
            lines += _array_decl(lg, arr, T)
            lines += ["", ""] if py else [""]
            lines += _poly_function(lg, f"{prefix}_{tag}{j}", arr, T, f.family)
            lines += ["", ""] if py else [""]
    # the evaluator
    r = lg.real
    if py:
        lines += [f"def {prefix}_eval(x):",
                  f'    """Values of the {k} channel(s) at a point x (sequence of {d})."""',
                  "    out = []"]
    elif lang_key == "c":
        lines += [f"/* Values of the {k} channel(s) at a point x in the fit's variables. */",
                  f"void {prefix}_eval(const double x[RATFIT_DIM], double out[RATFIT_NCHANNELS])",
                  "{", "    double t[RATFIT_DIM];"]
    else:
        lines += [f"// Values of the {k} channel(s) at a point x in the fit's variables.",
                  f"void {prefix}_eval(float x[RATFIT_DIM], out float res[RATFIT_NCHANNELS])",
                  "{", "    float t[RATFIT_DIM];"]
    dst = "res" if lang_key == "glsl" else "out"
    for j, f in enumerate(forms):
        if py:
            if f.scale is None or f.shift is None:
                lines.append("    t = list(x)")
            else:
                terms = ", ".join(f"{lg.lit(f.scale[i])} * x[{i}] + {lg.lit(f.shift[i])}"
                                  for i in range(d))
                lines.append(f"    t = [{terms}]")
            ratio = f"{prefix}_p{j}(t) / {prefix}_q{j}(t)"
            lines.append(f"    out.append(math.exp({ratio}))" if log_values else
                         f"    out.append({ratio})")
        else:
            for i in range(d):
                if f.scale is None or f.shift is None:
                    lines.append(f"    t[{i}] = x[{i}];")
                else:
                    lines.append(f"    t[{i}] = {lg.lit(f.scale[i])} * x[{i}] + "
                                 f"{lg.lit(f.shift[i])};")
            ratio = f"{prefix}_p{j}(t) / {prefix}_q{j}(t)"
            lines.append(f"    {dst}[{j}] = exp({ratio});" if log_values else
                         f"    {dst}[{j}] = {ratio};")
    lines += ["    return out"] if py else ["}"]
    if pname:
        lines += ["", ""] if py else [""]
        lines += _param_lines(lg, pname, prefix, k, cosine_weighted, fold_phi_d,
                              np.asarray(saved.space.domain, dtype=float))
    del r
    text = "\n".join(lines).rstrip() + "\n"
    return ExportResult(text, lang_key, forms, pname, checks)


# The checked values are those of IEEE double arithmetic performed as written: a
# compiler that fuses a * b + c into one FMA, or reorders (-ffast-math), rounds
# differently, and the recurrence can amplify that difference by ~1e12.
_C_EXACT = [
    "/* The operations below are the ones ratfit checked, in this order: build without",
    "   -ffast-math and without FMA contraction (gcc/clang: -ffp-contract=off). */",
    "#if defined(__FAST_MATH__) && !defined(RATFIT_ALLOW_FAST_MATH)",
    "#error \"ratfit export: -ffast-math reorders the checked arithmetic (define "
    "RATFIT_ALLOW_FAST_MATH to build an unchecked variant)\"",
    "#endif",
    "#if defined(__clang__)",
    "#pragma STDC FP_CONTRACT OFF",
    "#elif defined(__GNUC__)",
    "#pragma GCC optimize (\"fp-contract=off\")",
    "#endif",
]


def _exactness_lines(lang: str, forms: tuple[ChannelForm, ...],
                     checks: tuple[FormCheck, ...], log_values: bool = False) -> list[str]:
    """What the header may claim about the exported formula itself."""
    if lang == "glsl":
        return ["NOT CHECKED in this form: GLSL evaluates in float precision (and GPUs "
                "fuse multiply-adds), so values differ from the verified float64 ones; "
                "the C and Python exports are checked."]
    out = []
    for c in checks:
        out.append(("Checked: " if c.ok else "NOT VERIFIED: ") + c.describe() +
                   " (float64, this code's operations in this order).")
    if not checks:
        same = [f.name for f in forms if f.form == "recurrence"]
        if same:
            out.append(f"Channel(s) {', '.join(same)}: the same operations in the same order "
                       "as ratfit's own evaluation" + (
                           " (p / q bit for bit; then exp, which the C library and numpy "
                           "may round differently in the last bit)." if log_values else
                           " (equal to ratfit eval bit for bit)."))
        out.append("Segments NOT re-checked with this formula (no data at export; "
                   "`ratfit export --data` checks every one).")
    return out


def _validity(saved: SavedFit) -> str:
    """The header's claim: "verified" only for an unedited file that records a verified fit."""
    integrity = getattr(saved, "integrity", "sealed")
    if integrity == "edited":
        return ("NOT VERIFIED: the fit file was edited after ratfit wrote it (its digest does "
                "not match); nothing is known about this function's accuracy or poles.")
    if integrity == "alta":
        return ("NOT VERIFIED: an ALTA function file; ratfit copied its coefficients and "
                "checked nothing about its accuracy or poles. Domain as above.")
    if integrity == "legacy":
        return ("NOT VERIFIED: an old fit file without a content digest (cannot be told from "
                "an edited one); refit to get a verified one. Domain as above.")
    from ratfit.brdf.validity import reprove_saved
    from ratfit.io.fitfile import scope_text

    return "Valid on that domain only. " + scope_text(saved, reprove_saved(saved))


def load_any_fit(path: str | os.PathLike[str]) -> tuple[SavedFit, Any]:
    """A saved fit and its :class:`~ratfit.brdf.fitter.BRDFFit` (None for a `ratfit fit` file)."""
    from ratfit.io.fitfile import load_fit

    saved = load_fit(path)
    if isinstance(getattr(saved, "extra", {}).get("brdf"), dict):
        from ratfit.brdf.fitter import load_brdf_fit

        return saved, load_brdf_fit(path)
    if saved.integrity == "alta":
        from ratfit.brdf.fitter import alta_brdf_fit

        bf = alta_brdf_fit(saved)
        if bf is not None:
            return bf.saved, bf
    return saved, None


def export_fit(
    fit_path: str | os.PathLike[str], lang: str, output: str | os.PathLike[str], *,
    form: str = "auto", prefix: str = "ratfit", points: ArrayLike | None = None,
    data: str | os.PathLike[str] | None = None,
) -> ExportResult:
    """Read a fit file, generate its source and write it atomically to ``output``.

    The segments are checked with the exported formula on ``data`` (a data file, read
    with the widths the fit file records), else on the fit's own input file when it is
    still there unchanged (same sha256); a missed segment raises
    :class:`UnverifiedExport` and nothing is written."""
    saved, bf = load_any_fit(fit_path)
    seg, src = _export_segments(saved, bf, fit_path, data)
    res = export_source(saved, lang, parametrization=None if bf is None else bf.parametrization,
                        cosine_weighted=bool(getattr(bf, "cosine_weighted", False)),
                        fold_phi_d=bool(getattr(bf, "fold_phi_d", False)), form=form,
                        log_values=saved.values == "log",
                        points=points, prefix=prefix, source=Path(fit_path).name,
                        segments=seg, segments_source=src)
    with atomic_open(output, "w") as fh:
        fh.write(res.text)
    return res


def _export_segments(saved: SavedFit, bf: Any, fit_path: str | os.PathLike[str],
                     data: str | os.PathLike[str] | None) -> tuple[Any, str]:
    """(segments, where from) for the export's check; (None, "") when there is no data."""
    from ratfit.io.fitfile import file_sha256

    if data is None:
        prov = saved.provenance if isinstance(saved.provenance, dict) else {}
        path, sha = prov.get("input"), prov.get("input_sha256")
        if bf is not None or not isinstance(path, str) or not isinstance(sha, str):
            return None, ""
        try:
            if not Path(path).is_file() or file_sha256(path) != sha:
                return None, ""
            seg = _data_segments(saved, bf, path)
        except (OSError, RatfitError):
            return None, ""
        return (None, "") if seg is None else (seg, f"the fit's input {Path(path).name}")
    seg = _data_segments(saved, bf, data)
    if seg is None:
        raise InputError(f"{data}: cannot rebuild the fit's segments on this data (the fit "
                         "file records no widths and the file has no bounds)")
    return seg, Path(data).name


def _data_segments(saved: SavedFit, bf: Any, path: str | os.PathLike[str]) -> Any:
    """The segments the fit file's widths give on a data file; None when they cannot be
    rebuilt."""
    if bf is not None:
        raise InputError("export --data checks fits from `ratfit fit`; a BRDF fit's segments "
                         "live in its coordinates after dropped columns and symmetry images "
                         "(not checked in the exported form yet: the header says so)")
    from ratfit.io.data import read_data
    from ratfit.io.fitfile import recorded_segments

    ds = read_data(path)
    if ds.dim != saved.space.dim:
        raise InputError(f"{path} has {ds.dim} input dimension(s) but the fit has "
                         f"{saved.space.dim}")
    seg = recorded_segments(saved, ds)
    if seg is not None and seg.n_channels != len(saved.channels):
        raise InputError(f"{path} has {seg.n_channels} channel(s) but the fit has "
                         f"{len(saved.channels)}")
    return seg
