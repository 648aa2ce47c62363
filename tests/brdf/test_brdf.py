"""BRDF files, ALTA interop and rational BRDF fits (library and `ratfit brdf`)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from ratfit.brdf.fitter import (
    BRDFFitter,
    brdf_metrics,
    fit_brdf,
    load_brdf_fit,
    save_brdf_fit,
    valid_grid,
)
from ratfit.brdf.io import (
    MERL_SHAPE,
    brdf_dataset,
    cie1931_xyz,
    merl_coords,
    merl_from_function,
    read_alta_binary,
    read_astm,
    read_cornell,
    read_exr,
    read_merl,
    spectrum_to_rgb,
    write_merl,
)
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.cli import main
from ratfit.core.bases import PolynomialSpace
from ratfit.core.rational import RationalFunction
from ratfit.core.segments import Segments
from ratfit.core.verify import verify
from ratfit.errors import FileFormatError, InputError
from ratfit.io.alta_function import read_alta_function, write_alta_data, write_alta_function
from ratfit.io.data import Dataset, read_data
from ratfit.io.fitfile import save_fit

KD = np.array([0.05, 0.08, 0.12])
KS = np.array([0.6, 0.5, 0.4])


def ggx_brdf(L: np.ndarray, V: np.ndarray) -> np.ndarray:
    """Lambert + GGX distribution lobe: an analytic RGB BRDF (N, 3)."""
    h = L + V
    c = h[:, 2] / np.linalg.norm(h, axis=1)
    a2 = 0.35**2
    d = a2 / (np.pi * ((a2 - 1.0) * c * c + 1.0) ** 2)
    return KD[None, :] + KS[None, :] * d[:, None]


@pytest.fixture(scope="module")
def merl_file(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    table = merl_from_function(ggx_brdf)
    path = tmp_path_factory.mktemp("merl") / "ggx.binary"
    write_merl(path, table)
    return path, table


# ---------------------------------------------------------------------------- MERL
@pytest.mark.slow
def test_merl_round_trip(merl_file: tuple[Path, np.ndarray]) -> None:
    path, table = merl_file
    assert path.stat().st_size == 12 + 3 * 8 * int(np.prod(MERL_SHAPE))
    m = read_merl(path)
    ok = m.valid
    assert np.array_equal(ok, np.isfinite(table[..., 0]))
    assert 0.5 < ok.mean() < 0.9  # cells below the horizon are stored as missing
    # Scale factors 1/1500, 1.15/1500, 1.66/1500 undo exactly what the writer applied.
    assert np.max(np.abs(m.rgb[ok] - table[ok]) / table[ok]) < 1e-15
    # Lookup at MERL's sample points (lower cell edges) gives the analytic values there.
    P = get_parametrization("RUSIN_TH_TD_PD")
    rng = np.random.default_rng(3)
    cells = rng.choice(np.flatnonzero(ok.ravel()), 300, replace=False)
    L, V = P.to_dirs(merl_coords()[cells])
    assert np.allclose(m.lookup(L, V), ggx_brdf(L, V), rtol=1e-14)
    s = m.samples()
    assert s.coords.shape == (int(ok.sum()), 3) and s.coords[:, 2].max() < np.pi


@pytest.mark.slow
def test_merl_bad_files(tmp_path: Path, merl_file: tuple[Path, np.ndarray]) -> None:
    data = merl_file[0].read_bytes()
    short = tmp_path / "short.binary"
    short.write_bytes(data[:-8])
    with pytest.raises(FileFormatError, match="truncated: a MERL file is 34992012 bytes"):
        read_merl(short)
    dims = tmp_path / "dims.binary"
    dims.write_bytes(np.array([90, 90, 90], "<i4").tobytes() + data[12:])
    with pytest.raises(FileFormatError, match=r"header dims \(90, 90, 90\), expected"):
        read_merl(dims)
    with pytest.raises(InputError, match="shape"):
        write_merl(tmp_path / "x.binary", np.zeros((90, 90, 90, 3)))
    assert not (tmp_path / "x.binary").exists()
    out = tmp_path / "fit.json"
    res = CliRunner().invoke(main, ["brdf", "fit", str(short), "--dt", "0.1", "-o", str(out)])
    assert res.exit_code == 2 and "truncated" in res.output and "Traceback" not in res.output
    assert not out.exists()


@pytest.mark.slow
def test_merl_fit_subsample(merl_file: tuple[Path, np.ndarray]) -> None:
    """A 3-channel 3-D fit of MERL samples; evaluation on directions meets the data."""
    ds = brdf_dataset(merl_file[0], "COS_TH_TD_PD", max_points=3000)
    fitter, seg, meta = fit_brdf(ds, dt=0.05, max_total=40)
    assert fitter.success_, [r.message for r in fitter.results_]
    assert meta["fold_phi_d"] is False and meta["parametrization"] == "COS_TH_TD_PD"
    for r in fitter.results_:
        assert r.verification is not None and r.verification.max_rel_error <= 0.05 + 1e-12


# ---------------------------------------------------------------------------- ALTA
def test_alta_kirby2_reference_numbers(shared_data: Path) -> None:
    f = read_alta_function(shared_data / "alta" / "fits" / "Kirby2.brdf")
    ds = read_data(shared_data / "alta" / "Kirby2.dat")
    assert ds.y is not None
    err = f(ds.x)[:, 0] - ds.y[:, 0]
    assert np.sqrt(np.mean(err**2)) == pytest.approx(0.0279415, abs=5e-8)
    assert np.abs(err).max() == pytest.approx(0.27124, abs=5e-6)
    assert f.metrics == {"L2": 0.0279415, "Linf": 0.27124}


def test_alta_rational_example_loads_and_evaluates(shared_data: Path) -> None:
    f = read_alta_function(shared_data / "alta" / "fits" / "rational-example-01.brdf")
    assert (f.nx, f.ny, f.basis, f.param_in) == (2, 3, "chebyshev", "STARK_2D")
    assert [(b.p.size, b.q.size) for b in f.rational] == [(100, 50)] * 3
    g = np.linspace(0.05, 0.95, 40)
    x = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    x = x[np.hypot(x[:, 0], x[:, 1]) < 0.95]  # valid STARK_2D configurations
    v = f(x)
    assert v.shape == (len(x), 3) and np.all(np.isfinite(v))
    # Gold: red above green above blue on average.
    assert v[:, 0].mean() > v[:, 1].mean() > v[:, 2].mean() > 0
    g2 = read_alta_function(shared_data / "alta" / "fits" / "nonlinear-example-01.brdf")
    L = np.array([[0.0, 0.0, 1.0]])
    assert g2(np.hstack([L, L]))[0] == pytest.approx(
        [0.00137237 + 0.12853947, 0.0010724 + 0.13073475, 0.00284847 + 0.36481634], rel=1e-6
    )


def test_alta_binary_matches_text(shared_data: Path) -> None:
    b = read_alta_binary(shared_data / "alta" / "brdf_small_simu_two_layers_binary.alta")
    t = read_data(shared_data / "alta" / "brdf_small_simu_two_layers_txt.alta")
    assert b.meta["param_in"] == "ISOTROPIC_TV_TL_DPHI" and b.n_points == 29
    assert np.allclose(b.x, t.x, atol=1e-15) and np.allclose(b.y, t.y, atol=1e-15)


@pytest.mark.slow
def test_alta_function_and_data_writers(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    L = rng.normal(size=(400, 3))
    L /= np.linalg.norm(L, axis=1)[:, None]
    L[:, 2] = np.abs(L[:, 2]) + 0.2
    L /= np.linalg.norm(L, axis=1)[:, None]
    V = L[::-1].copy()
    P = get_parametrization("COS_TH_TD")
    ds = Dataset(P.from_dirs(L, V), ggx_brdf(L, V)[:, :2], meta={"param_in": "COS_TH_TD"})
    fitter, seg, meta = fit_brdf(ds, dt=0.05, max_total=30)
    assert fitter.success_
    fit = tmp_path / "f.json"
    save_brdf_fit(fit, fitter.results_, meta)
    saved = load_brdf_fit(fit)
    out = tmp_path / "f.brdf"
    write_alta_function(out, saved.saved, param_in="COS_TH_TD")
    back = read_alta_function(out)
    assert back.basis == "legendre" and back.param_in == "COS_TH_TD"
    assert np.allclose(back(seg.x), saved.eval_coords(seg.x), rtol=1e-9, atol=0)
    data = tmp_path / "d.alta"
    write_alta_data(data, ds)
    again = read_data(data)
    assert again.meta["param_in"] == "COS_TH_TD" and np.array_equal(again.y, ds.y)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("#DIM 3 1\n#VS 1\n#PARAM_IN RUSIN_TH_TD_PD\n0.1 0.2 0.3 1.0\n", "expected 5 numbers"),
        ("#DIM 3 1\n#PARAM_IN NOT_A_PARAM\n0.1 0.2 0.3 1.0\n0.2 0.3 0.4 2\n",
         "parametrization 'NOT_A_PARAM' is unknown"),
        ("#DIM 3\n0.1 0.2 0.3 1.0\n", "malformed #DIM"),
    ],
)
def test_bad_alta_data_exit_2(tmp_path: Path, text: str, match: str) -> None:
    p = tmp_path / "bad.alta"
    p.write_text(text)
    out = tmp_path / "o.json"
    res = CliRunner().invoke(main, ["brdf", "fit", str(p), "--param", "STARK_2D", "--dt", "0.1",
                                    "-o", str(out)])
    assert res.exit_code == 2, res.output
    assert match in res.output and "Traceback" not in res.output and not out.exists()


# ---------------------------------------------------------------------------- colour, Cornell
def test_cie_and_srgb() -> None:
    lam = np.arange(380.0, 781.0, 5.0)
    cmf = cie1931_xyz(lam)
    assert lam[np.argmax(cmf[:, 1])] == pytest.approx(555, abs=10)  # photopic peak
    xyz = spectrum_to_rgb(lam, np.ones((1, lam.size)), space="xyz")[0]
    assert xyz[1] == pytest.approx(1.0)  # flat spectrum s -> Y = s
    x, y = xyz[:2] / xyz.sum()
    assert x == pytest.approx(1 / 3, abs=0.01) and y == pytest.approx(1 / 3, abs=0.01)
    # A reddish spectrum is red in sRGB.
    rgb = spectrum_to_rgb(lam, np.where(lam > 600, 1.0, 0.05)[None, :])[0]
    assert rgb[0] > 3 * rgb[1] and rgb[0] > 3 * rgb[2]


def test_cornell_reader(shared_data: Path, tmp_path: Path) -> None:
    s = read_cornell(shared_data / "cornell" / "garnet_red.brdf")
    assert s.coords.shape == (1439, 6) and s.values.shape == (1439, 31)
    assert s.meta["material"] == "Garnet Red"
    ds = brdf_dataset(shared_data / "cornell" / "garnet_red.brdf", "ISOTROPIC_TV_TL_DPHI")
    assert ds.output_names == ("R", "G", "B") and ds.dim == 3
    assert ds.y is not None and np.median(ds.y[:, 0]) > np.median(ds.y[:, 2])  # garnet red
    one = brdf_dataset(shared_data / "cornell" / "garnet_red.brdf", color="spectral",
                       channels=["550nm", "5"])
    assert one.output_names == ("550nm", "450nm") and one.dim == 6
    with pytest.raises(InputError, match="no channel 'Q'"):
        brdf_dataset(shared_data / "cornell" / "garnet_red.brdf", channels=["Q"])
    lines = (shared_data / "cornell" / "garnet_red.brdf").read_text().splitlines()
    cut = tmp_path / "cut.brdf"
    cut.write_text("\n".join(lines[:-1] + [" ".join(lines[-1].split()[:10])]) + "\n")
    with pytest.raises(FileFormatError, match="not a whole number of rows of 35"):
        read_cornell(cut)


def test_astm_reader(tmp_path: Path) -> None:
    p = tmp_path / "m.astm"
    p.write_text("NAME test\nNUM_POINTS 2\nVARS theta_i,phi_i,theta_s,phi_s,R,G,B\n"
                 "10,0,20,180,0.1,0.2,0.3\n30,0,40,90,0.4,0.5,0.6\n")
    s = read_astm(p)
    assert s.channel_names == ("R", "G", "B") and s.values[1].tolist() == [0.4, 0.5, 0.6]
    iso = get_parametrization("ISOTROPIC_TV_TL_DPHI").from_dirs(s.coords[:, 3:], s.coords[:, :3])
    assert iso[0] == pytest.approx(np.radians([20, 10, -180 % 360 - 360]) * [1, 1, -1])
    p.write_text("NUM_POINTS 3\nVARS theta_i,phi_i,theta_s,phi_s,Y\n10,0,20,180,0.1\n")
    with pytest.raises(FileFormatError, match="truncated: NUM_POINTS 3, found 1"):
        read_astm(p)
    p.write_text("VARS theta_i,phi_i,theta_s,phi_s,Y\n10,0,120,180,0.1\n")
    with pytest.raises(InputError, match="below the horizon"):
        read_astm(p)


def test_exr_slice(shared_data: Path) -> None:
    s = read_exr(shared_data / "alta" / "data-example-01.exr")
    assert s.param == "STARK_2D" and s.values.shape == (512 * 512, 3)
    assert s.coords.min() == pytest.approx(0.5 / 512) and s.coords.max() == pytest.approx(
        1 - 0.5 / 512
    )
    assert np.all(s.values > 0)


# ---------------------------------------------------------------------------- fits, CLI
def _synthetic_alta(tmp_path: Path, n: int = 600) -> Path:
    rng = np.random.default_rng(5)
    P = get_parametrization("ISOTROPIC_TV_TL_DPHI")
    c = np.column_stack([rng.uniform(0.05, 1.3, n), rng.uniform(0.05, 1.3, n),
                         rng.uniform(-np.pi, np.pi, n)])
    L, V = P.to_dirs(c)
    p = tmp_path / "synth.alta"
    from ratfit.io.data import write_alta

    # A dull lobe (a fifth of KS): a small fit in every 3-D parametrization.
    vals = KD[None, :2] + 0.2 * (ggx_brdf(L, V)[:, :2] - KD[None, :2])
    write_alta(p, c, vals, param_in="ISOTROPIC_TV_TL_DPHI",
               param_out="INV_STERADIAN")
    return p


@pytest.mark.slow
def test_cli_fit_eval_round_trip(tmp_path: Path) -> None:
    data = _synthetic_alta(tmp_path)
    fit = tmp_path / "fit.json"
    run = CliRunner()
    res = run.invoke(main, ["brdf", "fit", str(data), "--param", "COS_TH_TD_PD", "--dt", "0.1",
                            "--abs-width", "1e-4", "--max-total", "30", "--json",
                            "-o", str(fit)])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    plain = run.invoke(main, ["fit", str(data), "--dt", "0.05", "--max-total", "3", "--json"])
    assert set(json.loads(plain.output)) <= set(doc)  # the same keys as `ratfit fit --json`
    assert doc["parametrization"] == "COS_TH_TD_PD" and len(doc["channels"]) == 2
    assert set(doc["metrics"]["y0"]) == {"rmse", "rel_rmse", "log_rmse", "linf", "cos_rmse"}
    saved = json.loads(fit.read_text())
    assert saved["brdf"]["parametrization"] == "COS_TH_TD_PD"
    assert saved["brdf"]["cosine_weighted"] is False
    # Evaluate on directions: values land inside the data's segments.
    P = get_parametrization("ISOTROPIC_TV_TL_DPHI")
    ds = read_data(data)
    L, V = P.to_dirs(ds.x[:50])
    dirs = tmp_path / "dirs.csv"
    np.savetxt(dirs, np.hstack([L, V]), delimiter=",", header="lx,ly,lz,vx,vy,vz")
    out = tmp_path / "vals.csv"
    res = run.invoke(main, ["brdf", "eval", str(fit), "--dirs", str(dirs), "-o", str(out)])
    assert res.exit_code == 0, res.output
    vals = np.loadtxt(out, delimiter=",", skiprows=1)[:, 6:]
    fitted = load_brdf_fit(fit)
    assert fitted.channel_names == ("y0", "y1") and fitted.n_channels == 2
    assert np.allclose(vals, fitted.eval_dirs(L, V), rtol=1e-15)
    bound = np.maximum(0.1 * ds.y[:50], 1e-4)
    assert np.all(np.abs(vals - ds.y[:50]) <= bound * (1 + 1e-9))
    # A cosine-weighted fit divides by cos(theta_l) on evaluation.
    cw = replace(fitted, cosine_weighted=True)
    assert np.allclose(cw.eval_dirs(L, V), fitted.eval_dirs(L, V) / L[:, 2:], rtol=1e-14)
    c = get_parametrization("COS_TH_TD_PD").from_dirs(L, V)
    assert np.allclose(cw.eval_coords(c) * L[:, 2:], fitted.eval_coords(c), rtol=1e-12)
    res = run.invoke(main, ["brdf", "eval", str(fit), "--data", str(data)])
    m = json.loads(res.stdout)["metrics"]
    assert m["y0"]["rmse"] <= 0.1 * ds.y[:, 0].max() and "cos_rmse" in m["y0"]


@pytest.mark.slow
def test_cli_eval_bad_directions(tmp_path: Path) -> None:
    data = _synthetic_alta(tmp_path, 200)
    fit = tmp_path / "fit.json"
    run = CliRunner()
    res = run.invoke(main, ["brdf", "fit", str(data), "--param", "RUSIN_TH_TD", "--dt", "0.1",
                            "--abs-width", "1e-3", "-o", str(fit)])
    assert res.exit_code == 0, res.output
    dirs = tmp_path / "d.csv"
    dirs.write_text("0 0 1 0 0 1\n0.6 0 0.8 0.6 0 -0.8\n")
    out = tmp_path / "o.csv"
    res = run.invoke(main, ["brdf", "eval", str(fit), "--dirs", str(dirs), "-o", str(out)])
    assert res.exit_code == 2 and "below the horizon" in res.output and not out.exists()
    res = run.invoke(main, ["brdf", "fit", str(data), "--param", "NOPE", "--dt", "0.1"])
    assert res.exit_code == 2 and "unknown parametrization 'NOPE'" in res.output
    doc = json.loads(fit.read_text())
    del doc["brdf"]  # what `ratfit fit` writes
    plain = tmp_path / "plain.json"
    save_fit(plain, doc)  # sealed with its digest, as `ratfit fit` writes it
    res = run.invoke(main, ["brdf", "eval", str(plain), "--dirs", str(dirs)])
    assert res.exit_code == 2 and "not a BRDF fit" in res.output


def test_metrics_values() -> None:
    ref = np.array([[1.0, 2.0], [2.0, 4.0]])
    pred = np.array([[1.1, 2.0], [1.8, 4.0]])
    m = brdf_metrics(pred, ref, cos_l=[1.0, 0.5], names=("a", "b"))
    assert m["a"]["rmse"] == pytest.approx(np.sqrt((0.01 + 0.04) / 2))
    assert m["a"]["rel_rmse"] == pytest.approx(0.1)
    assert m["a"]["linf"] == pytest.approx(0.2)
    assert m["a"]["cos_rmse"] == pytest.approx(np.sqrt((0.01 + 0.01) / 2))
    assert m["a"]["log_rmse"] == pytest.approx(
        np.sqrt(((np.log(2.1) - np.log(2)) ** 2 + (np.log(2.8) - np.log(3)) ** 2) / 2)
    )
    assert m["b"] == {"rmse": 0.0, "rel_rmse": 0.0, "log_rmse": 0.0, "linf": 0.0,
                      "cos_rmse": 0.0}


# ---------------------------------------------------------------------------- pole check
def _stark_candidate(q_const: float) -> tuple[BRDFFitter, RationalFunction, Segments]:
    """r = p / q = 0.5 with q = q_const - hp - b in STARK_2D, data where q > 0."""
    space = PolynomialSpace("legendre", [[0.0, 1.0], [0.0, 1.0]], "total")
    probe = np.random.default_rng(3).uniform(0, 1, (50, 2))
    qc = np.linalg.lstsq(space.design(probe, 3), q_const - probe.sum(axis=1), rcond=None)[0]
    rf = RationalFunction(space, 0.5 * qc, qc)
    x = np.random.default_rng(4).uniform(0, 1, (4000, 2))
    x = x[(np.hypot(x[:, 0], x[:, 1]) <= 1.0) & (x.sum(axis=1) < 1.1)]
    seg = Segments.from_absolute(x, np.full(len(x), 0.5), 0.1)
    fitter = BRDFFitter()
    fitter.parametrization = "STARK_2D"
    return fitter, rf, seg


def test_pole_check_only_on_valid_configurations() -> None:
    """q < 0 only in the box corner hp + b > 1.9 (hp^2 + b^2 > 1: no directions) is accepted;
    q < 0 at hp + b > 1.2, which holds valid pairs such as (0.7, 0.7), is rejected."""
    fitter, rf, seg = _stark_candidate(1.9)
    assert not verify(rf, seg).verified  # the plain check sees q < 0 at the corner (1, 1)
    ver = fitter._verify(rf, seg, 0)
    assert ver.verified and not ver.denominator_sign_changes and ver.n_violations == 0
    fitter, rf, seg = _stark_candidate(1.2)
    assert np.all(rf.denominator(seg.x) > 0)  # the data alone would not show it
    ver = fitter._verify(rf, seg, 0)
    assert not ver.verified and ver.denominator_sign_changes
    grid = valid_grid("STARK_2D", [[0.0, 1.0], [0.0, 1.0]])
    assert grid is not None and np.all(np.hypot(grid[:, 0], grid[:, 1]) <= 1.0 + 1e-9)
    assert np.any(grid.sum(axis=1) > 1.3)
    # Segment violations are never relaxed.
    bad = Segments.from_absolute(seg.x, np.full(seg.n_points, 0.8), 0.1)
    fitter, rf, _ = _stark_candidate(1.9)
    assert not fitter._verify(rf, bad, 0).verified


@pytest.mark.slow
def test_positive_q_rows_and_fit() -> None:
    """With positive_q the QP itself keeps q > 0 on the valid grid: its extra rows are
    q(g)/|psi(g)|, consistent with residuals(), and the fit verifies."""
    P = get_parametrization("STARK_2D")
    rng = np.random.default_rng(5)
    x = rng.uniform(0, 1, (1500, 2))
    x = x[np.hypot(x[:, 0], x[:, 1]) <= 1.0]
    L, V = P.to_dirs(x)
    y = ggx_brdf(L, V)[:, :1]
    ds = Dataset(x, y, None, None, P.coords, ("R",), {"param_in": "STARK_2D"})
    fitter = BRDFFitter(max_total=30)
    fitter.parametrization, fitter.positive_q = "STARK_2D", True
    seg = Segments.from_relative(x, y[:, 0], 0.05)
    system = fitter._split_system(fitter.prepare(seg), seg, 0, 4, 4)
    assert system is not None and system.n_rows > 2 * seg.n_points
    c = rng.normal(size=8)
    assert np.allclose(system.rows(4, 4) @ c, system.residuals(4, 4, c), atol=1e-12)
    fitted, seg2, _ = fit_brdf(ds, dt=0.05, max_total=30, positive_q=True)
    assert fitted.success_ and fitted.positive_q
    rf = fitted.results_[0].rational
    assert np.all(rf.denominator(valid_grid("STARK_2D", rf.space.domain)) > 0)
