"""BRDF fits with one denominator for every channel (`brdf fit --shared-denominator`,
ratfit.brdf.shared): verified and proved like per-channel fits, stored as p_c / q with
the same q, evaluated and exported unchanged; the combinations it refuses."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import above_horizon, exported_brdf_in_c, one_error_line, run_cli

from ratfit.brdf.analytic_models import Model
from ratfit.brdf.fitter import (
    brdf_fit_of,
    fit_brdf,
    fit_coefficients,
    load_brdf_fit,
    save_brdf_fit,
)
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.brdf.validity import prove_validity, reprove_saved
from ratfit.errors import FileFormatError, InputError
from ratfit.io.data import Dataset
from ratfit.io.fitfile import load_fit

FRAME = "RUSIN_TH_TD_SYM"
# the same glossy lobe under three diffuse colours: channels whose poles are the lobe's
# (at these widths each channel's own fit is 3+1, 3+1, 3+2: 13 numbers)
PARAMS = ([0.5, 0.25, 0.5, 0.05], [0.4, 0.25, 0.5, 0.05], [0.3, 0.25, 0.5, 0.05])


def _rgb_material(n: int, seed: int = 0) -> Dataset:
    rng = np.random.default_rng(seed)
    L, V = above_horizon(rng, n), above_horizon(rng, n)
    model = Model("lambert+ggx")
    y = np.stack([model(L, V, p) for p in PARAMS], axis=1)
    x = get_parametrization(FRAME)._from(L, V)
    return Dataset(x=x, y=y, output_names=("R", "G", "B"),
                   meta={"param_in": FRAME, "source": "rgb"})


WIDTHS = {"dt": 0.03, "floor_rel": 0.002, "time_limit": None}


@pytest.fixture(scope="module")
def known():
    ds = _rgb_material(120)
    shared = fit_brdf(ds, shared_denominator=True, **WIDTHS)
    own = fit_brdf(ds, **WIDTHS)
    return ds, shared, own


def test_a_known_material_fitted_with_one_q_is_verified_and_proved(known, tmp_path):
    ds, (fitter, seg, meta), _ = known
    assert fitter.success_
    res = fitter.results_
    # one q: the family-form coefficients each channel stores are the same numbers
    q = res[0].rational.q
    assert all(np.array_equal(r.rational.q, q) for r in res)
    assert len({r.m for r in res}) == 1
    # every channel meets its segments and is proved valid as p_c / q
    for j, r in enumerate(res):
        assert r.verification.n_violations == 0
        v = r.rational(seg.x)
        assert np.all(v >= seg.lo[:, j] - 1e-12) and np.all(v <= seg.hi[:, j] + 1e-12)
        assert prove_validity(r.rational, FRAME).proved
    assert meta["shared_denominator"] is True
    assert all(p is not None and p["proved"] for p in meta["proof"])
    sh = meta["shared"]
    assert sh["m"] == res[0].m and sh["n"] == [r.n for r in res]
    assert sh["coefficients"] == sum(sh["n"]) + sh["m"] == fit_coefficients(fitter)
    assert sh["stored_coefficients"] == sum(r.n + r.m for r in res)
    assert meta["polish"] is False

    # the saved file: q identical in every channel, the proofs hold on its numbers
    path = tmp_path / "shared.json"
    save_brdf_fit(path, res, meta)
    doc = json.loads(path.read_text())
    qs = [c["q"] for c in doc["channels"]]
    assert all(qq == qs[0] for qq in qs)
    assert doc["brdf"]["shared_denominator"] is True
    assert reprove_saved(load_fit(path)) is True
    fit = load_brdf_fit(path)
    L, V = above_horizon(np.random.default_rng(4), 50), above_horizon(
        np.random.default_rng(5), 50)
    np.testing.assert_allclose(fit.eval_dirs(L, V), brdf_fit_of(res, meta).eval_dirs(L, V),
                               rtol=1e-12)


def test_one_q_needs_no_more_numbers_than_a_q_per_channel(known):
    _, (shared, _, _), (own, _, own_meta) = known
    assert own.success_ and own_meta["shared_denominator"] is False
    per_channel = sum(r.n + r.m for r in own.results_)
    assert fit_coefficients(own) == per_channel
    assert fit_coefficients(shared) <= per_channel


def test_a_shared_file_whose_denominators_differ_is_refused(known, tmp_path):
    _, (fitter, _, meta), _ = known
    path = tmp_path / "shared.json"
    save_brdf_fit(path, fitter.results_, meta)
    doc = json.loads(path.read_text())
    doc["channels"][1]["q"][0] *= 1.5
    edited = tmp_path / "edited.json"
    edited.write_text(json.dumps(doc))
    from ratfit.brdf.fitter import brdf_fit_of_saved
    from ratfit.io.fitfile import FitFileWarning

    with pytest.warns(FitFileWarning):
        saved = load_fit(edited, trust_edited=True)
    with pytest.raises(FileFormatError, match="denominators differ"):
        brdf_fit_of_saved(saved, str(edited))


def test_the_library_refuses_what_a_shared_denominator_cannot_honour():
    ds = _rgb_material(40)
    one = Dataset(x=ds.x, y=ds.y[:, :1], output_names=("R",), meta=dict(ds.meta))
    with pytest.raises(InputError, match="at least two channels"):
        fit_brdf(one, shared_denominator=True, **WIDTHS)
    with pytest.raises(InputError, match="drop n"):
        fit_brdf(ds, shared_denominator=True, n=3, m=3, **WIDTHS)
    with pytest.raises(InputError, match="drop total"):
        fit_brdf(ds, shared_denominator=True, total=8, **WIDTHS)
    with pytest.raises(InputError, match="positive_q"):
        fit_brdf(ds, shared_denominator=True, positive_q=True, **WIDTHS)


# ---------------------------------------------------------------------------- CLI
CLI_ARGS = ("--max-points", "80", "--dt", "0.3", "--floor-rel", "0.01", "--param", FRAME)


@pytest.fixture(scope="module")
def cli_fit(tmp_path_factory, shared_data: Path):
    out = tmp_path_factory.mktemp("shared") / "fit.json"
    r = run_cli("brdf", "fit", shared_data / "cornell" / "garnet_red.brdf", *CLI_ARGS,
                "--shared-denominator", "-o", out)
    return r, out


def test_cli_fits_rgb_with_one_q_and_says_so(cli_fit):
    r, out = cli_fit
    assert r.exit_code == 0, r.output
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith("shared denominator:")]
    assert len(lines) == 1
    block = json.loads(out.read_text())
    sh = block["brdf"]["shared"]
    assert f"(m = {sh['m']})" in lines[0]
    assert f"{sh['coefficients']} coefficients with q counted once" in lines[0]
    assert f"{sh['stored_coefficients']} stored" in lines[0]
    assert block["brdf"]["shared_denominator"] is True
    assert all(p["proved"] for p in block["brdf"]["proof"])
    qs = [c["q"] for c in block["channels"]]
    assert len(qs) == 3 and all(q == qs[0] for q in qs)
    assert [c["diagnostics"]["m"] for c in block["channels"]] == [sh["m"]] * 3


def _dirs_file(path: Path, n: int = 60) -> np.ndarray:
    rng = np.random.default_rng(11)
    LV = np.hstack([above_horizon(rng, n, 0.2), above_horizon(rng, n, 0.2)])
    path.write_text("lx,ly,lz,vx,vy,vz\n" + "\n".join(",".join(repr(float(v)) for v in row)
                                                      for row in LV) + "\n")
    return LV


def test_brdf_eval_and_the_exports_agree_on_a_shared_fit(cli_fit, tmp_path):
    r, fit_path = cli_fit
    assert r.exit_code == 0, r.output
    LV = _dirs_file(tmp_path / "dirs.csv")
    ev = run_cli("brdf", "eval", fit_path, "--dirs", tmp_path / "dirs.csv", "-o",
                 tmp_path / "vals.npy")
    assert ev.exit_code == 0, ev.output
    ref = np.load(tmp_path / "vals.npy")
    assert ref.shape == (len(LV), 3) and np.all(np.isfinite(ref)) and np.all(ref >= 0)

    py = tmp_path / "fit.py"
    assert run_cli("export", fit_path, "--lang", "python", "-o", py).exit_code == 0
    ns: dict = {}
    exec(compile(py.read_text(), str(py), "exec"), ns)
    got = np.array([ns["ratfit_brdf"](list(row[:3]), list(row[3:])) for row in LV])
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())

    c = tmp_path / "fit.c"
    assert run_cli("export", fit_path, "--lang", "c", "-o", c).exit_code == 0
    got_c = exported_brdf_in_c(c, LV[:, :3], LV[:, 3:], tmp_path)
    np.testing.assert_allclose(got_c, ref, rtol=1e-9, atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("extra,pattern", [
    (("--n", "3", "--m", "3"), r"--shared-denominator.*drop --n/--total"),
    (("--total", "9"), r"--shared-denominator.*drop --n/--total"),
    (("--channel", "R"), r"--shared-denominator needs at least two channels"),
    (("--positive-q",), r"positive_q"),
    (("--strategy", "exhaustive"), r"does not take strategy"),
])
def test_cli_refuses_bad_combinations_in_one_line(extra, pattern, shared_data, tmp_path):
    out = tmp_path / "no.json"
    r = run_cli("brdf", "fit", shared_data / "cornell" / "garnet_red.brdf",
                "--shared-denominator", *extra, "-o", out)
    one_error_line(r, pattern)
    assert not out.exists()
