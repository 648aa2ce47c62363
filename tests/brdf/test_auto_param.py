"""No --param: an isotropic fit is also tried in the half-vector frame, and the
verified fit with fewer coefficients is kept (narrower segments first)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from conftest import run_cli

from ratfit.brdf.fitter import HALF_VECTOR, alternative_parametrizations, fit_brdf_auto
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.brdf.validity import check_validity
from ratfit.io.data import Dataset

ISO = "ISOTROPIC_TV_TL_DPHI"
DEG = np.pi / 180


def _lobe(param: str) -> Dataset:
    """A sharp specular lobe on a gonioreflectometer grid, in ``param`` coordinates."""
    th = np.array([0, 15, 30, 45, 60, 75]) * DEG
    ph = np.linspace(0, np.pi, 7)
    x = np.stack([g.ravel() for g in np.meshgrid(th, th, ph, indexing="ij")], axis=1)
    L, V = get_parametrization(ISO).to_dirs(x)
    h = L + V
    c = h[:, 2] / np.linalg.norm(h, axis=1)
    y = (0.05 + 2.0 / (1.0 + 60.0 * (1.0 - c)))[:, None]
    coords = get_parametrization(param).from_dirs(L, V)
    names = ("a", "b", "c")
    return Dataset(coords, y, None, None, names, ("R",), {"param_in": param})


def test_alternatives_only_for_isotropic_angle_sets() -> None:
    assert alternative_parametrizations(ISO) == (HALF_VECTOR,)
    assert alternative_parametrizations("isotropic_tl_tv_proj_dphi") == (HALF_VECTOR,)
    assert alternative_parametrizations(HALF_VECTOR) == ()
    assert alternative_parametrizations("STARK_2D") == ()
    assert alternative_parametrizations("UNKNOWN") == ()


def test_auto_keeps_the_verified_fit_and_caps_the_second_search() -> None:
    """A lobe in cos(theta_h) is a small rational in the half-vector frame and has no
    fit up to 40 coefficients in (theta_v, theta_l, dphi)."""
    iso, half = _lobe(ISO), _lobe(HALF_VECTOR)
    fitter, seg, meta = fit_brdf_auto([iso, half], dt=0.05, floor_rel=0.002, max_total=40)
    first, second = meta["candidates"]
    assert (first["parametrization"], first["verified"]) == (ISO, False)
    assert first["searched_up_to"] == 40 and second["searched_up_to"] == 40  # no cap
    assert second["verified"] and second["coefficients"] <= 12
    assert fitter.success_ and meta["parametrization"] == HALF_VECTOR
    assert sum(r.n + r.m for r in fitter.results_) == second["coefficients"]
    # the kept fit is in the kept coordinates, and physically valid there
    assert np.allclose(seg.x, half.x) and np.array_equal(seg.center[:, 0], half.y[:, 0])
    assert check_validity(fitter.result_.rational, HALF_VECTOR).valid
    # the other order: after a verified fit, the next search stops at its size
    fitter2, _, meta2 = fit_brdf_auto([half, iso], dt=0.05, floor_rel=0.002, max_total=40)
    a, b = meta2["candidates"]
    assert a["verified"] and b["searched_up_to"] == a["coefficients"] and not b["verified"]
    assert meta2["parametrization"] == HALF_VECTOR
    assert fitter2.result_.n + fitter2.result_.m == a["coefficients"]


def test_cli_default_fit_of_cayman_is_in_the_half_vector_frame(shared_data: Path,
                                                               tmp_path: Path) -> None:
    """cayman (mirror-like): 41-42 coefficients in (theta_v, theta_l, dphi), about 25
    in (theta_h, theta_d, phi_d)."""
    out = tmp_path / "cayman.json"
    r = run_cli("brdf", "fit", shared_data / "cornell" / "cayman.brdf", "-o", out, "--json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    iso, half = doc["parametrization_candidates"]
    assert iso["parametrization"] == ISO and iso["verified"]
    assert half["parametrization"] == HALF_VECTOR and half["verified"]
    assert half["coefficients"] < 0.75 * iso["coefficients"]
    assert doc["parametrization"] == HALF_VECTOR
    assert sum(doc["n"]) + sum(doc["m"]) == half["coefficients"]
    saved = json.loads(out.read_text())
    assert saved["brdf"]["parametrization"] == HALF_VECTOR
    # evaluating the saved fit at the measured directions stays inside the segments
    ev = run_cli("brdf", "compare", shared_data / "cornell" / "cayman.brdf", out, "--json")
    assert ev.exit_code == 0, ev.output
    rows = [row for row in json.loads(ev.stdout)["rows"] if row["name"] == out.name]
    assert len(rows) == 3 and all(row["rmse"] < 0.6 for row in rows)


def test_a_named_parametrization_is_kept(shared_data: Path, tmp_path: Path) -> None:
    r = run_cli("brdf", "fit", shared_data / "cornell" / "mystique.brdf", "--param", ISO,
                "--json", "--max-total", "16", "--max-points", "300")
    doc = json.loads(r.stdout)
    assert doc["parametrization"] == ISO
    assert [c["parametrization"] for c in doc["parametrization_candidates"]] == [ISO]
