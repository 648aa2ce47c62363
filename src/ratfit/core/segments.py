"""Vertical segments: points x_i with intervals [lo_i, hi_i] per output channel.

This is the one gatekeeper for array input: code downstream of a
:class:`Segments` can trust that arrays are finite, shaped and ordered.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.errors import InputError

__all__ = ["Segments", "check_points", "check_values"]


def check_points(x: ArrayLike, name: str = "x") -> NDArray[np.float64]:
    """Return x as a finite (N, d) float array or raise InputError naming it."""
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
    _check_finite(arr, name)
    return arr


def check_values(v: ArrayLike, n_points: int, name: str) -> NDArray[np.float64]:
    """Return v as a finite (N, k) float array with N == n_points."""
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
    _check_finite(arr, name)
    return arr


def _check_finite(arr: NDArray[np.float64], name: str) -> None:
    bad = ~np.isfinite(arr)
    if bad.any():
        row = int(np.argwhere(bad)[0][0])
        kind = "NaN" if np.isnan(arr[bad]).any() else "inf"
        raise InputError(
            f"{name} contains {int(bad.sum())} non-finite value(s) ({kind}); first at row {row}"
        )


@dataclass(frozen=True)
class Segments:
    """Points ``x`` (N, d) with bounds ``lo``, ``hi`` (N, k) for k channels.

    ``y`` (N, k) is the measured value when known (used for reports and relative
    errors); it is ``None`` for explicit-interval data without a centre value.
    Build with :meth:`from_relative`, :meth:`from_absolute` or :meth:`from_bounds`.
    """

    x: NDArray[np.float64]
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]
    y: NDArray[np.float64] | None = None
    names: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        x = check_points(self.x, "x")
        lo = check_values(self.lo, x.shape[0], "lo")
        hi = check_values(self.hi, x.shape[0], "hi")
        if lo.shape != hi.shape:
            raise InputError(f"lo has shape {lo.shape} but hi has shape {hi.shape}")
        bad = lo > hi
        if bad.any():
            i, j = (int(v) for v in np.argwhere(bad)[0])
            raise InputError(
                f"lo > hi in {int(bad.sum())} segment(s); first at row {i}, channel {j}: "
                f"lo={lo[i, j]!r} > hi={hi[i, j]!r}"
            )
        y = None if self.y is None else check_values(self.y, x.shape[0], "y")
        if y is not None and y.shape != lo.shape:
            raise InputError(f"y has shape {y.shape} but the bounds have shape {lo.shape}")
        span = x.max(axis=0) - x.min(axis=0)
        if x.shape[0] > 1 and np.any(span == 0):
            dim = int(np.flatnonzero(span == 0)[0])
            raise InputError(
                f"x is constant in dimension {dim} (value {float(x[0, dim])!r}); "
                "a polynomial basis in that variable is degenerate: drop that column"
            )
        names = tuple(self.names) or tuple(f"y{j}" for j in range(lo.shape[1]))
        if len(names) != lo.shape[1]:
            raise InputError(f"{len(names)} channel names given for {lo.shape[1]} channels")
        for attr, val in (("x", x), ("lo", lo), ("hi", hi), ("y", y), ("names", names)):
            if isinstance(val, np.ndarray):
                val.setflags(write=False)
            object.__setattr__(self, attr, val)

    # -- constructors -------------------------------------------------------
    @classmethod
    def from_relative(cls, x: ArrayLike, y: ArrayLike, dt: float, **kw) -> Segments:
        """lo = (1 - dt) y, hi = (1 + dt) y (ordered, so negative y works too)."""
        dt = _check_width(dt, "dt")
        xa = check_points(x)
        ya = check_values(y, xa.shape[0], "y")
        a, b = (1.0 - dt) * ya, (1.0 + dt) * ya
        return cls(xa, np.minimum(a, b), np.maximum(a, b), ya, **kw)

    @classmethod
    def from_absolute(cls, x: ArrayLike, y: ArrayLike, width: float, **kw) -> Segments:
        """lo = y - width, hi = y + width."""
        width = _check_width(width, "abs_width")
        xa = check_points(x)
        ya = check_values(y, xa.shape[0], "y")
        return cls(xa, ya - width, ya + width, ya, **kw)

    @classmethod
    def from_bounds(
        cls, x: ArrayLike, lo: ArrayLike, hi: ArrayLike, y: ArrayLike | None = None, **kw
    ) -> Segments:
        return cls(x, lo, hi, y, **kw)

    # -- views ----------------------------------------------------------------
    @property
    def n_points(self) -> int:
        return int(self.x.shape[0])

    @property
    def dim(self) -> int:
        return int(self.x.shape[1])

    @property
    def n_channels(self) -> int:
        return int(self.lo.shape[1])

    @property
    def center(self) -> NDArray[np.float64]:
        """y when known, else the midpoint of each segment."""
        return self.y if self.y is not None else 0.5 * (self.lo + self.hi)

    def channel(self, j: int) -> Segments:
        """The single-channel segments of channel j."""
        if not 0 <= j < self.n_channels:
            raise InputError(f"channel {j} out of range: data has {self.n_channels} channel(s)")
        y = None if self.y is None else self.y[:, j : j + 1]
        return Segments(self.x, self.lo[:, j : j + 1], self.hi[:, j : j + 1], y, (self.names[j],))

    def bounds(self) -> NDArray[np.float64]:
        """Data bounds as a (d, 2) array [[min, max], ...]."""
        return np.stack([self.x.min(axis=0), self.x.max(axis=0)], axis=1)


def _check_width(w: float, name: str) -> float:
    try:
        w = float(w)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {w!r}") from None
    if not np.isfinite(w) or w < 0:
        raise InputError(f"{name} must be a finite number >= 0, got {w!r}")
    return w
