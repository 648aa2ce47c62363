"""The benchmark scripts' shared writer (benchmarks/_bench.py): the docs' benchmark tables
are its output, stamped with the date, the commit and the machine."""

from __future__ import annotations

import datetime
import importlib.util
import json
import os
import platform
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("_bench", ROOT / "benchmarks" / "_bench.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["_bench"] = mod  # dataclasses look their module up
    spec.loader.exec_module(mod)
    yield mod
    sys.modules.pop("_bench", None)


def _md_rows(text: str) -> list[list[str]]:
    """The cells of every pipe-table row (header and alignment rows included)."""
    return [[c.strip() for c in ln.strip().strip("|").split(" | ")]
            for ln in text.splitlines() if ln.startswith("|")]


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True,
                          text=True).stdout.strip()


def test_markdown_has_the_stamp_and_the_rows(bench, tmp_path: Path, capsys) -> None:
    x = np.linspace(0.0, 1.0, 4)
    rows = [[f"{v:.2f}", f"{v ** 2:.4f}", "yes" if v > 0.5 else "no"] for v in x]
    md = tmp_path / "out" / "demo.md"
    rep = bench.Report(script="bench_demo.py", markdown=md,
                       command="python benchmarks/bench_demo.py --markdown")
    rep.table("squares | of four points", ["x", "x^2", "big"], rows, note="a note")
    rep.note("Times: best of 3.")
    assert rep.write() == md
    text = md.read_text()
    printed = capsys.readouterr().out

    today = datetime.datetime.now(datetime.UTC).date().isoformat()
    lines = [ln.strip() for ln in text.splitlines()]
    date = next(ln for ln in lines if ln.startswith("- Date: "))
    commit = next(ln for ln in lines if ln.startswith("- Commit: "))
    machine = next(ln for ln in lines if ln.startswith("- Machine: "))
    # the date is today's (UTC), to the minute
    assert re.fullmatch(rf"- Date: {today} \d\d:\d\d UTC", date), date
    # the commit is this checkout's HEAD, "+dirty" exactly when code differs from it
    # (a source tree without .git, e.g. an unpacked archive, stamps "unknown")
    inside = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True)
    if inside.returncode != 0:
        assert commit == "- Commit: unknown"
    else:
        head = inside.stdout.strip()
        dirty = _git(ROOT, "status", "--porcelain", "--", ".",
                     ":(exclude)docs/benchmarks/generated", ":(exclude,glob)**/*.md") != ""
        assert commit == f"- Commit: {head}" + ("+dirty" if dirty else "")
    # the machine: cores, RAM, Python and numpy of this process
    ram = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    for part in (f"{os.cpu_count()} cores", f"{ram:.1f} GiB RAM",
                 f"Python {platform.python_version()}", f"numpy {np.__version__}"):
        assert part in machine, (part, machine)
    assert "- Command: `python benchmarks/bench_demo.py --markdown`" in lines
    assert f'!!! info "Measured {today} at {commit.removeprefix("- Commit: ")}"' in lines

    # the table: the title, the header, numeric columns right-aligned, the rows as given
    assert r"**squares | of four points**" in text
    table = _md_rows(text)
    assert table[0] == ["x", "x^2", "big"]
    assert table[1] == ["---:", "---:", "---"]
    assert table[2:] == rows
    assert [float(r[1]) for r in table[2:]] == pytest.approx(x**2, abs=5e-5)
    assert text.index("a note") > text.index(table[-1][0] + " | ")
    assert text.rstrip().endswith("Times: best of 3.")

    # the terminal shows the same rows, right-aligned under the same header
    term = printed.splitlines()
    i = term.index("squares | of four points")
    assert term[i + 1].split() == ["x", "x^2", "big"]
    assert [ln.split() for ln in term[i + 2:i + 6]] == rows
    assert len({len(ln) for ln in term[i + 1:i + 6]}) == 1  # one width


def test_cells_with_pipes_stars_and_rows_of_the_wrong_width(bench) -> None:
    t = bench.Table("vs lambert+ggx*2", ["a", "b"], [["|x|", "-"], ["1e-3", "2.5x"],
                                                     ["46+45 *", "1"]])
    assert t.markdown().startswith(r"**vs lambert+ggx\*2**")  # a star, not emphasis
    assert _md_rows(t.markdown())[2] == [r"\|x\|", "-"]
    assert _md_rows(t.markdown())[4] == [r"46+45 \*", "1"]
    assert _md_rows(t.markdown())[1] == ["---", "---:"]  # "-" is no cell, "2.5x" a number
    with pytest.raises(ValueError, match="a row has 1 cells for 2 columns"):
        bench.Table("t", ["a", "b"], [["1"]])


