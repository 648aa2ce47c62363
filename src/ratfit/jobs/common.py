"""What every job shares: its clock, the JSON summary of per-channel results, the
monomial forms a fit file may carry, and the checks of a request's plain fields."""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ratfit.core.results import FitResult
from ratfit.core.validation import check_bool, check_int, check_width
from ratfit.errors import InputError

__all__ = ["Clock", "as_path", "check_channels", "monomial_forms", "results_summary"]


@dataclass
class Clock:
    """Seconds spent in each named phase of a job (``read``, ``fit``, ``write``...)."""

    seconds: dict[str, float] = field(default_factory=dict)

    @contextmanager
    def phase(self, name: str) -> Iterator[None]:
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - t0

    @property
    def total(self) -> float:
        return sum(self.seconds.values())


def as_path(value: Any, name: str, *, allow_none: bool = False) -> Path | None:
    """A request's path field as a Path (str or path-like), or InputError."""
    if value is None and allow_none:
        return None
    if isinstance(value, (str, os.PathLike)) and str(value):
        return Path(value)
    raise InputError(f"{name} must be a file path, got {value!r}")


def check_channels(value: Any) -> tuple[int | str, ...]:
    """Channels as a tuple of 0-based indices or names (empty: every channel)."""
    vals = () if value is None else (value,) if isinstance(value, (str, int)) else tuple(value)
    for v in vals:
        ok = isinstance(v, str) or (isinstance(v, (int, np.integer)) and not isinstance(v, bool)
                                    and v >= 0)
        if not ok:
            raise InputError(f"channels must be 0-based indices or channel names, got {value!r}")
    return tuple(int(v) if isinstance(v, (int, np.integer)) else v for v in vals)


def check_flag(value: Any, name: str) -> bool:
    return bool(check_bool(value, name))


def check_count(value: Any, name: str, minimum: int) -> int | None:
    return check_int(value, name, minimum=minimum, allow_none=True)


def check_nonnegative(value: Any, name: str) -> float | None:
    return check_width(value, name, allow_none=True)


def monomial_forms(results: Sequence[FitResult], x: NDArray[np.float64]
                   ) -> tuple[list[dict[str, Any] | None], list[str]]:
    """Each channel's monomial form (the original variables), and what to warn about:
    digits lost in the conversion, or why a channel has none (a fit in log x has no
    monomial form in x; a conversion that fails leaves the verified fit without one)."""
    from ratfit.core.monomial import to_monomial
    from ratfit.errors import AccuracyWarning

    forms: list[dict[str, Any] | None] = []
    notes: list[str] = []
    for r in results:
        if r.rational is None or getattr(r.rational.space, "variable", "x") != "x":
            forms.append(None)
            continue
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", AccuracyWarning)
                mf = to_monomial(r.rational, x)
        except Exception as exc:  # an optional extra: the verified fit is kept without it
            notes.append(f"channel {r.channel}: no monomial form ({type(exc).__name__}: {exc})")
            forms.append(None)
            continue
        notes.extend(f"channel {r.channel}: {w.message}" for w in caught)
        forms.append(mf.to_dict())
    return forms, notes


def results_summary(results: Sequence[FitResult], output: Path | None) -> dict[str, Any]:
    """The ``--json`` object of per-channel results: one channel's summary at the top
    level, or for several the sizes per channel and the worst errors, with every
    channel's summary under ``"channels"``."""
    per = [r.summary() for r in results]
    if len(per) == 1:
        doc = dict(per[0])
    else:
        doc = {
            "n": [p["n"] for p in per],
            "m": [p["m"] for p in per],
            "total": sum(p["total"] for p in per),
            "basis": per[0]["basis"],
            "verified": all(p["verified"] for p in per),
            "success": all(p["success"] for p in per),
            "max_violation": _worst(per, "max_violation"),
            "linf": _worst(per, "linf"),
            "l2": _worst(per, "l2"),
            "max_rel_error": _worst(per, "max_rel_error"),
            "delta": min((p["delta"] for p in per if p["delta"] is not None), default=None),
            "sigma_min": min((p["sigma_min"] for p in per if p["sigma_min"] is not None),
                             default=None),
            "sigma_max": max((p["sigma_max"] for p in per if p["sigma_max"] is not None),
                             default=None),
            "seconds": sum(p["seconds"] for p in per),
        }
        # one certificate per channel (null where that channel has a fit)
        doc["infeasible_proof"] = [p.get("infeasible_proof") for p in per]
    doc["channels"] = per
    doc["output"] = str(output) if output else None
    return doc


def _worst(vals: list[dict[str, Any]], key: str) -> float | None:
    xs = [p[key] for p in vals]
    return None if any(v is None for v in xs) else max(xs)
