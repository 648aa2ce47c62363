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

import dataclasses
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Self

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
    "DEFAULT_WORK_LIMIT",
    "FIT_OPTIONS",
    "FORMULATIONS",
    "FitOptions",
    "SEGMENT_OPTIONS",
    "SPLIT_RULES",
    "STRATEGIES",
    "Option",
    "check_fit_params",
    "check_options_class",
    "extend_spec",
]

STRATEGIES = ("staircase", "exhaustive")
FORMULATIONS = ("auto", "arnoldi", "basis")
SPLIT_RULES = ("min-m", "error")
VARIABLE_CHOICES = ("auto", "x", "log")
DEFAULT_MAX_TOTAL = 100
# Wall-clock seconds per channel: none by default (the answer would depend on the
# machine's load); the work limit bounds the search instead.
DEFAULT_TIME_LIMIT: float | None = None
# QP solves a search may spend per channel before it stops with what it has (a
# search that finds nothing otherwise walks every total up to max_total). A count,
# not seconds: the same command stops at the same split on any load and any --jobs.
DEFAULT_WORK_LIMIT = 4000


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
    validator : callable, optional
        Checks and normalises a value itself (``validator(value) -> value``,
        InputError when bad) instead of the kind's rule: names with aliases.
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
    validator: Callable[[Any], Any] | None = None

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    def allowed(self) -> tuple[str, ...]:
        c = self.choices
        return tuple(c() if callable(c) else (c or ()))

    def check(self, value: Any, where: str | None = None) -> Any:
        """``value`` checked (and normalised: floats as float), or InputError."""
        label = self.label or self.name
        if self.validator is not None:
            try:
                return self.validator(value)
            except InputError as exc:
                raise InputError(f"{where}: {exc}" if where else str(exc)) from None
        if self.kind == "choice":
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
            return None if out is None else tuple((float(a), float(b)) for a, b in out)
        if self.kind == "callable":
            if value is not None and not callable(value):
                raise InputError(f"{label} must be callable, got {value!r}")
            return value
        raise AssertionError(self.kind)  # pragma: no cover


def _opts(*options: Option) -> dict[str, Option]:
    return {o.name: o for o in options}


def _check_solver(value: Any) -> str:
    from ratfit.core.solvers import check_solver

    return check_solver(value)


def extend_spec(base: Mapping[str, Option], *options: Option,
                defaults: Mapping[str, Any] | None = None) -> dict[str, Option]:
    """``base`` plus ``options`` (an estimator's own), with some defaults changed:
    the spec of a fitter that takes every base option and a few of its own."""
    out = {k: dataclasses.replace(o, default=defaults[k]) if defaults and k in defaults else o
           for k, o in base.items()}
    clash = set(out) & {o.name for o in options}
    if clash:
        raise ValueError(f"options already in the base spec: {sorted(clash)}")
    return {**out, **_opts(*options)}


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
           extensible=True, validator=_check_solver),
    Option("cross_check", "choice", "orth", "How a solver's 'infeasible' is checked.",
           _cross_checks, label="cross check"),
    Option("active_set", "bool", None, "Active set: None = automatic (large data).", cli=False),
    Option("jobs", "int", None, "Threads for independent QPs (default: all cores).", minimum=1),
    Option("callback", "callable", None, "Called with each attempt (progress).", cli=False),
    Option("formulation", "choice", "auto",
           "arnoldi: data-orthonormal bases (smallest fits); basis: the seed's matrix; auto: "
           "arnoldi where it applies.", FORMULATIONS, label="formulation"),
    Option("time_limit", "seconds", DEFAULT_TIME_LIMIT,
           "Wall-clock seconds per channel before the search stops with what it has "
           "(default: none). With a clock the answer can depend on the machine's load."),
    Option("work_limit", "int", DEFAULT_WORK_LIMIT,
           "QP solves per channel before the search stops with what it has: a "
           "deterministic budget (the same answer on any load and any --jobs).",
           minimum=1),
    Option("variable", "choice", "auto",
           "p, q polynomials in x or in log x (auto: also log x for positive 1-D data over "
           "more than 3 decades, keeping the smaller fit).", VARIABLE_CHOICES, label="variable"),
    Option("warm_start", "bool", True,
           "Carry active sets across splits and start each channel at the previous "
           "channel's total (only the speed depends on it).", cli=False),
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
    own = {k: v for k, v in params.items() if k not in extra or k in FIT_OPTIONS}
    return FitOptions.from_params(own, where=where).params()



