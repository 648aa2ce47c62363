"""What a new user meets in the first hour: batch naming and overrides, the Dask
``__main__`` guard, install hints that work from a checkout, tool-dependent tests."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from ratfit.batch.runner import INSTALL_HINT, plan


def _csv(path: Path) -> Path:
    x = np.linspace(0.0, 1.0, 12)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("x,y\n" + "".join(f"{a!r},{1.0 / (1.0 + a)!r}\n" for a in x.tolist()))
    return path


def test_symlinked_input_keeps_its_own_name(tmp_path: Path) -> None:
    real = _csv(tmp_path / "far" / "away" / "store" / "real.csv")
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "link.csv").symlink_to(real)
    tasks, bad = plan({"defaults": {"dt": 0.05}, "inputs": [{"path": "link.csv"}]},
                      base_dir=tmp_path / "m")
    assert not bad and len(tasks) == 1
    assert tasks[0].name.startswith("link.y."), tasks[0].name
    assert ".." not in tasks[0].name and "--" not in tasks[0].name


def test_entry_abs_width_replaces_the_defaults_dt(tmp_path: Path) -> None:
    _csv(tmp_path / "a.csv")
    _csv(tmp_path / "b.csv")
    tasks, _ = plan({"defaults": {"dt": 0.05},
                     "inputs": [{"path": "a.csv", "abs_width": 0.5}, {"path": "b.csv"}]},
                    base_dir=tmp_path)
    by = {t.input: t.settings for t in tasks}
    assert by["a.csv"]["abs_width"] == 0.5 and by["a.csv"]["dt"] is None
    assert by["b.csv"]["dt"] == 0.05 and by["b.csv"]["abs_width"] is None
    # an entry that gives both keeps both
    tasks, _ = plan({"defaults": {"dt": 0.05},
                     "inputs": [{"path": "a.csv", "abs_width": 0.5, "dt": 0.01}]},
                    base_dir=tmp_path)
    assert tasks[0].settings["dt"] == 0.01 and tasks[0].settings["abs_width"] == 0.5


@pytest.mark.slow
def test_batch_script_without_main_guard_is_refused_with_the_fix(tmp_path: Path) -> None:
    _csv(tmp_path / "a.csv")
    (tmp_path / "m.toml").write_text('[defaults]\ndt = 0.05\n[[inputs]]\npath = "a.csv"\n')
    script = tmp_path / "run_fits.py"
    script.write_text(textwrap.dedent("""
        import ratfit.batch
        ratfit.batch.run("m.toml", outdir="out", workers=1)
    """))
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True,
                         text=True, timeout=120)
    assert res.returncode != 0
    assert 'if __name__ == "__main__":' in res.stderr
    assert time.perf_counter() - t0 < 60  # refused before any worker starts
    assert not (tmp_path / "out").exists()


def test_install_hints_work_from_a_checkout() -> None:
    assert 'pip install ".[batch]"' in INSTALL_HINT
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    assert 'pip install "ratfit[' not in readme


@pytest.mark.slow
def test_tool_dependent_tests_skip_outside_ci_and_fail_inside(tmp_path: Path) -> None:
    """The README's test command on a machine without glslangValidator: the GLSL tests
    are skipped with the reason; under CI (CI=true) they fail instead."""
    repo = Path(__file__).resolve().parents[2]
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    env["PATH"] = str(Path(sys.executable).parent)  # no /usr/bin: no glslangValidator
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rs",
           str(repo / "tests" / "export" / "test_export.py"), "-k", "glsl_validates"]
    res = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stdout[-2000:]
    assert "4 skipped" in res.stdout and "glslangValidator not found" in res.stdout
    res = subprocess.run(cmd, cwd=tmp_path, env={**env, "CI": "true"}, capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 1 and "4 failed" in res.stdout


@pytest.mark.parametrize("width", [80])
def test_result_table_fits_80_columns_without_ellipses(width: int, tmp_path: Path) -> None:
    from click.testing import CliRunner

    from ratfit.cli import main

    src = _csv(tmp_path / "a.csv")
    res = CliRunner().invoke(main, ["fit", str(src), "--dt", "0.01"],
                             env={"COLUMNS": str(width)})
    assert res.exit_code == 0, res.output
    assert "…" not in res.stdout and "..." not in res.stdout, res.stdout
    assert max(len(ln) for ln in res.stdout.splitlines()) <= width, res.stdout
