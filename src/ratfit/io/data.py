"""Reading and writing interval data: ALTA text, CSV, NPZ and NIST StRD files.

Every reader returns a :class:`Dataset` whose arrays are finite and shaped, so
callers only need to choose how to turn values into intervals
(:meth:`Dataset.segments`). Errors are :class:`FileFormatError` (the file is not
what it claims, or is truncated) or :class:`InputError` (the file parses, but the
values cannot be fitted: NaN, inf, lo > hi); each message is one line naming the
file and, for text files, the line number.
"""

from __future__ import annotations

import io
import os
import re
import zipfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit._atomic import atomic_open
from ratfit.core.segments import MAX_MAGNITUDE, Segments, check_points, check_values
from ratfit.errors import FileFormatError, InputError

__all__ = ["FORMATS", "Dataset", "read_data", "write_alta", "write_csv"]

FORMATS: tuple[str, ...] = ("alta", "csv", "npz", "nist")

_Array = NDArray[np.float64]
_PathLike = str | os.PathLike[str]


# ---------------------------------------------------------------------------
# Dataset
# ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Dataset:
    """Points ``x`` (N, d) with values ``y`` and/or explicit bounds ``lo``/``hi`` (N, k).

    ``lo``/``hi`` are ``None`` when the file has no intervals (they are then
    derived on demand by :meth:`segments`); ``y`` is ``None`` for files that only
    give bounds. ``meta`` holds what the file says about itself (``format``,
    ``source``, ALTA ``param_in``/``param_out``, NIST certified values...).
    """

    x: _Array
    y: _Array | None = None
    lo: _Array | None = None
    hi: _Array | None = None
    input_names: tuple[str, ...] = ()
    output_names: tuple[str, ...] = ()
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        src = str(self.meta.get("source", "dataset"))
        x = check_points(self.x, f"{src}: x")
        n = x.shape[0]
        y = None if self.y is None else check_values(self.y, n, f"{src}: y")
        if (self.lo is None) != (self.hi is None):
            raise InputError(f"{src}: lo and hi must be given together")
        lo = hi = None
        if self.lo is not None and self.hi is not None:
            lo = check_values(self.lo, n, f"{src}: lo")
            hi = check_values(self.hi, n, f"{src}: hi")
            if lo.shape != hi.shape:
                raise InputError(f"{src}: lo has shape {lo.shape} but hi has shape {hi.shape}")
            if y is not None and y.shape != lo.shape:
                raise InputError(f"{src}: y has shape {y.shape} but lo/hi have shape {lo.shape}")
        if y is None and lo is None:
            raise InputError(f"{src}: no output values (neither y nor lo/hi)")
        k = (y if y is not None else lo).shape[1]  # type: ignore[union-attr]
        inames = tuple(str(s) for s in self.input_names) or tuple(
            f"x{i}" for i in range(x.shape[1])
        )
        onames = tuple(str(s) for s in self.output_names) or tuple(f"y{j}" for j in range(k))
        if len(inames) != x.shape[1]:
            raise InputError(f"{src}: {len(inames)} input names for {x.shape[1]} input dimensions")
        if len(onames) != k:
            raise InputError(f"{src}: {len(onames)} output names for {k} output channels")
        if lo is not None and hi is not None:
            _check_order(src, lo, hi, onames)
        for name, arr in (("x", x), ("y", y), ("lo", lo), ("hi", hi)):
            if arr is None or not arr.size:
                continue
            big = float(np.max(np.abs(arr)))
            if big > MAX_MAGNITUDE:
                row = int(np.argwhere(np.abs(arr) > MAX_MAGNITUDE)[0][0])
                raise InputError(
                    f"{src}: {name} holds a value of magnitude {big:.3g} (first at data row "
                    f"{row + 1}); ratfit handles magnitudes up to {MAX_MAGNITUDE:.0e}: "
                    "rescale the data"
                )
        for attr, val in (
            ("x", x),
            ("y", y),
            ("lo", lo),
            ("hi", hi),
            ("input_names", inames),
            ("output_names", onames),
        ):
            if isinstance(val, np.ndarray):
                val.setflags(write=False)
            object.__setattr__(self, attr, val)

    @property
    def dim(self) -> int:
        """Number of input dimensions d."""
        return int(self.x.shape[1])

    @property
    def n_channels(self) -> int:
        """Number of output channels k."""
        ref = self.y if self.y is not None else self.lo
        assert ref is not None
        return int(ref.shape[1])

    @property
    def n_points(self) -> int:
        """Number of data points N."""
        return int(self.x.shape[0])

    @property
    def source(self) -> str:
        """The file this came from, for messages."""
        return str(self.meta.get("source", "dataset"))

    def segments(self, *, dt: float | None = None, abs_width: float | None = None) -> Segments:
        """Build the fitting intervals, from ``y`` when a width is given, else from the file.

        With both ``dt`` (relative) and ``abs_width`` each segment is the union of
        the two intervals, so small values keep a usable absolute tolerance.
        """
        if dt is None and abs_width is None:
            if self.lo is None or self.hi is None:
                raise InputError(f"{self.source} has no intervals: give --dt or --abs-width")
            return Segments(self.x, self.lo, self.hi, self.y, self.output_names)
        if self.y is None:
            raise InputError(
                f"{self.source} has only lo/hi bounds, no y values: "
                "--dt/--abs-width cannot be applied"
            )
        return Segments.from_widths(self.x, self.y, dt=dt, abs_width=abs_width,
                                    names=self.output_names)


