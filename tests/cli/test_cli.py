"""End-to-end tests of the ``ratfit`` command line.

Conventions checked here (the project's rules):

* exit code 0 on success, 1 when a run finds no verified fit, 2 on bad input or usage;
* bad input gives ONE line ``error: ...`` on stderr naming the problem, no traceback,
  nothing on stdout, and no output file (also when ``-o`` points into a fresh folder);
* ``--json`` prints exactly one strict JSON object (no NaN/Infinity tokens);
* ``eval`` reproduces the saved fit exactly; ``demo addendum`` matches the paper's table.

Most tests run the CLI in-process with :class:`click.testing.CliRunner`; a few run a
real subprocess where that matters (traceback absence, the installed entry point, pipes).
"""

from __future__ import annotations

import json
import re
import struct
import subprocess
import sys
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import Result
from conftest import one_error_line, run_cli, write_file

from ratfit.core.solvers import available_solvers
from ratfit.io.data import read_data, write_alta, write_csv
from ratfit.io.fitfile import load_fit

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

FIT_JSON_KEYS = {
    "n",
    "m",
    "total",
    "basis",
    "verified",
    "max_violation",
    "linf",
    "l2",
    "max_rel_error",
    "delta",
    "sigma_min",
    "sigma_max",
    "seconds",
}

# The seed's table for n = m = 20 (delta, sigma_min, sigma_max).
PAPER = {
    "legendre": (1.4e-05, 0.10, 7160.0),
    "chebyshev": (1.0e-05, 0.11, 11023.0),
    "monomial": (1.8e-10, 1.5e-06, 8173.0),
}


# ------------------------------------------------------------------------------- helpers
cli = run_cli


def script_cmd() -> list[str]:
    """The installed ``ratfit`` entry point next to this interpreter, else ``-m``."""
    exe = Path(sys.executable).with_name("ratfit")
    return [str(exe)] if exe.is_file() else [sys.executable, "-m", "ratfit"]


def _reject_constant(name: str) -> Any:
    raise AssertionError(f"non-standard JSON token {name!r} in --json output")


def strict_json(text: str) -> dict[str, Any]:
    """The whole text must be exactly one JSON object without NaN/Infinity tokens."""
    doc = json.loads(text, parse_constant=_reject_constant)
    assert isinstance(doc, dict), f"--json printed a {type(doc).__name__}, not an object"
    return doc


def assert_no_crash(result: Result) -> None:
    assert result.exception is None or isinstance(result.exception, SystemExit), (
        f"uncaught {type(result.exception).__name__}: {result.exception}"
    )
    assert "Traceback" not in result.output


def assert_not_written(out: Path) -> None:
    """No output file, and no stray temporary file beside where it would have been."""
    assert not out.exists(), f"{out} was written"
    if out.parent.exists():
        assert not any(out.parent.iterdir()), f"left behind: {list(out.parent.iterdir())}"


def assert_error_line(result: Result, patterns: tuple[str, ...], out: Path | None) -> str:
    """Exit 2, one ``error:`` line on stderr matching every regex in ``patterns``."""
    assert_no_crash(result)
    line = one_error_line(result, *patterns)
    if out is not None:
        assert_not_written(out)
    return line


def assert_usage_error(result: Result, patterns: tuple[str, ...], out: Path | None) -> None:
    """A click usage error: exit 2, an ``Error:`` line naming the problem, no file."""
    assert_no_crash(result)
    assert result.exit_code == 2, f"exit {result.exit_code}\n{result.output}"
    err = [ln for ln in result.stderr.splitlines() if ln.lower().startswith("error:")]
    assert len(err) == 1, result.stderr
    for pat in patterns:
        assert re.search(pat, err[0], re.IGNORECASE), f"{pat!r} not in {err[0]!r}"
    assert result.stdout == ""
    if out is not None:
        assert_not_written(out)


def tiny_png(width: int = 2, height: int = 2) -> bytes:
    """A valid grayscale PNG image, built by hand."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    raw = b"".join(b"\x00" + bytes(range(width)) for _ in range(height))
    return (
        PNG_SIGNATURE
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(raw))
        + chunk(b"IEND", b"")
    )


def png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE, f"{path} is not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def addendum_f(x: np.ndarray) -> np.ndarray:
    return 1000 * np.exp(-(x**2)) * x**2 + 0.1 * np.exp(-100 * (x - 9) ** 2) * x**3 + 0.1


def rational_2d(x: np.ndarray) -> np.ndarray:
    """Degree (1, 1) in two variables: exactly representable with n = m = 3 (total order)."""
    return (2 + x[:, 0] + 0.5 * x[:, 1]) / (3 + 0.5 * x[:, 0] - x[:, 1])


def _cut_last_row(data: bytes) -> bytes:
    """Cut a text file inside its last data row, keeping only that row's first number."""
    eol = b"\r\n" if b"\r\n" in data else b"\n"
    lines = data.rstrip().split(eol)
    first = lines[-1].split()[0]
    indent = lines[-1][: len(lines[-1]) - len(lines[-1].lstrip())]
    return eol.join(lines[:-1]) + eol + indent + first


