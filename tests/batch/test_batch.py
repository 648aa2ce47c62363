"""Batch fitting on Dask (``ratfit.batch``, ``ratfit batch``).

One local cluster (2 worker processes on loopback) serves the whole module. The
checks: results of a batch in which a worker is SIGKILLed are all present,
verified and bit-identical to a serial run; an interrupted batch resumes without
refitting; failed tasks rerun only on request; bad manifests exit 2 with one line.
"""

from __future__ import annotations

import json
import logging
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import Result
from conftest import one_error_line, run_cli

from ratfit.batch import runner as batch
from ratfit.core.segments import Segments
from ratfit.core.verify import verify
from ratfit.errors import InputError
from ratfit.fitting.search import RationalFitter
from ratfit.io.data import read_data, write_csv
from ratfit.io.fitfile import load_fit

distributed = pytest.importorskip("distributed")  # the `batch` extra (in `test` too)


# ------------------------------------------------------------------------------ fixtures
@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(
        n_workers=2, processes=True, threads_per_worker=1, dashboard_address=None,
        host="127.0.0.1", silence_logs=logging.ERROR,
    )
    cl = distributed.Client(cluster)
    yield cl
    cl.close()
    cluster.close()


def write_synthetic(folder: Path) -> Path:
    """Two 2-channel CSVs of smooth functions, plus one whose zero value breaks dt."""
    folder.mkdir(parents=True, exist_ok=True)
    x = np.linspace(-1.0, 2.0, 240)
    write_csv(folder / "waves.csv", x[:, None],
              np.stack([np.exp(np.sin(3 * x)) + 0.5, np.arctan(8 * x) + 2.0], axis=1),
              output_names=("exps", "atan"))
    write_csv(folder / "bumps.csv", x[:, None],
              np.stack([1.0 / (1.0 + 4 * (x - 0.3) ** 2), np.cosh(x) + np.sin(5 * x) / 4],
                       axis=1), output_names=("runge", "cosh"))
    y = x.copy()  # passes through zero: relative segments have zero width there
    y[np.argmin(np.abs(y))] = 0.0
    write_csv(folder / "zero" / "line.csv", x[:, None], y[:, None])
    return folder


def manifest_for(shared: Path | None, synth: Path) -> dict[str, Any]:
    inputs: list[Any] = [
        {"path": "*.csv", "settings": [{"dt": 1e-3}, {"dt": 1e-4, "basis": "chebyshev"}]},
        {"path": "zero/line.csv", "settings": [{"dt": 0.01}]},
    ]
    if shared is not None:
        nist = shared / "nist"
        inputs += [str(nist / "Rat4*.dat"),
                   {"path": str(nist / "Kirby2.dat"), "basis": "chebyshev"},
                   {"path": str(nist / "ENSO.dat"), "max_total": 6, "settings": [{"dt": 0.01}]}]
    return {"defaults": {"max_total": 40},
            "settings": [{"dt": 0.05}, {"dt": 0.01}], "inputs": inputs}


def serial_fit(row: dict[str, Any], base: Path):
    """The same fit, in this process, without ratfit.batch.runner: RationalFitter on the file."""
    s = json.loads(row["settings"])
    path = Path(row["input"])
    data = read_data(path if path.is_absolute() else base / path, fmt=s["format"])
    seg = data.segments(dt=s["dt"], abs_width=s["abs_width"])
    j = seg.names.index(row["channel"])
    seg = Segments(seg.x, seg.lo[:, [j]], seg.hi[:, [j]], seg.y[:, [j]], (row["channel"],))
    params = {k: s[k] for k in batch.FIT_PARAMS}
    return RationalFitter(**params).fit(seg).result_, seg


def leftovers(out: Path) -> list[Path]:
    return [p for p in out.rglob("*") if p.name.endswith(".tmp")]


