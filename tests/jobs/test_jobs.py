"""The jobs floor: one request in, one report out, the same fit from the CLI and Python.

Each job is what its command runs: the fit file a command writes is the report's
document, coefficient for coefficient; the file is parsed once and (BRDF) each
frame's default widths are resolved once.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import run_cli

from ratfit.brdf.options import BRDFOptions
from ratfit.core.options import FitOptions
from ratfit.errors import InputError
from ratfit.fitting.shared_denominator import SharedOptions
from ratfit.io.data import write_csv
from ratfit.io.fitfile import load_fit
from ratfit.jobs import BRDFFitRequest, FitRequest, fit_brdf_file, fit_file


def _coefficients(doc_or_path: dict | Path) -> list[tuple[str, list[float], list[float]]]:
    doc = json.loads(Path(doc_or_path).read_text()) if isinstance(doc_or_path, Path) \
        else doc_or_path
    return [(c["name"], c["p"], c["q"]) for c in doc["channels"]]


@pytest.fixture
def waves(tmp_path: Path) -> Path:
    x = np.linspace(-1.0, 2.0, 120)
    path = tmp_path / "waves.csv"
    write_csv(path, x[:, None], np.stack([np.exp(np.sin(3 * x)) + 0.5, 1 / (3 + x)], axis=1),
              output_names=("exps", "pole"))
    return path


# ------------------------------------------------------------------------------ ratfit fit
def test_fit_file_is_what_ratfit_fit_writes(waves: Path, tmp_path: Path) -> None:
    out = tmp_path / "cli.json"
    res = run_cli("fit", waves, "--dt", "1e-3", "--max-total", "30", "-o", out)
    assert res.exit_code == 0, res.output
    report = fit_file(FitRequest(waves, FitOptions(max_total=30), dt=1e-3))
    assert report.success and report.written is None
    assert _coefficients(report.document()) == _coefficients(out)
    saved = json.loads(out.read_text())["channels"]
    assert [(r.n, r.m) for r in report.results] == [(c["n"], c["m"]) for c in saved]
    assert load_fit(out).integrity == "sealed"
    # the same request from flat settings (the CLI's names, a manifest's keys)
    again = FitRequest.from_settings(waves, {"dt": 1e-3, "max_total": 30})
    assert again == FitRequest(waves, FitOptions(max_total=30), dt=1e-3)


def test_fit_file_writes_only_verified_fits_and_reports_its_phases(waves: Path,
                                                                   tmp_path: Path) -> None:
    out = tmp_path / "f.json"
    report = fit_file(FitRequest(waves, FitOptions(max_total=3), dt=1e-3, output=out))
    assert not report.success and not out.exists() and report.written is None
    with pytest.raises(InputError, match="refusing to save unverified"):
        report.document()
    ok = fit_file(FitRequest(waves, dt=1e-3, channels=("pole",), output=out))
    assert ok.success and ok.written == out and out.exists()
    assert [r.channel for r in ok.results] == ["pole"] and (ok.results[0].n,
                                                            ok.results[0].m) == (1, 2)
    assert set(ok.seconds) >= {"read", "segments", "fit", "write"}
    assert all(v >= 0 for v in ok.seconds.values())
    assert ok.summary()["output"] == str(out)


def test_fit_job_parses_the_file_once(waves: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import ratfit.io.data as data

    calls: list[Path] = []
    real = data.read_data

    def counting(path, **kw):
        calls.append(Path(path))
        return real(path, **kw)

    monkeypatch.setattr(data, "read_data", counting)
    assert fit_file(FitRequest(waves, dt=1e-3, output=None)).success
    assert calls == [waves]


@pytest.mark.parametrize(("make", "message"), [
    (lambda p: FitRequest(p, dt=-1.0), "dt must be"),
    (lambda p: FitRequest(p, channels=(True,)), "channels must be"),
    (lambda p: FitRequest(p, format="xls"), "unknown format 'xls'"),
    (lambda p: FitRequest(p, options={"basis": "x"}), "options must be FitOptions"),
    (lambda p: FitRequest.from_settings(p, {"n": 3}), "give both n and m"),
    (lambda p: FitRequest.from_settings(p, {"shared_denominator": True, "min_total": 30}),
     "a shared denominator does not take min_total"),
    (lambda p: BRDFFitRequest(p, color="cmyk"), "unknown color 'cmyk'"),
    (lambda p: BRDFFitRequest(p, parametrization="NO_SUCH"), "unknown parametrization"),
    (lambda p: BRDFFitRequest(p, max_points=1), "max_points must be an integer >= 2"),
    (lambda p: BRDFFitRequest(p, BRDFOptions(parametrization="STARK_2D")),
     "the job chooses the options' parametrization"),
    (lambda p: BRDFFitRequest.from_settings(p, {"polish": "no"}), "polish must be true"),
])
def test_requests_are_checked_when_made(make, message: str, tmp_path: Path) -> None:
    with pytest.raises(InputError, match=message):
        make(tmp_path / "any.csv")


def test_requests_are_frozen_values(tmp_path: Path) -> None:
    req = FitRequest(str(tmp_path / "a.csv"), dt=0.1)
    assert isinstance(req.input, Path)
    with pytest.raises(dataclasses.FrozenInstanceError):
        req.dt = 0.2  # type: ignore[misc]
    shared = FitRequest.from_settings(req.input, {"shared_denominator": True, "m": 2,
                                                  "max_total": 12})
    assert isinstance(shared.options, SharedOptions) and shared.shared_denominator
    assert (shared.options.m, shared.options.max_n) == (2, 12)
    # a progress hook is not part of what is asked
    assert req.with_progress(print) == req


# ------------------------------------------------------------------------------ BRDF files
@pytest.mark.slow
def test_fit_brdf_file_is_what_ratfit_brdf_fit_writes(shared_data: Path, tmp_path: Path) -> None:
    """Same file, same options: the same coefficients from the command and from Python,
    in the 3-D frame the command picks for Cornell's Cartesian pairs (not 6-D)."""
    path = shared_data / "cornell" / "cayman.brdf"
    out = tmp_path / "cli.json"
    res = run_cli("brdf", "fit", path, "--max-points", "60", "--channel", "R", "-o", out)
    assert res.exit_code == 0, res.output
    report = fit_brdf_file(BRDFFitRequest(path, max_points=60, channels=("R",)))
    assert report.success
    assert _coefficients(report.document()) == _coefficients(out)
    doc = report.document()
    assert doc["brdf"]["parametrization"] == json.loads(out.read_text())["brdf"][
        "parametrization"]
    assert report.file_parametrization == "CARTESIAN"
    assert report.parametrization != "CARTESIAN" and report.segments.dim == 3
    assert report.status() == ("verified on a subset of 60 of 1439 samples only "
                               "(--max-points); not checked at the other 1379")