def _check_order(
    src: str,
    lo: _Array,
    hi: _Array,
    names: Sequence[str],
    lines: Sequence[int] | None = None,
) -> None:
    bad = lo > hi
    if bad.any():
        i, j = (int(v) for v in np.argwhere(bad)[0])
        where = f"{src} line {lines[i]}" if lines is not None else src
        raise InputError(
            f"{where}: lo > hi at row {i}, channel {names[j]!r} "
            f"(lo={float(lo[i, j])!r}, hi={float(hi[i, j])!r}; {int(bad.sum())} such segment(s))"
        )


def _check_finite(
    src: str, arr: _Array, colnames: Sequence[str], lines: Sequence[int] | None = None
) -> None:
    """Report the first NaN/inf with its file line, before check_points gives a row index."""
    bad = ~np.isfinite(arr)
    if bad.any():
        i, j = (int(v) for v in np.argwhere(bad)[0])
        where = f"{src} line {lines[i]}" if lines is not None else f"{src} row {i}"
        raise InputError(
            f"{where}: non-finite value {float(arr[i, j])!r} in column {colnames[j]!r} "
            f"({int(bad.sum())} non-finite value(s) in all)"
        )


# ---------------------------------------------------------------------------
# dispatch
# ---------------------------------------------------------------------------
def read_data(path: _PathLike, *, fmt: str | None = None, dim: int | None = None) -> Dataset:
    """Read a data file, guessing its format from content/extension when ``fmt`` is None.

    Parameters
    ----------
    path : str or path-like
        ALTA text data, CSV, ``.npz`` or NIST StRD ``.dat``.
    fmt : {"alta", "csv", "npz", "nist"}, optional
        Format (default: from the content and extension).
    dim : int, optional
        Input columns of a header-less CSV; for formats that declare it (ALTA
        ``#DIM``, NIST, NPZ) it must agree with the file.

    Returns
    -------
    Dataset
        Points, values and/or intervals; ``.segments(dt=..., abs_width=...)``
        builds the fitting segments.

    Examples
    --------
    >>> import os, tempfile
    >>> from ratfit.io import read_data
    >>> path = os.path.join(tempfile.mkdtemp(), "d.csv")
    >>> _ = open(path, "w").write("x,y\\n0,1\\n1,2\\n2,4\\n")
    >>> ds = read_data(path)
    >>> ds.x[:, 0].tolist(), ds.segments(dt=0.5).hi[:, 0].tolist()
    ([0.0, 1.0, 2.0], [1.5, 3.0, 6.0])
    """
    src = str(path)
    if fmt is not None:
        key = str(fmt).strip().lower()
        if key not in FORMATS:
            raise InputError(f"unknown data format {fmt!r}: valid formats are {', '.join(FORMATS)}")
    if dim is not None:
        if isinstance(dim, bool) or not isinstance(dim, (int, np.integer)) or dim < 1:
            raise InputError(f"dim must be a positive integer, got {dim!r}")
        dim = int(dim)
    p = Path(path)
    if not p.exists():
        raise FileFormatError(f"{src}: no such file")
    if p.is_dir():
        raise FileFormatError(f"{src}: is a directory, not a data file")
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise FileFormatError(f"{src}: cannot read: {exc.strerror or exc}") from None
    if fmt is None:
        key = _sniff(p, data)
    if key == "npz":
        ds = _read_npz(src, data)
    else:
        if not data.strip():
            raise FileFormatError(f"{src}: empty file")
        reader = {"alta": _read_alta, "nist": _read_nist, "csv": _read_csv}[key]
        ds = reader(src, data, dim)
    if dim is not None and ds.dim != dim and key != "csv":
        raise InputError(f"{src}: the file has {ds.dim} input dimension(s) but dim={dim} given")
    return ds


