"""`ratfit render`: a fitted BRDF on a sphere in Mitsuba 3, optionally beside the measured data."""

from __future__ import annotations

import json
from pathlib import Path

import click
import numpy as np

from ratfit.cli.options import FiniteFloatRange


@click.command("render")
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
@click.option("--cosine-weight", type=FiniteFloatRange(0.0, 1.0), default=0.2,
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
@click.option("--seed", type=click.IntRange(0, 2**32 - 1), default=0, show_default=True,
              help="Mitsuba's sampler seed (32 bits).")
@click.option("--variant", type=click.Choice(["auto", "llvm_ad_rgb", "scalar_rgb"]),
              default="auto", show_default=True, help="Mitsuba variant.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
def render_cmd(fit_path: Path, output: Path, scene: str, spp: int, size: int, sampling: str,
               cosine_weight: float, incidence_nodes: int, conditional_nodes: int,
               data: Path | None, exposure: float | None, seed: int,
               variant: str, as_json: bool) -> None:
    """Render a BRDF fit on a sphere with Mitsuba 3 (extra: pip install ".[render]").

    FIT.json is a `ratfit brdf fit` file or an analytic model fitted by `ratfit brdf
    model`: both are drawn in the same scene, so fit, model and data compare image
    to image."""
    from ratfit.jobs import RenderRequest, render_fit
    from ratfit.jobs.render import IMAGE_SUFFIXES

    if output.suffix.lower() not in IMAGE_SUFFIXES:
        raise click.UsageError(f"output {output} must end in .exr or .png")
    if exposure is not None and not (np.isfinite(exposure) and exposure > 0):
        raise click.UsageError(f"--exposure must be a finite number > 0, got {exposure!r}")
    from ratfit.cli.progress import message_progress

    # notes and phases on stderr, passes with an estimate of the time left (one status
    # line on a terminal, a line every few seconds in a log); stdout keeps the result
    say, stop = message_progress()
    try:
        report = render_fit(RenderRequest(
            fit_path, output, scene=scene, spp=spp, size=size, sampling=sampling,
            cosine_weight=cosine_weight, incidence_nodes=incidence_nodes,
            conditional_nodes=conditional_nodes, data=data, exposure=exposure, seed=seed,
            variant=variant, progress=say))
    finally:
        stop()
    if as_json:
        click.echo(json.dumps(report.summary(), indent=1, allow_nan=False))
        return
    click.echo(f"rendered {fit_path} ({report.variant}, {scene}, {size}x{size}, {spp} spp, "
               f"{sampling} sampling) in {report.seconds.get('render', 0.0):.1f} s")
    if report.difference is not None:
        d = report.difference
        click.echo(f"fit vs data ({data}) over {d['pixels']} sphere pixels: relative RMSE "
                   f"{d['rel_rmse']:.4f}, mean |luminance difference| / mean luminance "
                   f"{d['mean_abs_rel_luminance']:.4f} (fit {d['mean_luminance_fit']:.4g}, "
                   f"data {d['mean_luminance_data']:.4g})")
    for p in report.outputs:
        click.echo(f"wrote {p}")
