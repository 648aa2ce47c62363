"""Measured BRDFs: parametrizations, file formats (MERL, ALTA binary, Cornell, ASTM, EXR),
rational BRDF fits, analytic lobe models, albedo checks.
"""

from ratfit.brdf.albedo import AlbedoResult, directional_albedo
from ratfit.brdf.analytic_models import Model, ModelFit, fit_model
from ratfit.brdf.fitter import (
    BRDFFit,
    BRDFFitter,
    brdf_metrics,
    fit_brdf,
    load_brdf_fit,
    save_brdf_fit,
)
from ratfit.brdf.io import BRDFSamples, brdf_dataset, read_brdf, read_merl, write_merl
from ratfit.brdf.parametrizations import Parametrization, convert, get_parametrization

__all__ = [
    "AlbedoResult",
    "BRDFFit",
    "BRDFFitter",
    "BRDFSamples",
    "Model",
    "ModelFit",
    "Parametrization",
    "brdf_dataset",
    "brdf_metrics",
    "convert",
    "directional_albedo",
    "fit_brdf",
    "fit_model",
    "get_parametrization",
    "load_brdf_fit",
    "read_brdf",
    "read_merl",
    "save_brdf_fit",
    "write_merl",
]
