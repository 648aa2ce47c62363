"""`ratfit render`: a fitted BRDF on a sphere in Mitsuba 3, optionally beside the measured data."""

from __future__ import annotations

import json
import time
from pathlib import Path

import click
import numpy as np

from ratfit.cli.main import main

_EXTS = (".exr", ".png")


def _tonemap(img: np.ndarray, scale: float) -> np.ndarray:
    """Linear RGB x scale -> sRGB-encoded uint8."""
    v = np.clip(img * scale, 0.0, 1.0)
    v = np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1.0 / 2.4) - 0.055)
    return np.round(v * 255.0).astype(np.uint8)


def _write(mi, path: Path, img: np.ndarray, scale: float) -> None:
    """Write atomically: EXR linear float32, PNG tonemapped with ``scale``."""
    from ratfit._atomic import atomic_path

    with atomic_path(path) as tmp:
        if path.suffix.lower() == ".exr":
            bmp = mi.Bitmap(np.ascontiguousarray(img, dtype=np.float32))
            bmp.write(str(tmp), mi.Bitmap.FileFormat.OpenEXR)
        else:
            mi.Bitmap(np.ascontiguousarray(_tonemap(img, scale))).write(
                str(tmp), mi.Bitmap.FileFormat.PNG)


def _side_path(output: Path, tag: str) -> Path:
    return output.with_name(f"{output.stem}-{tag}{output.suffix}")


@main.command("render")
@click.argument("fit_path", metavar="FIT.json", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Image (.exr linear, or .png tonemapped). With --data: fit | data | |diff| "
                   "side by side; the difference alone goes to OUTPUT-diff.")
@click.option("--scene", type=click.Choice(["sphere", "sky", "point", "sphere-point",
                                           "furnace"]),
              default="sphere", show_default=True,
              help="sphere: environment light with a bright window; sky: the same without the "
                   "window; point: a point light; "
                   "furnace: constant white environment (pixels = albedo).")
@click.option("--spp", type=click.IntRange(1, 1 << 16), default=64, show_default=True,
              help="Samples per pixel.")
@click.option("--size", type=click.IntRange(8, 4096), default=256, show_default=True,
              help="Image width and height in pixels.")
@click.option("--sampling", type=click.Choice(["fit", "cosine"]), default="fit",
              show_default=True,
              help="fit: importance sampling with rational CDFs fitted to the BRDF; cosine: "
                   "cosine-weighted hemisphere.")
@click.option("--cosine-weight", type=click.FloatRange(0.0, 1.0), default=0.2,
              show_default=True, help="Share of cosine samples mixed into fit sampling.")
@click.option("--incidence-nodes", type=click.IntRange(1, 90), default=9, show_default=True,
              help="Fit sampling: incidence angles with their own CDFs (interpolated between).")
@click.option("--conditional-nodes", type=click.IntRange(2, 64), default=12, show_default=True,
              help="Fit sampling: half-vector elevations with a conditional CDF of phi_h.")
@click.option("--data", "data", type=click.Path(dir_okay=False, path_type=Path),
              help="Measured BRDF file: render it (interpolated) with the same camera, light, "
                   "samples and exposure, and write the difference.")
