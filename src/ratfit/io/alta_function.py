"""ALTA interoperability: fitted-function files (read, evaluate, write) and data files.

An ALTA function file has a header (``#ALTA FUNC HEADER`` ... ``#ALTA HEADER
END``: ``#CMD``, ``#DIM nx ny``, ``#PARAM_IN``) and ``#FUNC`` blocks. A
``rational_function`` block gives ``#MIN``/``#MAX`` of the input domain (mapped
to [-1, 1]^nx before evaluation), then per output channel ``#NP``/``#NQ`` and
NP + NQ lines "i_1 .. i_nx coefficient" (the multi-index of a product of 1-D
basis polynomials). The basis is monomial unless the command line used
ALTA's Chebyshev (or Legendre) rational plugin. The ``nonlinear_function_diffuse``
and ``nonlinear_function_blinn`` blocks (kd; Ks, N per channel) are summed.

Checked: ``alta/fits/Kirby2.brdf`` gives RMS 0.0279415 and Linf 0.27124 on
``alta/Kirby2.dat``, the numbers in its ``#CMD`` line.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.polynomial import chebyshev as _cheb
from numpy.polynomial import legendre as _leg
from numpy.polynomial import polynomial as _poly
from numpy.typing import ArrayLike, NDArray

from ratfit._atomic import atomic_open
from ratfit.errors import FileFormatError, InputError
from ratfit.io.data import Dataset, write_alta

if TYPE_CHECKING:
    from ratfit.core.bases import PolynomialSpace
    from ratfit.io.fitfile import SavedFit

__all__ = ["ALTAFunction", "RationalBlock", "read_alta_function", "write_alta_data",
           "write_alta_function"]

Array = NDArray[np.float64]
_VANDER = {"monomial": _poly.polyvander, "chebyshev": _cheb.chebvander,
           "legendre": _leg.legvander}
_PLUGIN = {"monomial": "rational_function", "chebyshev": "rational_function_chebychev",
           "legendre": "rational_function_legendre"}


@dataclass(frozen=True)
class RationalBlock:
    """One channel of an ALTA rational function: p / q with explicit multi-indices."""

    p_idx: NDArray[np.int64]
    p: Array
    q_idx: NDArray[np.int64]
    q: Array


@dataclass(frozen=True)
class ALTAFunction:
    """A parsed ALTA function file; call it on points (N, nx) for values (N, ny)."""

    nx: int
    ny: int
    param_in: str
    cmd: str
    basis: str
    lo: Array | None = None
    hi: Array | None = None
    rational: tuple[RationalBlock, ...] = ()
    diffuse: Array | None = None
    blinn: tuple[tuple[float, float], ...] = ()
    source: str = "alta"
    metrics: dict[str, float] = field(default_factory=dict)

    def __call__(self, x: ArrayLike) -> Array:
        xa = np.asarray(x, dtype=float)
        if xa.ndim == 1:
            xa = xa[:, None] if self.nx == 1 else xa[None, :]
        if xa.ndim != 2 or xa.shape[1] != self.nx:
            raise InputError(f"{self.source}: points must have shape (N, {self.nx})")
        out = np.zeros((xa.shape[0], self.ny))
        if self.rational:
            assert self.lo is not None and self.hi is not None
            t = 2.0 * (xa - self.lo) / (self.hi - self.lo) - 1.0
            deg = max(int(max(b.p_idx.max(), b.q_idx.max())) for b in self.rational)
            vs: list[Array] = [np.asarray(_VANDER[self.basis](t[:, k], deg), dtype=np.float64)
                               for k in range(self.nx)]
            for j, b in enumerate(self.rational):
                with np.errstate(divide="ignore", invalid="ignore"):
                    out[:, j] += _poly_val(vs, b.p_idx, b.p) / _poly_val(vs, b.q_idx, b.q)
        if self.diffuse is not None:
            out += self.diffuse[None, :]
        if self.blinn:
            if self.nx != 6:
                raise InputError(f"{self.source}: the Blinn lobe needs CARTESIAN input (6-D)")
            h = xa[:, :3] + xa[:, 3:]
            hz = h[:, 2] / np.linalg.norm(h, axis=1)
            for j, (ks, n) in enumerate(self.blinn):
                out[:, j] += ks * np.power(np.clip(hz, 0.0, None), n)
        return out


    def to_saved_fit(self) -> SavedFit:
        """This rational function as a :class:`~ratfit.io.fitfile.SavedFit`: what
        :func:`~ratfit.io.fitfile.load_fit` returns for an ALTA file, so ``eval``,
        ``export``, ``plot`` and ``report`` take ALTA fits as they take ratfit's.

        ALTA maps ``#MIN``/``#MAX`` to [-1, 1] as ratfit maps its domain, so the
        coefficients go over unchanged (placed at their multi-indices in ratfit's
        graded order, zeros between). The result is marked ``integrity="alta"``:
        ratfit holds no verification record for it (``verified`` is False).
        ``provenance["param_in"]`` keeps ``#PARAM_IN``: where it names a ratfit BRDF
        parametrization of the same dimension,
        :func:`ratfit.export.code.load_any_fit` makes it a BRDF fit.
        """
        from ratfit.core.bases import PolynomialSpace
        from ratfit.core.rational import RationalFunction
        from ratfit.io.fitfile import SavedChannel, SavedFit

        if not self.rational or self.diffuse is not None or self.blinn:
            kinds = [k for k, have in (("rational", bool(self.rational)),
                                       ("diffuse", self.diffuse is not None),
                                       ("Blinn", bool(self.blinn))) if have]
            raise FileFormatError(
                f"{self.source}: an ALTA {' + '.join(kinds)} function; ratfit commands take "
                "ALTA rational functions only (ratfit.io.alta_function.read_alta_function "
                "evaluates the others in Python)")
        assert self.lo is not None and self.hi is not None
        space = PolynomialSpace(self.basis, np.stack([self.lo, self.hi], axis=1))
        channels = []
        for j, b in enumerate(self.rational):
            p, q = _graded(space, b.p_idx, b.p), _graded(space, b.q_idx, b.q)
            summary: dict[str, object] = {"verified": False, "source": "ALTA"}
            summary.update({f"alta_{k}": v for k, v in self.metrics.items()})
            channels.append(SavedChannel(f"y{j}", RationalFunction(space, p, q), summary,
                                         None))
        prov = {"source": "ALTA function file", "alta_cmd": self.cmd,
                "param_in": self.param_in}
        return SavedFit(space, tuple(channels), prov, 0, {}, integrity="alta")


def _graded(space: PolynomialSpace, idx: NDArray[np.int64], coef: Array) -> Array:
    """Coefficients at ALTA's multi-indices ``idx`` placed in ``space``'s graded order."""
    count = _total_count(space.dim, int(idx.sum(axis=1).max()))
    order = {tuple(int(v) for v in row): i for i, row in enumerate(space.indices(count))}
    out = np.zeros(count)
    for row, c in zip(idx.tolist(), coef, strict=True):
        out[order[tuple(row)]] += float(c)
    last = int(np.flatnonzero(out)[-1]) + 1 if np.any(out) else 1
    return out[:last]


def _total_count(dim: int, degree: int) -> int:
    """Multi-indices in ``dim`` variables of total degree <= ``degree``."""
    from math import comb

    return comb(degree + dim, dim)


def _poly_val(vs: list[Array], idx: NDArray[np.int64], coef: Array) -> Array:
    b = vs[0][:, idx[:, 0]].copy()
    for k in range(1, len(vs)):
        b *= vs[k][:, idx[:, k]]
    return b @ coef


def read_alta_function(path: str | os.PathLike[str], *, basis: str | None = None) -> ALTAFunction:
    """Parse an ALTA function file (rational, diffuse and Blinn blocks)."""
    src = str(path)
    p = Path(path)
    if not p.is_file():
        raise FileFormatError(f"{src}: no such file")
    try:
        text = p.read_text()
    except UnicodeDecodeError:
        raise FileFormatError(f"{src}: not a text file") from None
    lines = [(n, s.strip()) for n, s in enumerate(text.splitlines(), start=1)]
    if not any(s.startswith("#ALTA FUNC HEADER") for _, s in lines[:3]):
        raise FileFormatError(f"{src}: no '#ALTA FUNC HEADER' line: not an ALTA function file")
    nx = ny = None
    param_in, cmd = "UNKNOWN_INPUT", ""
    i = 0
    while i < len(lines):
        n, s = lines[i]
        i += 1
        if s.startswith("#ALTA HEADER END"):
            break
        parts = s[1:].split() if s.startswith("#") else []
        if parts and parts[0] == "DIM":
            try:
                nx, ny = int(parts[1]), int(parts[2])
            except (IndexError, ValueError):
                raise FileFormatError(f"{src} line {n}: malformed #DIM {s!r}") from None
        elif parts and parts[0] == "PARAM_IN":
            param_in = " ".join(parts[1:])
        elif parts and parts[0] == "CMD":
            cmd = " ".join(parts[1:])
    else:
        raise FileFormatError(f"{src}: no '#ALTA HEADER END' line")
    if nx is None or ny is None or nx < 1 or ny < 1:
        raise FileFormatError(f"{src}: missing or bad '#DIM nx ny' in the header")
    if basis is None:
        low = cmd.lower()
        basis = ("chebyshev" if "chebychev" in low or "chebyshev" in low
                 else "legendre" if "legendre" in low else "monomial")
    if basis not in _VANDER:
        raise InputError(f"unknown ALTA basis {basis!r}; choose {', '.join(_VANDER)}")
    metrics = {}
    for key in ("L2", "Linf"):
        m = re.search(rf"--{key}\s+(\S+)", cmd)
        if m:
            try:
                metrics[key] = float(m.group(1))
            except ValueError:
                pass
    lo = hi = None
    blocks: list[RationalBlock] = []
    diffuse: list[float] = []
    blinn: list[float] = []
    func = None
    np_ = nq = None
    rows: list[tuple[int, list[str]]] = []

    def flush() -> None:
        nonlocal np_, nq, rows
        if func == "rational_function" and np_ is not None:
            if len(rows) != np_ + nq:
                raise FileFormatError(
                    f"{src}: channel {len(blocks)}: #NP {np_} + #NQ {nq} coefficients announced, "
                    f"{len(rows)} given (truncated file?)"
                )
            idx = np.array([[int(t) for t in r[:-1]] for _, r in rows], dtype=np.int64)
            coef = np.array([float(r[-1]) for _, r in rows])
            blocks.append(RationalBlock(idx[:np_], coef[:np_], idx[np_:], coef[np_:]))
        np_ = nq = None
        rows = []

    for n, s in lines[i:]:
        if not s:
            continue
        if s.startswith("#"):
            parts = s[1:].split()
            key = parts[0] if parts else ""
            if key == "FUNC":
                flush()
                func = parts[1] if len(parts) > 1 else ""
            elif key in ("MIN", "MAX"):
                vals = _nums(src, n, parts[1:], nx, key)
                lo, hi = (vals, hi) if key == "MIN" else (lo, vals)
            elif key == "NP":
                flush()
                np_ = _count(src, n, parts)
            elif key == "NQ":
                nq = _count(src, n, parts)
            continue
        t = s.split()
        if func == "rational_function":
            if np_ is None or nq is None:
                raise FileFormatError(f"{src} line {n}: coefficient before #NP/#NQ")
            if len(t) != nx + 1:
                raise FileFormatError(
                    f"{src} line {n}: expected {nx} indices and a coefficient, got {len(t)} values"
                )
            try:
                [int(v) for v in t[:-1]]
                float(t[-1])
            except ValueError:
                raise FileFormatError(f"{src} line {n}: malformed coefficient line {s!r}") from None
            rows.append((n, t))
        elif func == "nonlinear_function_diffuse":
            diffuse.append(_nums(src, n, t[1:2], 1, "kd")[0])
        elif func == "nonlinear_function_blinn":
            blinn.append(_nums(src, n, t[1:2], 1, t[0])[0])
        else:
            raise FileFormatError(f"{src} line {n}: unsupported ALTA function block {func!r}")
    flush()
    if func is None:
        raise FileFormatError(f"{src}: no #FUNC block")
    if blocks:
        if len(blocks) != ny:
            raise FileFormatError(f"{src}: #DIM says {ny} channel(s), {len(blocks)} given")
        if lo is None or hi is None or np.any(hi <= lo):
            raise FileFormatError(f"{src}: a rational function needs #MIN < #MAX")
    if diffuse and len(diffuse) != ny:
        raise FileFormatError(f"{src}: {len(diffuse)} diffuse value(s) for {ny} channel(s)")
    if blinn and len(blinn) != 2 * ny:
        raise FileFormatError(f"{src}: Blinn lobe needs Ks and N for each of {ny} channel(s)")
    return ALTAFunction(
        nx, ny, param_in, cmd, basis, lo, hi, tuple(blocks),
        np.array(diffuse) if diffuse else None,
        tuple((blinn[2 * j], blinn[2 * j + 1]) for j in range(len(blinn) // 2)),
        src, metrics,
    )


def _nums(src: str, n: int, toks: list[str], count: int, what: str) -> Array:
    try:
        vals = np.array([float(v) for v in toks])
    except ValueError:
        raise FileFormatError(f"{src} line {n}: malformed #{what} values") from None
    if vals.size != count or not np.all(np.isfinite(vals)):
        raise FileFormatError(f"{src} line {n}: #{what} needs {count} finite number(s)")
    return vals


def _count(src: str, n: int, parts: list[str]) -> int:
    try:
        v = int(parts[1])
    except (IndexError, ValueError):
        raise FileFormatError(f"{src} line {n}: malformed #{parts[0]} line") from None
    if v < 1:
        raise FileFormatError(f"{src} line {n}: #{parts[0]} must be >= 1")
    return v


def write_alta_function(path: str | os.PathLike[str], saved, *, param_in: str = "UNKNOWN_INPUT",
                        cmd: str = "") -> None:
    """Write a ratfit fit (a :class:`ratfit.io.fitfile.SavedFit`) as an ALTA function file.

    ALTA maps ``#MIN``/``#MAX`` to [-1, 1] like ratfit's domain, so coefficients
    are copied as they are; the basis is named in ``#CMD`` (``--func``) because
    ALTA picks its evaluation plugin from the command line.
    """
    space = saved.space
    basis = space.family.name
    lo, hi = space.domain[:, 0], space.domain[:, 1]
    fmt = "{:.17g}".format
    out = ["#ALTA FUNC HEADER",
           f"#CMD --func {_PLUGIN[basis]} {cmd}".rstrip(),
           f"#DIM {space.dim} {len(saved.channels)}",
           f"#PARAM_IN {param_in}",
           "#ALTA HEADER END", "",
           "#FUNC rational_function",
           "#MIN " + " ".join(fmt(v) for v in lo),
           "#MAX " + " ".join(fmt(v) for v in hi)]
    for ch in saved.channels:
        # Fits held in data-orthonormal bases are converted to the family first.
        rf = ch.rational.to_family() if hasattr(ch.rational, "to_family") else ch.rational
        out += [f"#NP {rf.n}", f"#NQ {rf.m}"]
        for idx, coef in ((space.indices(rf.n), rf.p), (space.indices(rf.m), rf.q)):
            out += [" ".join(str(int(v)) for v in row) + "\t" + fmt(c)
                    for row, c in zip(idx, coef, strict=True)]
    with atomic_open(path, "w") as fh:
        fh.write("\n".join(out) + "\n")


def write_alta_data(path: str | os.PathLike[str], ds: Dataset, *,
                    param_out: str | None = None) -> None:
    """Write a Dataset as ALTA text data with its parametrization in ``#PARAM_IN``."""
    if ds.y is None:
        raise InputError(f"{path}: ALTA data needs values, not only bounds")
    write_alta(path, ds.x, ds.y, lo=ds.lo, hi=ds.hi,
               param_in=str(ds.meta.get("param_in", "UNKNOWN")),
               param_out=param_out or str(ds.meta.get("param_out", "UNKNOWN")))
