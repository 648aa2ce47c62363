"""Fitted importance sampling against cosine sampling in Mitsuba 3, at equal samples per pixel.

Materials: a glossy Cornell measurement fitted by ``ratfit brdf fit`` (default
garnet_red, ISOTROPIC_TV_TL_DPHI, dt 0.2, floor 0.05 %, q > 0 on the valid grid;
``--fit`` to pass your own fit file) and a synthetic lambert+GGX (alpha 0.1)
evaluated analytically. For each, in two scenes (``sphere``: environment with
a bright window, whose variance no BSDF sampler removes; ``sky``: the same
smooth environment without it): a reference image at high spp, then renders at
``--spp`` with the rational-CDF sampler (``fit``) and with cosine sampling,
under two integrators:

* ``bsdf only``: Mitsuba's ``direct`` integrator with bsdf_samples=1,
  emitter_samples=0: the image error is the BSDF sampler's alone;
* ``MIS``: ``path`` (max_depth 2), emitter and BSDF samples combined by MIS.

Columns: RMSE of the sphere's pixels against the reference (relative to the
reference's RMS), the variance reduction MSE(cosine) / MSE(fit) at equal spp,
and the time per sample (render seconds / (pixels x spp); the plugin runs
numpy on whole wavefronts in llvm_ad_rgb). The sampler's build time (all
rational CDF fits) is printed per material.

Run:  python benchmarks/bench_render.py [--size 64] [--spp 16] [--ref-spp 1024]
      [--fit FIT.json] [--data-root ../shared/data]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _bench import add_markdown_option, report  # benchmarks/_bench.py

from ratfit.render import AnalyticMaterial, FitMaterial, HalfVectorSampler
from ratfit.render import mitsuba_bsdf as mb
from ratfit.render.scene import render_image, sphere_view

REPO = Path(__file__).resolve().parents[1]


def cornell_fit(data_root: Path, name: str, out: Path) -> Path:
    cmd = [sys.executable, "-m", "ratfit", "brdf", "fit", str(data_root / "cornell" / name),
           "--param", "ISOTROPIC_TV_TL_DPHI", "--dt", "0.2", "--floor-rel", "0.0005",
           "--positive-q", "-o", str(out)]
    print("fitting:", " ".join(cmd[3:]), file=sys.stderr, flush=True)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--fit", type=Path, help="a BRDF fit file (default: fit garnet_red)")
    ap.add_argument("--cornell", default="garnet_red.brdf")
    ap.add_argument("--data-root", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("--seeds", type=int, default=2, help="independent renders averaged")
    add_markdown_option(ap)
    args = ap.parse_args()
    rep = report(args, __file__)
    variant = mb.setup()
    print(f"mitsuba variant {variant}", file=sys.stderr)
    with tempfile.TemporaryDirectory() as tmp:
        fit = args.fit or cornell_fit(args.data_root, args.cornell, Path(tmp) / "fit.json")
        fmat = FitMaterial(fit)
        if fmat.negative_fraction > 0:
            print(f"note: {fit} is negative on {100 * fmat.negative_fraction:.1f}% of a "
                  "hemisphere grid; clamped to 0", file=sys.stderr)
        mats = {f"Cornell {Path(args.cornell).stem} (fit)": fmat,
                "lambert+GGX a=0.1": AnalyticMaterial("lambert+ggx", [0.2, 1.0, 0.1, 0.04],
                                                      rgb=(0.9, 0.5, 0.3))}
        hit, _ = sphere_view(args.size)
        rows, builds = [], []
        for name, mat in mats.items():
            t0 = time.perf_counter()
            sampler = HalfVectorSampler().fit(mat)
            builds.append(f"{name}: sampler {sampler.fits_} CDFs, n+m {sampler.coefficients_}, "
                          f"{sampler.fallbacks_} uniform fallbacks, "
                          f"{time.perf_counter() - t0:.1f} s")
            print(builds[-1], file=sys.stderr, flush=True)
            for scene in ("sphere", "sky"):
                ref = render_image(mat, size=args.size, spp=args.ref_spp, sampler=sampler,
                                   seed=1000, scene=scene,
                                   progress=lambda m: print(m, file=sys.stderr),
                                   label=f"{name} {scene} reference")
                rms = float(np.sqrt(np.mean(ref[hit] ** 2)))
                for integ, label in (("bsdf", "bsdf only"), ("path", "MIS")):
                    mse, tps = {}, {}
                    for sampling in ("fit", "cosine"):
                        errs, secs = [], 0.0
                        for seed in range(args.seeds):
                            t0 = time.perf_counter()
                            img = render_image(mat, size=args.size, spp=args.spp,
                                               sampler=sampler, sampling=sampling,
                                               integrator=integ, seed=seed, scene=scene)
                            secs += time.perf_counter() - t0
                            errs.append(np.mean((img[hit] - ref[hit]) ** 2))
                        mse[sampling] = float(np.mean(errs))
                        tps[sampling] = secs / (args.seeds * args.size**2 * args.spp)
                    for sampling in ("fit", "cosine"):
                        rows.append([name, scene, label, sampling, str(args.spp),
                                     f"{np.sqrt(mse[sampling]) / rms:.4f}",
                                     f"{mse['cosine'] / mse[sampling]:.2f}",
                                     f"{1e6 * tps[sampling]:.2f}"])
    rep.table(f"{args.size}x{args.size}, {args.spp} spp (mean of {args.seeds} seeds) "
              f"vs {args.ref_spp}-spp reference, {variant}",
              ["material", "scene", "integrator", "sampling", "spp", "rel. RMSE", "MSE cos/this",
               "us/sample"], rows)
    for b in builds:
        rep.note(b)
    rep.write()


if __name__ == "__main__":
    main()
