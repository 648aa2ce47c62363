"""How faithfully ``ratfit render --data`` draws the measurement: the interpolation of
measured samples (:class:`ratfit.render.material.DataMaterial`) predicting held-out
samples of each Cornell file (5-fold, seed 0), against a baseline interpolation in the
same run: the same k-nearest-neighbour average embedded by the two directions' own
angles (L rotated to azimuth 0, V's azimuth folded; every sample entered with L and V
exchanged), which ``ratfit render`` used before.

    python benchmarks/bench_data_interp.py [--data-root DIR] [--markdown [PATH]]

Per channel: RMSE, cos-weighted RMSE (f cos theta_l) and relative RMSE of
log((f + e) / (y + e)), e = 1e-3 1/sr, of each interpolation at the held-out samples,
and the ratio this / baseline (below 1: this interpolation is closer to the data).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np
from _bench import add_markdown_option, report  # benchmarks/_bench.py

REPO = Path(__file__).resolve().parents[1]
DEFAULT_DATA = Path(os.environ.get("RATFIT_SHARED_DATA", REPO.parent / "shared" / "data"))
MATERIALS = ("garnet_red", "acryl_blue", "cayman", "krylon_blue", "mystique")
FOLDS = 5
E = 1e-3


def baseline_class():
    """The interpolation embedded by the directions' own angles (the baseline)."""
    from ratfit.render.material import DataMaterial

    class DirectionAngles(DataMaterial):
        @staticmethod
        def _features(L: np.ndarray, V: np.ndarray) -> np.ndarray:
            sl = np.hypot(L[:, 0], L[:, 1])
            dphi = np.arctan2(V[:, 1], V[:, 0]) - np.arctan2(L[:, 1], L[:, 0])
            sv = np.hypot(V[:, 0], V[:, 1])
            return np.stack([sl, L[:, 2], sv * np.cos(dphi), sv * np.abs(np.sin(dphi)),
                             V[:, 2]], 1)

        @classmethod
        def from_pairs(cls, L, V, rgb, **kw):  # reciprocity by entering each pair twice
            return super().from_pairs(np.vstack([L, V]), np.vstack([V, L]),
                                      np.vstack([rgb, rgb]), **kw)

    return DirectionAngles


def held_out(cls, L: np.ndarray, V: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Each sample predicted by ``cls`` from the folds without it."""
    fold = np.random.default_rng(0).permutation(len(y)) % FOLDS
    pred = np.zeros_like(y)
    for k in range(FOLDS):
        tr, te = fold != k, fold == k
        pred[te] = cls.from_pairs(L[tr], V[tr], y[tr])(L[te], V[te])
    return pred


def errors(pred: np.ndarray, y: np.ndarray, cos_l: np.ndarray) -> np.ndarray:
    """(3, channels): RMSE, cos-weighted RMSE, relative RMSE."""
    d = pred - y
    return np.stack([np.sqrt(np.mean(d**2, 0)), np.sqrt(np.mean((d * cos_l[:, None])**2, 0)),
                     np.sqrt(np.mean(np.log((pred + E) / (y + E))**2, 0))])


def main() -> None:
    from ratfit.render.material import DataMaterial, measured_pairs

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data-root", type=Path, default=DEFAULT_DATA,
                    help="folder holding cornell/<material>.brdf")
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    base = baseline_class()
    rows, better = [], np.zeros(3, dtype=int)
    total = 0
    for name in MATERIALS:
        path = args.data_root / "cornell" / f"{name}.brdf"
        if not path.exists():
            sys.exit(f"error: {path} not found (--data-root)")
        L, V, y, _ = measured_pairs(path)
        y = np.maximum(y, 0.0)  # as the render's interpolation takes them
        this, was = (errors(held_out(c, L, V, y), y, L[:, 2]) for c in (DataMaterial, base))
        for c, ch in enumerate("RGB"):
            cells = [f"{this[i, c]:.4g} / {was[i, c]:.4g} ({this[i, c] / was[i, c]:.2f})"
                     for i in range(3)]
            rows.append([name, ch, str(len(y)), *cells])
            better += this[:, c] < was[:, c]
            total += 1
    note = (f"Lower than the baseline's in {better[0]} of {total} channels (RMSE), "
            f"{better[1]} (cos RMSE), {better[2]} (relative RMSE). Each cell: this / "
            "baseline (ratio).")
    rep.table(f"measured samples interpolated as `ratfit render --data` draws them: {FOLDS}-fold "
              "held-out errors at each Cornell file's samples; this: half-vector frame "
              "(sqrt theta_h, difference vector), baseline: the directions' own angles; "
              "k = 8 nearest, inverse squared distance",
              ["material", "ch", "samples", "RMSE", "cos RMSE", "rel. RMSE"], rows, note=note)
    rep.write()


if __name__ == "__main__":
    main()
