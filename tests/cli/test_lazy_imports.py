"""``ratfit fit`` imports what the fit command needs, not every command's module (issue 26)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from ratfit.io.data import write_csv

# ``python -m ratfit ARGS``, then the ratfit modules it imported, as JSON, into a file
_RUN = """
import json, runpy, sys
out, sys.argv, code = sys.argv[1], ["ratfit", *sys.argv[2:]], None
try:
    runpy.run_module("ratfit", run_name="__main__")
except SystemExit as exc:
    code = exc.code
with open(out, "w") as fh:
    json.dump({"code": code, "modules": sorted(m for m in sys.modules if m.startswith("ratfit"))},
              fh)
"""

OTHER_COMMANDS = ["ratfit.cli.batch", "ratfit.cli.brdf", "ratfit.cli.cdf", "ratfit.cli.demo",
                  "ratfit.cli.export", "ratfit.cli.render", "ratfit.cli.tolerance"]


def _imported(tmp_path: Path, *args: str) -> tuple[int, set[str], str]:
    log = tmp_path / "modules.json"
    proc = subprocess.run([sys.executable, "-c", _RUN, str(log), *args],
                          capture_output=True, text=True, check=True)
    doc = json.loads(log.read_text())
    return doc["code"], set(doc["modules"]), proc.stdout


def test_fit_help_imports_no_other_command(tmp_path: Path) -> None:
    code, modules, out = _imported(tmp_path, "fit", "--help")
    assert code == 0
    assert out.startswith("Usage: ratfit fit [OPTIONS] INPUT")
    assert "ratfit.cli.fit" in modules
    assert not modules & {*OTHER_COMMANDS, "ratfit.brdf"}


def test_a_fit_imports_no_brdf_alta_function_or_certificate(tmp_path: Path) -> None:
    x = np.linspace(0.0, 1.0, 20)
    data = tmp_path / "data.csv"
    write_csv(data, x[:, None], (1.0 / (2.0 + x))[:, None])
    code, modules, out = _imported(tmp_path, "fit", str(data), "--dt", "0.01", "--json")
    assert code == 0
    doc = json.loads(out)
    assert doc["verified"] is True
    assert (doc["n"], doc["m"]) == (1, 2)  # 1 / (2 + x): a constant over a line
    assert not modules & {*OTHER_COMMANDS, "ratfit.brdf", "ratfit.io.alta_function",
                          "ratfit.fitting.certificate"}


def test_brdf_fit_help_imports_the_brdf_package(tmp_path: Path) -> None:
    """The check above sees imports: the BRDF command's help loads its package."""
    code, modules, out = _imported(tmp_path, "brdf", "fit", "--help")
    assert code == 0
    assert out.startswith("Usage: ratfit brdf fit [OPTIONS] INPUT")
    assert {"ratfit.cli.brdf", "ratfit.brdf"} <= modules
    assert "ratfit.cli.export" not in modules  # brdf compare's module: not needed here