# ------------------------------------------------------------------------------ fault tolerance
@pytest.mark.slow
def test_worker_killed_mid_batch_matches_serial(client, shared_data, tmp_path):
    synth = write_synthetic(tmp_path / "data")
    manifest = manifest_for(shared_data, synth)
    out = tmp_path / "out"
    before = client.run(os.getpid)
    killed: dict[str, Any] = {}

    written: list[dict[str, Any]] = []

    def kill_one(row: dict[str, Any]) -> None:
        written.append(row)  # (a new folder is built beside ``out``: count the rows)
        if killed or len(written) < 2:
            return
        busy = {w: ks for w, ks in client.processing().items() if ks}
        victim = sorted(busy)[0]
        killed.update(worker=victim, pid=before[victim], keys=list(busy[victim]))
        os.kill(before[victim], signal.SIGKILL)

    summary = batch.run(manifest, client, outdir=out, base_dir=synth, on_result=kill_one)

    assert killed and killed["keys"], "no worker was busy when the kill came"
    client.wait_for_workers(2, timeout=30)
    after = client.run(os.getpid)
    assert killed["pid"] not in after.values()  # the nanny started a new process
    rows = summary.rows
    assert len(rows) >= 12 + 4 and summary.fitted == len(rows) and summary.skipped == 0
    by_status = {s: [r for r in rows if r["status"] == s] for s in ("ok", "no-fit", "failed")}
    assert len(by_status["ok"]) >= 12
    assert len(by_status["failed"]) == 1  # zero/line.csv with dt: a zero-width segment
    for r in by_status["failed"]:
        assert r["input"] == "zero/line.csv" and "zero width" in r["message"]
        assert r["fit_file"] == "" and r["n"] is None
    # the summary keeps the path as named (a symlinked data folder stays symlinked)
    assert [Path(r["input"]).resolve() for r in by_status["no-fit"]] == [
        (shared_data / "nist" / "ENSO.dat").resolve()]
    for r in rows:
        result, seg = serial_fit(r, synth) if r["status"] != "failed" else (None, None)
        if r["status"] == "failed":
            with pytest.raises(InputError, match="zero width"):
                serial_fit(r, synth)
            continue
        assert (r["n"], r["m"]) == (result.n, result.m)
        if r["status"] == "no-fit":
            assert not result.success and r["fit_file"] == ""
            continue
        saved = load_fit(out / r["fit_file"])
        rf = saved.channels[0].rational
        np.testing.assert_array_equal(rf.p, result.rational.p)  # bit-identical coefficients
        np.testing.assert_array_equal(rf.q, result.rational.q)
        v = verify(rf, seg)
        assert v.verified and v.max_violation == 0.0
        assert r["linf"] == pytest.approx(v.linf, rel=1e-12)
        assert saved.provenance["batch"]["settings_id"] == r["settings_id"]
    files = sorted(p.name for p in out.glob("*.json"))
    assert files == sorted(r["fit_file"] for r in by_status["ok"])
    assert not leftovers(out)
    # the summary table on disk says the same
    import pyarrow.parquet as pq

    table = pq.read_table(out / "summary.parquet").to_pylist()
    assert [(t["input"], t["channel"], t["settings_id"], t["status"], t["n"]) for t in table] == [
        (r["input"], r["channel"], r["settings_id"], r["status"], r["n"]) for r in rows]
    csv_lines = (out / "summary.csv").read_text().splitlines()
    assert csv_lines[0].split(",") == list(batch.COLUMNS) and len(csv_lines) == len(rows) + 1


