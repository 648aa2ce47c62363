"""The options of a BRDF fit: the fitter's (:data:`~ratfit.core.options.FIT_OPTIONS`)
plus the parametrization and the physical checks, checked like them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from ratfit.brdf.parametrizations import PARAMETRIZATIONS, find_parametrization
from ratfit.core.options import (
    DEFAULT_TIME_LIMIT,
    FIT_OPTIONS,
    FitOptions,
    Option,
    check_options_class,
    extend_spec,
)
from ratfit.core.rational import VALUE_FORMS
from ratfit.core.solvers import first_available
from ratfit.errors import InputError

__all__ = ["BRDF_OPTIONS", "BRDF_SOLVER", "NOISE_FLOOR", "POLISH_ERRORS",
           "BRDFOptions", "UNKNOWN_PARAMETRIZATION", "VALUES"]

# DAQP first: quadprog was seen looping forever inside one call on a BRDF QP with
# validity rows (1217 x 37, garnet_red) that DAQP solves in 6 ms.
BRDF_SOLVER = first_available(("daqp", "quadprog"))
#: 1/sr: the absolute level under which a measured BRDF value is noise (the e of the
#: relative error log((f + e)/(y + e)) that held-out errors and the relative polish use).
#: Cornell's diffuse values of glossy paints lie at 3e-3..5e-2 1/sr, 1e-4 of their peak.
NOISE_FLOOR = 1e-3
#: What the least-squares polish minimises: "relative" the sum of ((f - y)/(|y| + e))^2,
#: e = :data:`NOISE_FLOOR`, "absolute" the sum of (f - y)^2, "auto" (the default) the
#: relative one when the segments have an absolute floor (a noise level: a MERL table's
#: default, or ``--abs-width``), else the absolute one. Measured 2026-11-26: with a noise
#: floor the relative polish gives garnet_red's diffuse samples (theta_h > 0.3) a median
#: fit/data of R/G/B 0.97/1.04/0.97 against 0.97/1.22/0.88 (dt 0.1, floor 2e-3,
#: RUSIN_TH_TD_PD); under a floor of 0.1 % of the peak it raises mystique B's RMSE from
#: 0.059 to 0.78 at a peak of 591 and leaves garnet_red's diffuse colour as wrong.
POLISH_ERRORS = ("auto", "absolute", "relative")
#: What a BRDF fit's p / q approximates: the values ("linear": the fit is p / q, proved
#: q > 0 and p >= 0) or their logarithms ("log": the fit is exp(p / q), proved q > 0 and
#: p / q <= C, :data:`~ratfit.brdf.fitter.LOG_CEILING_FACTOR`; positive by construction,
#: and a relative segment width is one log width at every value).
#: "auto": log values for a full table of every cell (MERL) in the half-vector frame
#: and for scattered measurements with ratfit's widths (noise-level floors), else linear
#: (:func:`ratfit.brdf.fitter.resolve_values`).
VALUES = ("auto", *VALUE_FORMS)
#: The parametrization of coordinates no registry entry describes: the plain pole check.
UNKNOWN_PARAMETRIZATION = "UNKNOWN"


def _check_parametrization(value: Any) -> str:
    """An ALTA name (any case) as its registry spelling, or "UNKNOWN"."""
    if isinstance(value, str) and value.strip().upper() == UNKNOWN_PARAMETRIZATION:
        return UNKNOWN_PARAMETRIZATION
    p = find_parametrization(value) if isinstance(value, str) else None
    if p is None:
        raise InputError(f"unknown parametrization {value!r}; valid names: "
                         f"{', '.join(PARAMETRIZATIONS)}, {UNKNOWN_PARAMETRIZATION}")
    return p.name


def _check_coords(value: Any) -> tuple[int, ...] | None:
    if value is None:
        return None
    try:
        out = tuple(int(v) for v in value)
        ok = all(int(v) == v and not isinstance(v, bool) for v in value) and all(
            v >= 0 for v in out) and len(set(out)) == len(out) and len(out) > 0
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError(f"used_coords must be distinct coordinate indices >= 0 or None, "
                         f"got {value!r}")
    return out


#: :class:`~ratfit.brdf.fitter.BRDFFitter`'s options.
BRDF_OPTIONS = extend_spec(
    FIT_OPTIONS,
    Option("parametrization", "choice", UNKNOWN_PARAMETRIZATION,
           "ALTA name of the input coordinates.", validator=_check_parametrization, cli=False),
    Option("positive_q", "bool", False, "q > 0 on the valid grid inside the QP.", cli=False),
    Option("physical", "bool", True, "q > 0, p >= 0 on valid direction pairs.", cli=False),
    Option("polish", "bool", True, "Least-squares polish of each verified fit.", cli=False),
    Option("polish_error", "choice", "auto",
           "Error the polish minimises: relative (to |y| + 1e-3), absolute, or auto "
           "(relative when the segments have an absolute floor).",
           POLISH_ERRORS, cli=False),
    Option("values", "choice", "auto",
           "What p / q fits: the values (linear) or their logarithms (log: the fit is "
           "exp(p / q), positive by construction); auto: log for a full MERL table in "
           "the half-vector frame and for scattered measurements with ratfit's widths, "
           "else linear.", VALUES, cli=False),
    Option("envelope", "bool", None,
           "Fits of log values: the search's and the polish's validity rows keep p / q "
           "under the samples' envelope over theta_h and theta_d and above their "
           "highlight's floor (ratfit.brdf.validity.SampleCeiling, SampleFloor; under an "
           "envelope over theta_h alone in a frame without theta_d), "
           "not only under the channel's ceiling, and the validity proof proves it; "
           "None: for scattered measurements "
           "(ratfit.brdf.fitter.fit_brdf decides).", cli=False),
    Option("held_out_size", "bool", None,
           "Fits of log values: after the search's smallest verified fit, polish it at "
           "larger sizes too (ratfit.brdf.fitter.GROWTH_FACTORS times n and m) and keep the "
           "size with the lowest 5-fold held-out relative error, when proved and no "
           "further above the samples near it off the highlight than the smallest; "
           "None: for "
           "scattered measurements at ratfit's widths and sizes "
           "(ratfit.brdf.fitter.fit_brdf decides).", cli=False),
    Option("used_coords", "indices", None,
           "Coordinates of the parametrization the data holds (None: all).",
           validator=_check_coords, cli=False),
    defaults={"solver": BRDF_SOLVER},
)


@dataclass(frozen=True)
class BRDFOptions(FitOptions):
    """The checked options of a BRDF fit (:data:`BRDF_OPTIONS`)."""

    SPEC: ClassVar = BRDF_OPTIONS

    solver: str = BRDF_SOLVER
    time_limit: float | None = DEFAULT_TIME_LIMIT
    parametrization: str = UNKNOWN_PARAMETRIZATION
    positive_q: bool = False
    physical: bool = True
    polish: bool = True
    polish_error: str = "auto"
    values: str = "auto"
    envelope: bool | None = None
    held_out_size: bool | None = None
    used_coords: tuple[int, ...] | None = None


check_options_class(BRDFOptions)
