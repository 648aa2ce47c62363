"""Tests for ratfit.io.data: real ALTA/NIST files, round trips, and broken inputs."""

from __future__ import annotations

import io
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from ratfit.errors import FileFormatError, InputError
from ratfit.io.data import FORMATS, Dataset, read_data, write_alta, write_csv


def _raises(exc: type[Exception], call, *args, match: str, **kw) -> str:
    """Call and check error type, that the message is one line and mentions ``match``."""
    with pytest.raises(exc) as info:
        call(*args, **kw)
    msg = str(info.value)
    assert "\n" not in msg, msg
    assert match in msg, msg
    return msg


def _sorted_rows(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    table = np.hstack([x, y])
    return table[np.lexsort(table.T[::-1])]


# ---------------------------------------------------------------------------
# real data
# ---------------------------------------------------------------------------
def test_alta_kirby2(shared_data: Path) -> None:
    ds = read_data(shared_data / "alta" / "Kirby2.dat")
    assert ds.meta["format"] == "alta"
    assert (ds.n_points, ds.dim, ds.n_channels) == (151, 1, 1)
    assert ds.x[0, 0] == 9.65 and ds.y is not None and ds.y[0, 0] == 0.0082
    assert ds.x[-1, 0] == 371.30 and ds.y[-1, 0] == 92.2
    assert ds.lo is None and ds.hi is None
    assert ds.meta["vs"] == 0
    assert ds.meta["param_in"] == "UNKNOWN" and ds.meta["param_out"] == "UNKNOWN"
    _raises(InputError, ds.segments, match="has no intervals: give --dt or --abs-width")
    seg = ds.segments(dt=0.1)
    assert seg.lo[0, 0] == pytest.approx(0.9 * 0.0082) and seg.hi[0, 0] == 1.1 * 0.0082


def test_nist_kirby2(shared_data: Path) -> None:
    ds = read_data(shared_data / "nist" / "Kirby2.dat")
    assert ds.meta["format"] == "nist"
    assert ds.meta["n_observations"] == 151 and ds.n_points == 151
    assert ds.input_names == ("x",) and ds.output_names == ("y",)
    assert ds.x[0, 0] == 9.65 and ds.y is not None and ds.y[0, 0] == 0.0082
    assert ds.meta["certified_residual_sd"] == 1.6354535131e-01
    assert ds.meta["certified_rss"] == 3.9050739624e00
    assert ds.meta["degrees_of_freedom"] == 146
    params = ds.meta["certified_params"]
    assert list(params) == ["b1", "b2", "b3", "b4", "b5"]
    assert params["b1"] == 1.6745063063e00 and params["b5"] == 2.1664802578e-05
    assert ds.meta["certified_param_sd"]["b1"] == 8.7989634338e-02
    assert "quadratic/quadratic" in ds.meta["model"] and "b5*x**2" in ds.meta["model"]
    # Same (x, y) set as ALTA's copy of the data.
    alta = read_data(shared_data / "alta" / "Kirby2.dat")
    assert alta.y is not None
    assert np.array_equal(_sorted_rows(ds.x, ds.y), _sorted_rows(alta.x, alta.y))
    # The certified parameters really fit this data (RSS reproduces to 1e-9).
    b = [params[f"b{i}"] for i in range(1, 6)]
    x, y = ds.x[:, 0], ds.y[:, 0]
    pred = (b[0] + b[1] * x + b[2] * x**2) / (1 + b[3] * x + b[4] * x**2)
    assert np.sum((y - pred) ** 2) == pytest.approx(ds.meta["certified_rss"], rel=1e-9)


def test_nist_mgh09(shared_data: Path) -> None:
    ds = read_data(shared_data / "nist" / "MGH09.dat", fmt="nist")
    assert ds.n_points == 11 and ds.meta["n_observations"] == 11
    assert ds.x[0, 0] == 4.0 and ds.y is not None and ds.y[0, 0] == 0.1957
    assert ds.x[-1, 0] == 0.0625 and ds.y[-1, 0] == 0.0246
    assert ds.meta["certified_params"] == {
        "b1": 1.9280693458e-01,
        "b2": 1.9128232873e-01,
        "b3": 1.2305650693e-01,
        "b4": 1.3606233068e-01,
    }
    assert ds.meta["certified_residual_sd"] == 6.6279236551e-03
    assert "linear/quadratic" in ds.meta["model"]


def test_alta_retro_3m_fast(shared_data: Path) -> None:
    path = shared_data / "alta" / "retro-3M-jaune.dat"
    t0 = time.perf_counter()
    ds = read_data(path)
    elapsed = time.perf_counter() - t0
    assert (ds.n_points, ds.dim, ds.n_channels) == (7397, 3, 1)
    assert ds.meta["param_in"] == "ISOTROPIC_TL_TV_PROJ_DPHI"
    assert ds.meta["param_out"] == "INV_STERADIAN_COSINE_FACTOR"
    assert ds.x[0, 0] == 0.26179938779914940782944654529274
    assert ds.y is not None and ds.y[0, 0] == 0.00050174400000000003978922746839
    assert elapsed < 1.0, f"reading {ds.n_points} rows took {elapsed:.2f} s"


def test_alta_multichannel_with_begin_end_header(shared_data: Path) -> None:
    ds = read_data(shared_data / "alta" / "brdf_small_simu_two_layers_txt.alta")
    assert (ds.n_points, ds.dim, ds.n_channels) == (29, 3, 3)
    assert ds.meta["param_out"] == "RGB_COLOR"
    assert ds.x[0, 1] == 0.00872664625997165 and ds.y is not None
    assert ds.y[0, 2] == 0.01969683810007047


def test_alta_binary_real_file_refused(shared_data: Path) -> None:
    path = shared_data / "alta" / "brdf_small_simu_two_layers_binary.alta"
    msg = _raises(FileFormatError, read_data, path, match="binary")
    assert "line 7" in msg and "not supported" in msg


def test_alta_function_file_refused(shared_data: Path) -> None:
    path = shared_data / "alta" / "fits" / "Kirby2.brdf"
    _raises(FileFormatError, read_data, path, fmt="alta", match="function file")


# ---------------------------------------------------------------------------
# ALTA text variants
# ---------------------------------------------------------------------------
def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_alta_vs1_vs2_layout(tmp_path: Path) -> None:
    # VS 1, two channels: x, y0, y1, dt0, dt1.
    p1 = _write(
        tmp_path / "vs1.dat",
        "#DIM 1 2\n#VS 1\n#PARAM_IN P\n0.5\t1.0 -2.0  0.25 0.5  \n\n1.5 3.0 4.0 0.0 1.0\n",
    )
    ds = read_data(p1)
    assert ds.meta["vs"] == 1 and ds.n_channels == 2
    assert ds.lo is not None and ds.hi is not None
    assert ds.lo.tolist() == [[0.75, -2.5], [3.0, 3.0]]
    assert ds.hi.tolist() == [[1.25, -1.5], [3.0, 5.0]]
    # VS 2, two channels: x, y0, y1, lo0, hi0, lo1, hi1.
    p2 = _write(tmp_path / "vs2.dat", "#DIM 1 2\n#VS 2\n0 1 2 0.5 1.5 1 3\n1 1 2 0 2 2 2\n")
    ds2 = read_data(p2)
    assert ds2.lo is not None and ds2.hi is not None
    assert ds2.lo.tolist() == [[0.5, 1.0], [0.0, 2.0]]
    assert ds2.hi.tolist() == [[1.5, 3.0], [2.0, 2.0]]
    seg = ds2.segments()
    assert np.array_equal(seg.lo, ds2.lo) and seg.names == ("y0", "y1")
    assert seg.y is not None and np.array_equal(seg.y, ds2.y)


@pytest.mark.parametrize("vs", [0, 1, 2])
def test_alta_and_csv_round_trip(tmp_path: Path, vs: int) -> None:
    rng = np.random.default_rng(vs)
    x, y = rng.normal(size=(40, 2)), rng.normal(size=(40, 2)) * 1e-3
    if vs == 1:
        extra_cols = np.abs(rng.normal(size=(40, 2)))
    elif vs == 2:
        a, b = y - np.abs(rng.normal(size=y.shape)), y + np.abs(rng.normal(size=y.shape))
        extra_cols = np.column_stack([a[:, 0], b[:, 0], a[:, 1], b[:, 1]])
    else:
        extra_cols = np.empty((40, 0))
    rows = np.hstack([x, y, extra_cols])
    body = "\n".join(" ".join(repr(v) for v in r) for r in rows.tolist())
    src = _write(tmp_path / f"vs{vs}.dat", f"#DIM 2 2\n#VS {vs}\n{body}\n")
    ds = read_data(src)
    assert np.array_equal(ds.x, x) and ds.y is not None and np.array_equal(ds.y, y)
    assert (ds.lo is None) == (vs == 0)

    out = tmp_path / "out.alta"
    write_alta(out, ds.x, ds.y, lo=ds.lo, hi=ds.hi, param_in="IN_P", param_out="OUT_P")
    back = read_data(out)
    assert back.meta["vs"] == (0 if vs == 0 else 2)
    assert back.meta["param_in"] == "IN_P" and back.meta["param_out"] == "OUT_P"
    _assert_same(ds, back)

    csv = tmp_path / "out.csv"
    write_csv(csv, ds.x, ds.y, ds.lo, ds.hi, ("a", "b"), ("r", "g"))
    cback = read_data(csv)
    assert cback.input_names == ("a", "b") and cback.output_names == ("r", "g")
    _assert_same(ds, cback)


def _assert_same(a: Dataset, b: Dataset) -> None:
    assert np.array_equal(a.x, b.x)
    for name in ("y", "lo", "hi"):
        va, vb = getattr(a, name), getattr(b, name)
        assert (va is None) == (vb is None), name
        if va is not None:
            assert np.array_equal(va, vb), name


def test_write_alta_header_and_exact_floats(tmp_path: Path) -> None:
    out = tmp_path / "sub" / "w.alta"
    write_alta(out, [0.1, 1 / 3], [[2.0 / 3.0], [1e-300]])
    text = out.read_text().splitlines()
    assert text[:4] == ["#DIM 1 1", "#VS 0", "#PARAM_IN UNKNOWN", "#PARAM_OUT UNKNOWN"]
    assert text[4] == f"0.1 {2.0 / 3.0!r}"
    assert read_data(out).y[1, 0] == 1e-300  # type: ignore[index]


def test_write_is_atomic_on_bad_input(tmp_path: Path) -> None:
    out = tmp_path / "w.alta"
    _raises(InputError, write_alta, out, [1.0, 2.0], [1.0, np.nan], match="non-finite")
    _raises(InputError, write_csv, out, [1.0, 2.0], [1.0, 2.0], [1, 3], [2, 2], match="lo > hi")
    assert list(tmp_path.iterdir()) == []


def test_write_csv_rejects_ambiguous_names(tmp_path: Path) -> None:
    out = tmp_path / "w.csv"
    _raises(InputError, write_csv, out, [1.0], [1.0], input_names=["lo"], match="'lo'")
    _raises(InputError, write_csv, out, [1.0], [1.0], input_names=["a b"], match="'a b'")
    _raises(InputError, write_alta, out, [1.0], [1.0], param_in="a\nb", match="param_in")
    assert not out.exists()


# ---------------------------------------------------------------------------
# segments()
# ---------------------------------------------------------------------------
def test_segments_relative_absolute_and_both() -> None:
    ds = Dataset(
        np.array([[0.0], [1.0], [2.0]]),
        np.array([[1.0], [-100.0], [0.001]]),
        output_names=("v",),
    )
    rel = ds.segments(dt=0.1)
    assert np.allclose(rel.lo[:, 0], [0.9, -110.0, 0.0009])
    assert np.allclose(rel.hi[:, 0], [1.1, -90.0, 0.0011])
    ab = ds.segments(abs_width=0.5)
    assert ab.lo[:, 0].tolist() == [0.5, -100.5, 0.001 - 0.5]
    both = ds.segments(dt=0.1, abs_width=0.5)
    assert np.allclose(both.lo[:, 0], [0.5, -110.0, 0.001 - 0.5])
    assert np.allclose(both.hi[:, 0], [1.5, -90.0, 0.501])
    assert both.names == ("v",)
    _raises(InputError, ds.segments, dt=-1.0, match="dt")


def test_segments_bounds_only_needs_no_width() -> None:
    ds = Dataset(np.array([0.0, 1.0]), lo=np.array([0.0, 1.0]), hi=np.array([1.0, 2.0]))
    assert ds.y is None and ds.n_channels == 1
    assert ds.segments().hi[:, 0].tolist() == [1.0, 2.0]
    _raises(InputError, ds.segments, dt=0.1, match="no y values")


# ---------------------------------------------------------------------------
# CSV
# ---------------------------------------------------------------------------
def test_csv_headerless_and_dim(tmp_path: Path) -> None:
    p = _write(tmp_path / "a.csv", "# comment\n1,2,3\n\n4, 5 ,6\n")
    ds = read_data(p)
    assert ds.dim == 2 and ds.n_channels == 1 and ds.x.tolist() == [[1, 2], [4, 5]]
    ds1 = read_data(p, dim=1)
    assert ds1.dim == 1 and ds1.y is not None and ds1.y.tolist() == [[2, 3], [5, 6]]
    _raises(InputError, read_data, p, dim=3, match="no output column")
    bom = tmp_path / "bom.csv"
    bom.write_bytes("x,y\r\n1,2\r\n".encode("utf-8-sig"))
    assert read_data(bom).input_names == ("x",)
    w = _write(tmp_path / "w.txt", "1 2\n3\t4  \n")
    assert read_data(w).y.tolist() == [[2.0], [4.0]]  # type: ignore[union-attr]


def test_csv_header_roles(tmp_path: Path) -> None:
    p = _write(
        tmp_path / "h.csv",
        "theta,phi,y_r,y_g,lo_g,hi_g,lo_r,hi_r\n0,1,0.5,0.6,0.5,0.7,0.4,0.6\n",
    )
    ds = read_data(p)
    assert ds.input_names == ("theta", "phi") and ds.output_names == ("r", "g")
    assert ds.lo is not None and ds.hi is not None
    assert ds.lo.tolist() == [[0.4, 0.5]] and ds.hi.tolist() == [[0.6, 0.7]]
    q = _write(tmp_path / "b.csv", "x,lo,hi\n0,1,2\n1,2,3\n")
    dq = read_data(q)
    assert dq.y is None and dq.output_names == ("y",) and dq.segments().lo.tolist() == [[1], [2]]
    # A header with no y/lo/hi column is positional, like a header-less file.
    r = _write(tmp_path / "c.csv", "a,b,c\n0,1,2\n")
    dr = read_data(r, dim=1)
    assert dr.input_names == ("a",) and dr.output_names == ("b", "c")
    _raises(InputError, read_data, p, dim=3, match="dim=3")


def test_csv_bad_header(tmp_path: Path) -> None:
    p = _write(tmp_path / "h.csv", "x,y,lo\n0,1,2\n")
    _raises(FileFormatError, read_data, p, match="line 1: lo/hi columns must come in pairs")
    q = _write(tmp_path / "d.csv", "x,y_a,lo_b,hi_b\n0,1,2,3\n")
    _raises(FileFormatError, read_data, q, match="'a'")
    r = _write(tmp_path / "e.csv", "y,lo,hi\n0,1,2\n")
    _raises(FileFormatError, read_data, r, match="no input (x) column")


# ---------------------------------------------------------------------------
# NPZ
# ---------------------------------------------------------------------------
def test_npz_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    x, y = rng.normal(size=(30, 2)), rng.normal(size=(30, 2))
    lo, hi = y - 1, y + 2
    p = tmp_path / "d.npz"
    np.savez_compressed(
        p, x=x, y=y, lo=lo, hi=hi, input_names=np.array(["u", "v"]), output_names=["r", "g"]
    )
    ds = read_data(p)
    assert ds.meta["format"] == "npz"
    assert ds.input_names == ("u", "v") and ds.output_names == ("r", "g")
    assert np.array_equal(ds.x, x) and np.array_equal(ds.y, y)  # type: ignore[arg-type]
    assert np.array_equal(ds.lo, lo) and np.array_equal(ds.hi, hi)  # type: ignore[arg-type]
    b = tmp_path / "bytes.npz"
    np.savez(b, x=x, y=y, output_names=np.array([b"r", b"g"]))
    assert read_data(b).output_names == ("r", "g")
    q = tmp_path / "one.npz"
    np.savez(q, x=x[:, 0], y=y[:, 0])
    d1 = read_data(q)
    assert d1.x.shape == (30, 1) and d1.lo is None and d1.output_names == ("y0",)


def test_npz_errors(tmp_path: Path) -> None:
    noise = tmp_path / "noise.npz"
    noise.write_bytes(np.random.default_rng(0).bytes(500))
    _raises(FileFormatError, read_data, noise, match="not a readable .npz")

    good = tmp_path / "good.npz"
    np.savez(good, x=np.arange(100.0), y=np.arange(100.0))
    cut = tmp_path / "cut.npz"
    cut.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    _raises(FileFormatError, read_data, cut, match="corrupt or truncated")

    # A zip whose member is damaged (CRC mismatch) must not escape as BadZipFile.
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as zf:
        with zf.open("x.npy", "w") as fh:
            np.save(fh, np.arange(50.0))
    raw = bytearray(buf.getvalue())
    raw[200] ^= 0xFF
    bad = tmp_path / "crc.npz"
    bad.write_bytes(bytes(raw))
    _raises(FileFormatError, read_data, bad, match="corrupt or truncated")

    nox = tmp_path / "nox.npz"
    np.savez(nox, a=np.arange(3.0), y=np.arange(3.0))
    _raises(FileFormatError, read_data, nox, match="no 'x' array; keys found: ['a', 'y']")
    nolo = tmp_path / "nolo.npz"
    np.savez(nolo, x=np.arange(3.0), lo=np.arange(3.0))
    _raises(FileFormatError, read_data, nolo, match="only one of 'lo'/'hi'")
    nan = tmp_path / "nan.npz"
    np.savez(nan, x=np.arange(3.0), y=np.array([1.0, np.nan, 2.0]))
    _raises(InputError, read_data, nan, match="row 1: non-finite value nan")
    swapped = tmp_path / "swapped.npz"
    np.savez(swapped, x=np.arange(3.0), lo=np.array([0.0, 2, 0]), hi=np.array([1.0, 1, 1]))
    _raises(InputError, read_data, swapped, match="lo > hi at row 1")
    obj = tmp_path / "obj.npz"
    np.savez(obj, x=np.array([1, "a"], dtype=object), y=np.arange(2.0))
    _raises(FileFormatError, read_data, obj, match="not a readable .npz")


# ---------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------
def test_dispatch_errors(tmp_path: Path) -> None:
    _raises(FileFormatError, read_data, tmp_path / "none.dat", match="no such file")
    p = _write(tmp_path / "a.csv", "1,2\n")
    msg = _raises(InputError, read_data, p, fmt="xls", match="unknown data format 'xls'")
    assert all(f in msg for f in FORMATS)
    _raises(InputError, read_data, p, dim=0, match="dim must be a positive integer")
    _raises(FileFormatError, read_data, tmp_path, match="is a directory")


def test_dim_must_match_declared(shared_data: Path) -> None:
    path = shared_data / "alta" / "retro-3M-jaune.dat"
    _raises(InputError, read_data, path, dim=2, match="3 input dimension(s) but dim=2")


@pytest.mark.parametrize(
    ("text", "exc", "match"),
    [
        # truncated row
        (
            "#DIM 1 1\n#VS 0\n1 2\n3\n",
            FileFormatError,
            "line 4: expected 2 numbers (#DIM 1 1, #VS 0), got 1",
        ),
        ("#DIM 2 1\n#VS 2\n1 2 3 4 5 6\n", FileFormatError, "line 3: expected 5 numbers"),
        # bad #DIM
        ("#DIM 1\n1 2\n", FileFormatError, "line 1: malformed #DIM header"),
        ("#DIM a b\n1 2\n", FileFormatError, "line 1: malformed #DIM header"),
        ("#DIM 0 1\n1 2\n", FileFormatError, "nx and ny must be >= 1"),
        ("#DIM 1 1\n#DIM 1 1\n1 2\n", FileFormatError, "line 2: duplicate #DIM"),
        (
            "#ALTA_BEGIN_HEADER\n#VS 0\n#ALTA_END_HEADER\n1 2\n",
            FileFormatError,
            "line 4: data row before the #DIM",
        ),
        ("#DIM 1 1\n#VS 3\n1 2\n", FileFormatError, "line 2: malformed #VS"),
        # non-numeric token
        ("#DIM 1 1\n1 2\n3 4x\n", FileFormatError, "line 3: non-numeric value '4x' in column 2"),
        # binary
        ("#DIM 1 1\n#FORMAT binary\n", FileFormatError, "line 2: ALTA binary files"),
        # NaN / inf
        ("#DIM 1 1\n1 2\n3 nan\n", InputError, "line 3: non-finite value nan in column 'y0'"),
        ("#DIM 1 1\n-inf 2\n", InputError, "line 2: non-finite value -inf in column 'x0'"),
        # lo > hi
        ("#DIM 1 1\n#VS 2\n1 2 1 3\n2 2 3 1\n", InputError, "line 4: lo > hi at row 1"),
        ("#DIM 1 1\n#VS 1\n1 2 -0.5\n", InputError, "line 3: lo > hi at row 0, channel 'y0'"),
        # header only
        ("#DIM 1 1\n#VS 0\n", FileFormatError, "no data rows"),
    ],
)
def test_alta_errors(tmp_path: Path, text: str, exc: type[Exception], match: str) -> None:
    p = _write(tmp_path / "bad.dat", text)
    msg = _raises(exc, read_data, p, match=match)
    assert str(p) in msg


def test_alta_missing_dim_and_binary_body(tmp_path: Path) -> None:
    p = _write(tmp_path / "nodim.alta", "#VS 0\n#PARAM_IN X\n")
    _raises(FileFormatError, read_data, p, match="missing '#DIM nx ny' header")
    q = _write(tmp_path / "x.csv", "1 2\n")
    _raises(FileFormatError, read_data, q, fmt="alta", match="line 1: data row before the #DIM")
    b = tmp_path / "bin.dat"
    b.write_bytes(b"#DIM 1 1\n#VS 0\n1 2\n\xff\xfe\x00\x01\n")
    _raises(FileFormatError, read_data, b, match="line 4: not a text file")


@pytest.mark.parametrize(
    ("text", "exc", "match"),
    [
        ("1,2\n3,4,5\n", FileFormatError, "line 2: expected 2 values, got 3"),
        ("x,y\n1,2\n3\n", FileFormatError, "line 3: expected 2 values, got 1"),
        ("x,y\n1,2\n3,abc\n", FileFormatError, "line 3: non-numeric value 'abc' in column 2"),
        ("x,y\n1,\n", FileFormatError, "line 2: empty value in column 2"),
        ("1,,2\n", FileFormatError, "line 1: empty value in column 2"),
        ("x,y\n1,2\n3,NaN\n", InputError, "line 3: non-finite value nan in column 'y'"),
        ("x,y,lo,hi\n1,2,1,3\n2,2,3,1\n", InputError, "line 3: lo > hi at row 1, channel 'y'"),
        ("", FileFormatError, "empty file"),
        ("  \n\n", FileFormatError, "empty file"),
        ("# only a comment\n", FileFormatError, "no data"),
        ("x,y\n", FileFormatError, "no data rows after the header"),
        ("x,x,y\n1,2,3\n", FileFormatError, "line 1: duplicate column names"),
        ("5\n6\n", FileFormatError, "need at least 2 columns"),
    ],
)
def test_csv_errors(tmp_path: Path, text: str, exc: type[Exception], match: str) -> None:
    p = _write(tmp_path / "bad.csv", text)
    msg = _raises(exc, read_data, p, match=match)
    assert str(p) in msg


def test_empty_file_any_format(tmp_path: Path) -> None:
    p = _write(tmp_path / "empty.dat", "")
    for fmt in ("alta", "csv", "nist"):
        _raises(FileFormatError, read_data, p, fmt=fmt, match="empty file")
    _raises(FileFormatError, read_data, p, fmt="npz", match="not a readable .npz")


def test_nist_truncated(shared_data: Path, tmp_path: Path) -> None:
    raw = (shared_data / "nist" / "Kirby2.dat").read_bytes()
    lines = raw.split(b"\r\n")
    cut = tmp_path / "Kirby2-cut.dat"
    cut.write_bytes(b"\r\n".join(lines[:-6]))
    _raises(
        FileFormatError,
        read_data,
        cut,
        match="truncated: header says 151 observations, found 146 data rows",
    )
    # Cut in the middle of a row: the partial row is reported with its line.
    half = tmp_path / "Kirby2-half.dat"
    half.write_bytes(raw[: raw.rindex(b"371.30E0")].rstrip())
    _raises(FileFormatError, read_data, half, match="line 211: expected 2 numbers (y x), got 1")


def test_nist_header_errors(shared_data: Path, tmp_path: Path) -> None:
    raw = (shared_data / "nist" / "MGH09.dat").read_bytes()
    nodata = tmp_path / "nodata.dat"
    nodata.write_bytes(raw.replace(b"Data:  y               x", b"Values: y x"))
    _raises(FileFormatError, read_data, nodata, match="no 'Data:' line with column names")
    nonum = tmp_path / "nonum.dat"
    nonum.write_bytes(raw.replace(b"Number of Observations:", b"Observations:"))
    _raises(FileFormatError, read_data, nonum, match="no 'Number of Observations:'")
    notnist = _write(tmp_path / "n.dat", "1 2\n")
    _raises(FileFormatError, read_data, notnist, fmt="nist", match="not a NIST StRD file")


# ---------------------------------------------------------------------------
# property: random finite floats survive ALTA and CSV round trips bit-exactly
# ---------------------------------------------------------------------------
# ratfit refuses magnitudes beyond 1e300 (core.segments.MAX_MAGNITUDE) on read
_finite = st.floats(-1e300, 1e300, allow_nan=False, allow_infinity=False, width=64)


@st.composite
def _tables(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    n = draw(st.integers(1, 12))
    d = draw(st.integers(1, 3))
    k = draw(st.integers(1, 2))
    x = draw(hnp.arrays(np.float64, (n, d), elements=_finite))
    y = draw(hnp.arrays(np.float64, (n, k), elements=_finite))
    if not draw(st.booleans()):
        return x, y, None, None
    a = draw(hnp.arrays(np.float64, (n, k), elements=_finite))
    b = draw(hnp.arrays(np.float64, (n, k), elements=_finite))
    return x, y, np.minimum(a, b), np.maximum(a, b)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_tables())
def test_round_trip_property(
    table: tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None],
) -> None:
    x, y, lo, hi = table
    with tempfile.TemporaryDirectory() as tmp:
        alta = Path(tmp) / "p.alta"
        write_alta(alta, x, y, lo=lo, hi=hi)
        a = read_data(alta)
        csv = Path(tmp) / "p.csv"
        write_csv(csv, x, y, lo, hi)
        c = read_data(csv)
    for ds in (a, c):
        assert np.array_equal(ds.x, x) and np.array_equal(ds.y, y)  # type: ignore[arg-type]
        # -0.0 must survive too: compare signs bitwise.
        assert np.array_equal(np.signbit(ds.x), np.signbit(x))
        if lo is None:
            assert ds.lo is None and ds.hi is None
        else:
            assert np.array_equal(ds.lo, lo) and np.array_equal(ds.hi, hi)  # type: ignore[arg-type]