# ------------------------------------------------------------------------------ resume
@pytest.mark.slow
def test_interrupted_batch_resumes_without_refitting(client, tmp_path):
    synth = write_synthetic(tmp_path / "data")
    manifest = {"settings": [{"dt": 1e-2}, {"dt": 1e-3}, {"dt": 1e-4}],
                "inputs": ["waves.csv", "bumps.csv"]}
    out = tmp_path / "out"
    seen: list[dict[str, Any]] = []

    def stop_after_three(row: dict[str, Any]) -> None:
        seen.append(row)
        if len(seen) == 3:
            raise KeyboardInterrupt

    with pytest.raises(batch.BatchInterrupted) as info:
        batch.run(manifest, client, outdir=out, base_dir=synth, on_result=stop_after_three)
    first = info.value.summary
    assert isinstance(info.value, KeyboardInterrupt)
    assert first.counts["ok"] == 3 and first.counts["pending"] == 12 - 3
    done = {r["fit_file"]: (out / r["fit_file"]).stat().st_mtime_ns for r in seen}
    assert sorted(p.name for p in out.glob("*.json")) == sorted(done)
    assert not leftovers(out)
    assert (out / "summary.csv").read_text().count(",pending,") == 9
    # the cluster is still usable: cancelled futures do not linger
    assert client.submit(sum, [1, 2], pure=False).result() == 3

    time.sleep(0.01)  # mtimes of refitted files would differ from the first run's
    again = batch.run(manifest, client, outdir=out, base_dir=synth)
    assert again.fitted == 9 and again.skipped == 3 and again.counts["ok"] == 12
    for name, mtime in done.items():
        assert (out / name).stat().st_mtime_ns == mtime, f"{name} was refitted"
    resumed = {r["fit_file"] for r in again.rows if r["resumed"]}
    assert resumed == set(done)
    for r in again.rows:
        if r["resumed"]:
            old = next(s for s in seen if s["fit_file"] == r["fit_file"])
            assert {k: r[k] for k in ("n", "m", "linf", "seconds")} == {
                k: old[k] for k in ("n", "m", "linf", "seconds")}

    third = batch.run(manifest, None, outdir=out, base_dir=synth)  # nothing to do: no cluster
    assert third.fitted == 0 and third.skipped == 12


@pytest.mark.slow
def test_failed_rerun_on_request_and_changed_input_refits(client, tmp_path):
    synth = write_synthetic(tmp_path / "data")
    manifest = {"inputs": [{"path": "zero/line.csv", "dt": 0.01},
                           {"path": "waves.csv", "dt": 1e-3, "channels": ["atan"]},
                           {"path": "bumps.csv", "dt": 1e-3, "channels": [0],
                            "max_total": 3}]}
    out = tmp_path / "out"
    s1 = batch.run(manifest, client, outdir=out, base_dir=synth)
    assert [r["status"] for r in s1.rows] == ["failed", "ok", "no-fit"]
    assert [r["channel"] for r in s1.rows] == ["y", "atan", "runge"]
    names = sorted(p.name for p in (out / batch.ROWS_DIR).iterdir())
    assert [n.rsplit("-", 1)[0] for n in names] == sorted(
        ("bumps.runge." + s1.rows[2]["settings_id"], "line.y." + s1.rows[0]["settings_id"]))
    ok_file = out / s1.rows[1]["fit_file"]
    mtime = ok_file.stat().st_mtime_ns

    s2 = batch.run(manifest, client, outdir=out, base_dir=synth)
    assert s2.fitted == 0 and [r["status"] for r in s2.rows] == ["failed", "ok", "no-fit"]
    assert s2.rows[0]["message"] == s1.rows[0]["message"]

    s3 = batch.run(manifest, client, outdir=out, base_dir=synth, rerun_failed=True)
    assert s3.fitted == 2 and ok_file.stat().st_mtime_ns == mtime
    assert [r["resumed"] for r in s3.rows] == [False, True, False]

    # the failing input is repaired: its content hash changes, so it is fitted again
    x = np.linspace(-1.0, 2.0, 240)
    write_csv(synth / "zero" / "line.csv", x[:, None], (x + 3.0)[:, None])
    s4 = batch.run(manifest, client, outdir=out, base_dir=synth)
    assert s4.fitted == 1 and [r["status"] for r in s4.rows] == ["ok", "ok", "no-fit"]
    assert not list((out / batch.ROWS_DIR).glob(f"line.y.{s1.rows[0]['settings_id']}-*"))
    assert load_fit(out / s4.rows[0]["fit_file"]).channels[0].summary["verified"]