@pytest.mark.slow
def test_brdf_job_reads_once_and_resolves_each_frames_widths_once(
        shared_data: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import ratfit.brdf.fitter as fitter
    import ratfit.brdf.io as bio
    from ratfit.brdf.fitter import HALF_VECTOR

    reads: list[str] = []
    widths: list[int] = []
    real_read, real_dt = bio.read_brdf, fitter.default_dt

    def read(path, **kw):
        reads.append(str(path))
        return real_read(path, **kw)

    def dt(x, y, *a, **kw):
        widths.append(x.shape[1])
        return real_dt(x, y, *a, **kw)

    monkeypatch.setattr(bio, "read_brdf", read)
    monkeypatch.setattr(fitter, "default_dt", dt)
    report = fit_brdf_file(BRDFFitRequest(shared_data / "cornell" / "cayman.brdf",
                                          max_points=60, channels=("R",)))
    frames = {c["parametrization"] for c in report.meta["candidates"]}
    assert len(reads) == 1
    # the half-vector frame, then the angles (widths known before a fit: maybe skipped);
    # after a verified fit in the symmetric frame the angles need no widths at all
    assert frames == {HALF_VECTOR, "ISOTROPIC_TV_TL_DPHI"}
    iso = next(c for c in report.meta["candidates"]
               if c["parametrization"] == "ISOTROPIC_TV_TL_DPHI")
    assert len(widths) == (1 if "reciprocal" in (iso.get("skipped") or "") else 2)


def _scattered_lobes(path: Path, n: int = 200) -> Path:
    """``n`` scattered measurements of three lambert+ggx channels (diffuse 0.2, 0.05,
    0.01 under one lobe) at random light and view angles, as an ALTA text file."""
    from conftest import above_horizon

    from ratfit.brdf.analytic_models import Model
    from ratfit.brdf.parametrizations import get_parametrization

    rng = np.random.default_rng(0)
    L, V = above_horizon(rng, n), above_horizon(rng, n)
    y = np.stack([Model("lambert+ggx")(L, V, [kd, 1.0, 0.2, 0.05]) for kd in (0.2, 0.05, 0.01)],
                 axis=1)
    x = get_parametrization("ISOTROPIC_TV_TL_DPHI").from_dirs(L, V)
    rows = "\n".join(" ".join(f"{v!r}" for v in r) for r in np.hstack([x, y]).tolist())
    path.write_text("#DIM 3 3\n#PARAM_IN ISOTROPIC_TV_TL_DPHI\n#PARAM_OUT RGB_COLOR\n"
                    f"{rows}\n")
    return path


def test_fit_brdf_file_of_a_path_equals_the_default_command(tmp_path: Path) -> None:
    """``fit_brdf_file(path)`` and ``ratfit brdf fit path``: every default, whole file
    (scattered angles: log values at each channel's noise level, half-vector frame)."""
    path = _scattered_lobes(tmp_path / "lobes.alta")
    out = tmp_path / "cli.json"
    res = run_cli("brdf", "fit", path, "-o", out)
    assert res.exit_code == 0, res.output
    report = fit_brdf_file(path)
    assert report.success and report.segments.n_points == 200
    assert _coefficients(report.document()) == _coefficients(out)
    brdf = json.loads(out.read_text())["brdf"]
    assert brdf["values"] == "log" and brdf["segments"]["noise_estimated"]
    assert brdf["parametrization"] == report.parametrization == "RUSIN_TH_TD_SYM"


@pytest.mark.slow
def test_a_brdf_fit_does_not_depend_on_its_threads(shared_data: Path) -> None:
    """The BRDF verifier hands later splits the validity points it finds: splits
    tested side by side took them in thread order, so the same request gave other
    coefficients with 2 threads than with 1 (cayman, 200 samples, R) and from run to
    run. Its splits now run in the walk's order whatever ``jobs`` says."""
    path = shared_data / "cornell" / "cayman.brdf"
    fits = [fit_brdf_file(BRDFFitRequest(path, BRDFOptions(jobs=jobs), max_points=200,
                                         channels=("R",))).document()
            for jobs in (1, 2)]
    assert _coefficients(fits[0]) == _coefficients(fits[1])