def test_the_commit_is_dirty_only_for_code(bench, tmp_path: Path) -> None:
    repo = tmp_path / "repo"
    repo.mkdir()
    _git(repo, "init", "-q")
    (repo / "a.py").write_text("x = 1\n")
    _git(repo, "add", "a.py")
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "one")
    head = _git(repo, "rev-parse", "--short", "HEAD")
    assert bench.git_commit(repo) == head
    # what the benchmarks write is no change to the code measured
    gen = repo / "docs" / "benchmarks" / "generated"
    gen.mkdir(parents=True)
    (gen / "bench_x.md").write_text("table\n")
    assert bench.git_commit(repo) == head
    # nor is prose written beside a run (a page, the changelog), at any depth
    (repo / "CHANGELOG.md").write_text("one\n")
    (repo / "docs" / "page.md").write_text("text\n")
    assert bench.git_commit(repo) == head
    (repo / "docs" / "hook.py").write_text("x = 3\n")  # code under docs/ is code
    assert bench.git_commit(repo) == f"{head}+dirty"
    (repo / "docs" / "hook.py").unlink()
    (repo / "a.py").write_text("x = 2\n")
    assert bench.git_commit(repo) == f"{head}+dirty"
    assert bench.git_commit(tmp_path / "not-a-repo") == "unknown"


def test_a_record_keeps_its_own_stamp(bench, tmp_path: Path) -> None:
    record = {"script": "bench_slow.py", "date": "2026-11-23", "commit": "c179048",
              "machine": "2-core test machine", "recorded": "copied from the run's output",
              "command": "python benchmarks/bench_slow.py --size 48",
              "tables": [{"title": "slow", "header": ["n", "s"],
                          "rows": [["1", "24.9"], ["2", "51.6"]]}]}
    path = tmp_path / "bench_slow.json"
    path.write_text(json.dumps(record))
    out = tmp_path / "bench_slow.md"
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "_bench.py"), str(path),
                    "--markdown", str(out)], check=True, capture_output=True)
    text = out.read_text()
    lines = [ln.strip() for ln in text.splitlines()]
    assert '!!! info "Measured 2026-11-23 at c179048 (kept as a record)"' in lines
    assert {"- Date: 2026-11-23", "- Commit: c179048", "- Machine: 2-core test machine",
            "- Recorded: copied from the run's output"} <= set(lines)
    assert not any(ln.startswith("- Load average") for ln in lines)  # not measured now
    assert _md_rows(text)[2:] == [["1", "24.9"], ["2", "51.6"]]


def test_model_comparison_rows(bench) -> None:
    cmp = bench.ModelComparison(["rmse", "cos_rmse"])
    models = {"ggx": {"R": {"rmse": 0.4, "cos_rmse": 0.2}, "G": {"rmse": 0.1, "cos_rmse": 0.1}},
              "beckmann": {"R": {"rmse": 0.3, "cos_rmse": 0.5},
                           "G": {"rmse": 0.2, "cos_rmse": 0.05}}}
    assert cmp.add("m", "R", "3+5", {"rmse": 0.1, "cos_rmse": 0.1}, models, 2.0)
    assert not cmp.add("m", "G", "3+5", {"rmse": 0.05, "cos_rmse": 0.08}, models, 2.0)
    cmp.add_missing("m", "B", "-", "no verified fit", 2.0)
    # R: the better model is beckmann for rmse (0.3), ggx for cos (0.2)
    assert cmp.rows[0] == ["m", "R", "3+5", "0.1 / 0.3 (3.00x)", "0.1 / 0.2 (2.00x)", "yes",
                           "2.0"]
    assert cmp.rows[1][3:6] == ["0.05 / 0.1 (2.00x)", "0.08 / 0.05 (0.62x)", "no"]
    assert cmp.rows[2] == ["m", "B", "-", "no verified fit", "-", "no", "2.0"]
    assert (cmp.wins, cmp.total) == (1, 3)
    assert cmp.ratios[0][1] == pytest.approx([3.0, 2.0])
    assert len(cmp.header("n+m", "s")) == len(cmp.rows[0])