# ------------------------------------------------------------------------------ manifests
def test_plan_names_ids_and_precedence(tmp_path):
    synth = write_synthetic(tmp_path / "data")
    toml = synth / "m.toml"
    toml.write_text(
        '[defaults]\ndt = 0.05\nmax_total = 30\njobs = 2\n\n'
        '[[settings]]\nbasis = "legendre"\n[[settings]]\nbasis = "chebyshev"\n\n'
        '[[inputs]]\npath = "*.csv"\nchannels = [1]\n'
        '[[inputs]]\npath = "waves.csv"\nchannels = ["exps", 0]\n'
        '[[inputs]]\npath = "**/line.csv"\ndt = 0.5\nabs_width = 0.1\n'
    )
    tasks, bad = batch.plan(toml)
    assert bad == []
    names = [t.name for t in tasks]
    assert len(names) == len(set(names)) == 8  # (bumps, waves: ch 1; waves: exps; line) x 2
    assert all(re.fullmatch(r"[\w.-]+\.[0-9a-f]{10}-[0-9a-f]{8}", n) for n in names)
    assert [n.rsplit(".", 1)[0] for n in names[::2]] == [
        "bumps.cosh", "waves.atan", "waves.exps", "zero--line.y"]
    assert {t.channel for t in tasks if t.input == "waves.csv"} == {"exps", "atan"}
    line = [t for t in tasks if t.input == "zero/line.csv"]
    assert [t.name.split(".")[0] for t in line] == ["zero--line"] * 2
    assert all(t.settings["dt"] == 0.5 and t.settings["abs_width"] == 0.1 for t in line)
    assert {t.settings["basis"] for t in line} == {"legendre", "chebyshev"}
    # the same manifest as JSON gives the same names; jobs does not change the ids
    doc = {"defaults": {"dt": 0.05, "max_total": 30}, "settings": [{"basis": "legendre"},
                                                                   {"basis": "chebyshev"}],
           "inputs": [{"path": "*.csv", "channels": [1]},
                      {"path": "waves.csv", "channels": ["exps", 0]},
                      {"path": "**/line.csv", "dt": 0.5, "abs_width": 0.1}]}
    (synth / "m.json").write_text(json.dumps(doc))
    assert [t.name for t in batch.plan(synth / "m.json")[0]] == names
    doc["defaults"]["max_total"] = 31
    assert not set(t.name for t in batch.plan(doc, synth)[0]) & set(names)


@pytest.mark.slow
def test_unreadable_input_is_a_failed_row_not_an_error(client, tmp_path):
    synth = write_synthetic(tmp_path / "data")
    (synth / "broken.csv").write_text("x,y\n1,2\n3\n")
    s = batch.run({"inputs": ["*.csv"], "defaults": {"dt": 1e-2}}, client,
                  outdir=tmp_path / "out", base_dir=synth)
    failed = [r for r in s.rows if r["status"] == "failed"]
    assert len(failed) == 1 and failed[0]["input"] == "broken.csv"
    assert "broken.csv" in failed[0]["message"] and "line 3" in failed[0]["message"]
    assert s.counts["ok"] == 4


BAD_MANIFESTS = [
    ('inputs = ["*.csv"]\ncolour = 1\n', (r"unknown key 'colour'", r"m\.toml")),
    ('[[inputs]]\npath = "*.csv"\nbasis = "fourier"\n', (r"inputs\[0\]", r"basis", "fourier")),
    ('[[inputs]]\npath = "*.csv"\nwidth = 1\n',
     (r"inputs\[0\] \('\*\.csv'\)", "unknown key 'width'")),
    ('[defaults]\ndt = -0.1\n[[inputs]]\npath = "*.csv"\n', (r"defaults", r"dt must be", "-0.1")),
    ('inputs = ["*.csv", "nothing/*.dat"]\ndefaults = {dt = 0.1}\n',
     (r"inputs\[1\]", "matched no file")),
    ('inputs = ["*.csv"]\n[[settings]]\nn = 3\n', (r"settings\[0\]|inputs\[0\]", "both n and m")),
    ('inputs = ["*.csv"]\ndefaults = {dt = 0.1, channels = [7]}\n',
     (r"inputs\[0\]", "channel 7 does not exist")),
    ('inputs = ["*.csv"]\n', (r"inputs\[0\]", "no intervals")),
    ('inputs = ["*.csv"]\ndefaults = = 1\n', (r"invalid TOML", r"line 2")),
    ('inputs = []\n', (r"no inputs",)),
]


