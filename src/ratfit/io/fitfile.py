"""Versioned JSON fit files: basis, domain, index sets, coefficients, diagnostics.

Coefficients are written with Python's shortest round-trip float repr, so
``load_fit(save_fit(...))`` gives back bit-identical arrays. Only verified fits
are written: exporting an unverified fit would hand a user a function that
misses its segments.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import platform
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit._atomic import atomic_open
from ratfit.core.bases import PolynomialSpace
from ratfit.core.rational import RationalFunction
from ratfit.core.results import FitResult
from ratfit.errors import FileFormatError, InputError

__all__ = ["FORMAT", "VERSION", "SavedFit", "SavedChannel", "fit_document", "load_fit", "save_fit"]

FORMAT = "ratfit.fit"
VERSION = 2  # 2: optional p_basis / q_basis (Arnoldi recurrences) per channel


@dataclass(frozen=True)
class SavedChannel:
    name: str
    rational: RationalFunction
    summary: dict[str, Any]
    monomial: dict[str, Any] | None


@dataclass(frozen=True)
class SavedFit:
    space: PolynomialSpace
    channels: tuple[SavedChannel, ...]
    provenance: dict[str, Any]
    version: int
    # Top-level keys an application added with fit_document(extra=...) (e.g. "brdf").
    extra: dict[str, Any] = field(default_factory=dict)

    def __call__(self, x: ArrayLike) -> NDArray[np.float64]:
        """Values (N, k) of every channel at points x."""
        return np.stack([c.rational(x) for c in self.channels], axis=1)


def file_sha256(path: str | os.PathLike[str]) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def fit_document(
    results: list[FitResult],
    *,
    monomial: list[dict | None] | None = None,
    provenance: dict[str, Any] | None = None,
    extra: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The JSON document for verified ``results`` (one per channel).

    ``extra`` adds application keys at the top level (e.g. ``"brdf"``: the
    parametrization of the inputs); they come back as ``SavedFit.extra``.
    """
    from ratfit._version import __version__

    if not results:
        raise InputError("no fit to save")
    bad = [r.channel for r in results if not r.success or r.rational is None]
    if bad:
        raise InputError(f"refusing to save unverified fit(s) for channel(s) {', '.join(bad)}")
    space = results[0].rational.space  # type: ignore[union-attr]
    chans = []
    for i, r in enumerate(results):
        rf = r.rational
        assert rf is not None
        if rf.space != space:
            raise InputError("all channels of one fit file must share basis and domain")
        chans.append(
            {
                "name": r.channel,
                "n": rf.n,
                "m": rf.m,
                "p": rf.p.tolist(),
                "q": rf.q.tolist(),
                "p_indices": space.indices(rf.n).tolist(),
                "q_indices": space.indices(rf.m).tolist(),
                **rf.bases_dict(),
                "diagnostics": r.summary(),
                "monomial": (monomial or [None] * len(results))[i],
            }
        )
    prov = {
        "ratfit_version": __version__,
        "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "command": sys.argv,
    }
    prov.update(provenance or {})
    doc = {
        "format": FORMAT,
        "version": VERSION,
        "space": space.to_dict(),
        "channels": chans,
        "provenance": prov,
    }
    for key, val in (extra or {}).items():
        if key in doc:
            raise InputError(f"extra key {key!r} clashes with a fit file key")
        doc[key] = val
    return doc


def save_fit(
    path: str | os.PathLike[str],
    fit: Any,
    *,
    monomial: list[dict | None] | None = None,
    provenance: dict[str, Any] | None = None,
    extra: dict[str, Any] | None = None,
) -> None:
    """Write a fit file atomically (no partial file on failure).

    Parameters
    ----------
    path : str or path-like
        The JSON file to write.
    fit : dict, FitResult, list of FitResult, or a fitted estimator
        A document from :func:`fit_document`, one channel's result, one result
        per channel, or anything with ``results_`` (``RationalFitter``,
        ``MonotoneFitter``, ``BRDFFitter``, ``SharedDenominatorFitter``).
        Only verified fits are written.
    monomial, provenance, extra
        As for :func:`fit_document` (not with a ready document).

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from ratfit import RationalFitter, Segments
    >>> from ratfit.io import load_fit, save_fit
    >>> x = np.linspace(-1, 1, 30)
    >>> f = RationalFitter().fit(Segments.from_relative(x, np.exp(x), 0.01))
    >>> path = os.path.join(tempfile.mkdtemp(), "fit.json")
    >>> save_fit(path, f)
    >>> load_fit(path).channels[0].rational.n == f.result_.n
    True
    """
    if isinstance(fit, dict):
        if monomial is not None or provenance is not None or extra is not None:
            raise InputError("save_fit: monomial/provenance/extra go to fit_document, "
                             "not with a ready document")
        document = fit
    else:
        document = fit_document(_as_results(fit), monomial=monomial, provenance=provenance,
                                extra=extra)
    text = json.dumps(document, indent=1, allow_nan=False)
    with atomic_open(path, "w") as fh:
        fh.write(text)
        fh.write("\n")


