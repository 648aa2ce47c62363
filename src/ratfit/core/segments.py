"""Vertical segments: points x_i with intervals [lo_i, hi_i] per output channel.

This is the one gatekeeper for array input: code downstream of a
:class:`Segments` can trust that arrays are finite, shaped and ordered.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.core.validation import check_finite as _check_finite  # noqa: F401
from ratfit.core.validation import check_order, check_points, check_values, check_width
from ratfit.errors import InputError

__all__ = ["Segments", "check_points", "check_values"]


# Values beyond this leave no headroom below the float range (1.8e308): a width or a
# sum of two bounds overflows (channels are scaled by a power of two before fitting,
# so large values below it are fine); an x range narrower than SPAN_RTOL of its
# magnitude leaves too few digits to tell the points apart once mapped to [-1, 1].
MAX_MAGNITUDE = 1e300
SPAN_RTOL = 1e-12
# The n-D pole check samples at least 3^d points and a degree-s shell has O(s^d)
# basis functions: beyond this many input dimensions fits are out of reach.
MAX_DIM = 12


def _check_magnitudes(x: NDArray[np.float64], lo: NDArray[np.float64],
                      hi: NDArray[np.float64], span: NDArray[np.float64]) -> None:
    """Refuse numbers the fitting arithmetic cannot carry (instead of failing inside it)."""
    for name, arr in (("x", x), ("lo", lo), ("hi", hi)):
        big = float(np.max(np.abs(arr)))
        if big > MAX_MAGNITUDE:
            raise InputError(
                f"{name} holds values up to {big:.3g} in magnitude; ratfit handles magnitudes "
                f"up to {MAX_MAGNITUDE:.0e}: rescale the data (or use a narrower width)"
            )
    if x.shape[0] > 1:
        scale = np.max(np.abs(x), axis=0)
        narrow = (span < SPAN_RTOL * scale) | (span < 1e-150)
        if np.any(narrow):
            dim = int(np.flatnonzero(narrow)[0])
            raise InputError(
                f"x spans only {float(span[dim]):.3g} in dimension {dim} (values near "
                f"{float(scale[dim]):.3g}): too narrow to map to [-1, 1]; shift or rescale x"
            )


@dataclass(frozen=True)
class Segments:
    """Points ``x`` (N, d) with bounds ``lo``, ``hi`` (N, k) for k channels.

    The one gatekeeper for array input: everything downstream trusts that the
    arrays are finite, shaped, and ordered (lo <= hi). Build with
    :meth:`from_widths` (relative and/or absolute widths around y),
    :meth:`from_relative`, :meth:`from_absolute` or :meth:`from_bounds`.

    Parameters
    ----------
    x : array-like of shape (N,) or (N, d)
        Points.
    lo, hi : array-like of shape (N,) or (N, k)
        Segment bounds per channel.
    y : array-like of shape (N, k), optional
        Measured values (reports, relative errors); None for bare intervals.
    names : tuple of str, optional
        Channel names (default y0, y1, ...).

    Attributes
    ----------
    n_points, dim, n_channels : int
    center : ndarray of shape (N, k)
        y when known, else the midpoints.

    Examples
    --------
    >>> from ratfit import Segments
    >>> s = Segments.from_relative([0.0, 1.0, 2.0], [1.0, -2.0, 4.0], 0.1)
    >>> s.n_points, s.dim, s.n_channels, s.lo[:, 0].tolist()
    (3, 1, 1, [0.9, -2.2, 3.6])
    >>> Segments([0.0, 1.0], [1.0, 3.0], [2.0, 2.5])
    Traceback (most recent call last):
    ...
    ratfit.errors.InputError: lo > hi in 1 segment(s); first at row 1, channel 0: lo=3.0 > hi=2.5
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
        check_order(lo, hi)
        if x.shape[1] > MAX_DIM:
            raise InputError(
                f"x has {x.shape[1]} input dimensions; ratfit fits up to {MAX_DIM} (the pole "
                "check and the basis grow exponentially with the dimension): is the last "
                "column really the only output?"
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
        _check_magnitudes(x, lo, hi, span)
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
        return cls.from_widths(x, y, dt=_check_width(dt, "dt"), **kw)

    @classmethod
    def from_absolute(cls, x: ArrayLike, y: ArrayLike, width: float, **kw) -> Segments:
        """lo = y - width, hi = y + width."""
        return cls.from_widths(x, y, abs_width=_check_width(width, "abs_width"), **kw)

    @classmethod
    def from_widths(cls, x: ArrayLike, y: ArrayLike, *, dt: float | None = None,
                    abs_width: float | ArrayLike | None = None, **kw) -> Segments:
        """The one segment builder: [(1-dt) y, (1+dt) y] joined with [y - w, y + w].

        With both widths each segment is the union of the two intervals, so
        values near zero keep a usable absolute tolerance. ``abs_width`` may
        give one width per channel (shape (k,)).

        Parameters
        ----------
        x : array-like of shape (N,) or (N, d)
        y : array-like of shape (N,) or (N, k)
        dt : float, optional
            Relative half-width, finite and >= 0.
        abs_width : float or array-like of shape (k,), optional
            Absolute half-width(s), finite and >= 0.
        **kw
            ``names`` of the channels.

        Returns
        -------
        Segments

        Examples
        --------
        >>> from ratfit import Segments
        >>> s = Segments.from_widths([0, 1, 2], [0.0, 1.0, 10.0], dt=0.1, abs_width=0.5)
        >>> s.lo[:, 0].tolist(), s.hi[:, 0].tolist()
        ([-0.5, 0.5, 9.0], [0.5, 1.5, 11.0])
        """
        if dt is None and abs_width is None:
            raise InputError("give a relative width (dt) or an absolute one (abs_width)")
        xa = check_points(x)
        ya = check_values(y, xa.shape[0], "y")
        lo, hi = ya.copy(), ya.copy()
        if dt is not None:
            rel = _check_width(dt, "dt")
            a, b = (1.0 - rel) * ya, (1.0 + rel) * ya
            lo, hi = np.minimum(a, b), np.maximum(a, b)
        if abs_width is not None:
            w = np.asarray(abs_width, dtype=float)
            if w.ndim > 1 or (w.ndim == 1 and w.size != ya.shape[1]):
                raise InputError(f"abs_width: one width or one per channel ({ya.shape[1]}), "
                                 f"got shape {w.shape}")
            for v in np.atleast_1d(w):
                _check_width(float(v), "abs_width")
            if dt is None:
                lo, hi = ya - w, ya + w
            else:
                lo, hi = np.minimum(lo, ya - w), np.maximum(hi, ya + w)
        return cls(xa, lo, hi, ya, **kw)

    @classmethod
    def from_bounds(
        cls, x: ArrayLike, lo: ArrayLike, hi: ArrayLike, y: ArrayLike | None = None, **kw
    ) -> Segments:
        return cls(np.asarray(x, dtype=float), np.asarray(lo, dtype=float),
                   np.asarray(hi, dtype=float), None if y is None else np.asarray(y, dtype=float),
                   **kw)

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
    out = check_width(w, name, allow_none=False)
    assert out is not None
    return out
