"""Where outputs go: a regular file appears whole, a device or pipe is written through and
stays what it is, a symlink is followed, a directory is refused, and a multi-file output
(report, demo, batch folder) appears whole or not at all.

The real /dev/null is never named directly: a symlink to it in tmp_path takes the same
path through the code, and under the old code only the link (not the device) was lost.
"""

from __future__ import annotations

import errno
import json
import os
import stat
import threading
from pathlib import Path

import numpy as np
import pytest
from conftest import one_error_line, run_cli

from ratfit._atomic import atomic_dir, atomic_open, atomic_path, output_kind
from ratfit.io.fitfile import load_fit, save_fit


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("outputs")
    x = np.linspace(0.0, 2.0, 40)
    csv = d / "data.csv"
    csv.write_text("x,y\n" + "".join(f"{a!r},{1.0 / (1.0 + a * a) + 0.5!r}\n"
                                     for a in x.tolist()))
    fit = d / "fit.json"
    res = run_cli("fit", csv, "--dt", "0.01", "-o", fit)
    assert res.exit_code == 0, res.output
    return fit, csv


def _dev_null_intact() -> None:
    st = os.lstat("/dev/null")
    assert stat.S_ISCHR(st.st_mode), "/dev/null is no longer a character device"


def _read_fifo(path: Path) -> tuple[threading.Thread, list[bytes]]:
    got: list[bytes] = []

    def reader() -> None:
        with open(path, "rb") as fh:
            got.append(fh.read())

    t = threading.Thread(target=reader, daemon=True)
    t.start()
    return t, got


@pytest.mark.parametrize("lang", ["c", "python"])
def test_export_to_a_link_to_dev_null_keeps_both(made, tmp_path: Path, lang: str) -> None:
    fit, _ = made
    link = tmp_path / "null"
    link.symlink_to("/dev/null")
    res = run_cli("export", fit, "--lang", lang, "-o", link)
    assert res.exit_code == 0, res.output
    assert link.is_symlink() and os.readlink(link) == "/dev/null"
    _dev_null_intact()
    assert list(tmp_path.iterdir()) == [link]  # no temporary file left beside it


def test_eval_fit_and_sample_to_a_link_to_dev_null(made, tmp_path: Path) -> None:
    fit, csv = made
    link = tmp_path / "null.npy"
    link.symlink_to("/dev/null")
    for args in (["eval", fit, csv, "-o", link], ["fit", csv, "--dt", "0.01", "-o", link]):
        res = run_cli(*args)
        assert res.exit_code == 0, res.output
        assert link.is_symlink()
        _dev_null_intact()


def test_export_to_a_fifo_streams_the_code(made, tmp_path: Path) -> None:
    fit, _ = made
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    t, got = _read_fifo(fifo)
    res = run_cli("export", fit, "--lang", "python", "-o", fifo)
    t.join(10)
    assert res.exit_code == 0, res.output
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)  # still a pipe, not a regular file
    code = got[0].decode()
    assert code.startswith("# ") and "def ratfit_eval" in code
    ns: dict = {}
    exec(compile(code, "exported", "exec"), ns)  # the streamed code is complete
    assert ns["ratfit_eval"]([1.0])[0] == pytest.approx(load_fit(fit)([1.0])[0, 0], rel=1e-12)


def test_export_dash_is_stdout_and_the_notes_go_to_stderr(made) -> None:
    fit, _ = made
    res = run_cli("export", fit, "--lang", "python", "-o", "-")
    assert res.exit_code == 0, res.output
    ns: dict = {}
    exec(compile(res.stdout, "exported", "exec"), ns)
    assert "ratfit_eval" in ns and "wrote -" in res.stderr
    assert not Path("-").exists()


def test_symlink_to_a_file_is_followed_and_stays_a_link(made, tmp_path: Path) -> None:
    fit, csv = made
    (tmp_path / "real").mkdir()
    target = tmp_path / "real" / "values.csv"
    target.write_text("old\n")
    target.chmod(0o640)
    link = tmp_path / "values.csv"
    link.symlink_to(target)
    res = run_cli("eval", fit, csv, "-o", link)
    assert res.exit_code == 0, res.output
    assert link.is_symlink() and link.resolve() == target
    rows = target.read_text().splitlines()
    assert rows[0] == "x0,y" and len(rows) == 41
    assert stat.S_IMODE(target.stat().st_mode) == 0o640  # the replaced file keeps its mode
    assert sorted(p.name for p in (tmp_path / "real").iterdir()) == ["values.csv"]


