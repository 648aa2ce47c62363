"""Issue 27: option combinations that cannot mean anything are refused in one line, and
directions typed to 4 digits are taken as the unit vectors they mean."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import one_error_line, run_cli

from ratfit.brdf.fitter import fit_brdf, load_brdf_fit
from ratfit.brdf.io import brdf_dataset
from ratfit.errors import InputError
from ratfit.jobs import BRDFFitRequest


def test_floor_rel_without_dt_is_refused(shared_data: Path, tmp_path: Path) -> None:
    # ran 177 s with a relative width of 0 at the peak, then exited 1
    out = tmp_path / "fit.json"
    r = run_cli("brdf", "fit", shared_data / "cornell" / "cayman.brdf", "--floor-rel", "0.0001",
                "-o", out)
    one_error_line(r, r"--floor-rel 0\.0001 without --dt", r"--dt 0\.05 --floor-rel 0\.0001")
    assert not out.exists()
    # the library says the same; with --dt or --abs-width the floor means something
    ds = brdf_dataset(shared_data / "cornell" / "cayman.brdf", None, channels=["R"],
                      max_points=40)
    with pytest.raises(InputError, match="without --dt"):
        fit_brdf(ds, floor_rel=1e-4)
    for widths in ({"dt": 0.05}, {"abs_width": 0.01}):
        req = BRDFFitRequest.from_settings("x.brdf", {"floor_rel": 1e-4, **widths})
        assert req.floor_rel == 1e-4
    with pytest.raises(InputError, match="without --dt"):
        BRDFFitRequest.from_settings("x.brdf", {"floor_rel": 1e-4})


def test_directions_typed_to_four_digits(shared_data: Path, tmp_path: Path) -> None:
    fit_path = shared_data / "alta" / "fits" / "rational-example-01.brdf"  # STARK_2D
    rows = np.array([[0.7071, 0.0, 0.7071, 0.0, 0.6, 0.8],
                     [0.5774, 0.5774, 0.5774, 0.0, 0.0, 1.0]])
    dirs = tmp_path / "dirs.csv"
    dirs.write_text("lx,ly,lz,vx,vy,vz\n" + "\n".join(
        ",".join(f"{v:g}" for v in row) for row in rows) + "\n")
    r = run_cli("brdf", "eval", fit_path, "--dirs", dirs)
    assert r.exit_code == 0, r.output  # refused: length np.float64(0.99998...) != 1
    got = np.loadtxt(r.stdout.splitlines()[1:], delimiter=",")[:, 6:]
    L = rows[:, :3] / np.linalg.norm(rows[:, :3], axis=1, keepdims=True)
    V = rows[:, 3:] / np.linalg.norm(rows[:, 3:], axis=1, keepdims=True)
    ref = load_brdf_fit(fit_path).eval_dirs(L, V)
    assert got.shape == (2, 3) and np.all(ref > 0)
    assert np.allclose(got, ref, rtol=1e-12, atol=0)
    # clearly not unit vectors: refused in plain numbers
    for bad, length in (([0.8, 0.0, 0.8], "1.13137"), ([0.7, 0.0, 0.7], "0.989949")):
        wrong = tmp_path / "wrong.csv"
        wrong.write_text(",".join(str(v) for v in bad + [0.0, 0.0, 1.0]) + "\n")
        e = run_cli("brdf", "eval", fit_path, "--dirs", wrong)
        line = one_error_line(e, rf"direction L row 0 is not a unit vector \(length {length};",
                              r"within 0\.001 of length 1 are normalised")
        assert "np.float64" not in line


@pytest.mark.parametrize("args, pattern", [
    (["--n", "3", "--m", "3", "--max-total", "10"],
     r"--n/--m fix the split: --max-total only steers a search over totals"),
    (["--n", "3", "--m", "3", "--strategy", "exhaustive", "--split-rule", "error"],
     r"--n/--m fix the split: --strategy, --split-rule only steer"),
    (["--total", "6", "--min-total", "3"], r"--total fixes the total: --min-total only steers"),
])
def test_a_fixed_size_refuses_search_options(shared_data: Path, args: list[str],
                                             pattern: str) -> None:
    r = run_cli("fit", shared_data / "nist" / "Kirby2.dat", "--dt", "0.05", *args)
    one_error_line(r, pattern)


def test_fixed_total_keeps_its_split_rule(shared_data: Path) -> None:
    # --total tries every split of one total: --split-rule picks among them, so it stays
    r = run_cli("fit", shared_data / "nist" / "Kirby2.dat", "--dt", "0.05", "--total", "5",
                "--split-rule", "error", "--json")
    assert r.exit_code in (0, 1) and "error:" not in r.stderr


def test_color_is_for_spectral_data(shared_data: Path) -> None:
    r = run_cli("brdf", "fit", shared_data / "alta" / "retro-3M-jaune.dat", "--color", "xyz")
    one_error_line(r, r"--color xyz converts spectral \(Cornell\) data", "channels y0 already")