def _sniff(p: Path, data: bytes) -> str:
    if p.suffix.lower() == ".npz" or data.startswith(b"PK\x03\x04"):
        return "npz"
    if p.suffix.lower() == ".alta":
        return "alta"
    if data.lstrip().startswith(b"NIST/ITL StRD"):
        return "nist"
    # ALTA: a #DIM line in the leading block of comment lines.
    for raw in data[:65536].splitlines():
        s = raw.strip()
        if not s:
            continue
        if not s.startswith(b"#"):
            break
        key = s[1:].split(maxsplit=1)
        if key and key[0] in (b"DIM", b"ALTA_BEGIN_HEADER"):
            return "alta"
    return "csv"


def _lines(src: str, data: bytes) -> Iterator[tuple[int, str]]:
    """Yield (1-based line number, stripped text), decoding lazily so binary tails fail late."""
    for n, raw in enumerate(data.split(b"\n"), start=1):
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise FileFormatError(
                f"{src} line {n}: not a text file (undecodable byte 0x{raw[exc.start]:02x})"
            ) from None
        yield n, (text.lstrip("\ufeff") if n == 1 else text).strip()


def _count(n: int, word: str) -> str:
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def _short(tok: str) -> str:
    return repr(tok if len(tok) <= 40 else tok[:37] + "...")


def _to_array(src: str, rows: list[list[str]], lines: list[int], ncols: int) -> _Array:
    """Convert already count-checked token rows to an (N, ncols) array."""
    flat = [t for r in rows for t in r]
    try:
        vals = list(map(float, flat))
    except ValueError:
        for n, r in zip(lines, rows, strict=True):
            for j, t in enumerate(r):
                try:
                    float(t)
                except ValueError:
                    raise FileFormatError(
                        f"{src} line {n}: non-numeric value {_short(t)} in column {j + 1}"
                    ) from None
        raise  # pragma: no cover - float() failed above, so the loop raises
    return np.asarray(vals, dtype=np.float64).reshape(len(rows), ncols)


