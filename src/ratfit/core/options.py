"""The fitter's options, declared once: name, kind, default, allowed values, help.

From :data:`FIT_OPTIONS` come the validation of
:class:`~ratfit.fitting.search.RationalFitter`'s parameters
(:func:`check_fit_params`), the click options of every command that fits
(``ratfit.cli.options``) and the keys a batch manifest accepts
(``ratfit.batch.runner``). A new option added here reaches all three.
Allowed values are read from the registries (:data:`ratfit.core.bases.FAMILIES`,
:data:`ratfit.core.solvers.SOLVERS`, ...), never copied.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ratfit.core.validation import (
    check_bool,
    check_choice,
    check_domain,
    check_int,
    check_width,
)
from ratfit.errors import InputError

__all__ = [
    "DEFAULT_MAX_TOTAL",
    "DEFAULT_TIME_LIMIT",
    "FIT_OPTIONS",
    "FORMULATIONS",
    "SEGMENT_OPTIONS",
    "SPLIT_RULES",
    "STRATEGIES",
    "Option",
    "check_fit_params",
    "check_segment_params",
]

STRATEGIES = ("staircase", "exhaustive")
FORMULATIONS = ("auto", "arnoldi", "basis")
SPLIT_RULES = ("min-m", "error")
VARIABLE_CHOICES = ("auto", "x", "log")
DEFAULT_MAX_TOTAL = 100
# Seconds a search may spend per channel before it stops with what it has (a
# search that finds nothing otherwise walks every total up to max_total).
DEFAULT_TIME_LIMIT = 120.0


def _families() -> tuple[str, ...]:
    from ratfit.core.bases import FAMILIES

    return tuple(FAMILIES)


def _index_sets() -> tuple[str, ...]:
    from ratfit.core.bases import INDEX_SETS

    return tuple(INDEX_SETS)


def _solvers() -> tuple[str, ...]:
    from ratfit.core.solvers import SOLVERS

    return tuple(SOLVERS)


def _cross_checks() -> tuple[str, ...]:
    from ratfit.core.qp import CROSS_CHECKS

    return tuple(CROSS_CHECKS)


@dataclass(frozen=True)
class Option:
    """One option of a fit.

    Attributes
    ----------
    name : str
        Python name (``min_total``); the CLI spells it ``--min-total``.
    kind : {"choice", "int", "bool", "width", "seconds", "domain", "callable"}
    default : object
        Default value (None: automatic or absent).
    help : str
        One line for ``--help``.
    choices : tuple of str or callable, optional
        Allowed values of a "choice" (a callable reads a registry when asked).
    minimum : int, optional
        Smallest allowed "int".
    label : str
        How messages call it ("unknown basis ...", "n must be ...").
    cli : bool
        Whether commands expose it (callbacks and tri-state flags do not).
    note : str
        Added to the "must be" message (what the number counts).
    extensible : bool
        The choices come from a registry that may grow (solvers).
    """

    name: str
    kind: str
    default: Any
    help: str
    choices: tuple[str, ...] | Callable[[], tuple[str, ...]] | None = None
    minimum: int | None = None
    label: str = ""
    cli: bool = True
    note: str = ""
    extensible: bool = False

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    def allowed(self) -> tuple[str, ...]:
        c = self.choices
        return tuple(c() if callable(c) else (c or ()))

    def check(self, value: Any, where: str | None = None) -> Any:
        """``value`` checked (and normalised: floats as float), or InputError."""
        label = self.label or self.name
        if self.kind == "choice":
            if self.name == "solver":
                from ratfit.core.solvers import check_solver

                try:
                    return check_solver(value)
                except InputError as exc:
                    raise InputError(f"{where}: {exc}" if where else str(exc)) from None
            return check_choice(value, label, self.allowed(), where=where)
        if self.kind == "int":
            return check_int(value, label, minimum=self.minimum, where=where,
                             allow_none=self.default is None, note=self.note)
        if self.kind == "bool":
            return check_bool(value, label, where=where, allow_none=self.default is None)
        if self.kind == "width":
            return check_width(value, label, where=where, allow_none=True)
        if self.kind == "seconds":
            ok = value is None or (
                isinstance(value, (int, float, np.integer, np.floating))
                and not isinstance(value, bool) and math.isfinite(value) and value > 0)
            if not ok:
                msg = f"{label} must be a number of seconds > 0 or None, got {value!r}"
                raise InputError(f"{where}: {msg}" if where else msg)
            return None if value is None else float(value)
        if self.kind == "domain":
            out = check_domain(value, label, where=where)
            return None if out is None else out.tolist()
        if self.kind == "callable":
            if value is not None and not callable(value):
                raise InputError(f"{label} must be callable, got {value!r}")
            return value
        raise AssertionError(self.kind)  # pragma: no cover


def _opts(*options: Option) -> dict[str, Option]:
    return {o.name: o for o in options}


#: The parameters of :class:`~ratfit.fitting.search.RationalFitter`, in order.
FIT_OPTIONS: dict[str, Option] = _opts(
    Option("basis", "choice", "legendre", "Polynomial family of p and q.", _families,
           label="basis"),
    Option("index_set", "choice", "total", "n-D graded order of basis functions.", _index_sets,
           label="index set"),
    Option("domain", "domain", None,
           "Bounds mapped to [-1, 1], one LO HI pair per input dimension (default: the data "
           "bounds)."),
    Option("n", "int", None, "Numerator coefficients (fixes the split; give --m too).",
           minimum=1, note=" (a coefficient count)"),
    Option("m", "int", None, "Denominator coefficients (fixes the split; give --n too).",
           minimum=1, note=" (a coefficient count)"),
    Option("total", "int", None, "Try every split of this total n + m.", minimum=2),
    Option("min_total", "int", 2, "Smallest total n + m searched.", minimum=2),
    Option("max_total", "int", None, f"Largest total n + m searched (default "
           f"{DEFAULT_MAX_TOTAL}).", minimum=2),
    Option("strategy", "choice", "staircase",
           "staircase: O(best) QPs; exhaustive: every split of every total (ALTA's).",
           STRATEGIES, label="strategy"),
    Option("split_rule", "choice", "min-m", "Which feasible split of the minimal total to keep.",
           SPLIT_RULES, label="split rule"),
    Option("solver", "choice", "quadprog", "QP solver.", _solvers, label="solver",
           extensible=True),
    Option("cross_check", "choice", "orth", "How a solver's 'infeasible' is checked.",
           _cross_checks, label="cross check"),
    Option("active_set", "bool", None, "Active set: None = automatic (large data).", cli=False),
    Option("jobs", "int", None, "Threads for independent QPs (default: all cores).", minimum=1),
    Option("callback", "callable", None, "Called with each attempt (progress).", cli=False),
    Option("formulation", "choice", "auto",
           "arnoldi: data-orthonormal bases (smallest fits); basis: the seed's matrix; auto: "
           "arnoldi where it applies.", FORMULATIONS, label="formulation"),
    Option("time_limit", "seconds", DEFAULT_TIME_LIMIT,
           "Seconds per channel before the search stops with what it has (0: no limit)."),
    Option("variable", "choice", "auto",
           "p, q polynomials in x or in log x (auto: also log x for positive 1-D data over "
           "more than 3 decades, keeping the smaller fit).", VARIABLE_CHOICES, label="variable"),
)

#: How segments are built from y values (every command and the batch manifest).
SEGMENT_OPTIONS: dict[str, Option] = _opts(
    Option("dt", "width", None, "Relative segment width: [(1-dt) y, (1+dt) y]."),
    Option("abs_width", "width", None,
           "Absolute segment half-width: [y-w, y+w] (with --dt each segment takes the larger)."),
)


def check_fit_params(params: Mapping[str, Any], *, where: str | None = None,
                     names: Iterable[str] | None = None) -> dict[str, Any]:
    """Every fit parameter checked alone and together; returns them normalised.

    Parameters
    ----------
    params : mapping
        Parameter name -> value (a subset of :data:`FIT_OPTIONS`; missing ones
        take their defaults).
    where : str, optional
        Prefix of messages (a manifest entry, a file).
    names : iterable of str, optional
        Keys allowed besides :data:`FIT_OPTIONS` (checked by the caller).

    Returns
    -------
    dict
        Every :data:`FIT_OPTIONS` key, checked.

    Raises
    ------
    InputError
        One line naming the first bad value.
    """
    extra = set(names or ())
    for key in params:
        if key not in FIT_OPTIONS and key not in extra:
            msg = f"unknown parameter {key!r}; valid: {', '.join(FIT_OPTIONS)}"
            raise InputError(f"{where}: {msg}" if where else msg)
    out = {k: o.check(params.get(k, o.default), where) for k, o in FIT_OPTIONS.items()}
    _at = (lambda m: f"{where}: {m}") if where else (lambda m: m)
    if (out["n"] is None) != (out["m"] is None):
        raise InputError(_at("give both n and m, or neither"))
    if out["n"] is not None and out["total"] is not None:
        raise InputError(_at("n/m and total are exclusive: give one"))
    if out["max_total"] is not None and out["max_total"] < out["min_total"]:
        raise InputError(_at(
            f"max_total must be an integer >= min_total={out['min_total']}, "
            f"got {out['max_total']!r}"))
    return out


def check_segment_params(params: Mapping[str, Any], *, where: str | None = None) -> dict[str, Any]:
    """``dt`` and ``abs_width`` checked (each None or a finite number >= 0)."""
    return {k: o.check(params.get(k, o.default), where) for k, o in SEGMENT_OPTIONS.items()}
