"""One set of rules for input arrays and option values, with one-line messages.

Every reader, fitter and command checks through these functions, so the same
mistake (NaN in y, lo > hi, ``dt = -1``, ``n = 0``) gets the same
:class:`~ratfit.errors.InputError` message wherever it enters. Messages name the
argument and the first offending row; the CLI prints them as one ``error:`` line.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.errors import InputError

__all__ = [
    "check_bool",
    "check_choice",
    "check_domain",
    "check_finite",
    "check_int",
    "check_order",
    "check_points",
    "check_values",
    "check_width",
]

Array = NDArray[np.float64]


def _at(where: str | None, msg: str) -> str:
    return f"{where}: {msg}" if where else msg


# ----------------------------------------------------------------------------- arrays
def check_finite(arr: Array, name: str) -> None:
    """Raise unless every value of ``arr`` is finite (NaN and inf named, first row given)."""
    bad = ~np.isfinite(arr)
    if bad.any():
        row = int(np.argwhere(bad)[0][0])
        kind = "NaN" if np.isnan(arr[bad]).any() else "inf"
        raise InputError(
            f"{name} contains {int(bad.sum())} non-finite value(s) ({kind}); first at row {row}"
        )


def check_points(x: ArrayLike, name: str = "x") -> Array:
    """``x`` as a finite (N, d) float array with N >= 1, d >= 1.

    Parameters
    ----------
    x : array-like of shape (N,) or (N, d)
    name : str
        How the message calls it.

    Returns
    -------
    ndarray of shape (N, d)
    """
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be numeric: {exc}") from None
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise InputError(f"{name} must be 1-D or 2-D (points x dims), got shape {arr.shape}")
    if arr.shape[0] == 0:
        raise InputError(f"{name} is empty: no data points to fit")
    if arr.shape[1] == 0:
        raise InputError(f"{name} has no dimensions (shape {arr.shape})")
    check_finite(arr, name)
    return arr


def check_values(v: ArrayLike, n_points: int, name: str) -> Array:
    """``v`` as a finite (N, k) float array with N == ``n_points``, k >= 1."""
    try:
        arr = np.asarray(v, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name} must be numeric: {exc}") from None
    if arr.ndim == 0:
        raise InputError(f"{name} must be an array, got a scalar")
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise InputError(f"{name} must be 1-D or 2-D (points x channels), got shape {arr.shape}")
    if arr.shape[0] != n_points:
        raise InputError(
            f"mismatched lengths: x has {n_points} points but {name} has {arr.shape[0]}"
        )
    if arr.shape[1] == 0:
        raise InputError(f"{name} has no channels (shape {arr.shape})")
    check_finite(arr, name)
    return arr


def check_order(lo: Array, hi: Array, where: str | None = None) -> None:
    """Raise unless lo <= hi everywhere (same shapes)."""
    if lo.shape != hi.shape:
        raise InputError(_at(where, f"lo has shape {lo.shape} but hi has shape {hi.shape}"))
    bad = lo > hi
    if bad.any():
        i, j = (int(v) for v in np.argwhere(bad.reshape(bad.shape[0], -1))[0])
        lo2, hi2 = lo.reshape(lo.shape[0], -1), hi.reshape(hi.shape[0], -1)
        raise InputError(_at(
            where,
            f"lo > hi in {int(bad.sum())} segment(s); first at row {i}, channel {j}: "
            f"lo={float(lo2[i, j])!r} > hi={float(hi2[i, j])!r}",
        ))


# ----------------------------------------------------------------------------- scalars
@overload
def check_width(value: float, name: str, *, where: str | None = None, allow_none: bool = True,
                positive: bool = False, below_one: bool = False) -> float: ...


@overload
def check_width(value: Any, name: str, *, where: str | None = None, allow_none: bool = True,
                positive: bool = False, below_one: bool = False) -> float | None: ...


def check_width(value: Any, name: str, *, where: str | None = None, allow_none: bool = True,
                positive: bool = False, below_one: bool = False) -> float | None:
    """A segment width (``dt``, ``abs_width``, ...): a finite number >= 0 (> 0 if positive)."""
    if value is None and allow_none:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise InputError(_at(where, f"{name} must be a number, got {value!r}")) from None
    v = float(value)
    if not math.isfinite(v) or v < 0 or (positive and v == 0):
        bound = "> 0" if positive else ">= 0"
        raise InputError(_at(where, f"{name} must be a finite number {bound}, got {value!r}"))
    if below_one and v >= 1:
        raise InputError(_at(
            where, f"{name} must be < 1 (a relative width: [(1-{name}) y, (1+{name}) y]), "
                   f"got {value!r}"))
    return v


def check_int(value: Any, name: str, *, minimum: int | None = None, where: str | None = None,
              allow_none: bool = False, note: str = "") -> int | None:
    """An integer (bools refused) >= ``minimum``."""
    if value is None and allow_none:
        return None
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, bool)
    if not ok or (minimum is not None and value < minimum):
        bound = f" >= {minimum}" if minimum is not None else ""
        raise InputError(_at(where, f"{name} must be an integer{bound}{note}, got {value!r}"))
    return int(value)


def check_bool(value: Any, name: str, *, where: str | None = None,
               allow_none: bool = False) -> bool | None:
    """True or False (or None, "automatic", when allowed)."""
    if value is None and allow_none:
        return None
    if not isinstance(value, (bool, np.bool_)):
        what = "true, false or absent (automatic)" if allow_none else "true or false"
        raise InputError(_at(where, f"{name} must be {what}, got {value!r}"))
    return bool(value)


def check_choice(value: Any, name: str, choices: Iterable[str], *,
                 where: str | None = None) -> str:
    """One of ``choices`` (exact spelling)."""
    allowed = tuple(choices)
    if not isinstance(value, str) or value not in allowed:
        raise InputError(_at(where, f"unknown {name} {value!r}; choose one of "
                                    f"{', '.join(allowed)}"))
    return value


def check_domain(value: Any, name: str = "domain", *, dim: int | None = None,
                 where: str | None = None) -> Array | None:
    """Domain bounds as a (d, 2) array with finite lo < hi per row (None: from the data)."""
    if value is None:
        return None
    msg = f"{name} must be [lo, hi] pairs, one per input dimension, with lo < hi"
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(_at(where, f"{msg}, got {value!r}")) from None
    if arr.size == 0 or arr.size % 2:
        raise InputError(_at(where, f"{msg}, got {value!r}"))
    arr = arr.reshape(-1, 2)
    if not np.all(np.isfinite(arr)) or not np.all(arr[:, 0] < arr[:, 1]):
        raise InputError(_at(where, f"{msg}, got {value!r}"))
    if dim is not None and arr.shape[0] != dim:
        raise InputError(_at(where, f"{name} has {arr.shape[0]} dimension(s), data has {dim}"))
    return arr