# ---------------------------------------------------------------------------
# ALTA text
# ---------------------------------------------------------------------------
def _read_alta(src: str, data: bytes, dim: int | None) -> Dataset:
    nx = ny = None
    vs = 0
    meta: dict[str, Any] = {"format": "alta", "source": src}
    rows: list[list[str]] = []
    lines: list[int] = []
    ncols = 0
    for n, s in _lines(src, data):
        if not s:
            continue
        if s.startswith("#"):
            parts = s[1:].split()
            key = parts[0].upper() if parts else ""
            if key == "DIM":
                if nx is not None:
                    raise FileFormatError(f"{src} line {n}: duplicate #DIM header")
                if rows:
                    raise FileFormatError(f"{src} line {n}: #DIM header after data rows")
                try:
                    nx, ny = (int(v) for v in parts[1:])
                except ValueError:
                    raise FileFormatError(
                        f"{src} line {n}: malformed #DIM header {_short(s)}: "
                        "expected '#DIM nx ny' with two positive integers"
                    ) from None
                if nx < 1 or ny < 1:
                    raise FileFormatError(
                        f"{src} line {n}: malformed #DIM header {_short(s)}: nx and ny must be >= 1"
                    )
            elif key == "VS":
                if rows:
                    raise FileFormatError(f"{src} line {n}: #VS header after data rows")
                if len(parts) != 2 or parts[1] not in ("0", "1", "2"):
                    raise FileFormatError(
                        f"{src} line {n}: malformed #VS header {_short(s)}: expected 0, 1 or 2"
                    )
                vs = int(parts[1])
            elif key == "FUNC" or (key == "ALTA" and "FUNC" in (t.upper() for t in parts)):
                raise FileFormatError(
                    f"{src} line {n}: an ALTA function file (a fit result), not ALTA data"
                )
            elif key in ("PARAM_IN", "PARAM_OUT"):
                meta[key.lower()] = " ".join(parts[1:])
            elif key == "FORMAT":
                value = " ".join(parts[1:]).lower()
                if value == "binary":
                    raise FileFormatError(
                        f"{src} line {n}: ALTA binary files (#FORMAT binary) are not "
                        "supported by this reader; ratfit.brdf.io.read_alta_binary and "
                        "`ratfit brdf fit` read them"
                    )
                if value not in ("text", "ascii", "txt"):
                    raise FileFormatError(f"{src} line {n}: unknown ALTA #FORMAT {_short(value)}")
            continue
        if nx is None or ny is None:
            raise FileFormatError(
                f"{src} line {n}: data row before the #DIM header "
                "(an ALTA file needs '#DIM nx ny' first)"
            )
        if not ncols:
            ncols = nx + ny + ny * vs
        toks = s.split()
        if len(toks) != ncols:
            raise FileFormatError(
                f"{src} line {n}: expected {ncols} numbers "
                f"(#DIM {nx} {ny}, #VS {vs}), got {len(toks)}"
            )
        rows.append(toks)
        lines.append(n)
    if nx is None or ny is None:
        raise FileFormatError(f"{src}: missing '#DIM nx ny' header: not an ALTA text file")
    if not rows:
        raise FileFormatError(f"{src}: no data rows after the ALTA header")
    arr = _to_array(src, rows, lines, ncols)
    cols = [f"x{i}" for i in range(nx)] + [f"y{j}" for j in range(ny)]
    if vs == 1:
        cols += [f"dt{j}" for j in range(ny)]
    elif vs == 2:
        cols += [f"{b}{j}" for j in range(ny) for b in ("lo", "hi")]
    _check_finite(src, arr, cols, lines)
    x, y = arr[:, :nx], arr[:, nx : nx + ny]
    rest = arr[:, nx + ny :]
    lo = hi = None
    if vs == 1:
        lo, hi = y - rest, y + rest
    elif vs == 2:
        lo, hi = rest[:, 0::2], rest[:, 1::2]
    onames = tuple(f"y{j}" for j in range(ny))
    if lo is not None and hi is not None:
        _check_order(src, lo, hi, onames, lines)
    meta["vs"] = vs
    meta.setdefault("param_in", "UNKNOWN")
    meta.setdefault("param_out", "UNKNOWN")
    return Dataset(x, y, lo, hi, (), onames, meta)


def write_alta(
    path: _PathLike,
    x: ArrayLike,
    y: ArrayLike,
    *,
    lo: ArrayLike | None = None,
    hi: ArrayLike | None = None,
    param_in: str = "UNKNOWN",
    param_out: str = "UNKNOWN",
) -> None:
    """Write ALTA text (VS 2 with bounds, VS 0 without) that reads back bit-exactly."""
    src = str(path)
    xa, ya, loa, hia = _validate_for_write(src, x, y, lo, hi)
    if ya is None:
        raise InputError(f"{src}: ALTA files need y values, not only lo/hi bounds")
    for label, val in (("param_in", param_in), ("param_out", param_out)):
        if not str(val).strip() or any(c in str(val) for c in "\r\n"):
            raise InputError(f"{src}: {label} must be a non-empty single-line name, got {val!r}")
    vs = 0 if loa is None else 2
    blocks = [xa, ya]
    if loa is not None and hia is not None:
        inter = np.empty((loa.shape[0], 2 * loa.shape[1]))
        inter[:, 0::2], inter[:, 1::2] = loa, hia
        blocks.append(inter)
    table = np.hstack(blocks)
    with atomic_open(path, "w") as fh:
        fh.write(f"#DIM {xa.shape[1]} {ya.shape[1]}\n#VS {vs}\n")
        fh.write(f"#PARAM_IN {str(param_in).strip()}\n#PARAM_OUT {str(param_out).strip()}\n")
        fh.writelines(" ".join(map(repr, row)) + "\n" for row in table.tolist())


# ---------------------------------------------------------------------------
# NIST StRD
# ---------------------------------------------------------------------------
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eEdD][-+]?\d+)?"
_PARAM_RE = re.compile(r"^(b\d+)\s*=\s*(.*)$")
_IDENT_RE = re.compile(r"^[A-Za-z_]\w*$")


