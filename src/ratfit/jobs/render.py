"""The job behind ``ratfit render``: a BRDF fit (and optionally its data) rendered on a
sphere with Mitsuba 3, images written, one report out."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ratfit.core.validation import check_choice, check_int
from ratfit.errors import InputError
from ratfit.jobs.common import Clock, as_path

__all__ = ["RenderReport", "RenderRequest", "render_fit"]

IMAGE_SUFFIXES = (".exr", ".png")
SCENES = ("sphere", "sky", "point", "sphere-point", "furnace")
SAMPLINGS = ("fit", "cosine")
VARIANTS = ("auto", "llvm_ad_rgb", "scalar_rgb")
# Rec. 709 luminance of linear RGB.
LUMA = np.array([0.2126, 0.7152, 0.0722])


@dataclass(frozen=True)
class RenderRequest:
    """What a render of a BRDF fit asks for.

    ``output`` is an .exr (linear) or .png (tonemapped with ``exposure``, default
    the brighter render's 99.5th luminance percentile mapped to 1); with
    ``data`` (a measured BRDF file) it holds fit | data | |difference| side by
    side and the difference alone goes to OUTPUT-diff. ``progress`` receives
    one line per step (not part of what is asked: not compared); a line that starts
    with "~" reports a render pass with the time left, the others notes and phases.
    """

    fit: Path
    output: Path
    scene: str = "sphere"
    spp: int = 64
    size: int = 256
    sampling: str = "fit"
    cosine_weight: float = 0.2
    incidence_nodes: int = 9
    conditional_nodes: int = 12
    data: Path | None = None
    exposure: float | None = None
    seed: int = 0
    variant: str = "auto"
    progress: Callable[[str], None] | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        fix = object.__setattr__
        fix(self, "fit", as_path(self.fit, "fit"))
        fix(self, "output", as_path(self.output, "output"))
        fix(self, "data", as_path(self.data, "data", allow_none=True))
        if self.output.suffix.lower() not in IMAGE_SUFFIXES:
            raise InputError(f"output {self.output} must end in .exr or .png")
        if self.exposure is not None and not (np.isfinite(self.exposure) and self.exposure > 0):
            raise InputError(f"exposure must be a finite number > 0, got {self.exposure!r}")
        fix(self, "scene", check_choice(self.scene, "scene", SCENES))
        fix(self, "sampling", check_choice(self.sampling, "sampling", SAMPLINGS))
        fix(self, "variant", check_choice(self.variant, "variant", VARIANTS))
        for name, lo, hi in (("spp", 1, 1 << 16), ("size", 8, 4096), ("incidence_nodes", 1, 90),
                             ("conditional_nodes", 2, 64)):
            v = check_int(getattr(self, name), name, minimum=lo)
            if v is None or v > hi:
                raise InputError(f"{name} must be an integer in [{lo}, {hi}], got {v!r}")
        check_int(self.seed, "seed")
        if not 0.0 <= float(self.cosine_weight) <= 1.0:
            raise InputError(f"cosine_weight must be in [0, 1], got {self.cosine_weight!r}")

    def say(self, msg: str) -> None:
        if self.progress is not None:
            self.progress(msg)


@dataclass
class RenderReport:
    """What a render did: the images written, what the fit looked like to the
    renderer (negative or outside its domain), the sampler, the timings, and
    with data the difference between the two renders."""

    request: RenderRequest
    variant: str
    outputs: list[Path]
    exposure: float
    negative_fraction: float
    outside_fraction: float
    sampler: dict[str, Any] | None = None
    difference: dict[str, Any] | None = None
    seconds: dict[str, float] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """The ``ratfit render --json`` object."""
        req = self.request
        out: dict[str, Any] = {
            "fit": str(req.fit), "variant": self.variant, "scene": req.scene, "spp": req.spp,
            "size": req.size, "sampling": req.sampling,
            "negative_fraction": self.negative_fraction,
            "outside_fraction": self.outside_fraction}
        if self.sampler is not None:
            out["sampler"] = self.sampler
        out["render_seconds"] = self.seconds.get("render", 0.0)
        if self.difference is not None:
            out["data"] = str(req.data)
            out["difference"] = self.difference
        out["exposure"] = self.exposure
        out["outputs"] = [str(p) for p in self.outputs]
        return out


def render_fit(request: RenderRequest) -> RenderReport:
    """Render ``request.fit`` (and ``request.data`` beside it) and write the images."""
    from ratfit.render import mitsuba_bsdf as mb

    mi, _ = mb._import_mitsuba()  # missing extra: one error line, exit 2
    from ratfit.render.material import DataMaterial, material_of
    from ratfit.render.scene import render_image, sphere_view

    req, clock = request, Clock()
    mat = material_of(req.fit)  # a rational fit, or an analytic model fitted to data
    ref = DataMaterial(req.data) if req.data is not None else None
    if ref is not None and ref.below_horizon:
        req.say(f"note: {ref.below_horizon} of the data's samples put a direction below the "
                "horizon; left out of the data render")
    if mat.negative_fraction > 0:
        req.say(f"note: the fit is negative on {100 * mat.negative_fraction:.1f}% of a "
                "hemisphere grid of direction pairs; clamped to 0 for rendering")
    if mat.outside_fraction > 0:
        req.say(f"note: {100 * mat.outside_fraction:.1f}% of directions (theta_l = 34 deg) lie "
                "outside the fit's domain even after reciprocity/isotropy; evaluated at the "
                "nearest point of its box")
    if req.variant == "auto" and mb.variant() is None:
        req.say("choosing the Mitsuba variant (probing LLVM) ...")
    variant = mb.setup(None if req.variant == "auto" else req.variant)
    req.say(f"mitsuba variant {variant}" + (
        " (no working libLLVM >= 16 found)" if variant == "scalar_rgb" and req.variant == "auto"
        else "") + (": the scalar variant calls the BSDF once per sample, far slower; one "
                    "pass per sample per pixel, each reporting the time left"
                    if variant == "scalar_rgb" else ""))
    report = RenderReport(req, variant, [], 1.0, mat.negative_fraction, mat.outside_fraction)
    sampler = _sampler(req, mat, report, clock, "fitting the sampling CDFs ...")
    with clock.phase("render"):
        img = render_image(mat, size=req.size, spp=req.spp, sampling=req.sampling,
                           sampler=sampler, scene=req.scene, seed=req.seed, progress=req.say,
                           label="fit")
    if not np.all(np.isfinite(img)):
        raise InputError("the render has non-finite pixels (the fit has a pole?)")
    hit, _ = sphere_view(req.size)
    images, shown = {req.output: img}, [img]
    if ref is not None:
        # the data gets its own sampler: a poor fit's lobes would leave the data's
        # highlights to the cosine share of the mixture (unbiased, but speckled)
        dsampler = _sampler(req, ref, None, clock, "fitting the sampling CDFs of the data ...")
        with clock.phase("render data"):
            dimg = render_image(ref, size=req.size, spp=req.spp, sampling=req.sampling,
                                sampler=dsampler, scene=req.scene, seed=req.seed,
                                progress=req.say, label="data")
        shown.append(dimg)
        images = _side_by_side(req, img, dimg)
        report.difference = _difference(img[hit], dimg[hit])
    # one exposure for every image: the brighter render's 99.5th percentile maps to 1
    top = max(float(np.quantile(im[hit] @ LUMA, 0.995)) for im in shown)
    report.exposure = req.exposure if req.exposure is not None else 1.0 / max(top, 1e-12)
    with clock.phase("write"):
        for path, im in images.items():
            _write(mi, path, im, report.exposure)
    report.outputs = list(images)
    report.seconds = clock.seconds
    return report


def _sampler(req: RenderRequest, material: Any, report: RenderReport | None, clock: Clock,
             what: str) -> Any:
    """The importance sampler of ``material`` (fit sampling), else None."""
    from ratfit.render.sampler import HalfVectorSampler

    if req.sampling != "fit":
        return None
    from ratfit._progress import time_left

    req.say(what)
    t0 = time.perf_counter()
    label = "sampler" if report is not None else "data sampler"

    def step(done: int, total: int) -> None:
        # "~": a step of a long task, like a render pass (one status line on a terminal)
        el = time.perf_counter() - t0
        req.say(f"~{label}: CDF {done}/{total}, {el:.1f} s, "
                + ("done" if done == total else time_left(el, done, total)))

    with clock.phase("sampler"):
        sampler = HalfVectorSampler(cosine_weight=req.cosine_weight,
                                    n_incidence=req.incidence_nodes,
                                    n_conditional=req.conditional_nodes).fit(material, step)
    if report is not None:
        dt = time.perf_counter() - t0
        req.say(f"sampler: {sampler.fits_} verified rational CDFs (total n+m "
                f"{sampler.coefficients_}, {sampler.fallbacks_} uniform fallbacks), {dt:.1f} s")
        report.sampler = {"cdfs": sampler.fits_, "coefficients": sampler.coefficients_,
                          "uniform_fallbacks": sampler.fallbacks_, "seconds": dt}
    return sampler


def _side_by_side(req: RenderRequest, img: NDArray[np.float64],
                  dimg: NDArray[np.float64]) -> dict[Path, NDArray[np.float64]]:
    """fit | data | |diff| in the output, the difference alone beside it."""
    diff = img - dimg
    gap = np.zeros((req.size, max(2, req.size // 64), 3))
    side = req.output.with_name(f"{req.output.stem}-diff{req.output.suffix}")
    return {req.output: np.concatenate([img, gap, dimg, gap, np.abs(diff)], axis=1),
            side: diff if req.output.suffix.lower() == ".exr" else np.abs(diff)}


def _difference(a: NDArray[np.float64], b: NDArray[np.float64]) -> dict[str, Any]:
    """How far the fit's render (a) is from the data's (b) over the sphere's pixels."""
    la, lb = a @ LUMA, b @ LUMA
    return {
        "pixels": int(a.shape[0]),
        "rel_rmse": float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean(b**2))),
        "mean_abs_rel_luminance": float(np.mean(np.abs(la - lb)) / np.mean(lb)),
        "mean_luminance_fit": float(la.mean()), "mean_luminance_data": float(lb.mean()),
        "max_abs": float(np.abs(a - b).max()),
    }


def _tonemap(img: NDArray[np.float64], scale: float) -> NDArray[np.uint8]:
    """Linear RGB x scale -> sRGB-encoded uint8."""
    v = np.clip(img * scale, 0.0, 1.0)
    v = np.where(v <= 0.0031308, 12.92 * v, 1.055 * np.power(v, 1.0 / 2.4) - 0.055)
    return np.round(v * 255.0).astype(np.uint8)


def _write(mi: Any, path: Path, img: NDArray[np.float64], scale: float) -> None:
    """Write atomically: EXR linear float32, PNG tonemapped with ``scale``."""
    from ratfit._atomic import atomic_path

    with atomic_path(path) as tmp:
        if path.suffix.lower() == ".exr":
            bmp = mi.Bitmap(np.ascontiguousarray(img, dtype=np.float32))
            bmp.write(str(tmp), mi.Bitmap.FileFormat.OpenEXR)
        else:
            mi.Bitmap(np.ascontiguousarray(_tonemap(img, scale))).write(
                str(tmp), mi.Bitmap.FileFormat.PNG)
