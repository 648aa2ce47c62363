"""Where a renderer evaluates a BRDF fit: random direction pairs over the whole hemisphere.

For each fit file (default: every ``FIT.json`` given on the command line), this draws
``--pairs`` uniform random (L, V) pairs over the hemisphere (mirror pairs, theta_h = 0,
included) and evaluates the fit three ways: ``BRDFFit.eval_dirs`` (what ``ratfit brdf
eval`` prints), the C export (compiled with gcc, what a renderer links) and the
renderer's material (``ratfit.render.FitMaterial.raw``, what the Mitsuba plugin calls,
before its clamp at 0). Per channel it prints the smallest value of each, the count of
negative or non-finite values, the largest relative difference of the C export and the
material from ``eval_dirs``, the spread over phi_d at theta_h = 0 (an isotropic BRDF does
not depend on phi_d there), the proof stored in the fit file, the largest value
``eval_dirs`` gave beside the upper bound the proof states (a fit of log values), the
largest ratio of a value to the samples' envelope over theta_h the proof states (a
scattered log fit's steps, at the theta_h where the fit is evaluated), the smallest
ratio of a value to the floor of the highlight's samples the proof states (where one
sets it), and the seconds each took.

    python benchmarks/bench_validity.py FIT.json [FIT2.json ...] [--pairs 1000000]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
from _bench import add_markdown_option, report


def hemisphere(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(2):
        ct, ph = rng.uniform(0.0, 1.0, n), rng.uniform(-np.pi, np.pi, n)
        st = np.sqrt(1 - ct**2)
        out.append(np.stack([st * np.cos(ph), st * np.sin(ph), ct], 1))
    L, V = out
    k = max(1, n // 100)
    V[:k] = L[:k] * [-1, -1, 1]  # exact mirror pairs
    return L, V


def c_values(fit_path: Path, L: np.ndarray, V: np.ndarray) -> tuple[np.ndarray, float]:
    from ratfit.export.code import export_fit

    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "f.c"
        export_fit(fit_path, "c", src)
        src.write_text(src.read_text() + """
#include <stdio.h>
int main(void)
{
    double L[3], V[3], out[RATFIT_NCHANNELS];
    while (fread(L, sizeof L, 1, stdin) == 1 && fread(V, sizeof V, 1, stdin) == 1) {
        ratfit_brdf(L, V, out);
        fwrite(out, sizeof out, 1, stdout);
    }
    return 0;
}
""")
        exe = Path(tmp) / "f"
        subprocess.run(["gcc", "-std=c99", "-O2", "-o", str(exe), str(src), "-lm"],
                       check=True, capture_output=True)
        inp = np.ascontiguousarray(np.hstack([L, V]), dtype=np.float64).tobytes()
        t0 = time.perf_counter()
        out = subprocess.run([str(exe)], input=inp, capture_output=True, check=True).stdout
        sec = time.perf_counter() - t0
    return np.frombuffer(out, dtype=np.float64).reshape(len(L), -1), sec


def phi_d_spread(fit, k: int = 2000) -> np.ndarray:
    """Per channel: max - min over phi_d of the fit at theta_h = 0, relative to the mean,
    worst over theta_d in (0, 85 deg)."""
    from ratfit.brdf.parametrizations import get_parametrization

    rusin = get_parametrization("RUSIN_TH_TD_PD")
    worst = np.zeros(fit.n_channels)
    for td in np.linspace(0.01, np.radians(85), 24):
        pd = np.linspace(0.0, 2 * np.pi, k, endpoint=False)
        L, V = rusin.to_dirs(np.column_stack([np.zeros(k), np.full(k, td), pd]))
        v = fit.eval_dirs(L, V)
        spread = (v.max(axis=0) - v.min(axis=0)) / np.maximum(np.abs(v.mean(axis=0)), 1e-300)
        worst = np.maximum(worst, spread)
    return worst


def main() -> None:
    from ratfit.brdf.fitter import load_brdf_fit
    from ratfit.brdf.validity import FLOOR_LOG_MIN, envelope_from_dict
    from ratfit.render.material import FitMaterial

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("fits", nargs="+", type=Path)
    ap.add_argument("--pairs", type=int, default=1_000_000)
    ap.add_argument("--seed", type=int, default=0)
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    L, V = hemisphere(args.pairs, args.seed)
    rows = []
    for path in args.fits:
        fit = load_brdf_fit(path)
        proofs = json.loads(path.read_text())["brdf"].get("proof") or [None] * fit.n_channels
        t0 = time.perf_counter()
        ref = fit.eval_dirs(L, V)
        t_eval = time.perf_counter() - t0
        t0 = time.perf_counter()
        mat = FitMaterial(fit).raw(L, V) if fit.n_channels in (1, 3) else ref
        t_mat = time.perf_counter() - t0
        cv, t_c = c_values(path, L, V)
        spread = phi_d_spread(fit)
        kept = np.delete(fit.coords(L, V)[0], list(fit.dropped), axis=1)
        for j, name in enumerate(fit.channel_names):
            r = ref[:, j]
            scale = np.maximum(np.abs(r), 1e-12 * np.max(np.abs(r)))
            bad = int(np.sum(~np.isfinite(r) | (r < 0)) + np.sum(~np.isfinite(cv[:, j])
                                                                  | (cv[:, j] < 0)))
            pr = proofs[j] if j < len(proofs) else None
            steps = envelope_from_dict(pr)
            env = "-" if steps is None else f"{np.max(r / np.exp(steps.at_points(kept))):.3g}"
            floor = getattr(steps, "floor", None)
            low = "-"
            if floor is not None:
                f = floor.at_points(kept)
                held = f > FLOOR_LOG_MIN
                if held.any():
                    low = f"{np.min(r[held] / np.exp(f[held])):.3g} ({int(held.sum())})"
            rows.append([
                f"{path.stem}", name, f"{np.min(r):.4g}", f"{np.min(cv[:, j]):.4g}",
                f"{np.min(mat[:, j]):.4g}", str(bad), f"{np.max(r):.4g}",
                f"{pr['value_bound']:.4g}" if pr and pr.get("value_bound") else "-", env, low,
                f"{np.max(np.abs(cv[:, j] - r) / scale):.1e}",
                f"{np.max(np.abs(mat[:, j] - r) / scale):.1e}", f"{spread[j]:.1e}",
                "yes" if pr and pr.get("proved") else "no",
                f"{pr['q_margin']:.1e}" if pr else "-",
                f"{t_eval:.2f}/{t_c:.2f}/{t_mat:.2f}"])
    rep.table(f"{args.pairs} random pairs over the hemisphere (seed {args.seed})",
              ["fit", "ch", "min eval", "min C", "min plugin", "neg|nonfinite", "max eval",
               "proved bound", "max / envelope", "min / floor", "C vs eval", "plugin vs eval",
               "phi_d spread th_h=0", "proved", "q margin", "s eval/C/plugin"], rows,
              note="proved bound: the largest value the proof allows (fits of log values: "
                   "exp(p/q) <= twice the largest segment end); max / envelope: the "
                   "largest value over the proved envelope at its coordinates (at most 1 "
                   "where proved); min / floor: the smallest value over the proved floor "
                   "where one of the highlight's samples sets it (at least 1 where proved; "
                   "in brackets: how many pairs that is); '-': none stated.")
    rep.write()


if __name__ == "__main__":
    main()