def _nist_number(src: str, n: int, label: str, text: str) -> float:
    m = re.match(_NUM, text.strip())
    if not m:
        raise FileFormatError(f"{src} line {n}: cannot read the {label} value {_short(text)}")
    return _fortran_float(m.group(0))


def _fortran_float(text: str) -> float:
    return float(text.replace("D", "E").replace("d", "e"))


def _read_nist(src: str, data: bytes, dim: int | None) -> Dataset:
    all_lines = list(_lines(src, data))
    if not all_lines or not all_lines[0][1].startswith("NIST/ITL StRD"):
        raise FileFormatError(f"{src}: not a NIST StRD file (first line is not 'NIST/ITL StRD')")
    meta: dict[str, Any] = {"format": "nist", "source": src}
    params: dict[str, float] = {}
    param_sd: dict[str, float] = {}
    model: list[str] = []
    in_model = False
    columns: list[str] | None = None
    data_start = 0
    n_obs: int | None = None
    scalars = {
        "Residual Sum of Squares:": "certified_rss",
        "Residual Standard Deviation:": "certified_residual_sd",
    }
    for idx, (n, s) in enumerate(all_lines):
        if in_model:
            if "Starting values" in s or "Certified Values" in s or _PARAM_RE.match(s):
                in_model = False
            else:
                model.append(s)
                continue
        if s.startswith("Dataset Name:"):
            meta["dataset_name"] = " ".join(s[len("Dataset Name:") :].split()[:1])
        elif s.startswith("Model:"):
            in_model = True
            model.append(s[len("Model:") :].strip())
        elif s.startswith("Data:"):
            rest = s[len("Data:") :].split()
            if rest and all(_IDENT_RE.match(t) for t in rest):
                columns = rest
                data_start = idx + 1
                break
        elif (m := _PARAM_RE.match(s)) is not None:
            nums = re.findall(_NUM, m.group(2))
            if len(nums) < 2:
                raise FileFormatError(
                    f"{src} line {n}: certified parameter line {_short(s)} has no certified value"
                )
            params[m.group(1)] = _fortran_float(nums[-2])
            param_sd[m.group(1)] = _fortran_float(nums[-1])
        elif s.startswith("Degrees of Freedom:"):
            meta["degrees_of_freedom"] = int(_nist_number(src, n, "degrees of freedom", s[19:]))
        elif s.startswith("Number of Observations:"):
            n_obs = int(_nist_number(src, n, "number of observations", s[23:]))
        else:
            for label, key in scalars.items():
                if s.startswith(label):
                    meta[key] = _nist_number(src, n, label.rstrip(":"), s[len(label) :])
    if columns is None:
        raise FileFormatError(f"{src}: no 'Data:' line with column names (e.g. 'Data: y x')")
    if n_obs is None:
        raise FileFormatError(f"{src}: no 'Number of Observations:' line in the NIST header")
    ycols = [j for j, c in enumerate(columns) if c.lower() == "y"]
    if len(ycols) != 1:
        raise FileFormatError(
            f"{src} line {all_lines[data_start - 1][0]}: expected exactly one 'y' column "
            f"in the Data: line, got columns {columns}"
        )
    xcols = [j for j in range(len(columns)) if j != ycols[0]]
    if not xcols:
        raise FileFormatError(f"{src}: the Data: line names no predictor (x) column")
    rows: list[list[str]] = []
    lines: list[int] = []
    for n, s in all_lines[data_start:]:
        if not s:
            continue
        toks = s.split()
        if len(toks) != len(columns):
            raise FileFormatError(
                f"{src} line {n}: expected {len(columns)} numbers "
                f"({' '.join(columns)}), got {len(toks)}"
            )
        rows.append(toks)
        lines.append(n)
    if len(rows) != n_obs:
        what = "truncated" if len(rows) < n_obs else "has extra rows"
        raise FileFormatError(
            f"{src}: {what}: header says {n_obs} observations, found {len(rows)} data rows"
        )
    arr = _to_array(src, rows, lines, len(columns))
    _check_finite(src, arr, columns, lines)
    while model and not model[-1]:
        model.pop()
    meta["model"] = "\n".join(model)
    meta["certified_params"] = params
    meta["certified_param_sd"] = param_sd
    meta["n_observations"] = n_obs
    return Dataset(
        arr[:, xcols],
        arr[:, ycols],
        None,
        None,
        tuple(columns[j] for j in xcols),
        ("y",),
        meta,
    )