# ------------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def nist_fits(shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Kirby2 and MGH09 fitted once with --abs-width 3 x certified residual SD."""
    out: dict[str, Any] = {}
    tmp = tmp_path_factory.mktemp("nist")
    for name in ("Kirby2", "MGH09"):
        path = shared_data / "nist" / f"{name}.dat"
        data = read_data(path)
        w = 3 * data.meta["certified_residual_sd"]
        fit_path = tmp / "fresh" / f"{name}.json"
        res = cli("fit", path, "--abs-width", repr(w), "-o", fit_path, "--json")
        out[name] = {"path": path, "data": data, "w": w, "fit": fit_path, "result": res}
    return out


@pytest.fixture(scope="module")
def csv_2d(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rng = np.random.default_rng(12345)
    x = rng.uniform(-1.0, 1.0, (200, 2))
    path = tmp_path_factory.mktemp("two_d") / "rat2d.csv"
    write_csv(path, x, rational_2d(x))
    return path


@pytest.fixture(scope="module")
def addendum_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    x = np.linspace(0.0, 10.0, 1000)
    path = tmp_path_factory.mktemp("addendum") / "addendum.csv"
    write_csv(path, x, addendum_f(x))
    return path


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """``ratfit demo addendum --json`` run once for the whole module (a few seconds)."""
    outdir = tmp_path_factory.mktemp("demo") / "figs"
    res = cli("demo", "addendum", "-o", outdir, "--json")
    return {"result": res, "outdir": outdir}


# ------------------------------------------------------------------------------- help
@pytest.mark.parametrize(
    "args", [["--help"], ["fit", "--help"], ["eval", "--help"], ["demo", "addendum", "--help"]]
)
def test_help_exits_zero(args: list[str]) -> None:
    res = cli(*args)
    assert res.exit_code == 0, res.output
    assert "Usage:" in res.stdout
    if args[0] == "fit":
        for opt in (
            "--basis",
            "--dt",
            "--abs-width",
            "--total",
            "--min-total",
            "--max-total",
            "--index-set",
            "--solver",
            "--jobs",
            "--json",
        ):
            assert opt in res.stdout


# ------------------------------------------------------------------------------- NIST fits
@pytest.mark.parametrize("name,max_total", [("Kirby2", 6), ("MGH09", 4)])
def test_fit_nist_within_three_certified_sd(nist_fits: dict, name: str, max_total: int) -> None:
    case = nist_fits[name]
    res: Result = case["result"]
    assert_no_crash(res)
    assert res.exit_code == 0, res.output
    doc = strict_json(res.stdout)
    assert FIT_JSON_KEYS <= doc.keys()
    assert doc["total"] <= max_total
    assert doc["n"] + doc["m"] == doc["total"]
    assert doc["verified"] is True
    assert doc["max_violation"] == 0
    assert doc["basis"] == "legendre"
    assert doc["linf"] <= case["w"]
    assert doc["output"] == str(case["fit"])

    saved = load_fit(case["fit"])
    data = case["data"]
    assert len(saved.channels) == 1
    assert saved.space.dim == 1
    rf = saved.channels[0].rational
    assert (rf.n, rf.m) == (doc["n"], doc["m"])
    vals = saved(data.x)
    assert vals.shape == (data.n_points, 1)
    y, w = data.y[:, 0], case["w"]
    v = vals[:, 0]
    assert np.all(np.isfinite(v))
    assert np.all(v >= y - w), f"below y - w at rows {np.flatnonzero(v < y - w)}"
    assert np.all(v <= y + w), f"above y + w at rows {np.flatnonzero(v > y + w)}"
    # The JSON's own error figures are those of the saved function.
    assert np.max(np.abs(v - y)) == pytest.approx(doc["linf"], rel=1e-9)
    prov = saved.provenance
    assert prov["segments"]["abs_width"] == pytest.approx(w, rel=1e-15)
    assert prov["n_points"] == data.n_points


def test_kirby2_minimal_total_is_minimal(nist_fits: dict) -> None:
    """Nothing with one coefficient fewer fits Kirby2 at 3 SD: the search is not lazy."""
    case = nist_fits["Kirby2"]
    total = strict_json(case["result"].stdout)["total"]
    res = cli(
        "fit", case["path"], "--abs-width", repr(case["w"]), "--max-total", total - 1, "--json"
    )
    assert res.exit_code == 1, res.output
    assert strict_json(res.stdout)["verified"] is False


def test_kirby2_nist_and_alta_copies_agree(nist_fits: dict, shared_data: Path) -> None:
    """The ALTA copy of Kirby2 (same numbers, other format) gives the same minimal fit."""
    case = nist_fits["Kirby2"]
    res = cli("fit", shared_data / "alta" / "Kirby2.dat", "--abs-width", repr(case["w"]), "--json")
    assert res.exit_code == 0, res.output
    a, b = strict_json(res.stdout), strict_json(case["result"].stdout)
    assert (a["n"], a["m"]) == (b["n"], b["m"])


# ------------------------------------------------------------------------------- eval
def test_eval_csv_stdout_matches_saved_fit(nist_fits: dict, tmp_path: Path) -> None:
    case = nist_fits["Kirby2"]
    res = cli("eval", case["fit"], case["path"])
    assert res.exit_code == 0, res.output
    assert res.stderr == ""
    lines = res.stdout.splitlines()
    assert len(lines) == 152
    assert len(lines[0].split(",")) == 2
    table = np.array([[float(t) for t in ln.split(",")] for ln in lines[1:]])
    data = case["data"]
    expected = load_fit(case["fit"])(data.x)
    np.testing.assert_array_equal(table[:, :1], data.x)
    np.testing.assert_allclose(table[:, 1:], expected, rtol=1e-12, atol=0)

    out = tmp_path / "fresh" / "vals.csv"
    res2 = cli("eval", case["fit"], case["path"], "-o", out)
    assert res2.exit_code == 0, res2.output
    assert out.read_text() == res.stdout


def test_eval_npy_output(nist_fits: dict, tmp_path: Path) -> None:
    case = nist_fits["Kirby2"]
    out = tmp_path / "fresh" / "vals.npy"
    res = cli("eval", case["fit"], case["path"], "-o", out)
    assert res.exit_code == 0, res.output
    assert res.stdout == ""
    arr = np.load(out, allow_pickle=False)
    assert arr.shape == (151, 1)
    assert arr.dtype == np.float64
    np.testing.assert_allclose(arr, load_fit(case["fit"])(case["data"].x), rtol=1e-12, atol=0)


def test_eval_npy_suffix_case_insensitive(nist_fits: dict, tmp_path: Path) -> None:
    case = nist_fits["Kirby2"]
    out = tmp_path / "vals.NPY"
    res = cli("eval", case["fit"], case["path"], "-o", out)
    assert res.exit_code == 0, res.output
    assert np.load(out, allow_pickle=False).shape == (151, 1)


def test_eval_multichannel_roundtrip(tmp_path: Path) -> None:
    x = np.linspace(0.0, 1.0, 50)
    y = np.stack([1 / (1 + x), (1 + x**2) / (2 + x)], axis=1)
    src = tmp_path / "two_channels.csv"
    write_csv(src, x, y, output_names=("a", "b"))
    fit_path = tmp_path / "fit.json"
    res = cli("fit", src, "--dt", "0.01", "-o", fit_path, "--json")
    assert res.exit_code == 0, res.output
    doc = strict_json(res.stdout)
    assert FIT_JSON_KEYS <= doc.keys()
    assert doc["verified"] is True
    assert [c["channel"] for c in doc["channels"]] == ["a", "b"]
    assert doc["total"] == sum(c["total"] for c in doc["channels"])
    # 1/(1+x) needs n=1, m=2 at most; (1+x^2)/(2+x) at most 3 + 2.
    assert doc["channels"][0]["total"] <= 3
    assert doc["channels"][1]["total"] <= 5
    out = tmp_path / "vals.npy"
    assert cli("eval", fit_path, src, "-o", out).exit_code == 0
    vals = np.load(out)
    assert vals.shape == (50, 2)
    assert np.all(np.abs(vals - y) <= 0.01 * y * (1 + 1e-12))


# ------------------------------------------------------------------------------- 2-D data
SOLVER_ARGS = [s for s in ("daqp", "clarabel") if s in available_solvers()]


@pytest.mark.parametrize(
    "args,expect",
    [
        (["--n", "3", "--m", "3"], {"n": 3, "m": 3}),
        (["--total", "6"], {"total": 6, "min_qps": 5}),
        (["--basis", "chebyshev"], {"basis": "chebyshev", "max_total": 6}),
        (["--basis", "monomial"], {"basis": "monomial", "max_total": 6}),
        (["--index-set", "tensor"], {"index_set": "tensor", "max_total": 8}),
        (["--index-set", "tensor", "--n", "4", "--m", "4"], {"index_set": "tensor", "n": 4}),
        (["--jobs", "1"], {"max_total": 6}),
        (["--strategy", "exhaustive", "--split-rule", "error"], {"max_total": 6}),
        *[(["--solver", s], {"max_total": 6}) for s in SOLVER_ARGS],
    ],
    ids=lambda v: " ".join(v) if isinstance(v, list) else "",
)
def test_fit_2d_variants(csv_2d: Path, tmp_path: Path, args: list[str], expect: dict) -> None:
    out = tmp_path / "fresh" / "fit.json"
    res = cli("fit", csv_2d, "--dt", "0.02", "-o", out, "--json", *args)
    assert_no_crash(res)
    assert res.exit_code == 0, res.output
    doc = strict_json(res.stdout)
    assert FIT_JSON_KEYS <= doc.keys()
    assert doc["verified"] is True
    assert doc["max_violation"] == 0
    assert doc["basis"] == expect.get("basis", "legendre")
    assert doc["index_set"] == expect.get("index_set", "total")
    for key in ("n", "m", "total"):
        if key in expect:
            assert doc[key] == expect[key]
    if "max_total" in expect:
        assert doc["total"] <= expect["max_total"]
    if "min_qps" in expect:  # every split of the total was tried
        assert doc["qp_solves"] >= expect["min_qps"]

    saved = load_fit(out)
    assert saved.space.dim == 2
    assert saved.space.index_set == doc["index_set"]
    data = read_data(csv_2d)
    y = data.y[:, 0]
    v = saved(data.x)[:, 0]
    assert np.all(v >= 0.98 * y) and np.all(v <= 1.02 * y)


def test_fit_jobs_do_not_change_the_answer(csv_2d: Path) -> None:
    a = strict_json(cli("fit", csv_2d, "--dt", "0.005", "--json", "--jobs", "1").stdout)
    b = strict_json(cli("fit", csv_2d, "--dt", "0.005", "--json", "--jobs", "4").stdout)
    assert (a["n"], a["m"], a["verified"]) == (b["n"], b["m"], b["verified"])
    assert a["verified"] is True


# ------------------------------------------------------------------------------- no fit
def test_infeasible_range_exit_1_json(addendum_csv: Path, tmp_path: Path) -> None:
    out = tmp_path / "fresh" / "fit.json"
    res = cli("fit", addendum_csv, "--dt", "0.1", "--max-total", "8", "-o", out, "--json")
    assert_no_crash(res)
    assert res.exit_code == 1, res.output
    doc = strict_json(res.stdout)
    assert FIT_JSON_KEYS <= doc.keys()
    assert doc["verified"] is False
    assert doc["success"] is False
    assert doc["total"] <= 8
    assert "no verified fit" in doc["message"]
    assert doc["output"] is None
    assert_not_written(out)


def test_infeasible_range_exit_1_report(addendum_csv: Path, tmp_path: Path) -> None:
    out = tmp_path / "fit.json"
    res = cli("fit", addendum_csv, "--dt", "0.1", "--max-total", "8", "-o", out)
    assert_no_crash(res)
    assert res.exit_code == 1, res.output
    assert "no verified fit" in " ".join(res.stdout.split())
    assert "no fit file written" in res.stderr
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------------------- bad input
@dataclass
class Ctx:
    tmp: Path
    request: pytest.FixtureRequest

    def shared(self) -> Path:
        return self.request.getfixturevalue("shared_data")

    def write(self, name: str, content: str | bytes) -> Path:
        return write_file(self.tmp, name, content)

    def good_csv(self) -> Path:
        x = np.linspace(0.0, 1.0, 30)
        path = self.tmp / "good.csv"
        write_csv(path, x, 1.0 / (1.0 + x))
        return path

    def good_fit(self) -> Path:
        path = self.tmp / "good_fit.json"
        res = cli("fit", self.good_csv(), "--dt", "0.01", "-o", path, "--json")
        assert res.exit_code == 0, res.output
        return path


def _truncated_alta(c: Ctx) -> list[object]:
    x = np.linspace(0.0, 1.0, 20)
    full = c.tmp / "full.alta"
    write_alta(full, x, 1.0 + x)
    return [c.write("data.alta", _cut_last_row(full.read_bytes())), "--dt", "0.1"]


def _truncated_nist_at_row(c: Ctx) -> list[object]:
    data = (c.shared() / "nist" / "Kirby2.dat").read_bytes()
    lines = data.split(b"\r\n")
    return [c.write("data.dat", b"\r\n".join(lines[:-10]) + b"\r\n"), "--dt", "0.1"]


def _mismatched_npz(c: Ctx) -> list[object]:
    path = c.tmp / "data.npz"
    np.savez(path, x=np.linspace(0, 1, 5), y=np.ones(4))
    return [path, "--dt", "0.1"]


def _eval_nan_coefficient(c: Ctx) -> list[object]:
    doc = json.loads(c.good_fit().read_text())
    doc["channels"][0]["p"][0] = float("nan")
    return ["eval", c.write("fit.json", json.dumps(doc)), c.good_csv()]


def _npz_nan(c: Ctx) -> list[object]:
    path = c.tmp / "data.npz"
    np.savez(path, x=np.array([0.0, 1.0, np.nan]), y=np.array([1.0, 2.0, 3.0]))
    return [path, "--dt", "0.1"]


def _npy_as_npz(c: Ctx) -> list[object]:
    path = c.tmp / "data.npz"
    with open(path, "wb") as fh:
        np.save(fh, np.ones((3, 2)))
    return [path, "--dt", "0.1"]


FitCase = Callable[[Ctx], list[object]]

BAD_FIT: dict[str, tuple[FitCase, tuple[str, ...]]] = {
    "nan-in-y": (
        lambda c: [c.write("data.csv", "x,y\n0,1\n1,nan\n2,3\n"), "--dt", "0.1"],
        ("data.csv", r"\bnan\b", "line 3"),
    ),
    "inf-in-x": (
        lambda c: [c.write("data.csv", "x,y\n0,1\ninf,2\n2,3\n"), "--dt", "0.1"],
        ("data.csv", r"\binf", "line 3"),
    ),
    "nan-in-npz": (_npz_nan, ("data.npz", r"\bnan\b", r"\bx\b")),
    "lo-gt-hi-alta": (
        lambda c: [
            c.write("data.alta", "#DIM 1 1\n#VS 2\n0 1 0.9 1.1\n1 2 2.5 1.5\n2 3 2.9 3.1\n")
        ],
        ("data.alta", r"lo\s*>\s*hi", "line 4"),
    ),
    "lo-gt-hi-csv": (
        lambda c: [c.write("data.csv", "x,lo,hi\n0,1,2\n1,3,2\n2,3,4\n")],
        ("data.csv", r"lo\s*>\s*hi", "line 3"),
    ),
    "empty-file": (lambda c: [c.write("data.csv", ""), "--dt", "0.1"], ("data.csv", "empty")),
    "blank-lines-only": (
        lambda c: [c.write("data.csv", "\n  \n\n"), "--dt", "0.1"],
        ("data.csv", "empty|no data"),
    ),
    "header-only": (
        lambda c: [c.write("data.csv", "x,y\n"), "--dt", "0.1"],
        ("data.csv", "no data"),
    ),
    "ragged-rows": (
        lambda c: [c.write("data.csv", "x,y\n0,1\n1,2,3\n2,3\n"), "--dt", "0.1"],
        ("data.csv", "line 3", r"expected 2|got 3"),
    ),
    "mismatched-lengths-npz": (
        _mismatched_npz,
        ("data.npz", "mismatch|length", r"\b5\b", r"\b4\b"),
    ),
    "non-numeric-value": (
        lambda c: [c.write("data.csv", "x,y\n0,1\n1,two\n2,3\n"), "--dt", "0.1"],
        ("data.csv", "line 3", "two"),
    ),
    "x-constant-in-a-dimension": (
        lambda c: [c.write("data.csv", "a,b,y\n0,5,1\n1,5,2\n2,5,3\n3,5,4\n"), "--dt", "0.1"],
        (r"\bx\b", "constant", "dimension 1"),
    ),
    "n-zero": (
        lambda c: [c.good_csv(), "--dt", "0.1", "--n", "0", "--m", "3"],
        (r"\bn\b", r">= ?1|positive|at least"),
    ),
    "m-zero": (
        lambda c: [c.good_csv(), "--dt", "0.1", "--n", "3", "--m", "0"],
        (r"\bm\b", r">= ?1|positive|at least"),
    ),
    "dt-negative": (lambda c: [c.good_csv(), "--dt", "-0.1"], (r"\bdt\b", r"-0\.1")),
    "dt-nan": (lambda c: [c.good_csv(), "--dt", "nan"], (r"\bdt\b", "nan")),
    "abs-width-negative": (lambda c: [c.good_csv(), "--abs-width", "-1"], (r"abs.width", "-1")),
    "abs-width-inf": (lambda c: [c.good_csv(), "--abs-width", "inf"], (r"abs.width", "inf")),
    "missing-input": (
        lambda c: [c.tmp / "nosuch.csv", "--dt", "0.1"],
        ("nosuch.csv", "no such file|not found|does not exist"),
    ),
    "random-bytes-npz": (
        lambda c: [
            c.write("data.npz", b"\x00\x01" + np.random.default_rng(0).bytes(400)),
            "--dt",
            "0.1",
        ],
        ("data.npz", "npz|zip"),
    ),
    "npy-named-npz": (_npy_as_npz, ("data.npz", "npy|npz")),
    "png-named-csv": (
        lambda c: [c.write("data.csv", tiny_png()), "--dt", "0.1"],
        ("data.csv", "text|binary|png"),
    ),
    "alta-binary-real": (
        lambda c: [c.shared() / "alta" / "brdf_small_simu_two_layers_binary.alta", "--dt", "0.1"],
        ("binary",),
    ),
    "alta-function-file-real": (
        lambda c: [c.shared() / "alta" / "fits" / "Kirby2.brdf", "--dt", "0.1"],
        ("function|fit result",),
    ),
    "exr-image-real": (  # issue 27: names the command that fits it
        lambda c: [c.shared() / "alta" / "data-example-01.exr", "--dt", "0.1"],
        ("data-example-01.exr", "measured BRDF file \\(exr\\)", "`ratfit brdf fit "),
    ),
    "cornell-brdf-real": (
        lambda c: [c.shared() / "cornell" / "cayman.brdf", "--dt", "0.1"],
        ("cayman.brdf", "measured BRDF file \\(cornell\\)", "`ratfit brdf fit "),
    ),
    "truncated-alta-mid-row": (_truncated_alta, ("data.alta", "line 24", r"expected \d")),
    "truncated-alta-real": (
        lambda c: [
            c.write("data.dat", _cut_last_row((c.shared() / "alta" / "Kirby2.dat").read_bytes())),
            "--dt",
            "0.1",
        ],
        ("data.dat", "line 157", r"expected 2|got 1"),
    ),
    "truncated-nist-mid-row": (
        lambda c: [
            c.write("data.dat", _cut_last_row((c.shared() / "nist" / "Kirby2.dat").read_bytes())),
            "--dt",
            "0.1",
        ],
        ("data.dat", "line 211", r"expected 2|got 1|truncated"),
    ),
    "truncated-nist-at-row": (_truncated_nist_at_row, ("data.dat", "truncated|151")),
    "no-intervals": (
        lambda c: [c.write("data.alta", "#DIM 1 1\n#VS 0\n0 1\n1 2\n2 3\n")],
        ("data.alta", "--dt", "--abs-width"),
    ),
    "bounds-only-with-dt": (
        lambda c: [c.write("data.csv", "x,lo,hi\n0,1,2\n1,2,3\n2,3,4\n"), "--dt", "0.1"],
        ("data.csv", r"\by\b", r"dt"),
    ),
    "unknown-solver": (
        lambda c: [c.good_csv(), "--dt", "0.1", "--solver", "nope"],
        ("solver", "nope"),
    ),
    "min-total-above-max-total": (
        lambda c: [c.good_csv(), "--dt", "0.1", "--min-total", "10", "--max-total", "5"],
        (r"max.total|min.total", r"\b5\b|\b10\b"),
    ),
    "total-one": (lambda c: [c.good_csv(), "--dt", "0.1", "--total", "1"], ("total", r"\b1\b")),
    "jobs-zero": (lambda c: [c.good_csv(), "--dt", "0.1", "--jobs", "0"], ("jobs",)),
    "channel-out-of-range": (
        lambda c: [c.good_csv(), "--dt", "0.1", "--channel", "3"],
        ("channel", r"\b3\b"),
    ),
    "single-point": (
        lambda c: [c.write("data.csv", "x,y\n1,2\n"), "--dt", "0.1"],
        ("single|one point|domain",),
    ),
    "wrong-format-flag": (
        lambda c: [c.good_csv(), "--dt", "0.1", "--format", "nist"],
        ("good.csv", "nist"),
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_FIT))
def test_fit_bad_input(case: str, tmp_path: Path, request: pytest.FixtureRequest) -> None:
    build, patterns = BAD_FIT[case]
    ctx = Ctx(tmp_path, request)
    args = build(ctx)
    out = tmp_path / "fresh" / "fit.json"
    res = cli("fit", *args, "-o", out, "--json")
    assert_error_line(res, patterns, out)
    # Same without --json: the human report must not appear either.
    res2 = cli("fit", *args, "-o", out)
    assert_error_line(res2, patterns, out)


BAD_USAGE: dict[str, tuple[list[str], tuple[str, ...]]] = {
    "unknown-basis": (["--dt", "0.1", "--basis", "foo"], ("basis", "foo")),
    "unknown-index-set": (["--dt", "0.1", "--index-set", "sparse"], ("index.set", "sparse")),
    "n-without-m": (["--dt", "0.1", "--n", "3"], (r"--m",)),
    "m-without-n": (["--dt", "0.1", "--m", "3"], (r"--n",)),
    "split-and-total": (["--dt", "0.1", "--n", "3", "--m", "3", "--total", "6"], ("total",)),
    "dt-not-a-number": (["--dt", "ten"], ("dt", "ten")),
    "unknown-option": (["--dt", "0.1", "--frobnicate"], ("frobnicate",)),
}


@pytest.mark.parametrize("case", sorted(BAD_USAGE))
def test_fit_usage_errors(case: str, tmp_path: Path, request: pytest.FixtureRequest) -> None:
    args, patterns = BAD_USAGE[case]
    out = tmp_path / "fresh" / "fit.json"
    res = cli("fit", Ctx(tmp_path, request).good_csv(), *args, "-o", out, "--json")
    assert_usage_error(res, patterns, out)


def _eval_wrong_dim(c: Ctx) -> list[object]:
    x = np.random.default_rng(1).uniform(0, 1, (10, 2))
    path = c.tmp / "two_d.csv"
    write_csv(path, x, 1 + x[:, 0])
    return ["eval", c.good_fit(), path]


def _eval_truncated(c: Ctx) -> list[object]:
    text = c.good_fit().read_bytes()
    return ["eval", c.write("fit.json", text[: len(text) // 2]), c.good_csv()]


BAD_EVAL: dict[str, tuple[FitCase, tuple[str, ...]]] = {
    "truncated-fit-json": (_eval_truncated, ("fit.json", "json|truncated|corrupt")),
    "binary-fit-json": (
        lambda c: [
            "eval",
            c.write("fit.json", b"\xff\xfe" + np.random.default_rng(2).bytes(200)),
            c.good_csv(),
        ],
        ("fit.json", "binary|not a ratfit|json"),
    ),
    "json-but-not-a-fit": (
        lambda c: ["eval", c.write("fit.json", "[1, 2, 3]"), c.good_csv()],
        ("fit.json", "fit file|format"),
    ),
    "fit-missing-fields": (
        lambda c: [
            "eval",
            c.write("fit.json", '{"format": "ratfit.fit", "version": 1}'),
            c.good_csv(),
        ],
        ("fit.json", "malformed|missing|space"),
    ),
    "future-version": (
        lambda c: [
            "eval",
            c.write("fit.json", '{"format": "ratfit.fit", "version": 99}'),
            c.good_csv(),
        ],
        ("fit.json", "version"),
    ),
    "nan-coefficient": (_eval_nan_coefficient, ("fit.json", "non-finite|nan")),
    "wrong-dimension": (_eval_wrong_dim, ("two_d.csv", r"\b2\b", "dimension")),
    "missing-fit": (
        lambda c: ["eval", c.tmp / "nosuch.json", c.good_csv()],
        ("nosuch.json", "no such|not found|does not exist"),
    ),
    "bad-data": (
        lambda c: ["eval", c.good_fit(), c.write("data.csv", "x,y\n0,1\n1,nan\n")],
        ("data.csv", "line 3", "nan"),
    ),
}


@pytest.mark.parametrize("suffix", [".csv", ".npy"])
@pytest.mark.parametrize("case", sorted(BAD_EVAL))
def test_eval_bad_input(
    case: str, suffix: str, tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    build, patterns = BAD_EVAL[case]
    args = build(Ctx(tmp_path, request))
    out = tmp_path / "fresh" / f"values{suffix}"
    res = cli(*args, "-o", out)
    assert_error_line(res, patterns, out)


def test_demo_unknown_solver_writes_nothing(tmp_path: Path) -> None:
    outdir = tmp_path / "figs"
    res = cli("demo", "addendum", "-o", outdir, "--json", "--solver", "nope")
    assert_error_line(res, ("solver", "nope"), None)
    assert not outdir.exists()


def test_constant_dimension_message_is_plain(tmp_path: Path) -> None:
    src = tmp_path / "data.csv"
    src.write_text("a,b,y\n0,5,1\n1,5,2\n2,5,3\n")
    res = cli("fit", src, "--dt", "0.1")
    assert res.exit_code == 2
    assert "np.float64" not in res.stderr
    one_error_line(res, r"x is constant in dimension 1 \(value 5\.0\)")


def test_zero_width_segment_is_refused_with_the_fix(tmp_path: Path) -> None:
    # y = 0 under a relative width gives lo = hi = 0: no floating-point evaluation of
    # a rational can be verified to hit it exactly, so ratfit says so and names the fix.
    x = np.linspace(0.0, 1.0, 20)
    src = tmp_path / "line.csv"
    write_csv(src, x, x)
    out = tmp_path / "fresh" / "fit.json"
    res = cli("fit", src, "--dt", "0.1", "--max-total", "4", "-o", out)
    assert res.exit_code == 2
    assert "zero width" in res.stderr and "--abs-width" in res.stderr
    assert "Traceback" not in res.output and not out.exists()
    # ... and the fix works: relative width with an absolute floor
    res = cli("fit", src, "--dt", "0.1", "--abs-width", "1e-6", "--max-total", "4", "--json")
    doc = strict_json(res.stdout)
    assert res.exit_code == 0, doc["message"]
    assert doc["verified"] is True and doc["total"] <= 3


# ------------------------------------------------------------------------------- subprocess
def test_subprocess_bad_input_no_traceback(tmp_path: Path) -> None:
    src = tmp_path / "data.csv"
    src.write_text("x,y\n0,1\n1,nan\n2,3\n")
    out = tmp_path / "fresh" / "fit.json"
    proc = subprocess.run(
        [sys.executable, "-m", "ratfit", "fit", str(src), "--dt", "0.1", "-o", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr + proc.stdout
    assert proc.stdout == ""
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "nan" in lines[0].lower()
    assert_not_written(out)


@pytest.mark.slow
def test_installed_entry_point_fit_json(nist_fits: dict, tmp_path: Path) -> None:
    case = nist_fits["MGH09"]
    out = tmp_path / "fresh" / "mgh09.json"
    proc = subprocess.run(
        [
            *script_cmd(),
            "fit",
            str(case["path"]),
            "--abs-width",
            repr(case["w"]),
            "-o",
            str(out),
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    doc = strict_json(proc.stdout)
    ref = strict_json(case["result"].stdout)
    assert (doc["n"], doc["m"], doc["verified"]) == (ref["n"], ref["m"], True)
    assert load_fit(out).channels[0].rational.n == ref["n"]
    ver = subprocess.run([*script_cmd(), "--version"], capture_output=True, text=True, timeout=120)
    assert ver.returncode == 0 and "ratfit" in ver.stdout.lower()


def test_eval_into_closed_pipe_is_not_bad_input(nist_fits: dict) -> None:
    case = nist_fits["Kirby2"]
    with subprocess.Popen(
        [sys.executable, "-m", "ratfit", "eval", str(case["fit"]), str(case["path"])],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    ) as proc:
        assert proc.stdout is not None and proc.stderr is not None
        proc.stdout.close()  # the reader goes away before the first line is written
        err = proc.stderr.read().decode()
        proc.wait(timeout=120)
    assert "Traceback" not in err
    assert "error: : " not in err
    assert proc.returncode != 2


# ------------------------------------------------------------------------------- JSON output
def test_json_output_is_one_strict_object(nist_fits: dict, addendum_csv: Path) -> None:
    texts = [
        nist_fits["Kirby2"]["result"].stdout,
        cli("fit", addendum_csv, "--dt", "0.1", "--max-total", "4", "--json").stdout,
    ]
    for text in texts:
        assert text.lstrip().startswith("{") and text.rstrip().endswith("}")
        for token in ("NaN", "Infinity"):
            assert token not in text
        doc = strict_json(text)
        assert FIT_JSON_KEYS <= doc.keys()
        for key in FIT_JSON_KEYS - {"basis", "verified"}:
            v = doc[key]
            assert v is None or (isinstance(v, (int, float)) and np.isfinite(v)), (key, v)


# ------------------------------------------------------------------------------- demo
@pytest.mark.slow
def test_demo_addendum_table_matches_paper(demo_run: dict) -> None:
    res: Result = demo_run["result"]
    assert_no_crash(res)
    assert res.exit_code == 0, res.output
    doc = strict_json(res.stdout)
    assert set(doc["bases"]) == {"legendre", "chebyshev", "monomial"}
    for basis, (delta, smin, smax) in PAPER.items():
        b = doc["bases"][basis]
        assert {"delta", "sigma_min", "sigma_max", "verified", "poles_in_domain"} <= b.keys()
        assert f"{b['delta']:.2g}" == f"{delta:.2g}", (basis, b["delta"])
        assert f"{b['sigma_min']:.2g}" == f"{smin:.2g}", (basis, b["sigma_min"])
        assert b["sigma_max"] == pytest.approx(smax, rel=0.01), (basis, b["sigma_max"])
        assert b["verified"] is True, basis
        assert b["poles_in_domain"] == 0, basis


@pytest.mark.slow
def test_demo_addendum_minimal_total(demo_run: dict, addendum_csv: Path) -> None:
    doc = strict_json(demo_run["result"].stdout)
    mn = doc["minimal"]
    assert mn["verified"] is True
    assert mn["total"] < 40
    assert mn["n"] + mn["m"] == mn["total"]
    # The same data through `ratfit fit` agrees: the minimal total fits, one less does not.
    res = cli("fit", addendum_csv, "--dt", "0.1", "--total", mn["total"], "--json")
    assert res.exit_code == 0, res.output
    assert strict_json(res.stdout)["verified"] is True
    res = cli("fit", addendum_csv, "--dt", "0.1", "--total", mn["total"] - 1, "--json")
    assert res.exit_code == 1, res.output
    assert strict_json(res.stdout)["verified"] is False


@pytest.mark.slow
def test_demo_addendum_figures(demo_run: dict) -> None:
    outdir: Path = demo_run["outdir"]
    doc = strict_json(demo_run["result"].stdout)
    pngs = sorted(outdir.glob("*.png"))
    assert len(pngs) == 3, pngs
    assert sorted(Path(p) for p in doc["figures"]) == pngs
    for p in pngs:
        assert p.stat().st_size > 5000, p
        w, h = png_size(p)
        assert w >= 200 and h >= 150, (p, w, h)
    assert [p.name[:7] for p in pngs] == ["figure1", "figure2", "figure3"]


@pytest.mark.skipif("clarabel" not in available_solvers(), reason="clarabel not installed")
@pytest.mark.slow
def test_demo_addendum_clarabel(demo_run: dict, tmp_path: Path) -> None:
    res = cli("demo", "addendum", "-o", tmp_path / "figs", "--json", "--solver", "clarabel")
    assert_no_crash(res)
    assert res.exit_code == 0, res.output
    doc = strict_json(res.stdout)
    assert set(doc["bases"]) == {"legendre", "chebyshev", "monomial"}
    # Observed 2026-11-21: with clarabel all three bases are verified at n = m = 20,
    # monomial included (verified: true, no pole in the domain), and the minimal
    # Legendre total is 26, as with quadprog.
    ref = strict_json(demo_run["result"].stdout)
    for basis in PAPER:
        for key in ("delta", "sigma_min", "sigma_max"):
            # Conditioning numbers come from the constraint matrix, not from the solver.
            assert doc["bases"][basis][key] == pytest.approx(ref["bases"][basis][key], rel=1e-9)
    for basis, b in doc["bases"].items():
        assert b["verified"] is True and b["poles_in_domain"] == 0, (basis, b)
        assert b["decided_by"].startswith("clarabel"), (basis, b)
    # The solver changes nothing about the answer: the same minimal Legendre total.
    assert doc["minimal"]["verified"] and doc["minimal"]["total"] == ref["minimal"]["total"]


def test_many_solver_disagreements_print_as_a_few_lines_and_a_count(capsys) -> None:
    """A large fit's cross-checked disagreements (EXR B: 25) are three lines and a
    count on the terminal; --json keeps every one."""
    import dataclasses

    import numpy as np

    import ratfit
    from ratfit.cli.main import SHOWN_DISAGREEMENTS, _print_report

    x = np.linspace(0.0, 1.0, 30)
    res = ratfit.fit(ratfit.Segments.from_relative(x, np.exp(x), 1e-3))
    said = [f"({k},{k}): daqp reported infeasible, the lp check found a point"
            for k in range(2, 9)]
    _print_report([dataclasses.replace(res, disagreements=tuple(said))], None)
    out = capsys.readouterr().out
    assert out.count("y0 solver disagreement") == SHOWN_DISAGREEMENTS == 3
    assert "4 more solver disagreement(s)" in " ".join(out.split())
    assert dataclasses.replace(res, disagreements=tuple(said)).summary()["disagreements"] == said