cli = run_cli


def assert_exit2(result: Result, patterns: tuple[str, ...], out: Path) -> None:
    one_error_line(result, *patterns)
    assert not out.exists(), "bad input created the output folder"


@pytest.mark.parametrize(("text", "patterns"), BAD_MANIFESTS)
def test_cli_bad_manifest_exit_2(tmp_path, text, patterns):
    synth = write_synthetic(tmp_path / "data")
    (synth / "m.toml").write_text(text)
    assert_exit2(cli("batch", synth / "m.toml", "-o", tmp_path / "out"), patterns,
                 tmp_path / "out")


def test_cli_bad_usage_exit_2(tmp_path, monkeypatch):
    out = tmp_path / "out"
    assert_exit2(cli("batch", tmp_path / "none.toml", "-o", out), ("no such manifest",), out)
    (tmp_path / "m.yaml").write_text("inputs: []\n")
    assert_exit2(cli("batch", tmp_path / "m.yaml", "-o", out), (r"\.toml or \.json",), out)
    (tmp_path / "m.json").write_text('{"inputs": ["a.csv",]}')
    assert_exit2(cli("batch", tmp_path / "m.json", "-o", out), ("invalid JSON at line 1",), out)
    r = cli("batch", tmp_path / "m.json", "-o", out, "--workers", "0")
    assert r.exit_code == 2 and "--workers" in r.stderr
    r = cli("batch", tmp_path / "m.json", "-o", out, "--workers", "2", "--scheduler", "tcp://x:1")
    assert r.exit_code == 2 and "not with --scheduler" in r.stderr
    monkeypatch.setitem(sys.modules, "distributed", None)  # the extra is not installed
    assert_exit2(cli("batch", tmp_path / "m.json", "-o", out),
                 (re.escape('pip install ".[batch]"'), "distributed"), out)


@pytest.mark.slow
def test_cli_runs_on_an_existing_scheduler(client, shared_data, tmp_path, monkeypatch):
    monkeypatch.setattr(batch, "PROGRESS_EVERY", 0.0)
    m = tmp_path / "m.toml"
    m.write_text(f'[defaults]\ndt = 0.02\n[[inputs]]\npath = "{shared_data}/nist/Rat4*.dat"\n')
    out = tmp_path / "out"
    r = cli("batch", m, "-o", out, "--scheduler", client.scheduler.address, "--json")
    assert r.exit_code == 0, r.output
    # progress with an estimate on stderr (not a terminal: a plain line per result here)
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("ratfit: batch")]
    assert len(lines) == 2 and "about" in lines[0] and lines[0].endswith(" s left")
    assert lines[1].startswith("ratfit: batch 2/2, 0 failed or no fit,")
    doc = json.loads(r.stdout)
    assert (doc["tasks"], doc["fitted"], doc["ok"]) == (2, 2, 2)
    assert {Path(row["input"]).name for row in doc["rows"]} == {"Rat42.dat", "Rat43.dat"}
    for row in doc["rows"]:
        assert load_fit(out / row["fit_file"]).channels[0].summary["verified"]
    r = cli("batch", m, "-o", out, "--scheduler", client.scheduler.address)
    # table columns: ok, no fit, failed, run now, resumed
    counts = r"[│|]\s+2 [│|]\s+0 [│|]\s+0 [│|]\s+0 [│|]\s+2 [│|]"
    assert r.exit_code == 0 and re.search(counts, r.stdout), r.stdout