@dataclass(frozen=True)
class FitOptions:
    """The checked options of a fit: one object from the caller to the search engine.

    Every field is checked (and normalised) on construction against :attr:`SPEC`,
    alone and together, so an instance is always valid; ``dataclasses.replace``
    checks again. An estimator with options of its own subclasses this with a
    spec that extends :data:`FIT_OPTIONS` (:func:`extend_spec`) and adds its rules
    in :meth:`_check_together`.

    Parameters
    ----------
    basis, index_set, domain, n, m, total, min_total, max_total, strategy, split_rule, \
solver, cross_check, active_set, jobs, callback, formulation, time_limit, work_limit, \
variable, warm_start
        As for :class:`~ratfit.fitting.search.RationalFitter` (:data:`FIT_OPTIONS`).

    Examples
    --------
    >>> from ratfit.core.options import FitOptions
    >>> FitOptions(basis="chebyshev", time_limit=5).time_limit
    5.0
    >>> FitOptions(n=3)
    Traceback (most recent call last):
    ...
    ratfit.errors.InputError: give both n and m, or neither
    """

    SPEC: ClassVar[Mapping[str, Option]] = FIT_OPTIONS

    basis: str = "legendre"
    index_set: str = "total"
    domain: tuple[tuple[float, float], ...] | None = None
    n: int | None = None
    m: int | None = None
    total: int | None = None
    min_total: int = 2
    max_total: int | None = None
    strategy: str = "staircase"
    split_rule: str = "min-m"
    solver: str = "quadprog"
    cross_check: str = "orth"
    active_set: bool | None = None
    jobs: int | None = None
    callback: Callable[[Any], None] | None = field(default=None, compare=False)
    formulation: str = "auto"
    time_limit: float | None = DEFAULT_TIME_LIMIT
    work_limit: int | None = DEFAULT_WORK_LIMIT
    variable: str = "auto"
    warm_start: bool = True

    def __post_init__(self) -> None:
        self._check(None)

    def _check(self, where: str | None) -> None:
        for f in dataclasses.fields(self):
            object.__setattr__(self, f.name, self.SPEC[f.name].check(getattr(self, f.name),
                                                                      where))
        self._check_together(where)

    def _check_together(self, where: str | None) -> None:
        """Rules between options (subclasses add theirs after calling this)."""
        def at(msg: str) -> str:
            return f"{where}: {msg}" if where else msg

        if (self.n is None) != (self.m is None):
            raise InputError(at("give both n and m, or neither"))
        if self.n is not None and self.total is not None:
            raise InputError(at("n/m and total are exclusive: give one"))
        if self.max_total is not None and self.max_total < self.min_total:
            raise InputError(at(
                f"max_total must be an integer >= min_total={self.min_total}, "
                f"got {self.max_total!r}"))

    @classmethod
    def from_params(cls, params: Mapping[str, Any], *, where: str | None = None) -> Self:
        """The options of ``params`` (missing ones at their defaults), or one-line
        InputError prefixed by ``where``: an unknown name, a bad value, a bad pair."""
        names = [f.name for f in dataclasses.fields(cls)]
        for key in params:
            if key not in names:
                msg = f"unknown parameter {key!r}; valid: {', '.join(names)}"
                raise InputError(f"{where}: {msg}" if where else msg)
        checked = {k: cls.SPEC[k].check(v, where) for k, v in params.items()}
        try:
            return cls(**checked)
        except InputError as exc:  # a rule between options: the same prefix
            if where is None:
                raise
            raise InputError(f"{where}: {exc}") from None

    def params(self) -> dict[str, Any]:
        """Name -> value of every option (an estimator's keyword arguments)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def replace(self, **changes: Any) -> Self:
        """A copy with ``changes``, checked like the original."""
        return dataclasses.replace(self, **changes)

    def changed(self) -> dict[str, Any]:
        """The options that differ from the spec's defaults (messages, refusals)."""
        return {k: v for k, v in self.params().items() if v != self.SPEC[k].default}


def check_options_class(cls: type[FitOptions]) -> None:
    """An options class holds exactly its spec's options, with the spec's defaults
    (called once per class, at import: a field added to one but not the other fails)."""
    names = [f.name for f in dataclasses.fields(cls)]
    assert names == list(cls.SPEC), f"{cls.__name__} fields {names} != its spec"
    for f in dataclasses.fields(cls):
        assert f.default == cls.SPEC[f.name].default, f"{cls.__name__}.{f.name} default"


check_options_class(FitOptions)