def test_dangling_symlink_creates_its_target(made, tmp_path: Path) -> None:
    fit, _ = made
    link = tmp_path / "code.c"
    link.symlink_to(tmp_path / "made" / "code.c")
    res = run_cli("export", fit, "--lang", "c", "-o", link)
    assert res.exit_code == 0, res.output
    assert link.is_symlink() and "ratfit_eval" in (tmp_path / "made" / "code.c").read_text()


def test_directory_output_is_one_error_line(made, tmp_path: Path) -> None:
    fit, csv = made
    folder = tmp_path / "folder"
    folder.mkdir()
    link = tmp_path / "to-folder"
    link.symlink_to(folder)
    for out in (folder, link):
        line = one_error_line(run_cli("eval", fit, csv, "-o", out), "directory")
        assert "folder" in line
    assert list(folder.iterdir()) == []
    doc = json.loads(fit.read_text())
    with pytest.raises(IsADirectoryError) as info:
        save_fit(folder, doc)
    assert info.value.filename == str(folder)


def test_library_writers_follow_the_same_rules(tmp_path: Path) -> None:
    fifo = tmp_path / "p"
    os.mkfifo(fifo)
    t, got = _read_fifo(fifo)
    with atomic_path(fifo) as tmp:
        tmp.write_bytes(b"abc")
    t.join(10)
    assert got == [b"abc"] and stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert output_kind(fifo)[1] == "stream" and output_kind(tmp_path)[1] == "dir"
    assert output_kind("-")[1] == output_kind("/dev/stdout")[1] == "stdout"
    # a failed write leaves the old file and no temporary one
    f = tmp_path / "f.txt"
    f.write_text("old")
    with pytest.raises(OSError) as info, atomic_open(f) as fh:
        fh.write("half")
        raise OSError(errno.ENOSPC, "No space left on device")
    assert info.value.filename == str(f) and f.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.txt", "p"]


def test_folder_output_appears_whole_or_not_at_all(tmp_path: Path) -> None:
    target = tmp_path / "new" / "deep" / "out"
    with pytest.raises(OSError) as info, atomic_dir(target) as work:
        (work / "a.png").write_bytes(b"a")
        raise OSError(errno.ENOSPC, "No space left on device")
    assert info.value.filename == str(target)
    assert list(tmp_path.iterdir()) == []  # not even the parents made for it
    with atomic_dir(target) as work:
        (work / "a.png").write_bytes(b"a")
        (work / ".rows").mkdir()
        (work / ".rows" / "r.json").write_text("{}")
    assert sorted(p.relative_to(target).as_posix() for p in target.rglob("*")) == [
        ".rows", ".rows/r.json", "a.png"]
    # into an existing folder: the user's own files stay, ours are replaced
    (target / "mine.txt").write_text("keep")
    with atomic_dir(target) as work:
        (work / "a.png").write_bytes(b"b")
    assert (target / "a.png").read_bytes() == b"b" and (target / "mine.txt").read_text() == "keep"
    assert sorted(p.name for p in target.parent.iterdir()) == ["out"]
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(NotADirectoryError), atomic_dir(f):
        pass


def test_report_failing_midway_leaves_nothing_and_names_the_folder(
        made, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    fit, csv = made
    from ratfit.viz import pictures

    calls = []
    real = pictures.plot_error

    def full_disk(*args, **kw):
        calls.append(1)
        real(*args, **kw)  # the picture is written, then the disk is full
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(pictures, "plot_error", full_disk)
    out = tmp_path / "fresh" / "report"
    line = one_error_line(run_cli("report", fit, "--data", csv, "-o", out), "space")
    assert str(out) in line and calls
    assert list(tmp_path.iterdir()) == []  # no folder, no half report, no temporary
    monkeypatch.setattr(pictures, "plot_error", real)
    res = run_cli("report", fit, "--data", csv, "-o", out)
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in out.iterdir()) == ["error_0.png", "index.html", "relerr_0.png",
                                                     "slice_0.png"]
    assert sorted(p.name for p in (tmp_path / "fresh").iterdir()) == ["report"]
