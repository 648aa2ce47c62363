"""Rendering with fitted BRDFs: a Mitsuba 3 plugin sampled by rational CDFs.

:class:`~ratfit.render.sampler.HalfVectorSampler` (numpy only) importance-samples
any BRDF with verified monotone rational CDFs; :mod:`ratfit.render.mitsuba_bsdf`
wraps a BRDF and a sampler as the Mitsuba BSDF plugin ``ratfit`` (optional extra
``ratfit[render]``; Mitsuba is imported only when a render is asked for).
"""

from ratfit.render.material import AnalyticMaterial, DataMaterial, FitMaterial
from ratfit.render.sampler import HalfVectorSampler, cosine_pdf, cosine_sample, luminance

__all__ = ["AnalyticMaterial", "DataMaterial", "FitMaterial", "HalfVectorSampler",
           "cosine_pdf", "cosine_sample", "luminance"]
