"""Standard scenes for looking at a BRDF: a sphere under an environment or a point light.

Every scene is fixed (camera, light, exposure) so that two materials rendered
with the same scene name can be compared pixel by pixel. The environment is
procedural (no file to ship): a dim sky gradient, a darker ground and one
bright rectangular "window" whose reflection shows the glossy lobe.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from ratfit._progress import time_left
from ratfit.errors import InputError

__all__ = ["SCENES", "environment_map", "render_image", "sphere_view"]

Array = NDArray[np.float64]
SCENES = ("sphere", "sky", "point", "sphere-point", "furnace")


def environment_map(width: int = 256, window: bool = True) -> NDArray[np.float32]:
    """Lat-long RGB radiance (width/2, width, 3): sky, ground and (optionally) a bright
    window."""
    h = width // 2
    v = (np.arange(h) + 0.5) / h  # 0 at the top (up = +y in Mitsuba's envmap frame)
    u = (np.arange(width) + 0.5) / width
    V, U = np.meshgrid(v, u, indexing="ij")
    sky = np.clip(1.0 - V * 1.6, 0.0, 1.0)
    img = np.empty((h, width, 3), dtype=np.float32)
    img[..., 0] = 0.05 + 0.25 * sky
    img[..., 1] = 0.06 + 0.30 * sky
    img[..., 2] = 0.08 + 0.45 * sky
    ground = V > 0.5
    img[ground] = np.array([0.06, 0.05, 0.04], dtype=np.float32)
    # Mitsuba's envmap: d.y = cos(pi v), (d.x, -d.z) ~ (sin, cos)(2 pi u). The window sits
    # at d = (-0.67, 0.67, 0.33): the camera (on +z) sees it mirrored where the normal
    # is (-0.41, 0.41, 0.82), up and left of the sphere's centre.
    win = (np.abs(U - 0.677) < 0.045) & (np.abs(V - 0.268) < 0.06)
    if window:
        img[win] = np.array([40.0, 38.0, 34.0], dtype=np.float32)
    return img


INTEGRATORS = {
    "path": {"type": "path", "max_depth": 2},  # direct light, MIS of emitter and BSDF samples
    "bsdf": {"type": "direct", "emitter_samples": 0, "bsdf_samples": 1},  # BSDF samples only
}


def _scene_dict(mi, bsdf, scene: str, size: int, integrator: str = "path") -> dict:
    if scene not in SCENES:
        raise InputError(f"unknown scene {scene!r}; choose one of {', '.join(SCENES)}")
    if integrator not in INTEGRATORS:
        raise InputError(f"unknown integrator {integrator!r}; choose one of "
                         f"{', '.join(INTEGRATORS)}")
    T = mi.ScalarTransform4f
    d: dict = {
        "type": "scene",
        "integrator": dict(INTEGRATORS[integrator]),
        "sensor": {
            "type": "perspective", "fov": 28.0,
            "to_world": T().look_at(origin=[0.0, 0.0, 4.5], target=[0.0, 0.0, 0.0],
                                    up=[0.0, 1.0, 0.0]),
            "film": {"type": "hdrfilm", "width": size, "height": size,
                     "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": 1},
        },
        "sphere": {"type": "sphere", "radius": 1.0, "bsdf": bsdf},
    }
    if scene in ("sphere", "sphere-point"):
        d["env"] = {"type": "envmap", "bitmap": mi.Bitmap(environment_map())}
    if scene == "sky":  # smooth light only: image noise is the BSDF sampler's
        d["env"] = {"type": "envmap", "bitmap": mi.Bitmap(environment_map(window=False))}
    if scene == "furnace":  # white furnace: radiance 1 everywhere, pixel = albedo
        d["env"] = {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}}
    if scene in ("point", "sphere-point"):
        d["light"] = {"type": "point", "position": [2.5, 2.5, 4.0],
                      "intensity": {"type": "rgb", "value": [25.0, 25.0, 25.0]}}
        if scene == "point":
            d["ambient"] = {"type": "constant", "radiance": {"type": "rgb", "value": 0.02}}
    return d


def sphere_view(size: int) -> tuple[NDArray[np.bool_], Array]:
    """Pixels whose centre sees the unit sphere (same camera as every scene), and there
    the cosine between the surface normal and the direction to the camera."""
    f = 1.0 / np.tan(np.radians(28.0) / 2.0)
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    X, Y = np.meshgrid(c, -c)
    d = np.stack([X, Y, -np.full_like(X, f)], axis=-1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    o = np.array([0.0, 0.0, 4.5])
    b = d @ o
    disc = b * b - (o @ o - 1.0)
    hit = disc > 0
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    p = o + t[..., None] * d
    cos_v = np.where(hit, -(p * d).sum(axis=-1), 0.0)
    return hit, np.clip(cos_v, 0.0, 1.0)


def render_image(material, *, size: int = 256, spp: int = 64, sampling: str = "fit",
                 sampler=None, scene: str = "sphere", seed: int = 0, passes: int | None = None,
                 progress: Callable[[str], None] | None = None, label: str = "render",
                 integrator: str = "path") -> Array:
    """Render ``material`` (``f(L, V) -> (N, 3)``) in a standard scene; (size, size, 3) linear.

    The spp are split into passes (independent seeds, averaged) so a long render
    reports progress through ``progress`` after each pass. ``integrator``: "path"
    (MIS of light and BSDF samples) or "bsdf" (BSDF samples only: what a sampler
    alone achieves).
    """
    from ratfit.render.mitsuba_bsdf import _import_mitsuba, make_bsdf, setup, variant

    if size < 1 or spp < 1:
        raise InputError(f"size and spp must be >= 1, got size={size}, spp={spp}")
    setup()
    mi, _ = _import_mitsuba()
    bsdf = make_bsdf(material, sampler, sampling)
    sc = mi.load_dict(_scene_dict(mi, bsdf, scene, int(size), integrator))
    if passes is None:
        # about 1M samples a pass on the LLVM variant; the scalar one calls the Python
        # BSDF per sample (100x slower or more), so one sample per pixel a pass: the
        # first progress line and estimate come after 1/spp of the render
        budget = (1 << 20) if variant() != "scalar_rgb" else 0
        per = max(1, min(spp, budget // max(1, size * size)))
        passes = -(-spp // per)
    passes = max(1, min(int(passes), spp))
    base, extra = divmod(spp, passes)
    acc = np.zeros((size, size, 3))
    done = 0
    t0 = time.perf_counter()
    for k in range(passes):
        n = base + (1 if k < extra else 0)
        img = np.asarray(mi.render(sc, spp=n, seed=seed * 100_003 + k), dtype=np.float64)
        acc += img[..., :3] * n
        done += n
        if progress is not None:
            el = time.perf_counter() - t0
            eta = "done" if done == spp else time_left(el, done, spp)
            # "~": a step of a long task (a terminal shows it on one status line)
            progress(f"~{label}: pass {k + 1}/{passes}, {done}/{spp} spp, {el:.1f} s, {eta}")
    return acc / spp