# ---------------------------------------------------------------------------
# CSV
# ---------------------------------------------------------------------------
def _is_number(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def _classify(name: str) -> tuple[str, str]:
    """Column role ('x', 'y', 'lo', 'hi') and channel name from a CSV header name."""
    low = name.lower()
    for role in ("y", "lo", "hi"):
        if low == role:
            return role, "y"
        if low.startswith(role + "_") and len(name) > len(role) + 1:
            return role, name[len(role) + 1 :]
    return "x", name


def _read_csv(src: str, data: bytes, dim: int | None) -> Dataset:
    sep: str | None = None
    header: list[str] | None = None
    header_line = 0
    rows: list[list[str]] = []
    lines: list[int] = []
    ncols = 0
    for n, s in _lines(src, data):
        if not s or s.startswith("#"):
            continue
        if not ncols:
            sep = "," if "," in s else None
        toks = [t.strip() for t in s.split(sep)]
        if not ncols:
            ncols = len(toks)
            if not all(_is_number(t) for t in toks if t):
                header, header_line = toks, n
                for j, t in enumerate(toks):
                    if not t:
                        raise FileFormatError(f"{src} line {n}: empty column name {j + 1}")
                if len(set(toks)) != len(toks):
                    raise FileFormatError(f"{src} line {n}: duplicate column names in {toks}")
                continue
        if len(toks) != ncols:
            raise FileFormatError(
                f"{src} line {n}: expected {_count(ncols, 'value')}, got {len(toks)}"
            )
        for j, t in enumerate(toks):
            if not t:
                raise FileFormatError(f"{src} line {n}: empty value in column {j + 1}")
        rows.append(toks)
        lines.append(n)
    if not ncols:
        raise FileFormatError(f"{src}: no data (only comments or blank lines)")
    if not rows:
        raise FileFormatError(f"{src}: no data rows after the header")
    if header is None and sep == "," and ncols == 2:
        _check_decimal_commas(src, rows, lines)
    arr = _to_array(src, rows, lines, ncols)
    meta: dict[str, Any] = {"format": "csv", "source": src}
    roles = [_classify(h) for h in header] if header is not None else []
    if header is None or all(r == "x" for r, _ in roles):
        # Positional: the first `dim` columns are inputs, the rest output channels.
        if ncols < 2:
            raise FileFormatError(f"{src}: need at least 2 columns (x and y), got {ncols}")
        d = ncols - 1 if dim is None else dim
        if d >= ncols:
            raise InputError(f"{src}: dim={d} leaves no output column ({ncols} columns)")
        cols = header or [f"x{i}" for i in range(d)] + [f"y{j}" for j in range(ncols - d)]
        _check_finite(src, arr, cols, lines)
        inames = tuple(header[:d]) if header else ()
        onames = tuple(header[d:]) if header else ()
        return Dataset(arr[:, :d], arr[:, d:], None, None, inames, onames, meta)
    assert header is not None
    where = f"{src} line {header_line}"
    _check_finite(src, arr, header, lines)
    xcols = [j for j, (r, _) in enumerate(roles) if r == "x"]
    if not xcols:
        raise FileFormatError(f"{where}: no input (x) column in header {header}")
    by_role: dict[str, dict[str, int]] = {"y": {}, "lo": {}, "hi": {}}
    order: list[str] = []
    for j, (role, chan) in enumerate(roles):
        if role == "x":
            continue
        if chan in by_role[role]:
            raise FileFormatError(f"{where}: two {role} columns for channel {chan!r}")
        by_role[role][chan] = j
        if chan not in order:
            order.append(chan)
    ys, los, his = by_role["y"], by_role["lo"], by_role["hi"]
    if set(los) != set(his):
        odd = sorted(set(los) ^ set(his))
        raise FileFormatError(f"{where}: lo/hi columns must come in pairs; unpaired: {odd}")
    if ys and los and set(ys) != set(los):
        odd = sorted(set(ys) ^ set(los))
        raise FileFormatError(f"{where}: channels with y but no lo/hi (or lo/hi but no y): {odd}")
    if ys:
        order = [c for c in order if c in ys]
    y = arr[:, [ys[c] for c in order]] if ys else None
    lo = hi = None
    if los:
        lo = arr[:, [los[c] for c in order]]
        hi = arr[:, [his[c] for c in order]]
        _check_order(src, lo, hi, order, lines)
    x = arr[:, xcols]
    if dim is not None and dim != len(xcols):
        raise InputError(
            f"{src}: the header names {len(xcols)} input column(s) but dim={dim} given"
        )
    return Dataset(x, y, lo, hi, tuple(header[j] for j in xcols), tuple(order), meta)


_INT = re.compile(r"[+-]?[0-9]+")


def _check_decimal_commas(src: str, rows: list[list[str]], lines: list[int]) -> None:
    """Refuse one column of decimal-comma numbers ("0,0082") posing as x,y integer pairs.

    Read as CSV, "0,0082" is x = 0, y = 82: a silent misparse. The signs: every value
    an integer, and a second column with leading zeros or a first column that repeats.
    A header line (``x,y``) states that the file really holds integer pairs.
    """
    if not all(_INT.fullmatch(a) and _INT.fullmatch(b) for a, b in rows):
        return
    lead = [i for i, (_, b) in enumerate(rows) if len(b.lstrip("+-")) > 1 and
            b.lstrip("+-").startswith("0")]
    firsts = [a for a, _ in rows]
    if lead or len(set(firsts)) < len(firsts):
        i = lead[0] if lead else 0
        raise FileFormatError(
            f"{src} line {lines[i]}: {','.join(rows[i])!r} looks like a number with a decimal "
            "comma, not two columns: ratfit reads '.' as the decimal point (convert the file); "
            "if these really are integer x,y pairs, add a header line 'x,y'"
        )


_BAD_NAME = re.compile(r"[\s,#\"']")


def write_csv(
    path: _PathLike,
    x: ArrayLike,
    y: ArrayLike | None,
    lo: ArrayLike | None = None,
    hi: ArrayLike | None = None,
    input_names: Sequence[str] | None = None,
    output_names: Sequence[str] | None = None,
) -> None:
    """Write a headed CSV (x..., y_NAME..., lo_NAME, hi_NAME...) that reads back bit-exactly.

    A channel named ``y`` gets the columns ``y``, ``lo``, ``hi``; any other name
    ``N`` gets ``y_N``, ``lo_N``, ``hi_N``.
    """
    src = str(path)
    xa, ya, loa, hia = _validate_for_write(src, x, y, lo, hi)
    d = xa.shape[1]
    k = (ya if ya is not None else loa).shape[1]  # type: ignore[union-attr]
    inames = tuple(input_names) if input_names is not None else tuple(f"x{i}" for i in range(d))
    if output_names is not None:
        onames = tuple(output_names)
    else:
        onames = ("y",) if k == 1 else tuple(str(j) for j in range(k))
    if len(inames) != d:
        raise InputError(f"{src}: {len(inames)} input names for {d} input dimensions")
    if len(onames) != k:
        raise InputError(f"{src}: {len(onames)} output names for {k} output channels")
    for name in (*inames, *onames):
        if not isinstance(name, str) or not name or _BAD_NAME.search(name):
            raise InputError(
                f"{src}: column name {name!r} must be a non-empty string without "
                "blanks, commas, quotes or '#'"
            )
    for name in inames:
        if _classify(name)[0] != "x":
            raise InputError(
                f"{src}: input name {name!r} would be read back as an output or bound "
                "column (y, lo, hi, y_*, lo_*, hi_*); rename it"
            )

    def col(role: str, chan: str) -> str:
        return role if chan == "y" else f"{role}_{chan}"

    cols = list(inames)
    blocks = [xa]
    if ya is not None:
        cols += [col("y", c) for c in onames]
        blocks.append(ya)
    if loa is not None and hia is not None:
        inter = np.empty((loa.shape[0], 2 * k))
        inter[:, 0::2], inter[:, 1::2] = loa, hia
        blocks.append(inter)
        cols += [col(r, c) for c in onames for r in ("lo", "hi")]
    if len({c.lower() for c in cols}) != len(cols):
        raise InputError(f"{src}: duplicate column names {cols}")
    table = np.hstack(blocks)
    with atomic_open(path, "w") as fh:
        fh.write(",".join(cols) + "\n")
        fh.writelines(",".join(map(repr, row)) + "\n" for row in table.tolist())


def _validate_for_write(
    src: str,
    x: ArrayLike,
    y: ArrayLike | None,
    lo: ArrayLike | None,
    hi: ArrayLike | None,
) -> tuple[_Array, _Array | None, _Array | None, _Array | None]:
    xa = check_points(x, f"{src}: x")
    n = xa.shape[0]
    ya = None if y is None else check_values(y, n, f"{src}: y")
    if (lo is None) != (hi is None):
        raise InputError(f"{src}: lo and hi must be given together")
    loa = hia = None
    if lo is not None and hi is not None:
        loa = check_values(lo, n, f"{src}: lo")
        hia = check_values(hi, n, f"{src}: hi")
        if loa.shape != hia.shape or (ya is not None and ya.shape != loa.shape):
            raise InputError(
                f"{src}: y, lo and hi must have the same shape, got "
                f"{None if ya is None else ya.shape}, {loa.shape}, {hia.shape}"
            )
        _check_order(src, loa, hia, [f"y{j}" for j in range(loa.shape[1])])
    if ya is None and loa is None:
        raise InputError(f"{src}: nothing to write: give y or lo/hi")
    return xa, ya, loa, hia


# ---------------------------------------------------------------------------
# NPZ
# ---------------------------------------------------------------------------
_NPZ_ERRORS = (zipfile.BadZipFile, OSError, ValueError, EOFError, KeyError)


def _read_npz(src: str, data: bytes) -> Dataset:
    if not data.startswith(b"PK"):
        what = "a single .npy array" if data.startswith(b"\x93NUMPY") else "not a zip archive"
        raise FileFormatError(f"{src}: not a readable .npz file ({what})")
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            keys = list(npz.files)
            arrays = {k: npz[k] for k in keys}
    except _NPZ_ERRORS as exc:
        msg = " ".join(str(exc).split()) or type(exc).__name__
        if isinstance(exc, ValueError) and "pickle" in msg:
            why = "it holds object arrays, which are not loaded (allow_pickle=False)"
        else:
            why = f"corrupt or truncated: {msg}"
        raise FileFormatError(f"{src}: not a readable .npz file ({why})") from None
    for k, a in arrays.items():
        if not isinstance(a, np.ndarray):  # a zip member that is not a .npy array
            raise FileFormatError(f"{src}: .npz member {k!r} is not a .npy array "
                                  f"({type(a).__name__})")
    if "x" not in arrays:
        raise FileFormatError(f"{src}: .npz has no 'x' array; keys found: {sorted(keys)}")
    if ("lo" in arrays) != ("hi" in arrays):
        raise FileFormatError(f"{src}: .npz has only one of 'lo'/'hi'; keys found: {sorted(keys)}")
    if "y" not in arrays and "lo" not in arrays:
        raise FileFormatError(f"{src}: .npz needs 'y' or 'lo'+'hi'; keys found: {sorted(keys)}")

    def num(key: str) -> _Array | None:
        if key not in arrays:
            return None
        a = arrays[key]
        if a.dtype.kind not in "biuf":
            raise FileFormatError(f"{src}: .npz array {key!r} is not numeric (dtype {a.dtype})")
        a = np.asarray(a, dtype=np.float64)
        return a[:, None] if a.ndim == 1 else a

    def names(key: str) -> tuple[str, ...]:
        if key not in arrays:
            return ()
        a = arrays[key]
        if a.dtype.kind not in "US" or a.ndim > 1:
            raise FileFormatError(f"{src}: .npz {key!r} must be a 1-D array of strings")
        vals = np.atleast_1d(a).tolist()
        return tuple(v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v) for v in vals)

    x, y, lo, hi = num("x"), num("y"), num("lo"), num("hi")
    assert x is not None
    for key, arr in (("x", x), ("y", y), ("lo", lo), ("hi", hi)):
        if arr is not None and arr.ndim == 2:
            _check_finite(src, arr, [f"{key}[:, {j}]" for j in range(arr.shape[1])])
    inames, onames = names("input_names"), names("output_names")
    if lo is not None and hi is not None and lo.shape == hi.shape and lo.ndim == 2:
        k = lo.shape[1]
        _check_order(src, lo, hi, onames if len(onames) == k else [f"y{j}" for j in range(k)])
    meta: dict[str, Any] = {"format": "npz", "source": src}
    return Dataset(x, y, lo, hi, inames, onames, meta)
