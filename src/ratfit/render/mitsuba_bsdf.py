"""The Mitsuba 3 BSDF plugin ``ratfit``: a ratfit BRDF evaluated and importance-sampled.

Mitsuba is optional (``pip install ".[render]"``); importing this module does not
import it. :func:`setup` picks a variant: ``llvm_ad_rgb`` (vectorised: the
plugin's numpy code sees every lane of a wavefront at once, since symbolic
loops and calls are switched off) when libLLVM works here, ``scalar_rgb``
otherwise. Whether LLVM works is probed once in a subprocess: an incompatible
libLLVM aborts the process from inside the JIT, which no ``try`` can catch.

Convention: Mitsuba's ``si.wi`` (towards the camera) is the BRDF's V and ``wo``
(towards the light) its L; ``eval`` returns f(L, V) cos(theta_o) as Mitsuba
expects.
"""

from __future__ import annotations

import glob
import os
import re
import subprocess
import sys
from typing import Any

import numpy as np

from ratfit.errors import RatfitError

__all__ = ["MissingExtraError", "choose_variant", "make_bsdf", "register", "setup"]

INSTALL_HINT = 'pip install ".[render]"  (or: pip install mitsuba)'
_STATE: dict[str, Any] = {"variant": None, "registered": False}
_MODELS: dict[int, tuple[Any, Any, str]] = {}


class MissingExtraError(RatfitError):
    """Mitsuba (the ``render`` extra) is not installed."""


def _import_mitsuba():
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as exc:
        raise MissingExtraError(
            f"rendering needs Mitsuba 3, which is not installed ({exc.name or exc}); "
            f"install it with: {INSTALL_HINT}"
        ) from None
    return mi, dr


def _find_libllvm() -> str | None:
    """The newest libLLVM >= 16 on the usual paths (drjit 1.x needs a recent one)."""
    best: tuple[int, str] | None = None
    pats = ["/usr/lib/x86_64-linux-gnu/libLLVM*.so*", "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
            "/usr/lib/llvm-*/lib/libLLVM*.so*", "/usr/local/lib/libLLVM*.so*",
            "/opt/homebrew/opt/llvm/lib/libLLVM.dylib"]
    for pat in pats:
        for path in glob.glob(pat):
            m = re.search(r"(?:LLVM-|llvm-|\.so\.)(\d+)", path)
            if m and int(m.group(1)) >= 16 and (best is None or int(m.group(1)) > best[0]):
                best = (int(m.group(1)), path)
    return best[1] if best else None


_PROBE = """
import numpy as np
from ratfit.render import mitsuba_bsdf as mb
from ratfit.render.material import AnalyticMaterial
mb.setup("llvm_ad_rgb")
from ratfit.render.scene import render_image
img = render_image(AnalyticMaterial("lambert", [0.5]), size=8, spp=2, sampling="cosine")
assert np.all(np.isfinite(img)) and img.mean() > 0
print("ok")
"""


def choose_variant() -> str:
    """``RATFIT_MITSUBA_VARIANT`` if set, else llvm_ad_rgb when a probe render works, else
    scalar_rgb. Sets ``DRJIT_LIBLLVM_PATH`` to a recent libLLVM when unset."""
    forced = os.environ.get("RATFIT_MITSUBA_VARIANT")
    if forced:
        return forced
    mi, _ = _import_mitsuba()
    if "llvm_ad_rgb" not in mi.variants():
        return "scalar_rgb"
    if not os.environ.get("DRJIT_LIBLLVM_PATH"):
        lib = _find_libllvm()
        if lib:
            os.environ["DRJIT_LIBLLVM_PATH"] = lib
    env = dict(os.environ, RATFIT_MITSUBA_VARIANT="llvm_ad_rgb")
    try:
        out = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True,
                             timeout=120, env=env)
        ok = out.returncode == 0 and out.stdout.strip().endswith("ok")
    except (OSError, subprocess.TimeoutExpired):
        ok = False
    return "llvm_ad_rgb" if ok else "scalar_rgb"


def setup(variant: str | None = None) -> str:
    """Import Mitsuba, set its variant (once per process) and register the plugin."""
    mi, dr = _import_mitsuba()
    if _STATE["variant"] is None:
        v = variant or choose_variant()
        if v not in ("scalar_rgb", "llvm_ad_rgb"):
            raise RatfitError(f"unsupported Mitsuba variant {v!r}: use scalar_rgb or llvm_ad_rgb")
        mi.set_variant(v)
        if v.startswith("llvm"):
            # Wavefront (evaluated) mode: the plugin's Python code gets concrete arrays.
            dr.set_flag(dr.JitFlag.SymbolicLoops, False)
            dr.set_flag(dr.JitFlag.SymbolicCalls, False)
        _STATE["variant"] = v
    elif variant is not None and variant != _STATE["variant"]:
        raise RatfitError(f"Mitsuba already runs the {_STATE['variant']} variant in this process")
    register()
    return str(_STATE["variant"])


