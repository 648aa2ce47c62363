"""Tamper-evident fit files: a content digest written on save and checked on load."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ratfit.cli import main
from ratfit.errors import FileFormatError
from ratfit.io.fitfile import content_digest, load_fit


def _cli(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("tamper")
    x = np.linspace(0.0, 3.0, 40)
    csv = d / "data.csv"
    csv.write_text("x,y\n" + "".join(f"{a!r},{1.0 / (1.0 + a * a) + 0.2!r}\n"
                                     for a in x.tolist()))
    fit = d / "fit.json"
    res = _cli("fit", csv, "--dt", "0.02", "-o", fit)
    assert res.exit_code == 0, res.output
    return fit, csv


def _edit(src: Path, dst: Path, fn) -> Path:
    doc = json.loads(src.read_text())
    fn(doc)
    dst.write_text(json.dumps(doc))
    return dst


def test_saved_file_carries_the_digest_of_its_content(made) -> None:
    fit, _ = made
    doc = json.loads(fit.read_text())
    assert doc["digest"] == content_digest(doc) and doc["digest"].startswith("sha256:")
    assert load_fit(fit).integrity == "sealed" and load_fit(fit).verified


def test_reindenting_keeps_the_seal(made, tmp_path: Path) -> None:
    fit, _ = made
    doc = json.loads(fit.read_text())
    again = tmp_path / "pretty.json"
    again.write_text(json.dumps(doc, indent=4, sort_keys=True))
    assert load_fit(again).integrity == "sealed"


def _scale_p(doc):
    doc["channels"][0]["p"] = [1.5 * v for v in doc["channels"][0]["p"]]


def test_edited_numerator_is_refused_everywhere(made, tmp_path: Path) -> None:
    fit, csv = made
    bad = _edit(fit, tmp_path / "bad.json", _scale_p)
    with pytest.raises(FileFormatError, match="digest"):
        load_fit(bad)
    for args in (["eval", bad, csv], ["export", bad, "--lang", "c", "-o", tmp_path / "x.c"],
                 ["plot", bad, "-o", tmp_path / "p.png"], ["report", bad, "-o", tmp_path / "r"]):
        res = _cli(*args)
        assert res.exit_code == 2, res.output
        assert res.stderr.count("error:") == 1 and "--trust-edited" in res.stderr
    assert not any((tmp_path / n).exists() for n in ("x.c", "p.png", "r"))


def test_trust_edited_drops_the_verified_claim(made, tmp_path: Path) -> None:
    fit, csv = made
    bad = _edit(fit, tmp_path / "bad.json", _scale_p)
    out = tmp_path / "x.c"
    res = _cli("export", bad, "--lang", "c", "-o", out, "--trust-edited")
    assert res.exit_code == 0, res.output
    head = "\n".join(out.read_text().splitlines()[:4])
    assert "NOT VERIFIED" in head and "was verified" not in head
    assert "warning:" in res.stderr and "UNVERIFIED" in res.stderr
    # the edited function misses its own data's segments: eval says so
    res = _cli("eval", bad, csv, "--trust-edited")
    assert res.exit_code == 0
    assert "misses segments" in res.stderr
    assert load_fit(bad, trust_edited=True).verified is False


def test_old_file_without_digest_loads_with_a_warning_unverified(made, tmp_path: Path) -> None:
    fit, _ = made

    def old(doc):
        del doc["digest"]
        doc["version"] = 2

    legacy = _edit(fit, tmp_path / "old.json", old)
    with pytest.warns(UserWarning, match="older ratfit"):
        saved = load_fit(legacy)
    assert saved.integrity == "legacy" and not saved.verified
    out = tmp_path / "old.py"
    res = _cli("export", legacy, "--lang", "python", "-o", out)
    assert res.exit_code == 0, res.output
    assert res.stderr.count("warning:") == 1 and "older ratfit" in res.stderr
    assert "NOT VERIFIED" in out.read_text().splitlines()[2]


def test_digest_removed_from_a_current_file_is_refused(made, tmp_path: Path) -> None:
    fit, _ = made
    bad = _edit(fit, tmp_path / "nodigest.json", lambda d: d.pop("digest"))
    with pytest.raises(FileFormatError, match="no digest"):
        load_fit(bad)


def test_pole_moved_into_the_domain_is_refused_even_with_trust(made, tmp_path: Path) -> None:
    fit, _ = made

    def pole(doc):
        # q = the second basis function (orthogonal to constants on the data: it
        # changes sign in the domain)
        q = doc["channels"][0]["q"]
        assert len(q) >= 2
        doc["channels"][0]["q"] = [0.0, 1.0] + [0.0] * (len(q) - 2)

    bad = _edit(fit, tmp_path / "pole.json", pole)
    with pytest.raises(FileFormatError, match="pole|zero"):
        load_fit(bad, trust_edited=True)


def test_eval_on_own_data_reverifies(made, tmp_path: Path) -> None:
    fit, csv = made
    res = _cli("eval", fit, csv)
    assert res.exit_code == 0 and res.stderr == ""
    vals = np.array([[float(v) for v in ln.split(",")] for ln in res.stdout.splitlines()[1:]])
    assert vals.shape == (40, 2)
