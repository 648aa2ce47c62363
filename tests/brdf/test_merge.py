"""Channels that verified are never discarded: a fit whose channels did not all verify
keeps the verified ones beside the file asked for, and ``ratfit brdf merge`` joins them
with the others fitted alone."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import run_cli

from ratfit.brdf.merge import channel_meta
from ratfit.errors import InputError
from ratfit.io.fitfile import load_fit


def _two_channels(folder: Path, name: str = "two.dat", scale: float = 1.0) -> Path:
    """A smooth channel y0 (3 coefficients fit it at +-5 %) and one of noise y1 (no
    rational of 6 coefficients does; +-40 % lets two)."""
    rng = np.random.default_rng(3)
    g = np.radians(np.linspace(1.0, 80.0, 15))
    th, td = np.meshgrid(g, g, indexing="ij")
    smooth = scale * (1.0 + 0.2 * np.cos(th.ravel()))
    noise = 1.0 + 0.5 * rng.uniform(size=th.size)
    rows = "\n".join(f"{a:.17g} {b:.17g} {u:.17g} {v:.17g}" for a, b, u, v in
                     zip(th.ravel(), td.ravel(), smooth, noise, strict=True))
    path = folder / name
    path.write_text(f"#DIM 2 2\n#PARAM_IN RUSIN_TH_TD\n#PARAM_OUT INV_STERADIAN\n{rows}\n")
    return path


FAILS_Y1 = ("--max-total", "6", "--time-limit", "0")


def _points() -> np.ndarray:
    rng = np.random.default_rng(7)
    return np.radians(rng.uniform(1.0, 80.0, size=(500, 2)))


def test_the_verified_channels_are_kept_beside_the_file_asked_for(tmp_path: Path) -> None:
    data = _two_channels(tmp_path)
    out = tmp_path / "fit.json"
    r = run_cli("brdf", "fit", data, "-o", out, *FAILS_Y1, "--json")
    assert r.exit_code == 1 and not out.exists()
    kept = tmp_path / "fit.partial.json"
    assert json.loads(r.stdout)["kept"] == {"path": str(kept), "channels": ["y0"]}
    saved = load_fit(kept)
    assert [c.name for c in saved.channels] == ["y0"] and saved.verified
    meta = saved.extra["brdf"]
    assert meta["channel_names"] == ["y0"] and len(meta["proof"]) == 1
    assert meta["proof"][0]["proved"] is True
    assert saved.provenance["input_channels"] == ["y0", "y1"]
    # the kept channel is the channel of a fit of y0 alone, coefficient for coefficient
    alone = tmp_path / "y0.json"
    assert run_cli("brdf", "fit", data, "-o", alone, *FAILS_Y1, "--channel", "y0").exit_code == 0
    x = _points()
    assert np.array_equal(saved(x), load_fit(alone)(x))
    said = " ".join(r.stderr.split())
    assert f"ratfit brdf merge {kept} {tmp_path / 'fit.rest.json'} -o {out}" in said


def test_a_file_already_there_is_never_replaced(tmp_path: Path) -> None:
    data = _two_channels(tmp_path)
    out = tmp_path / "fit.json"
    mine = tmp_path / "fit.partial.json"
    mine.write_text("the user's own file\n")
    r = run_cli("brdf", "fit", data, "-o", out, *FAILS_Y1)
    assert r.exit_code == 1 and not out.exists()
    assert mine.read_text() == "the user's own file\n"
    second = tmp_path / "fit.partial-2.json"
    assert [c.name for c in load_fit(second).channels] == ["y0"]
    assert f"kept the verified channels y0 in {second}" in " ".join(r.stderr.split())


def test_no_file_is_kept_when_no_channel_verified_or_no_output_was_asked(
        tmp_path: Path) -> None:
    data = _two_channels(tmp_path)
    r = run_cli("brdf", "fit", data, "-o", tmp_path / "fit.json", *FAILS_Y1,
                "--channel", "y1")
    assert r.exit_code == 1
    r = run_cli("brdf", "fit", data, *FAILS_Y1)
    assert r.exit_code == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["two.dat"]


def test_merge_joins_the_kept_channels_with_one_refitted_alone(tmp_path: Path) -> None:
    data = _two_channels(tmp_path)
    out = tmp_path / "fit.json"
    assert run_cli("brdf", "fit", data, "-o", out, *FAILS_Y1).exit_code == 1
    kept, rest = tmp_path / "fit.partial.json", tmp_path / "fit.rest.json"
    r = run_cli("brdf", "fit", data, "--channel", "y1", "--dt", "0.4", "--max-total", "20",
                "-o", rest)
    assert r.exit_code == 0, r.stderr
    # given in either order, the channels come in the input's order
    r = run_cli("brdf", "merge", rest, kept, "-o", out)
    assert r.exit_code == 0, r.stderr
    assert r.stdout.strip() == f"wrote {out}: channels y0, y1 from 2 files"
    merged = load_fit(out)
    assert [c.name for c in merged.channels] == ["y0", "y1"] and merged.verified
    x = _points()
    assert np.array_equal(merged(x), np.hstack([load_fit(kept)(x), load_fit(rest)(x)]))
    meta = merged.extra["brdf"]
    assert [p["proved"] for p in meta["proof"]] == [True, True]
    # each channel keeps the widths it was fitted with, and the data meet them again
    assert [c["dt"] for c in meta["segments"]["per_channel"]] == [0.05, 0.4]
    assert [m["channels"] for m in meta["merged_from"]] == [["y1"], ["y0"]]
    r = run_cli("report", out, "--data", data, "-o", tmp_path / "report")
    assert r.exit_code == 0, r.stderr
    page = (tmp_path / "report" / "index.html").read_text()
    assert "y0: 225 of 225 met; y1: 225 of 225 met" in page
    # the merged file evaluates as any fit file does
    r = run_cli("brdf", "eval", out, "--data", data)
    assert r.exit_code == 0 and set(json.loads(r.stdout)["metrics"]) == {"y0", "y1"}


@pytest.mark.parametrize("case", ["same channel", "other data", "other subset", "not brdf",
                                  "edited", "one file", "alta function"])
def test_merge_refuses_files_that_are_not_one_fit(tmp_path: Path, shared_data: Path,
                                                  case: str) -> None:
    data = _two_channels(tmp_path)
    a = tmp_path / "a.json"
    assert run_cli("brdf", "fit", data, "--channel", "y0", *FAILS_Y1, "-o", a).exit_code == 0
    b = tmp_path / "b.json"
    if case == "same channel":
        args = ["--channel", "Y0", *FAILS_Y1]
        expect = "channel y0 is in"
    elif case == "other data":
        data = _two_channels(tmp_path, "other.dat", scale=1.01)
        args = ["--channel", "y1", "--dt", "0.4"]
        expect = "fits other data than"
    elif case == "other subset":
        args = ["--channel", "y1", "--dt", "0.4", "--max-points", "200"]
        expect = "differ in brdf.subset"
    else:
        args = ["--channel", "y1", "--dt", "0.4"]
        expect = {"not brdf": "not a fit file of ratfit brdf fit", "edited": "edited",
                  "one file": "give two or more fit files",
                  "alta function": "an ALTA function file, not a ratfit fit file"}[case]
    assert run_cli("brdf", "fit", data, *args, "-o", b).exit_code == 0
    if case == "not brdf":
        # a fit of ratfit fit: a 1-D fit of the same kind of file has no brdf block
        xy = tmp_path / "xy.dat"
        xy.write_text("\n".join(f"{t} {np.exp(t)}" for t in np.linspace(0, 1, 30)) + "\n")
        assert run_cli("fit", xy, "--dt", "0.01", "-o", b).exit_code == 0
    if case == "alta function":  # load_fit reads it; merge needs ratfit's own document
        b.write_bytes((shared_data / "alta" / "fits" / "rational-example-01.brdf").read_bytes())
    if case == "edited":
        doc = json.loads(b.read_text())
        doc["channels"][0]["p"][0] *= 1.5
        b.write_text(json.dumps(doc))
    out = tmp_path / "out.json"
    files = [a] if case == "one file" else [a, b]
    r = run_cli("brdf", "merge", *files, "-o", out)
    assert r.exit_code == 2 and not out.exists()
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and expect in lines[0], r.stderr


def test_a_shared_denominator_keeps_its_channels_together() -> None:
    meta = {"channel_names": ["R", "G"], "shared_denominator": True}
    with pytest.raises(InputError, match="share q"):
        channel_meta(meta, [0])


def test_channel_meta_cuts_every_per_channel_entry() -> None:
    meta = {"channel_names": ["R", "G", "B"], "validity": ["r", "g", "b"],
            "proof": [{"proved": True, "k": 0}, None, {"proved": True, "k": 2}],
            "held_out_size": [None, {"k": 1}, None], "parametrization": "X",
            "holdout": {"k": 5, "metrics": {"R": {"rmse": 1.0}, "G": {"rmse": 2.0},
                                            "B": {"rmse": 3.0}}},
            "segments": {"dt": 0.1, "channel_dt": [0.1, 0.2, 0.3], "abs_width": [1, 2, 3],
                         "floor_rel": None}}
    cut = channel_meta(meta, [0, 2])
    assert cut["channel_names"] == ["R", "B"] and cut["validity"] == ["r", "b"]
    assert [p["k"] for p in cut["proof"]] == [0, 2]
    assert cut["held_out_size"] == [None, None] and cut["parametrization"] == "X"
    assert cut["segments"]["channel_dt"] == [0.1, 0.3]
    assert cut["segments"]["abs_width"] == [1, 3]
    assert cut["holdout"] == {"k": 5, "metrics": {"R": {"rmse": 1.0}, "B": {"rmse": 3.0}}}
    assert meta["channel_names"] == ["R", "G", "B"]  # the report's own block is untouched
    assert set(meta["holdout"]["metrics"]) == {"R", "G", "B"}


def test_the_hint_quotes_paths_for_the_shell_and_makes_the_folder(tmp_path: Path) -> None:
    data = _two_channels(tmp_path)
    out = tmp_path / "my fits" / "a.b.json"  # a folder not made yet, a name with a dot
    r = run_cli("brdf", "fit", data, "-o", out, *FAILS_Y1)
    assert r.exit_code == 1 and not out.exists()
    kept = tmp_path / "my fits" / "a.b.partial.json"
    assert [c.name for c in load_fit(kept).channels] == ["y0"]
    said = " ".join(r.stderr.split())
    rest = tmp_path / "my fits" / "a.b.rest.json"
    assert f"ratfit brdf merge '{kept}' '{rest}' -o '{out}'" in said


def test_the_python_api_merges_as_the_command_does(tmp_path: Path) -> None:
    from ratfit.jobs import BRDFFitRequest, BRDFMergeRequest, fit_brdf_file, merge_brdf_fits

    data = _two_channels(tmp_path)
    out = tmp_path / "fit.json"
    report = fit_brdf_file(BRDFFitRequest.from_settings(data, {
        "max_total": 6, "output": out}))
    assert not report.success and report.kept == tmp_path / "fit.partial.json"
    assert report.verified_channels == [0]
    rest = fit_brdf_file(BRDFFitRequest.from_settings(data, {
        "channels": ["y1"], "dt": 0.4, "max_total": 20}))
    assert rest.success and rest.written is None
    path = tmp_path / "rest.json"
    from ratfit.io.fitfile import save_fit

    save_fit(path, rest.document())
    merged = merge_brdf_fits(BRDFMergeRequest([path, report.kept]))
    assert merged.channels == ["y0", "y1"] and merged.written is None
    assert not out.exists()
    with pytest.raises(InputError, match="two or more"):
        BRDFMergeRequest([path])