@pytest.mark.slow
def test_cli_ctrl_c_exits_130_and_leaves_no_partial_file(tmp_path):
    """A real SIGINT to `ratfit batch` with its own LocalCluster (1 worker)."""
    synth = write_synthetic(tmp_path / "data")
    m = synth / "m.json"
    m.write_text(json.dumps({"inputs": ["*.csv"], "settings": [
        {"dt": d, "basis": b} for d in (1e-2, 1e-3, 1e-4, 3e-5, 1e-5, 3e-6)
        for b in ("legendre", "chebyshev", "monomial")]}))  # 72 tasks: the signal comes first
    out = tmp_path / "out"
    exe = Path(sys.executable).with_name("ratfit")
    cmd = [str(exe)] if exe.is_file() else [sys.executable, "-m", "ratfit"]
    # the command as a terminal starts it, Ctrl-C delivered: a suite run in the background
    # of a shell without job control (``pytest &``) ignores SIGINT, and its children
    # inherit that (the batch then ran all its tasks and exited 0)
    proc = subprocess.Popen([*cmd, "batch", str(m), "-o", str(out), "--workers", "1"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 30
    # a new folder is built beside ``out`` (moved there when the batch stops)
    while not list(tmp_path.glob(".out.*.tmp/*.json")) and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert "interrupted:" in err and "Traceback" not in err
    written = list(out.glob("*.json")) + list((out / batch.ROWS_DIR).glob("*.json"))
    assert 1 <= len(written) < 72
    assert not leftovers(out)
    for p in out.glob("*.json"):
        assert load_fit(p).channels[0].summary["verified"]


# ------------------------------------------------------------------------------ BRDF files
def _cornell_manifest(shared: Path) -> dict[str, Any]:
    return {"defaults": {"max_points": 100, "channels": ["R"]},
            "inputs": [str(shared / "cornell" / "garnet_red.brdf"),
                       str(shared / "cornell" / "krylon_blue.brdf")]}


def test_a_cornell_entry_is_the_request_of_the_brdf_command(shared_data, tmp_path):
    """Issue 25: a Cornell file in a manifest failed ("line 9: expected 1 value, got
    19"); it is now one task per file whose request is the one `ratfit brdf fit
    FILE --max-points 100 --channel R --jobs 1` makes (BRDF solver by default)."""
    from ratfit.jobs import BRDFFitRequest

    tasks, unreadable = batch.plan(_cornell_manifest(shared_data), base_dir=tmp_path)
    assert not unreadable and [t.channel for t in tasks] == ["R", "R"]
    for t in tasks:
        req = batch.request_of(t.settings, Path(t.path))
        # jobs=1: the batch's default (Dask runs the tasks in parallel)
        assert req == BRDFFitRequest.from_settings(t.path, {"max_points": 100, "jobs": 1,
                                                            "channels": ["R"]})
        assert req.options.solver == BRDFFitRequest(t.path).options.solver
    # every channel of the file by default: one task for all of them
    tasks, _ = batch.plan({"inputs": [str(shared_data / "cornell" / "cayman.brdf")]})
    assert [(t.channel, t.settings["kind"]) for t in tasks] == [("R,G,B", "brdf")]
    assert batch.request_of(tasks[0].settings, Path(tasks[0].path)).channels == ()
    # BRDF settings on a data file (and data settings on a BRDF file) are refused
    with pytest.raises(InputError, match="max_points is a setting of BRDF files"):
        batch.load_manifest({"inputs": [{"path": "a.csv", "max_points": 5}]}, base_dir=tmp_path)
    with pytest.raises(InputError, match="monomial is a setting of data files"):
        batch.load_manifest({"inputs": [{"path": "b.brdf", "monomial": False}]},
                            base_dir=tmp_path)


def test_settings_ids_of_data_entries_do_not_move():
    """The BRDF settings are hashed only when set: ids of earlier data batches hold."""
    base = {k: batch.DEFAULTS[k] for k in batch.DEFAULTS}
    assert batch.settings_id(base) == batch.settings_id({**base, "kind": "data"})
    assert batch.settings_id({**base, "kind": "brdf"}) != batch.settings_id(base)
    assert batch.settings_id({**base, "max_points": 60}) != batch.settings_id(base)


@pytest.mark.slow
def test_a_batch_of_cornell_files_equals_them_fitted_one_by_one(client, shared_data, tmp_path):
    """Same file, same options: the same coefficients."""
    from ratfit.brdf.options import BRDFOptions
    from ratfit.jobs import BRDFFitRequest, fit_brdf_file

    out = tmp_path / "out"
    summary = batch.run(_cornell_manifest(shared_data), client, outdir=out)
    assert summary.ok and len(summary.rows) == 2
    for row in summary.rows:
        doc = json.loads((out / row["fit_file"]).read_text())
        alone = fit_brdf_file(BRDFFitRequest(shared_data / "cornell" / Path(row["input"]).name,
                                             BRDFOptions(jobs=1), max_points=100,
                                             channels=("R",))).document()
        assert [(c["p"], c["q"]) for c in doc["channels"]] == \
            [(c["p"], c["q"]) for c in alone["channels"]]
        assert doc["brdf"]["parametrization"] == alone["brdf"]["parametrization"]
        assert (row["n"], row["m"]) == (alone["channels"][0]["n"], alone["channels"][0]["m"])


# ------------------------------------------------------------------------------ names, resume
def _alike_channels(folder: Path) -> Path:
    """One CSV whose channels 'a b' and 'a_b' read alike once made file-safe."""
    folder.mkdir(parents=True, exist_ok=True)
    x = np.linspace(0.0, 1.0, 60)
    rows = "".join(f"{a!r},{1.0 + a!r},{2.0 + a * a!r}\n" for a in x.tolist())
    (folder / "two.csv").write_text("x,y_a b,y_a_b\n" + rows)
    return folder


def test_channels_that_read_alike_are_both_fitted(client, tmp_path):
    synth = _alike_channels(tmp_path / "data")
    out = tmp_path / "out"
    s = batch.run({"inputs": ["two.csv"], "defaults": {"dt": 0.01}}, client, outdir=out,
                  base_dir=synth)
    assert [(r["channel"], r["status"]) for r in s.rows] == [("a b", "ok"), ("a_b", "ok")]
    files = [r["fit_file"] for r in s.rows]
    assert len(set(files)) == 2 and all(f.startswith("two.a_b.") for f in files)
    x = np.array([[0.0], [0.5], [1.0]])
    for r, want in zip(s.rows, (1.0 + x[:, 0], 2.0 + x[:, 0] ** 2), strict=True):
        saved = load_fit(out / r["fit_file"])
        assert saved.channels[0].name == r["channel"]
        np.testing.assert_allclose(saved(x)[:, 0], want, rtol=0.011)
    import csv

    with open(out / "summary.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert [(t["channel"], t["status"]) for t in table] == [("a b", "ok"), ("a_b", "ok")]


def _reseal(path: Path, edit) -> None:
    """Edit a fit file and write a valid digest for the edit (anyone can: it is no MAC)."""
    from ratfit.io.fitfile import content_digest

    doc = json.loads(path.read_text())
    edit(doc)
    doc["digest"] = content_digest(doc)
    path.write_text(json.dumps(doc))


def test_resume_refits_results_that_no_longer_verify(client, tmp_path):
    synth = write_synthetic(tmp_path / "data")
    manifest = {"inputs": ["waves.csv"], "defaults": {"dt": 1e-3}}
    out = tmp_path / "out"
    first = batch.run(manifest, client, outdir=out, base_dir=synth)
    assert first.counts["ok"] == 2
    exps, atan = (out / r["fit_file"] for r in first.rows)

    def scale_p(doc):
        ch = doc["channels"][0]
        ch["p"] = [1.5 * v for v in ch["p"]]

    # exps: edited without a new digest; atan: edited AND re-sealed, so only the data
    # can tell that its function no longer meets the segments
    doc = json.loads(exps.read_text())
    scale_p(doc)
    exps.write_text(json.dumps(doc))
    _reseal(atan, scale_p)
    with pytest.raises(Exception, match="digest"):
        load_fit(exps)
    assert load_fit(atan).verified  # it claims to be verified
    again = batch.run(manifest, client, outdir=out, base_dir=synth)
    assert again.fitted == 2 and again.skipped == 0
    assert [r["resumed"] for r in again.rows] == [False, False]
    data = read_data(synth / "waves.csv")
    for r in again.rows:
        saved = load_fit(out / r["fit_file"])
        j = data.output_names.index(r["channel"])
        seg = data.segments(dt=1e-3)
        seg = Segments(seg.x, seg.lo[:, [j]], seg.hi[:, [j]], seg.y[:, [j]], (r["channel"],))
        assert verify(saved.channels[0].rational, seg).max_violation == 0.0
    # intact results are still resumed without refitting
    third = batch.run(manifest, None, outdir=out, base_dir=synth)
    assert third.fitted == 0 and third.skipped == 2


def test_a_new_output_folder_appears_whole_or_not_at_all(client, tmp_path, monkeypatch):
    synth = write_synthetic(tmp_path / "data")
    out = tmp_path / "fresh" / "out"

    def full_disk(rows, outdir):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(batch, "write_summary", full_disk)
    with pytest.raises(OSError, match="No space") as info:
        batch.run({"inputs": ["waves.csv"], "defaults": {"dt": 1e-2}}, client, outdir=out,
                  base_dir=synth)
    assert info.value.filename == str(out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data"]  # nothing half-written


def test_resume_of_a_brdf_file_reloads_its_block(client, tmp_path):
    """A BRDF task's result is resumed once its file loads as a BRDF fit; a re-sealed
    block of the wrong type ("cosine_weighted": "no") is fitted again."""
    from ratfit.brdf.parametrizations import get_parametrization
    from ratfit.io.data import write_alta

    rng = np.random.default_rng(5)
    c = np.column_stack([rng.uniform(0.05, 1.3, 300), rng.uniform(0.05, 1.3, 300),
                         rng.uniform(-np.pi, np.pi, 300)])
    L, V = get_parametrization("ISOTROPIC_TV_TL_DPHI").to_dirs(c)
    h = L + V
    cos_h = h[:, 2] / np.linalg.norm(h, axis=1)
    lobe = 0.1225 / (np.pi * ((0.1225 - 1.0) * cos_h * cos_h + 1.0) ** 2)
    write_alta(tmp_path / "lobe.alta", c, (0.05 + 0.12 * lobe)[:, None],
               param_in="ISOTROPIC_TV_TL_DPHI", param_out="INV_STERADIAN")
    manifest = {"inputs": [{"path": "lobe.alta", "kind": "brdf", "parametrization":
                            "COS_TH_TD_PD", "dt": 0.1, "abs_width": 1e-4, "max_total": 30}]}
    out = tmp_path / "out"
    first = batch.run(manifest, client, outdir=out, base_dir=tmp_path)
    assert first.counts["ok"] == 1, first.rows
    again = batch.run(manifest, None, outdir=out, base_dir=tmp_path)
    assert again.fitted == 0 and again.skipped == 1
    _reseal(out / first.rows[0]["fit_file"],
            lambda d: d["brdf"].update(cosine_weighted="no"))
    third = batch.run(manifest, client, outdir=out, base_dir=tmp_path)
    assert third.fitted == 1 and third.skipped == 0 and third.counts["ok"] == 1
    doc = json.loads((out / third.rows[0]["fit_file"]).read_text())
    assert doc["brdf"]["cosine_weighted"] is False