def variant() -> str | None:
    return _STATE["variant"]


# --------------------------------------------------------------------------- conversions
def _np3(v) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    return a.reshape(1, 3) if a.ndim == 1 else a.T


def _np1(v, n: int) -> np.ndarray:
    return np.broadcast_to(np.atleast_1d(np.asarray(v, dtype=np.float64)), (n,))


def _np2(v, n: int) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    a = a.reshape(1, 2) if a.ndim == 1 else a.T
    return np.broadcast_to(a, (n, 2))


def _mask(v, n: int) -> np.ndarray:
    return np.broadcast_to(np.atleast_1d(np.asarray(v, dtype=bool)), (n,))


def _floats(mi, a: np.ndarray):
    if _STATE["variant"] == "scalar_rgb":
        return float(a[0])
    return mi.Float(np.ascontiguousarray(a, dtype=np.float32))


def _vec(mi, cls, a: np.ndarray):
    return cls(*(_floats(mi, a[:, j]) for j in range(a.shape[1])))


# --------------------------------------------------------------------------- the plugin
def register() -> None:
    """Register the ``ratfit`` BSDF plugin with Mitsuba (after :func:`setup`)."""
    if _STATE["registered"]:
        return
    mi, dr = _import_mitsuba()

    class RatfitBSDF(mi.BSDF):  # type: ignore[name-defined]  # mitsuba builds it at run time
        """A ratfit BRDF: ``model`` = id from :func:`make_bsdf`."""

        def __init__(self, props: Any) -> None:
            mi.BSDF.__init__(self, props)
            key = int(props.get("model", -1))
            if key not in _MODELS:
                raise RatfitError(f"ratfit BSDF: unknown model id {key}; use make_bsdf()")
            self.brdf, self.sampler, self.sampling = _MODELS[key]
            flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            self.m_flags = flags
            self.m_components = [flags]

        # numpy side ---------------------------------------------------------------
        def _f_cos(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
            out = np.zeros((len(wi), 3))
            ok = (wi[:, 2] > 0) & (wo[:, 2] > 0)
            if ok.any():
                out[ok] = self.brdf(wo[ok], wi[ok]) * wo[ok, 2:3]
            return out

        def _pdf(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
            if self.sampling == "cosine":
                ok = (wi[:, 2] > 0) & (wo[:, 2] > 0)
                return np.where(ok, np.maximum(wo[:, 2], 0.0) / np.pi, 0.0)
            return self.sampler.pdf(wi, wo)

        def _sample(self, wi: np.ndarray, u1: np.ndarray, u2: np.ndarray):
            if self.sampling == "cosine":
                r, phi = np.sqrt(u2[:, 0]), 2.0 * np.pi * u2[:, 1]
                wo = np.stack([r * np.cos(phi), r * np.sin(phi),
                               np.sqrt(np.maximum(0.0, 1.0 - u2[:, 0]))], axis=1)
                return wo, self._pdf(wi, wo)
            return self.sampler.sample(wi, u1, u2)

        # Mitsuba side --------------------------------------------------------------
        def sample(self, ctx, si, sample1, sample2, active=True):
            wi = _np3(si.wi)
            n = len(wi)
            act = _mask(active, n) & (wi[:, 2] > 0)
            wo, pdf = self._sample(wi, _np1(sample1, n), _np2(sample2, n))
            val = self._f_cos(wi, wo)
            with np.errstate(divide="ignore", invalid="ignore"):
                weight = np.where((pdf > 0)[:, None], val / pdf[:, None], 0.0)
            good = act & (pdf > 0) & np.all(np.isfinite(weight), axis=1)
            weight = np.where(good[:, None], weight, 0.0)
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = _vec(mi, mi.Vector3f, wo)
            bs.pdf = _floats(mi, np.where(good, pdf, 0.0))
            bs.eta = 1.0
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
            bs.sampled_component = mi.UInt32(0)
            return bs, _vec(mi, mi.Color3f, weight)

        def eval(self, ctx, si, wo, active=True):
            wi = _np3(si.wi)
            w = np.broadcast_to(_np3(wo), wi.shape)
            val = self._f_cos(wi, w) * _mask(active, len(wi))[:, None]
            return _vec(mi, mi.Color3f, val)

        def pdf(self, ctx, si, wo, active=True):
            wi = _np3(si.wi)
            w = np.broadcast_to(_np3(wo), wi.shape)
            return _floats(mi, self._pdf(wi, w) * _mask(active, len(wi)))

        def eval_pdf(self, ctx, si, wo, active=True):
            wi = _np3(si.wi)
            w = np.broadcast_to(_np3(wo), wi.shape)
            m = _mask(active, len(wi))
            return (_vec(mi, mi.Color3f, self._f_cos(wi, w) * m[:, None]),
                    _floats(mi, self._pdf(wi, w) * m))

        def traverse(self, callback) -> None:
            pass

        def parameters_changed(self, keys=None) -> None:
            pass

        def to_string(self) -> str:
            return f"RatfitBSDF[sampling={self.sampling}]"

    mi.register_bsdf("ratfit", lambda props: RatfitBSDF(props))
    _STATE["registered"] = True


def make_bsdf(brdf, sampler=None, sampling: str = "fit"):
    """A Mitsuba BSDF object for ``brdf(L, V) -> (N, 3)``, sampled by ``sampler``
    (a fitted :class:`ratfit.render.sampler.HalfVectorSampler`) or cosine-weighted."""
    mi, _ = _import_mitsuba()
    if sampling not in ("fit", "cosine"):
        raise RatfitError(f"unknown sampling {sampling!r}: use fit or cosine")
    if sampling == "fit" and sampler is None:
        raise RatfitError("sampling 'fit' needs a fitted sampler")
    setup()
    key = len(_MODELS)
    _MODELS[key] = (brdf, sampler, sampling)
    return mi.load_dict({"type": "ratfit", "model": key})


def query(bsdf, wi, wo=None, u1=None, u2=None) -> dict[str, np.ndarray]:
    """Call a Mitsuba BSDF from numpy (checks, tests): ``eval``/``pdf`` at (wi, wo) rows, or
    ``sample`` with uniforms u1 (N,), u2 (N, 2). Returns numpy arrays: eval (N, 3) and pdf
    (N,), or wo (N, 3), pdf (N,) and weight (N, 3). Loops in the scalar variant."""
    mi, dr = _import_mitsuba()
    wi = np.atleast_2d(np.asarray(wi, dtype=float))
    n = len(wi)
    ctx = mi.BSDFContext()
    scalar = _STATE["variant"] == "scalar_rgb"

    def si_of(rows: np.ndarray):
        si = dr.zeros(mi.SurfaceInteraction3f) if scalar else dr.zeros(
            mi.SurfaceInteraction3f, len(rows))
        si.wi = mi.Vector3f(*rows[0]) if scalar else _vec(mi, mi.Vector3f, rows)
        return si

    if wo is not None:
        wo = np.broadcast_to(np.atleast_2d(np.asarray(wo, dtype=float)), wi.shape)
        if scalar:
            ev, pd = [], []
            for a, b in zip(wi, wo, strict=True):
                e, p = bsdf.eval_pdf(ctx, si_of(a[None]), mi.Vector3f(*b))
                ev.append(np.asarray(e, dtype=float))
                pd.append(float(p))
            return {"eval": np.array(ev).reshape(n, 3), "pdf": np.array(pd)}
        e, p = bsdf.eval_pdf(ctx, si_of(wi), _vec(mi, mi.Vector3f, wo))
        return {"eval": np.asarray(e, dtype=float).T.reshape(n, 3),
                "pdf": np.asarray(p, dtype=float).reshape(n)}
    u1 = np.broadcast_to(np.asarray(u1, dtype=float).ravel(), (n,))
    u2 = np.broadcast_to(np.atleast_2d(np.asarray(u2, dtype=float)), (n, 2))
    if scalar:
        wos, pds, ws = [], [], []
        for a, s1, s2 in zip(wi, u1, u2, strict=True):
            bs, w = bsdf.sample(ctx, si_of(a[None]), float(s1), mi.Point2f(*s2))
            wos.append(np.asarray(bs.wo, dtype=float))
            pds.append(float(bs.pdf))
            ws.append(np.asarray(w, dtype=float))
        return {"wo": np.array(wos).reshape(n, 3), "pdf": np.array(pds),
                "weight": np.array(ws).reshape(n, 3)}
    bs, w = bsdf.sample(ctx, si_of(wi), _floats(mi, u1), _vec(mi, mi.Point2f, u2))
    return {"wo": np.asarray(bs.wo, dtype=float).T.reshape(n, 3),
            "pdf": np.asarray(bs.pdf, dtype=float).reshape(n),
            "weight": np.asarray(w, dtype=float).T.reshape(n, 3)}
