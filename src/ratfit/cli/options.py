"""Click options generated from :mod:`ratfit.core.options`, shared by every command.

A command declares which fitter options it takes (``@fit_options(...)``) and gets
them back as one dict (:func:`pop_fit_params`) ready for the estimator: names,
defaults, allowed values and help come from the one spec. Old spellings of
renamed options stay as hidden aliases (:func:`deprecated_alias`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import click

from ratfit.core.options import FIT_OPTIONS, SEGMENT_OPTIONS, Option

__all__ = ["MAX_DRAWS", "MAX_POINTS", "MAX_WORKERS", "FiniteFloatRange", "aliased_option",
           "check_size_flags", "fit_options", "pop_fit_params", "segment_options"]

# Upper bounds of count options that size arrays or processes: a value beyond them is
# one error line (exit 2), not numpy's "Maximum allowed size exceeded" or 2^63 processes.
MAX_DRAWS = 10**9  # `sample -n`: 8 GB of draws
MAX_POINTS = 10**6  # `cdf --points/--grid`: QP rows
MAX_WORKERS = 1024  # `batch --workers` (the fitter's --jobs has the same bound)


class FiniteFloatRange(click.FloatRange):
    """``click.FloatRange`` that also refuses NaN (which no bound comparison catches)."""

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        rv = super().convert(value, param, ctx)
        if rv != rv:
            self.fail(f"{value!r} is not a number", param, ctx)
        return rv

F = Callable[..., Any]


def _click_option(opt: Option, default: Any, help_text: str | None,
                  required: bool = False) -> Callable[[F], F]:
    kw: dict[str, Any] = {"help": help_text or opt.help, "required": required}
    # Values are checked by the library (one-line InputError, exit 2), except fixed
    # choice lists, which click shows in --help. Registries that may grow (solvers)
    # take any name and list the known ones.
    if opt.kind == "choice" and opt.extensible:
        kw.update(type=str, default=default, show_default=True,
                  help=f"{kw['help']} Known: {', '.join(opt.allowed())}.")
    elif opt.kind == "choice":
        kw.update(type=click.Choice(opt.allowed()), default=default, show_default=True)
    elif opt.kind == "int":
        kw.update(type=int, default=default, show_default=default is not None)
    elif opt.kind == "width":
        kw.update(type=float, default=default)
    elif opt.kind == "seconds":
        kw.update(type=float, default=default, show_default=True)
    elif opt.kind == "domain":
        kw.update(type=(float, float), multiple=True, metavar="LO HI")
    else:  # pragma: no cover - kinds without a CLI form are filtered out
        raise AssertionError(opt.kind)
    return click.option(opt.flag, opt.name, **kw)


def _apply(options: list[Callable[[F], F]]) -> Callable[[F], F]:
    def deco(fn: F) -> F:
        for o in reversed(options):  # click lists options in decorator order
            fn = o(fn)
        return fn

    return deco


def fit_options(*, only: Iterable[str] | None = None, exclude: Iterable[str] = (),
                defaults: dict[str, Any] | None = None, helps: dict[str, str] | None = None,
                required: Iterable[str] = ()) -> Callable[[F], F]:
    """Add the click options of :data:`~ratfit.core.options.FIT_OPTIONS` to a command.

    ``only``/``exclude`` pick options (in spec order); ``defaults``/``helps``
    override one command's default or help; ``required`` makes options required.
    """
    names = [k for k, o in FIT_OPTIONS.items() if o.cli]
    if only is not None:
        keep = list(only)
        unknown = set(keep) - set(names)
        assert not unknown, f"not CLI fit options: {unknown}"
        names = [k for k in names if k in keep]
    names = [k for k in names if k not in set(exclude)]
    defaults, helps, req = defaults or {}, helps or {}, set(required)
    return _apply([
        _click_option(FIT_OPTIONS[k], defaults.get(k, FIT_OPTIONS[k].default), helps.get(k),
                      k in req)
        for k in names
    ])


def segment_options(*, helps: dict[str, str] | None = None) -> Callable[[F], F]:
    """``--dt`` and ``--abs-width`` (:data:`~ratfit.core.options.SEGMENT_OPTIONS`)."""
    helps = helps or {}
    return _apply([_click_option(o, o.default, helps.get(k)) for k, o in SEGMENT_OPTIONS.items()])


def pop_fit_params(kwargs: dict[str, Any]) -> dict[str, Any]:
    """Take the fitter's options out of a command's keyword arguments (CLI -> Python form)."""
    out: dict[str, Any] = {}
    for key, opt in FIT_OPTIONS.items():
        if key in kwargs:
            value = kwargs.pop(key)
            if opt.kind == "domain":
                value = [list(p) for p in value] or None
            elif opt.kind == "seconds" and value is not None and value == 0:
                value = None  # the CLI's 0: no limit
            out[key] = value
    return out


def check_size_flags(params: dict[str, Any], *, shared: bool = False) -> None:
    """The rules between --n, --m and --total, in the flags' own words (usage errors;
    the library says the same of n, m and total)."""
    n, m, total = params.get("n"), params.get("m"), params.get("total")
    if shared and (n is not None or total is not None):
        raise click.UsageError("--shared-denominator searches the numerator sizes itself: "
                               "drop --n/--total (--m fixes the shared denominator)")
    if (n is None) != (m is None) and not shared:
        raise click.UsageError("give both --n and --m, or neither")
    if n is not None and total is not None:
        raise click.UsageError("--n/--m and --total are exclusive")
    # Options that steer a search over totals mean nothing once the size is fixed.
    fixed = "--n/--m fix the split" if n is not None and m is not None else \
        "--total fixes the total" if total is not None else None
    if fixed is not None:
        search = ("min_total", "max_total", "strategy") + (
            ("split_rule",) if total is None else ())
        given = [FIT_OPTIONS[k].flag for k in search
                 if k in params and params[k] != FIT_OPTIONS[k].default]
        if given:
            raise click.UsageError(
                f"{fixed}: {', '.join(given)} only "
                f"{'steers' if len(given) == 1 else 'steer'} a search over totals; drop "
                f"{'it' if len(given) == 1 else 'them'} or drop {fixed.split()[0]}")


class _AliasedOption(click.Option):
    """An option with extra spellings that work but stay out of ``--help``."""

    def __init__(self, *args: Any, hidden_names: Iterable[str] = (), **kw: Any) -> None:
        super().__init__(*args, **kw)
        self.hidden_names = tuple(hidden_names)

    def get_help_record(self, ctx: click.Context) -> tuple[str, str] | None:
        saved = self.opts
        self.opts = [o for o in saved if o not in self.hidden_names]
        try:
            return super().get_help_record(ctx)
        finally:
            self.opts = saved

    def get_error_hint(self, ctx: click.Context | None) -> str:
        return " / ".join(f"'{o}'" for o in self.opts if o not in self.hidden_names)


def aliased_option(*names: str, hidden: Iterable[str] = (), **kw: Any) -> Callable[[F], F]:
    """``click.option(*names, **kw)`` whose ``hidden`` spellings (old names) are not listed."""
    return click.option(*names, *hidden, cls=_AliasedOption, hidden_names=tuple(hidden), **kw)