def _as_results(fit: Any) -> list[FitResult]:
    if isinstance(fit, FitResult):
        return [fit]
    if hasattr(fit, "results_"):
        return list(fit.results_)
    if hasattr(fit, "get_params") and not hasattr(fit, "results_"):
        raise InputError(f"save_fit: this {type(fit).__name__} is not fitted yet: call fit()")
    if isinstance(fit, (list, tuple)) and all(isinstance(r, FitResult) for r in fit):
        return list(fit)
    results = getattr(fit, "results", None)  # SharedFit and similar containers
    if isinstance(results, list) and all(isinstance(r, FitResult) for r in results):
        return results
    raise TypeError(
        "save_fit takes a fit document, a FitResult, a list of FitResult or a fitted "
        f"estimator, got {type(fit).__name__}"
    )


def load_fit(path: str | os.PathLike[str]) -> SavedFit:
    """Read a fit file, checking its format, version and internal consistency.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    SavedFit
        Callable on points (values of every channel); ``channels[j].rational``.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from ratfit import RationalFitter, Segments
    >>> from ratfit.io import load_fit, save_fit
    >>> x = np.linspace(1, 2, 20)
    >>> path = os.path.join(tempfile.mkdtemp(), "fit.json")
    >>> save_fit(path, RationalFitter().fit(Segments.from_relative(x, 1 / x, 1e-3)))
    >>> saved = load_fit(path)
    >>> bool(abs(saved([1.5])[0, 0] - 1 / 1.5) < 1e-3)
    True
    """
    p = Path(path)
    if not p.is_file():
        raise FileFormatError(f"{p}: no such fit file")
    try:
        doc = json.loads(p.read_text())
    except UnicodeDecodeError:
        raise FileFormatError(f"{p}: not a ratfit fit file (binary content)") from None
    except json.JSONDecodeError as exc:
        raise FileFormatError(
            f"{p}: not valid JSON (truncated or corrupt) at line {exc.lineno}: {exc.msg}"
        ) from None
    return parse_fit(doc, str(p))


def parse_fit(doc: Any, where: str = "fit") -> SavedFit:
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise FileFormatError(f"{where}: not a ratfit fit file (missing format {FORMAT!r})")
    version = doc.get("version")
    if not isinstance(version, int) or version > VERSION or version < 1:
        raise FileFormatError(
            f"{where}: unsupported fit file version {version!r} (this ratfit reads 1..{VERSION})"
        )
    try:
        space = PolynomialSpace.from_dict(doc["space"])
        chans = []
        for c in doc["channels"]:
            rf = RationalFunction.from_dict({**c, "space": None}, space)
            for key, count in (("p_indices", rf.n), ("q_indices", rf.m)):
                if key in c and c[key] != space.indices(count).tolist():
                    raise FileFormatError(f"{where}: {key} of channel {c['name']!r} do not match")
            if not (np.all(np.isfinite(rf.p)) and np.all(np.isfinite(rf.q))):
                raise FileFormatError(f"{where}: non-finite coefficients in {c['name']!r}")
            chans.append(SavedChannel(c["name"], rf, c.get("diagnostics", {}), c.get("monomial")))
    except (KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, FileFormatError):
            raise
        what = f"{type(exc).__name__}: {exc}"
        raise FileFormatError(f"{where}: malformed fit file ({what})") from None
    if not chans:
        raise FileFormatError(f"{where}: fit file has no channels")
    extra = {k: v for k, v in doc.items() if k not in _CORE_KEYS}
    return SavedFit(space, tuple(chans), doc.get("provenance", {}), version, extra)


_CORE_KEYS = frozenset({"format", "version", "space", "channels", "provenance"})
