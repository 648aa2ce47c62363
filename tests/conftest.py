"""Shared fixtures and helpers: where the real external data lives, running the CLI.

CI has ``../shared`` beside the checkout; ``RATFIT_SHARED_DATA`` overrides the
path of its ``data`` folder.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
from click.testing import CliRunner, Result

REPO = Path(__file__).resolve().parents[1]


def shared_data_dir() -> Path:
    env = os.environ.get("RATFIT_SHARED_DATA")
    return Path(env) if env else REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    path = shared_data_dir()
    if not path.is_dir():
        msg = f"shared data folder not found at {path} (set RATFIT_SHARED_DATA)"
        if os.environ.get("CI"):
            pytest.fail(msg)  # CI has the data beside the checkout: never skip there
        pytest.skip(msg)
    return path


# ---------------------------------------------------------------------------- CLI helpers
# Shared by the CLI, CDF and batch tests: ``from conftest import run_cli, one_error_line``.
def run_cli(*args: object) -> Result:
    """Run ``ratfit ARGS`` in-process (stdout and stderr kept apart, click >= 8.2)."""
    from ratfit.cli import main

    return CliRunner().invoke(main, [str(a) for a in args])


def write_file(folder: Path, name: str, content: str | bytes) -> Path:
    """``content`` (text or bytes) written to ``folder / name``; returns the path."""
    path = folder / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return path


def one_error_line(result: Result, *patterns: str) -> str:
    """Bad input: exit 2, nothing on stdout, one ``error:`` line on stderr naming it.

    Every regex in ``patterns`` must match that line (case-insensitive); returns it.
    """
    assert "Traceback" not in result.output, result.output
    assert result.exit_code == 2, f"exit {result.exit_code}\n{result.output}"
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, f"expected one stderr line, got {lines}"
    line = lines[0]
    assert line.startswith("error: "), line
    for pat in patterns:
        assert re.search(pat, line, re.IGNORECASE), f"{pat!r} not in {line!r}"
    assert result.stdout == "", f"stdout on bad input: {result.stdout!r}"
    return line


# --------------------------------------------------------------------------- BRDF helpers
# Shared by the BRDF tests that fit a known material: ``from conftest import above_horizon``.
def above_horizon(rng, n: int, z_min: float = 0.15):
    """``n`` unit directions with cos(theta) uniform in [z_min, 1] (away from grazing,
    where a known material's values are tame) and phi uniform."""
    import numpy as np

    z = rng.uniform(z_min, 1.0, n)
    phi = rng.uniform(0.0, 2 * np.pi, n)
    s = np.sqrt(1 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def lobe_on_sparse_grid():
    """A specular lobe in cos(theta_h), 0.1 + 0.5 exp(-8 (1 - cos theta_h)), on a sparse
    gonioreflectometer grid in ISOTROPIC_TV_TL_DPHI (elevations every 20 deg, azimuths
    every 45: 125 samples, one channel R). ``from conftest import lobe_on_sparse_grid``."""
    import numpy as np

    from ratfit.brdf.parametrizations import get_parametrization
    from ratfit.io.data import Dataset

    param = "ISOTROPIC_TV_TL_DPHI"
    th = np.radians([0, 20, 40, 60, 80])
    ph = np.radians([0, 45, 90, 135, 180])
    x = np.stack([g.ravel() for g in np.meshgrid(th, th, ph, indexing="ij")], axis=1)
    L, V = get_parametrization(param).to_dirs(x)
    h = L + V
    c = h[:, 2] / np.linalg.norm(h, axis=1)
    y = (0.1 + 0.5 * np.exp(-8 * (1 - c)))[:, None]
    return Dataset(x, y, None, None, ("theta_v", "theta_l", "delta_phi"), ("R",),
                   {"param_in": param})


# ------------------------------------------------------------------- fitter internals
@pytest.fixture
def channel_threads(monkeypatch) -> list[int]:
    """The thread count of each multi-channel fit while the test runs (1: channels in
    turn, more: a channel per thread), recorded at ``RationalFitter._fit_side_by_side``."""
    import ratfit.fitting.search as search

    seen: list[int] = []
    real = search.RationalFitter._fit_side_by_side

    def spy(self, space, log_space, seg, threads, finished):
        seen.append(threads)
        return real(self, space, log_space, seg, threads, finished)

    monkeypatch.setattr(search.RationalFitter, "_fit_side_by_side", spy)
    return seen


# ------------------------------------------------------------------- external tools, exports
def need_tool(name: str, why: str) -> None:
    """Skip when an external tool is missing on a developer's machine, with the reason;
    under CI (CI=true, where .ci/run installs it) a missing tool is a failure."""
    import shutil

    if shutil.which(name):
        return
    msg = f"{name} not found on PATH: {why}"
    if os.environ.get("CI", "").lower() in ("1", "true", "yes"):
        pytest.fail(msg + " (CI installs it through .ci/run: fix the CI image)")
    pytest.skip(msg)


_BRDF_C_DRIVER = r"""
#include <stdio.h>
int main(void)
{
    double L[3], V[3], out[RATFIT_NCHANNELS];
    while (scanf("%lf %lf %lf %lf %lf %lf", &L[0], &L[1], &L[2], &V[0], &V[1], &V[2]) == 6) {
        ratfit_brdf(L, V, out);
        for (int j = 0; j < RATFIT_NCHANNELS; ++j) printf("%.17g ", out[j]);
        printf("\n");
    }
    return 0;
}
"""


def exported_brdf_in_c(source: Path, L, V, folder: Path):
    """``ratfit_brdf`` of the exported C file ``source`` at each pair (L, V): an array
    (N, channels), compiled with gcc -Wall -Werror. ``from conftest import
    exported_brdf_in_c``."""
    import subprocess

    import numpy as np

    need_tool("gcc", "the exported C code is compiled and run with it")
    src = folder / "brdf_main.c"
    src.write_text(source.read_text() + _BRDF_C_DRIVER)
    exe = folder / "brdf_main"
    subprocess.run(["gcc", "-std=c99", "-O2", "-Wall", "-Werror", "-o", str(exe), str(src),
                    "-lm"], check=True, capture_output=True)
    rows = np.hstack([np.asarray(L, dtype=float), np.asarray(V, dtype=float)])
    run = subprocess.run([str(exe)], input="\n".join(" ".join(repr(float(v)) for v in row)
                                                     for row in rows),
                         capture_output=True, text=True, check=True)
    return np.array([[float(v) for v in ln.split()] for ln in run.stdout.strip().splitlines()])
