"""Numeric options are range-checked before use; a full stdout after the fit file was
written is reported as what it is; channel names reach CSV headers quoted."""

from __future__ import annotations

import csv
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import one_error_line, run_cli

from ratfit.io.fitfile import content_digest, load_fit

HUGE = "9223372036854775808"  # 2^63: one past int64


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("ranges")
    x = np.linspace(0.0, 2.0, 40).tolist()
    csv_path = d / "data.csv"
    csv_path.write_text("x,y\n" + "".join(f"{a!r},{1.0 / (1.0 + a * a) + 0.5!r}\n" for a in x))
    pdf = d / "pdf.csv"
    pdf.write_text("x,y\n" + "".join(f"{a!r},{float(np.exp(-a))!r}\n" for a in x))
    fit, cdf = d / "fit.json", d / "cdf.json"
    assert run_cli("fit", csv_path, "--dt", "0.01", "-o", fit).exit_code == 0
    assert run_cli("cdf", pdf, "--from", "pdf", "--abs-width", "0.01", "-o", cdf).exit_code == 0
    samples = d / "s.npy"
    np.save(samples, np.random.default_rng(0).normal(size=300))
    manifest = d / "m.toml"
    manifest.write_text(f'[defaults]\ndt = 0.1\n[[inputs]]\npath = "{csv_path}"\n')
    return {"csv": csv_path, "pdf": pdf, "fit": fit, "cdf": cdf, "samples": samples,
            "manifest": manifest, "dir": d}


CASES = {
    # (command line, pattern the error line must match); {out} is a fresh path
    "sample-n-2^63": (["sample", "{cdf}", "-n", HUGE, "-o", "{out}.npy"], "-n"),
    "sample-n-10^20": (["sample", "{cdf}", "-n", "99999999999999999999"], "-n"),
    "cdf-points-2^63": (["cdf", "{samples}", "--points", HUGE, "-o", "{out}"], "--points"),
    "cdf-grid-2^63": (["cdf", "{pdf}", "--grid", HUGE, "-o", "{out}"], "--grid"),
    "cdf-confidence-nan": (["cdf", "{samples}", "--confidence", "nan", "-o", "{out}"],
                           "confidence"),
    "compare-starts-2^63": (["brdf", "compare", "{csv}", "--model", "lambert", "--starts", HUGE],
                            "--starts"),
    "batch-workers-2^63": (["batch", "{manifest}", "-o", "{out}", "--workers", HUGE],
                           "--workers"),
    "batch-allowed-failures-2^63": (["batch", "{manifest}", "-o", "{out}",
                                     "--allowed-failures", HUGE], "--allowed-failures"),
    "render-seed-negative": (["render", "{fit}", "-o", "{out}.png", "--seed", "-1"], "--seed"),
    "render-seed-2^32": (["render", "{fit}", "-o", "{out}.png", "--seed", str(2**32)], "--seed"),
    "render-cosine-weight-nan": (["render", "{fit}", "-o", "{out}.png", "--cosine-weight",
                                  "nan"], "cosine-weight"),
    "tolerance-rtol-nan": (["tolerance", "{csv}", "--n", "2", "--m", "2", "--rtol", "nan"],
                           "rtol"),
}


@pytest.mark.parametrize("key", list(CASES))
def test_numeric_options_out_of_range(files, tmp_path: Path, key: str) -> None:
    args, pattern = CASES[key]
    out = tmp_path / "fresh" / "out"
    names = {k: str(v) for k, v in files.items()} | {"out": str(out)}
    res = run_cli(*[a.format(**names) for a in args])
    one_error_line(res, pattern)
    assert not (tmp_path / "fresh").exists()


def _ratfit() -> list[str]:
    exe = Path(sys.executable).with_name("ratfit")
    return [str(exe)] if exe.is_file() else [sys.executable, "-m", "ratfit"]


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full (Linux)")
@pytest.mark.parametrize("as_json", [True, False])
def test_full_stdout_after_the_fit_file_is_written(files, tmp_path: Path, as_json: bool) -> None:
    out = tmp_path / "fit.json"
    cmd = [*_ratfit(), "fit", str(files["csv"]), "--dt", "0.01", "-o", str(out)]
    with open("/dev/full", "w") as full:
        proc = subprocess.run(cmd + (["--json"] if as_json else []), stdout=full,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    # not 2 ("bad input, no file"): the fit file is there, verified, and the line says so
    assert proc.returncode == 74, proc.stderr
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in proc.stderr
    assert "standard output" in lines[0] and str(out) in lines[0]
    assert load_fit(out).verified


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full (Linux)")
def test_full_stdout_with_no_file_says_none_was_written(files) -> None:
    with open("/dev/full", "w") as full:
        proc = subprocess.run([*_ratfit(), "eval", str(files["fit"]), str(files["csv"])],
                              stdout=full, stderr=subprocess.PIPE, text=True, timeout=120)
    assert proc.returncode == 74, proc.stderr
    assert "no output file was written" in proc.stderr


HOSTILE_NAMES = ["a,b", "fake\n1,2", "cr\ronly", 'q"uote', "tab\tname", "=1+1"]


@pytest.mark.parametrize("name", HOSTILE_NAMES)
def test_channel_names_are_quoted_in_eval_csv(files, tmp_path: Path, name: str) -> None:
    doc = json.loads(files["fit"].read_text())
    doc["channels"][0]["name"] = name
    doc["digest"] = content_digest(doc)  # a valid seal: the name is taken as written
    fit = tmp_path / "named.json"
    fit.write_text(json.dumps(doc))
    for args in ([], ["-o", tmp_path / "v.csv"]):
        res = run_cli("eval", fit, files["csv"], *args)
        assert res.exit_code == 0, res.output
        if args:
            with open(tmp_path / "v.csv", newline="") as fh:  # keep a quoted lone CR
                text = fh.read()
        else:
            text = res.stdout
        rows = list(csv.reader(io.StringIO(text, newline="")))
        assert rows[0] == ["x0", name]
        assert len(rows) == 41 and all(len(r) == 2 for r in rows)
        assert float(rows[1][1]) == pytest.approx(load_fit(fit)([0.0])[0, 0], rel=1e-15)


def test_names_are_shown_as_written_not_as_rich_markup(tmp_path: Path) -> None:
    """Channel and file names go into rich tables and lines: '[/]' stopped `ratfit fit`
    with exit 3 (MarkupError) and '[bold]b' was shown as a bold 'b'."""
    x = np.linspace(0.0, 2.0, 40).tolist()
    data = tmp_path / "r.csv"
    data.write_text("x,y_[/],y_[bold]b\n" + "".join(
        f"{a!r},{1.0 / (1.0 + a * a) + 0.5!r},{a + 1.0!r}\n" for a in x))
    out = tmp_path / "fit[/].json"
    res = run_cli("fit", data, "--dt", "0.01", "-o", out)
    assert res.exit_code == 0, res.output
    table = res.stdout
    assert "\n [/] " in table and "\n [bold]b " in table and f"wrote {out}" in table
    assert [c.name for c in load_fit(out).channels] == ["[/]", "[bold]b"]
    res = run_cli("fit", data, "--dt", "0.01", "--max-total", "2")  # no fit: message lines
    assert res.exit_code == 1, res.output
    assert "\n[/]: no verified fit" in res.stdout and "\n[bold]b: no verified fit" in res.stdout