def test_a_figure_is_saved_beside_the_file_and_linked(bench, tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    cmp = bench.ModelComparison(["rmse"])
    cmp.add("m", "R", "1+1", {"rmse": 0.1}, {"g": {"R": {"rmse": 0.2}}}, 1.0)
    md = tmp_path / "gen" / "x.md"
    rep = bench.Report(script="x.py", markdown=md, quiet=True)
    png = rep.figure(cmp.figure(), "x", "a caption")
    assert png == tmp_path / "gen" / "x.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert rep.parts[-1] == "![a caption](x.png)"
    # in the pages' folder the link is relative to the pages that include the file
    pages = tmp_path / "pages"
    rep = bench.Report(script="x.py", markdown=pages / "generated" / "x.md", quiet=True)
    old, bench.PAGES = bench.PAGES, pages
    try:
        rep.figure(cmp.figure(), "x", "c")
    finally:
        bench.PAGES = old
    assert rep.parts[-1] == "![c](generated/x.png)"
    # without --markdown nothing is written
    assert bench.Report(script="x.py", quiet=True).figure(cmp.figure(), "x", "c") is None


def test_a_figure_can_be_a_jpeg(bench, tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    cmp = bench.ModelComparison(["rmse"])
    cmp.add("m", "R", "1+1", {"rmse": 0.1}, {"g": {"R": {"rmse": 0.2}}}, 1.0)
    rep = bench.Report(script="x.py", markdown=tmp_path / "gen" / "x.md", quiet=True)
    jpg = rep.figure(cmp.figure(), "x", "a caption", fmt="jpg")
    assert jpg == tmp_path / "gen" / "x.jpg"
    assert jpg.read_bytes()[:3] == b"\xff\xd8\xff"  # JPEG's start of image
    assert rep.parts[-1] == "![a caption](x.jpg)"
    with pytest.raises(ValueError, match="png or jpg"):
        rep.figure(cmp.figure(), "x", "c", fmt="gif")


def test_a_comparison_writes_its_table_its_count_and_its_plot(bench, tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    cmp = bench.ModelComparison(["rmse", "cos_rmse"])
    models = {"g": {"R": {"rmse": 0.3, "cos_rmse": 0.2}, "G": {"rmse": 0.1, "cos_rmse": 0.05}}}
    cmp.add("m", "R", "3+5", {"rmse": 0.1, "cos_rmse": 0.1}, models, 2.0)
    cmp.add("m", "G", "3+5", {"rmse": 0.05, "cos_rmse": 0.08}, models, 2.0)
    rep = bench.Report(script="x.py", markdown=tmp_path / "gen" / "x.md", quiet=True)
    cmp.write_to(rep, title="t", size="n+m", seconds="s", what="Held out, the fit",
                 legend="s: seconds.", plot="x", caption="a caption")
    text = rep.text()
    assert ("Held out, the fit beats the better model on all of rmse, cos_rmse in 1 of 2 "
            "channels. Each cell: rational / better model (model / rational); s: seconds.") in text
    assert _md_rows(text)[2][:3] == ["m", "R", "3+5"]
    assert rep.parts[-1] == "![a caption](x.png)"


def test_the_render_smape_weighs_every_pixel_where_rel_rmse_weighs_the_highlight(
        bench) -> None:
    spec = importlib.util.spec_from_file_location(
        "bench_cornell_render", ROOT / "benchmarks" / "bench_cornell_render.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["bench_cornell_render"] = mod
    try:
        spec.loader.exec_module(mod)
    finally:
        sys.modules.pop("bench_cornell_render", None)
    data = np.ones((4, 3))
    data[0] = 100.0  # a highlight pixel
    black = np.zeros_like(data)
    shifted = data.copy()
    shifted[0], shifted[1] = 1.0, 100.0  # the highlight one pixel off

    def rel_rmse(a: np.ndarray) -> float:
        return float(np.sqrt(np.mean((a - data) ** 2) / np.mean(data ** 2)))

    assert mod.smape(data, data) == 0.0
    e = 0.01 * 25.75  # 1 % of the data's mean
    assert mod.smape(black, data) == pytest.approx((9 / (1 + e) + 300 / (100 + e)) / 12)
    assert mod.smape(shifted, data) == pytest.approx(6 * 99 / (101 + e) / 12)
    # rel. RMSE ranks the black image first (1.0 against 1.4), SMAPE the shifted one
    assert rel_rmse(black) == pytest.approx(1.0)
    assert rel_rmse(shifted) == pytest.approx(1.4, abs=0.001)
    assert mod.smape(shifted, data) < 0.5 < mod.smape(black, data)
