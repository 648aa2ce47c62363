"""A BRDF fit along the mirror direction, where every highlight is, against its samples.

A Cornell file has one sample per incidence angle within 0.02 rad of the mirror
direction (theta_h) and none at the mirror itself below 40 degrees, so a fit's highlight
between them is what the fit makes of a handful of samples. For each fit: its value
(each channel) at the exact mirror pair for incidence angles from 5 to 85 degrees, and
at each sample within 0.02 rad of the mirror direction the sample's value, the fit's and
their ratio per channel (the highlight's colour is the ratio of the channels).

    python benchmarks/mirror_line.py FIT.json [FIT.json ...] [--data DIR] [--markdown [PATH]]

Each fit's material is its file name's stem (``mystique.json`` -> cornell/mystique.brdf).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from _bench import add_markdown_option, report  # benchmarks/_bench.py

from ratfit.brdf.fitter import load_brdf_fit
from ratfit.brdf.io import read_brdf, samples_dataset
from ratfit.brdf.parametrizations import get_parametrization

REPO = Path(__file__).resolve().parents[1]
OWN = "ISOTROPIC_TV_TL_DPHI"  # what `ratfit brdf fit` reads Cornell's Cartesian pairs as
HALF_DIFF = get_parametrization("RUSIN_TH_TD_PD")  # (theta_h, theta_d, phi_d)
MIRROR = 0.02  # rad of theta_h
DEGREES = (5, 10, 20, 30, 40, 50, 60, 65, 70, 75, 77, 79, 80, 85)


def _mirror_pairs(degrees: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(L, V) of the mirror pair (theta_h = 0) at each incidence angle (theta_d)."""
    td = np.radians(np.asarray(degrees, dtype=float))
    zero = np.zeros_like(td)
    return HALF_DIFF.to_dirs(np.stack([zero, td, zero], axis=1))


def _fmt(values: np.ndarray) -> str:
    return " / ".join(f"{v:.3g}" for v in values)


def _figure(rep, degrees: np.ndarray, curves: dict[str, np.ndarray],
            near: dict[str, tuple[np.ndarray, np.ndarray]]) -> None:
    """One panel per fit: each channel along the mirror direction (lines) and the samples
    within MIRROR of it (dots), on a log scale."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = ("tab:red", "tab:green", "tab:blue")
    fig, axes = plt.subplots(1, len(curves), figsize=(3.2 * len(curves), 3.2), sharey=True,
                             squeeze=False)
    for ax, (name, f) in zip(axes[0], curves.items(), strict=True):
        for j in range(f.shape[1]):
            c = colours[j % 3]
            ax.semilogy(degrees, np.maximum(f[:, j], 1e-4), color=c, lw=1.2)
            if name in near:
                ax.semilogy(near[name][0], np.maximum(near[name][1][:, j], 1e-4), "o",
                            color=c, ms=4, mfc="none")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("incidence = theta_d (deg)", fontsize=8)
        ax.set_ylim(1e-4, 1e4)
        ax.grid(True, which="major", alpha=0.3)
    axes[0][0].set_ylabel("fit at the mirror pair (1/sr)", fontsize=8)
    fig.tight_layout()
    rep.figure(fig, rep.stem("mirror_line"),
               "each fit along the mirror direction (lines: R, G, B) and the samples within "
               f"{MIRROR} rad of it (circles); values below 1e-4 drawn at 1e-4")
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("fits", type=Path, nargs="+", metavar="FIT")
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    L, V = _mirror_pairs(np.asarray(DEGREES))
    sample_rows: list[list[str]] = []
    lines: dict[str, np.ndarray] = {}
    near_samples: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    # the curve of the figure: every half degree
    fine = np.arange(1.0, 89.5, 0.5)
    Lf, Vf = _mirror_pairs(fine)
    curves: dict[str, np.ndarray] = {}
    for path in args.fits:
        fit = load_brdf_fit(path)
        lines[path.stem] = fit.eval_dirs(L, V)
        curves[path.stem] = fit.eval_dirs(Lf, Vf)
        data = args.data / "cornell" / f"{path.stem}.brdf"
        if not data.exists():
            continue
        ds = samples_dataset(read_brdf(data), OWN)
        Ls, Vs = get_parametrization(OWN).to_dirs(ds.x)
        theta_h = HALF_DIFF.from_dirs(Ls, Vs)[:, 0]
        near = np.flatnonzero(theta_h < MIRROR)
        theta_l = np.degrees(np.arccos(np.clip(Ls[near, 2], -1.0, 1.0)))
        order = np.argsort(theta_l)
        near, theta_l = near[order], theta_l[order]
        y = np.asarray(ds.y)[near]
        g = fit.eval_dirs(Ls[near], Vs[near])
        near_samples[path.stem] = (theta_l, y)
        for i, k in enumerate(near):
            sample_rows.append([path.stem, f"{theta_l[i]:.1f}",
                                f"{theta_h[k]:.4f}", _fmt(y[i]), _fmt(g[i]),
                                _fmt(g[i] / np.where(y[i] > 0, y[i], np.nan))])
    names = list(lines)
    rep.table("each fit at the mirror pair (theta_h = 0) of each incidence angle "
              "(1/sr, channels in the fit's order)",
              ["incidence (deg)", *names],
              [[str(d)] + [_fmt(lines[n][i]) for n in names] for i, d in enumerate(DEGREES)])
    _figure(rep, fine, curves, near_samples)
    if sample_rows:
        rep.table(f"the samples within {MIRROR} rad of the mirror direction: value, fit, "
                  "fit / value per channel",
                  ["fit", "theta_l (deg)", "theta_h", "y", "fit", "fit / y"], sample_rows)
    rep.write()


if __name__ == "__main__":
    main()