@click.option("--exposure", type=float, default=None,
              help="PNG scale (default: the 99.5th luminance percentile of the brighter of the "
                   "fit and data renders maps to 1).")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--variant", type=click.Choice(["auto", "llvm_ad_rgb", "scalar_rgb"]),
              default="auto", show_default=True, help="Mitsuba variant.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def render_cmd(fit_path: Path, output: Path, scene: str, spp: int, size: int, sampling: str,
               cosine_weight: float, incidence_nodes: int, conditional_nodes: int,
               data: Path | None, exposure: float | None, seed: int,
               variant: str, as_json: bool) -> None:
    """Render a BRDF fit on a sphere with Mitsuba 3 (extra: pip install ".[render]")."""
    from ratfit.errors import InputError

    if output.suffix.lower() not in _EXTS:
        raise click.UsageError(f"output {output} must end in .exr or .png")
    if exposure is not None and not (np.isfinite(exposure) and exposure > 0):
        raise click.UsageError(f"--exposure must be a finite number > 0, got {exposure!r}")
    from ratfit.render import mitsuba_bsdf as mb

    mi, _ = mb._import_mitsuba()  # missing extra: one error line, exit 2
    from ratfit.render.material import DataMaterial, FitMaterial
    from ratfit.render.sampler import HalfVectorSampler
    from ratfit.render.scene import render_image, sphere_view

    def say(msg: str) -> None:
        click.echo(msg, err=True)

    mat = FitMaterial(fit_path)
    ref = DataMaterial(data) if data is not None else None
    if mat.negative_fraction > 0:
        say(f"note: the fit is negative on {100 * mat.negative_fraction:.1f}% of a hemisphere "
            "grid of direction pairs; clamped to 0 for rendering")
    if mat.outside_fraction > 0:
        say(f"note: {100 * mat.outside_fraction:.1f}% of directions (theta_l = 34 deg) lie "
            "outside the fit's domain even after reciprocity/isotropy; evaluated at the "
            "nearest point of its box")
    v = mb.setup(None if variant == "auto" else variant)
    say(f"mitsuba variant {v}")
    sampler = None
    info: dict = {"fit": str(fit_path), "variant": v, "scene": scene, "spp": spp,
                  "size": size, "sampling": sampling,
                  "negative_fraction": mat.negative_fraction,
                  "outside_fraction": mat.outside_fraction}
    if sampling == "fit":
        t0 = time.perf_counter()
        say("fitting the sampling CDFs ...")
        sampler = HalfVectorSampler(cosine_weight=cosine_weight, n_incidence=incidence_nodes,
                                    n_conditional=conditional_nodes).fit(mat)
        dt = time.perf_counter() - t0
        say(f"sampler: {sampler.fits_} verified rational CDFs (total n+m "
            f"{sampler.coefficients_}, {sampler.fallbacks_} uniform fallbacks), {dt:.1f} s")
        info["sampler"] = {"cdfs": sampler.fits_, "coefficients": sampler.coefficients_,
                           "uniform_fallbacks": sampler.fallbacks_, "seconds": dt}
    t0 = time.perf_counter()
    img = render_image(mat, size=size, spp=spp, sampling=sampling, sampler=sampler,
                       scene=scene, seed=seed, progress=say, label="fit")
    info["render_seconds"] = time.perf_counter() - t0
    hit, _ = sphere_view(size)
    luma = np.array([0.2126, 0.7152, 0.0722])
    if not np.all(np.isfinite(img)):
        raise InputError("the render has non-finite pixels (the fit has a pole?)")
    outputs = {}
    shown = [img]
    if ref is None:
        outputs[output] = img
    else:
        # the data gets its own sampler: a poor fit's lobes would leave the data's
        # highlights to the cosine share of the mixture (unbiased, but speckled)
        dsampler = None
        if sampling == "fit":
            say("fitting the sampling CDFs of the data ...")
            dsampler = HalfVectorSampler(cosine_weight=cosine_weight, n_incidence=incidence_nodes,
                                         n_conditional=conditional_nodes).fit(ref)
        dimg = render_image(ref, size=size, spp=spp, sampling=sampling, sampler=dsampler,
                            scene=scene, seed=seed, progress=say, label="data")
        shown.append(dimg)
        diff = img - dimg
        a, b = img[hit], dimg[hit]
        la, lb = a @ luma, b @ luma
        info["data"] = str(data)
        info["difference"] = {
            "pixels": int(hit.sum()),
            "rel_rmse": float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b**2))),
            "mean_abs_rel_luminance": float(np.mean(np.abs(la - lb)) / np.mean(lb)),
            "mean_luminance_fit": float(la.mean()), "mean_luminance_data": float(lb.mean()),
            "max_abs": float(np.abs(a - b).max()),
        }
        gap = np.zeros((size, max(2, size // 64), 3))
        outputs[output] = np.concatenate([img, gap, dimg, gap, np.abs(diff)], axis=1)
        outputs[_side_path(output, "diff")] = diff if output.suffix.lower() == ".exr" \
            else np.abs(diff)
    # one exposure for every image: the brighter render's 99.5th percentile maps to 1
    top = max(float(np.quantile(im[hit] @ luma, 0.995)) for im in shown)
    scale = exposure if exposure is not None else 1.0 / max(top, 1e-12)
    info["exposure"] = scale
    for path, im in outputs.items():
        _write(mi, path, im, scale)
    info["outputs"] = [str(p) for p in outputs]
    if as_json:
        click.echo(json.dumps(info, indent=1, allow_nan=False))
        return
    click.echo(f"rendered {fit_path} ({v}, {scene}, {size}x{size}, {spp} spp, {sampling} "
               f"sampling) in {info['render_seconds']:.1f} s")
    if "difference" in info:
        d = info["difference"]
        click.echo(f"fit vs data ({data}) over {d['pixels']} sphere pixels: relative RMSE "
                   f"{d['rel_rmse']:.4f}, mean |luminance difference| / mean luminance "
                   f"{d['mean_abs_rel_luminance']:.4f} (fit {d['mean_luminance_fit']:.4g}, "
                   f"data {d['mean_luminance_data']:.4g})")
    for p in outputs:
        click.echo(f"wrote {p}")
