"""Versioned JSON fit files: basis, domain, index sets, coefficients, diagnostics.

Coefficients are written with Python's shortest round-trip float repr, so
``load_fit(save_fit(...))`` gives back bit-identical arrays. Only verified fits
are written: exporting an unverified fit would hand a user a function that
misses its segments.
"""

from __future__ import annotations

import contextlib
import contextvars
import datetime as _dt
import hashlib
import json
import math
import os
import platform
import re
import sys
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeGuard

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit._atomic import atomic_open
from ratfit.core.bases import PolynomialSpace
from ratfit.core.columns import MAX_DEGREE_CAP
from ratfit.core.rational import VALUE_FORMS, RationalFunction, ratio_values
from ratfit.core.results import FitResult
from ratfit.core.segments import MAX_DIM, MAX_MAGNITUDE, SPAN_RTOL
from ratfit.errors import FileFormatError, InputError

__all__ = [
    "FORMAT", "VERSION", "FitFileWarning", "SavedChannel", "SavedFit", "content_digest",
    "ceiling_bound", "fit_document", "load_fit", "read_fit_document", "run_provenance",
    "save_fit", "proof_ceiling", "scope_text", "subset_of", "trusting_edited",
]

FORMAT = "ratfit.fit"
VERSION = 3  # 2: optional p_basis / q_basis (Arnoldi recurrences); 3: content digest
DIGEST_SINCE = 3


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
    # "sealed": the content matches the digest ratfit wrote; "legacy": a file from
    # before digests; "edited": a mismatch accepted with --trust-edited; "alta": an
    # ALTA function file (no verification record).
    integrity: str = "sealed"

    @property
    def verified(self) -> bool:
        """Every channel recorded as verified, in a file known to be unedited."""
        return self.integrity == "sealed" and all(
            c.summary.get("verified") is True for c in self.channels)

    @property
    def values(self) -> str:
        """"log" when each channel's value is exp(p / q) (a BRDF fit of log values,
        ``"values"`` in the file's ``brdf`` block), else "linear": p / q."""
        brdf = self.extra.get("brdf")
        return str(brdf.get("values", "linear")) if isinstance(brdf, dict) else "linear"

    def channel_values(self, j: int, x: ArrayLike) -> NDArray[np.float64]:
        """Channel ``j``'s values at points x: p / q, or exp(p / q) for log values (the
        one place a saved fit's value is defined; every evaluator comes here)."""
        return ratio_values(self.channels[j].rational(x), self.values)

    def __call__(self, x: ArrayLike) -> NDArray[np.float64]:
        """Values (N, k) of every channel at points x."""
        return np.stack([self.channel_values(j, x) for j in range(len(self.channels))],
                        axis=1)


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
    prov = run_provenance()
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
    doc[DIGEST_KEY] = content_digest(doc)
    return doc


def run_provenance() -> dict[str, Any]:
    """What every fit file records of the run that wrote it: ratfit's version, the time,
    Python's and numpy's versions and the command line."""
    from ratfit._version import __version__

    return {
        "ratfit_version": __version__,
        "created": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "command": list(sys.argv),
    }


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
    doc = {k: v for k, v in document.items() if k != DIGEST_KEY}
    doc["version"] = VERSION
    doc[DIGEST_KEY] = content_digest(doc)  # sealed: load_fit refuses an edited file
    text = json.dumps(doc, indent=1, allow_nan=False)
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


# ---------------------------------------------------------------------------- digest
DIGEST_KEY = "digest"


def content_digest(document: dict[str, Any]) -> str:
    """sha256 of the canonical JSON of every key but the digest itself.

    That covers everything that defines the function (coefficients, bases and
    recurrences, index sets, domain, the BRDF parametrization) and the record of
    its verification (diagnostics): any edit, even one that keeps the file valid
    JSON, changes the digest. Canonical: sorted keys, no whitespace, floats in
    Python's shortest round-trip form, so re-indenting the file keeps it intact.
    """
    body = {k: v for k, v in document.items() if k != DIGEST_KEY}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False,
                      ensure_ascii=True)
    return "sha256:" + hashlib.sha256(text.encode("ascii")).hexdigest()


class FitFileWarning(UserWarning):
    """A fit file loaded without proof that it is what ratfit wrote (old or trusted edit)."""


_TRUST_EDITED: contextvars.ContextVar[bool] = contextvars.ContextVar("trust_edited",
                                                                     default=False)


@contextlib.contextmanager
def trusting_edited(flag: bool = True) -> Iterator[None]:
    """Within this block, load_fit accepts edited fit files as unverified functions."""
    token = _TRUST_EDITED.set(flag)
    try:
        yield
    finally:
        _TRUST_EDITED.reset(token)


# ---------------------------------------------------------------------------- load
def load_fit(path: str | os.PathLike[str], *, trust_edited: bool | None = None) -> SavedFit:
    """Read a fit file, checking its format, version, digest and internal consistency.

    A file whose content does not match its digest was edited after ratfit wrote
    it: refused, unless ``trust_edited`` (then loaded with ``verified`` False).
    An ALTA function file (``#ALTA FUNC HEADER``) is read too, as an unverified
    fit (:meth:`ratfit.io.alta_function.ALTAFunction.to_saved_fit`): every command
    that takes a fit file takes ALTA's rational functions through here.

    Parameters
    ----------
    path : str or path-like
    trust_edited : bool, optional
        Accept an edited file (default: ``--trust-edited`` of the CLI, else False).

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
    if _is_alta_function(p):
        from ratfit.io.alta_function import read_alta_function

        return read_alta_function(p).to_saved_fit()
    trust = _TRUST_EDITED.get() if trust_edited is None else trust_edited
    return parse_fit(read_fit_document(p), str(p), trust_edited=trust)


def read_fit_document(path: str | os.PathLike[str]) -> Any:
    """The JSON document of a ratfit fit file as it is stored, unchecked (FileFormatError
    for a missing file, an ALTA function file or one that is not JSON): :func:`parse_fit`
    checks it. For callers that need the stored document itself (``ratfit brdf merge``)
    as well as its check."""
    p = Path(path)
    if not p.is_file():
        raise FileFormatError(f"{p}: no such fit file")
    if _is_alta_function(p):
        raise FileFormatError(f"{p}: an ALTA function file, not a ratfit fit file")
    try:
        doc = json.loads(p.read_text())
    except UnicodeDecodeError:
        raise FileFormatError(f"{p}: not a ratfit fit file (binary content)") from None
    except json.JSONDecodeError as exc:
        raise FileFormatError(
            f"{p}: not valid JSON (truncated or corrupt) at line {exc.lineno}: {exc.msg}"
        ) from None
    except RecursionError:
        raise FileFormatError(f"{p}: not a ratfit fit file (JSON nested too deeply)") from None
    except ValueError as exc:  # e.g. an integer of more than 4300 digits
        raise FileFormatError(f"{p}: not a ratfit fit file ({exc})") from None
    return doc


def _is_alta_function(p: Path) -> bool:
    """An ALTA function file (its first line ``#ALTA FUNC HEADER``), which
    :func:`load_fit` reads through :mod:`ratfit.io.alta_function`."""
    try:
        with open(p, "rb") as fh:
            head = fh.read(64)
    except OSError:
        return False
    return head.lstrip(b"\xef\xbb\xbf \t\r\n").startswith(b"#ALTA FUNC HEADER")


def parse_fit(doc: Any, where: str = "fit", *, trust_edited: bool = False) -> SavedFit:
    """A :class:`SavedFit` from a decoded fit document, every field type-checked."""
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise FileFormatError(f"{where}: not a ratfit fit file (missing format {FORMAT!r})")
    version = doc.get("version")
    if not _is_int(version) or version > VERSION or version < 1:
        raise FileFormatError(
            f"{where}: unsupported fit file version {_short(version)} "
            f"(this ratfit reads 1..{VERSION})"
        )
    try:
        space = _space(doc.get("space"), where)
        is_brdf = isinstance(doc.get("brdf"), dict)
        chans_doc = doc.get("channels")
        if not isinstance(chans_doc, list) or not chans_doc:
            raise FileFormatError(f"{where}: fit file has no channels (a non-empty list)")
        chans = [_channel(c, i, space, where, pole_check=not is_brdf)
                 for i, c in enumerate(chans_doc)]
    except FileFormatError:
        raise
    except (KeyError, TypeError, ValueError, OverflowError, IndexError) as exc:
        what = f"{type(exc).__name__}: {exc}"
        raise FileFormatError(f"{where}: malformed fit file ({_cut(what)})") from None
    prov = doc.get("provenance", {})
    if not isinstance(prov, dict):
        raise FileFormatError(f"{where}: 'provenance' must be an object, got {_kind(prov)}")
    _check_fields(prov, _PROVENANCE_FIELDS, f"{where}: provenance")
    for i, c in enumerate(chans_doc):
        _check_fields(c.get("diagnostics") or {}, _DIAGNOSTICS_FIELDS,
                      f"{where}: channel {i} diagnostics")
    extra = {k: v for k, v in doc.items() if k not in _CORE_KEYS}
    if "brdf" in extra and not isinstance(extra["brdf"], dict):
        raise FileFormatError(f"{where}: 'brdf' must be an object, got {_kind(extra['brdf'])}")
    if "brdf" in extra:
        _check_fields(extra["brdf"], _BRDF_FIELDS, f"{where}: brdf")
    # Last: a corrupt file gets the message that names its defect, an intact but
    # edited one the digest message.
    integrity = _integrity(doc, where, version, trust_edited)
    return SavedFit(space, tuple(chans), prov, version, extra, integrity)


_CORE_KEYS = frozenset({"format", "version", "space", "channels", "provenance", DIGEST_KEY})


def _integrity(doc: dict[str, Any], where: str, version: int, trust_edited: bool) -> str:
    stored = doc.get(DIGEST_KEY)
    if stored is None and version < DIGEST_SINCE:
        warnings.warn(
            f"{where}: written by an older ratfit without a content digest: it cannot be "
            "told from an edited file, so it is treated as unverified (refit to renew it)",
            FitFileWarning, stacklevel=3,
        )
        return "legacy"
    if isinstance(stored, str) and stored == content_digest(doc):
        return "sealed"
    if trust_edited:
        warnings.warn(
            f"{where}: edited after ratfit wrote it (content does not match its digest); "
            "used as an UNVERIFIED function because of --trust-edited",
            FitFileWarning, stacklevel=3,
        )
        return "edited"
    what = "has no digest" if stored is None else "does not match its digest"
    raise FileFormatError(
        f"{where}: the fit file {what}: it was edited after ratfit wrote and verified it "
        "(a changed coefficient, recurrence or domain is another function); refit it, "
        "or pass --trust-edited to use it as an unverified function"
    )


def _space(d: Any, where: str) -> PolynomialSpace:
    if not isinstance(d, dict):
        raise FileFormatError(f"{where}: 'space' must be an object, got {_kind(d)}")
    fam, iset = d.get("family"), d.get("index_set", "total")
    if not isinstance(fam, str) or not isinstance(iset, str):
        raise FileFormatError(f"{where}: space 'family' and 'index_set' must be strings")
    dom = d.get("domain")
    if not isinstance(dom, list) or not dom or not all(
        isinstance(r, list) and len(r) == 2 and all(_is_num(v) for v in r) for r in dom
    ):
        raise FileFormatError(f"{where}: space 'domain' must be a list of [lo, hi] number pairs")
    arr = np.array(dom, dtype=float)
    if not np.all(np.isfinite(arr)) or float(np.max(np.abs(arr))) > MAX_MAGNITUDE:
        raise FileFormatError(f"{where}: domain {_cut(str(dom))} has non-finite or huge bounds "
                              f"(beyond {MAX_MAGNITUDE:.0e})")
    width = arr[:, 1] - arr[:, 0]
    scale = np.max(np.abs(arr), axis=1)
    if np.any(width <= 0) or np.any((width < SPAN_RTOL * scale) | (width < 1e-150)):
        raise FileFormatError(f"{where}: domain {_cut(str(dom))} is empty, reversed or too "
                              "narrow to map to [-1, 1]")
    if arr.shape[0] > MAX_DIM:
        raise FileFormatError(f"{where}: {arr.shape[0]} input dimensions (at most {MAX_DIM})")
    md = d.get("max_degree")
    if md is not None and (not isinstance(md, list) or len(md) != arr.shape[0]
                           or not all(_is_int(v) and 0 <= v <= MAX_DEGREE_CAP for v in md)):
        raise FileFormatError(f"{where}: space 'max_degree' must be {arr.shape[0]} integer "
                              "degree caps >= 0")
    var = d.get("variable", "x")
    if not isinstance(var, str):
        raise FileFormatError(f"{where}: space 'variable' must be a string, got {_kind(var)}")
    try:
        return PolynomialSpace(fam, arr, iset, None if md is None else tuple(md), variable=var)
    except InputError as exc:
        raise FileFormatError(f"{where}: {exc}") from None


def _channel(c: Any, i: int, space: PolynomialSpace, where: str, *,
             pole_check: bool) -> SavedChannel:
    from ratfit.core.arnoldi import ArnoldiBasis

    if not isinstance(c, dict):
        raise FileFormatError(f"{where}: channel {i} must be an object, got {_kind(c)}")
    name = c.get("name")
    if not isinstance(name, str) or not name:
        raise FileFormatError(f"{where}: channel {i} needs a non-empty string 'name', "
                              f"got {_kind(name)}")
    here = f"{where}: channel {name!r}"
    coef = {}
    for key in ("p", "q"):
        v = c.get(key)
        if not isinstance(v, list) or not v or not all(_is_num(t) for t in v):
            raise FileFormatError(f"{here}: '{key}' must be a non-empty list of numbers")
        arr = np.array(v, dtype=float)
        if not np.all(np.isfinite(arr)) or float(np.max(np.abs(arr))) > MAX_MAGNITUDE:
            raise FileFormatError(f"{here}: non-finite or huge coefficients in '{key}' "
                                  f"(beyond {MAX_MAGNITUDE:.0e})")
        coef[key] = arr
    if not np.any(coef["q"]):
        raise FileFormatError(f"{here}: the denominator is zero (every q coefficient is 0)")
    for key in ("n", "m"):
        if key in c and not (_is_int(c[key]) and c[key] == coef["p" if key == "n" else "q"].size):
            raise FileFormatError(f"{here}: '{key}' does not match the number of coefficients")
    bases = {}
    for key in ("p_basis", "q_basis"):
        b = c.get(key)
        if b is None:
            continue
        if not isinstance(b, dict):
            raise FileFormatError(f"{here}: '{key}' must be an object, got {_kind(b)}")
        if not _is_int(b.get("size")) or not 1 <= b["size"] <= 100_000:
            raise FileFormatError(f"{here}: '{key}' needs an integer 'size'")
        for sub in ("parents", "dims"):
            if not isinstance(b.get(sub), list) or not all(_is_int(t) for t in b[sub]):
                raise FileFormatError(f"{here}: '{key}.{sub}' must be a list of integers")
        h = b.get("H_upper")
        if not isinstance(h, list) or not all(_is_num(t) for t in h) or (
            len(h) != b["size"] * (b["size"] + 1) // 2
        ):
            raise FileFormatError(f"{here}: '{key}.H_upper' must be the "
                                  f"{b['size'] * (b['size'] + 1) // 2} numbers of the "
                                  "recurrence's upper triangle")
        if not all(abs(float(t)) <= MAX_MAGNITUDE for t in h):
            raise FileFormatError(f"{here}: huge entries in '{key}.H_upper'")
        try:
            bases[key] = ArnoldiBasis.from_dict(b, space)
        except (ValueError, InputError) as exc:
            raise FileFormatError(f"{here}: {key}: {exc}") from None
    try:
        rf = RationalFunction(space, coef["p"], coef["q"], **bases)
    except ValueError as exc:
        raise FileFormatError(f"{here}: {exc}") from None
    for key, count in (("p_indices", rf.n), ("q_indices", rf.m)):
        if key in c and c[key] != space.indices(count).tolist():
            raise FileFormatError(f"{here}: {key} do not match")
    for key in ("diagnostics", "monomial"):
        if c.get(key) is not None and not isinstance(c[key], dict):
            raise FileFormatError(f"{here}: '{key}' must be an object, got {_kind(c[key])}")
    _check_function(rf, here, pole_check)
    return SavedChannel(name, rf, dict(c.get("diagnostics") or {}), c.get("monomial"))


def _check_function(rf: RationalFunction, here: str, pole_check: bool) -> None:
    """The stored function is finite on its domain and has a denominator; in 1-D, q has
    no real root in the closed domain (proved in exact arithmetic: a double root, where
    q touches 0 without changing sign, included); in n-D (unless it is a BRDF, whose box
    domain holds directions below the horizon) no sign change of q on a grid."""
    d = rf.space.dim
    if d == 1:
        _check_poles_1d(rf, here)
    per = 1001 if d == 1 else max(3, int(20_000 ** (1.0 / d)))
    axes = [np.linspace(-1.0, 1.0, per)] * d
    grid = np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")], axis=1)
    with np.errstate(all="ignore"):
        q = rf.denominator(grid, window=True)
        p = rf.numerator(grid, window=True)
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(p))):
        raise FileFormatError(f"{here}: the function overflows on its domain (corrupt "
                              "coefficients or recurrence)")
    if not np.any(q):
        raise FileFormatError(f"{here}: the denominator is zero on the whole domain")
    if d > 1 and pole_check and np.any(q > 0) and np.any(q < 0):
        raise FileFormatError(f"{here}: the denominator changes sign on the domain: the "
                              "function has a pole there")


def _check_poles_1d(rf: RationalFunction, here: str) -> None:
    from ratfit.io.exact_roots import denominator_has_root

    try:
        root = denominator_has_root(rf)
    except ValueError as exc:
        raise FileFormatError(f"{here}: {exc}: the denominator cannot be proved free of "
                              "poles on the domain") from None
    if root is None:
        raise FileFormatError(f"{here}: the denominator's roots cluster at the domain so "
                              "closely that no pole-freedom could be proved there")
    if root:
        raise FileFormatError(f"{here}: the denominator has a real root in the domain "
                              "(found in exact arithmetic): the function has a pole there")


def _is_int(v: Any) -> TypeGuard[int]:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and (
        not isinstance(v, int) or abs(v) < 1 << 1000
    )


def _kind(v: Any) -> str:
    return {dict: "an object", list: "a list", str: "a string", bool: "a boolean",
            type(None): "null", int: "a number", float: "a number"}.get(type(v), "?")


def _short(v: Any) -> str:
    return _cut(repr(v))


def _cut(text: str, n: int = 80) -> str:
    return text if len(text) <= n else text[: n - 3] + "..."


# ---------------------------------------------------------------------------- field types
# The type of every field ratfit reads back from a fit file, checked on load: a wrong
# type is one error naming the field, never a value read as something else ("no" as
# true) or a crash where it is used. Fields not listed (a newer ratfit's) are kept as
# they are and never read.
def _number(v: Any) -> bool:
    return _is_num(v) and np.isfinite(float(v))


def _opt(test: Any) -> Any:
    return lambda v: v is None or test(v)


def _list_of(test: Any) -> Any:
    return lambda v: isinstance(v, list) and all(test(t) for t in v)


def _is_str(v: Any) -> bool:
    return isinstance(v, str)


def _is_bool(v: Any) -> bool:
    return isinstance(v, bool)


def _index_key(k: Any) -> bool:
    return isinstance(k, str) and k.isascii() and k.isdigit() and len(k) <= 3


def _coordinate_map(v: Any) -> bool:
    return isinstance(v, dict) and all(_index_key(k) and _number(t) for k, t in v.items())


def _segments_spec(v: Any) -> bool:
    if not isinstance(v, dict):
        return False
    for key, val in v.items():
        if key in ("dt", "floor_rel", "narrowed_floor_from"):
            if not (val is None or _number(val)):
                return False
        elif key == "abs_width":
            # one floor, one per channel (estimated from the data), or the request's
            # "auto" that asked for that estimate
            if not (val is None or _number(val) or _list_of(_number)(val) or val == "auto"):
                return False
        elif key == "noise_estimated":
            if not _is_bool(val):
                return False
        elif key in ("explicit", "default"):
            if not _is_bool(val):
                return False
        elif key == "widened_from" and not (val is None or _list_of(_number)(val)):
            return False
        elif key == "per_channel" and not (isinstance(val, list) and all(
                isinstance(c, dict) and all(c.get(k) is None or _number(c.get(k))
                                            for k in ("dt", "abs_width", "floor_rel"))
                for c in val)):
            # channels of runs with their own widths (ratfit brdf merge)
            return False
    return True


def _subset_spec(v: Any) -> bool:
    return (isinstance(v, dict) and _is_int(v.get("points")) and _is_int(v.get("of"))
            and 0 < v["points"] <= v["of"]
            and v.get("by", "samples") in ("samples", "pairs", "energy"))


_PROVENANCE_FIELDS: dict[str, tuple[Any, str]] = {
    "input": (_is_str, "a string"),
    "input_sha256": (_is_str, "a string"),
    "n_points": (_is_int, "an integer"),
    "solver": (_opt(_is_str), "a string or null"),
    "segments": (_segments_spec, "an object of widths (numbers or null) and flags"),
    "cdf": (lambda v: isinstance(v, dict), "an object"),
    "batch": (lambda v: isinstance(v, dict), "an object"),
    "command": (_list_of(_is_str), "a list of strings"),
    "between": (lambda v: isinstance(v, dict), "an object"),
}
_DIAGNOSTICS_FIELDS: dict[str, tuple[Any, str]] = {
    "verified": (_is_bool, "true or false"),
    "success": (_is_bool, "true or false"),
    "time_limited": (_is_bool, "true or false"),
    "n": (_is_int, "an integer"),
    "m": (_is_int, "an integer"),
    "total": (_is_int, "an integer"),
    "message": (_is_str, "a string"),
    **{k: (_opt(_is_num), "a number or null") for k in (
        "max_violation", "max_violation_rel", "min_margin", "linf", "l2", "max_rel_error",
        "delta", "sigma_min", "sigma_max", "cond", "coef_norm")},
}
_BRDF_FIELDS: dict[str, tuple[Any, str]] = {
    "parametrization": (_is_str, "a string"),
    "cosine_weighted": (_is_bool, "true or false"),
    "positive_q": (_is_bool, "true or false"),
    "polish": (_is_bool, "true or false"),
    "polish_error": (_opt(_is_str), "a string or null"),
    "fold_phi_d": (_is_bool, "true or false"),
    "clamp": (_opt(_number), "a finite number or null"),
    "param_out": (_opt(_is_str), "a string or null"),
    "channel_names": (_list_of(_is_str), "a list of strings"),
    "segments": (_segments_spec, "an object of widths (numbers or null) and flags"),
    "verified_on": (_is_str, "a string"),
    "subset": (_opt(_subset_spec), "an object {points, of} of integers, 0 < points <= of, "
                                   "and an optional 'by' of \"samples\", \"pairs\" or \"energy\""),
    "dropped_coords": (_coordinate_map, "an object mapping coordinate indices "
                                        "(\"0\", \"1\", ...) to numbers"),
    "validity": (_list_of(_opt(_is_str)), "a list of strings or nulls"),
    "proof": (_list_of(_opt(lambda v: isinstance(v, dict) and _is_bool(v.get("proved")))),
              "a list of nulls or objects with a true/false 'proved'"),
    "shared_denominator": (_is_bool, "true or false"),
    "values": (lambda v: v in VALUE_FORMS, " or ".join(f'"{v}"' for v in VALUE_FORMS)),
    "shared": (_opt(lambda v: isinstance(v, dict) and _is_int(v.get("m"))
                    and _is_int(v.get("coefficients"))),
               "null or an object with integers 'm' and 'coefficients'"),
    "holdout": (lambda v: isinstance(v, dict) and _is_int(v.get("k"))
                and isinstance(v.get("metrics"), dict),
                "an object with an integer 'k' and per-channel 'metrics'"),
}


def _check_fields(block: Any, fields: dict[str, tuple[Any, str]], where: str) -> None:
    if not isinstance(block, dict):
        return  # the caller has said what the block itself must be
    for key, (test, what) in fields.items():
        if key in block and not test(block[key]):
            raise FileFormatError(f"{where}: '{key}' must be {what}, got "
                                  f"{_kind(block[key])} {_cut(repr(block[key]), 40)}")


# ---------------------------------------------------------------------------- scope
_SUBSET = re.compile(r"subset of (\d+) of (\d+) samples")


def subset_of(saved: SavedFit) -> tuple[int, int] | None:
    """(points, of) when the fit was verified on a random subset of its data only (a
    ``brdf fit --max-points`` fit), else None: such a fit is never "verified on its
    data", and what says so must say "verified on a subset of points of of samples"."""
    meta = saved.extra.get("brdf") if isinstance(saved.extra, dict) else None
    if not isinstance(meta, dict):
        return None
    sub = meta.get("subset")
    if isinstance(sub, dict) and _subset_spec(sub):
        return int(sub["points"]), int(sub["of"])
    said = meta.get("verified_on")
    if isinstance(said, str) and said != "all samples":
        m = _SUBSET.search(said)
        return (int(m.group(1)), int(m.group(2))) if m else (0, 0)
    return None


def proof_ceiling(entry: object) -> float | None:
    """The ceiling C one channel's stored proof entry states (a BRDF fit of log values:
    C q - p >= 0 proved, so exp(p / q) <= exp(C)), or None where it states none (a file
    from before the bound) or something that is not a finite number."""
    value = entry.get("ceiling") if isinstance(entry, dict) else None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        return None
    return float(value)


def ceiling_bound(ceiling: float) -> float:
    """exp(C), the largest value a proved ceiling C allows a fit of log values; inf past
    float64's range."""
    return math.exp(ceiling) if ceiling < 709.0 else math.inf


def scope_text(saved: SavedFit, reproved: bool | None = None) -> str:
    """What the verification of a sealed fit file covered, in one sentence.

    ``reproved``: whether the caller proved an n-D BRDF fit valid again from its
    stored coefficients (:func:`ratfit.brdf.validity.reprove_saved`); a digest can be
    recomputed by anyone, so a stored "proved" is claimed only when that holds too.
    """
    sub = subset_of(saved)
    if sub is not None:
        k, n = sub
        if k and n:
            return (f"Verified on a subset of {k} of {n} samples only (brdf fit --max-points): "
                    f"not checked at the other {n - k} samples.")
        return "Verified on a subset of its samples only (brdf fit --max-points)."
    if saved.space.dim > 1:
        meta = saved.extra.get("brdf") if isinstance(saved.extra, dict) else None
        proofs = meta.get("proof") if isinstance(meta, dict) else None
        if (reproved is not False and isinstance(proofs, list)
                and len(proofs) == len(saved.channels)
                and all(isinstance(p, dict) and p.get("proved") is True for p in proofs)):
            if saved.values != "log":
                return ("Verified at every sample of its data; q > 0 and p >= 0 proved where "
                        "it is evaluated (Bernstein bounds, as the fit file records).")
            # the bound is exp of the ceiling the proof was made (and made again) with
            tops = [proof_ceiling(p) for p in proofs]
            bounds = [ceiling_bound(c) for c in tops if c is not None]
            if len(bounds) == len(tops) and all(math.isfinite(v) for v in bounds):
                # (reprove_saved refuses an envelope entry it cannot read)
                envs = [p.get("envelope") for p in proofs]
                over = ("theta_h and theta_d" if all(isinstance(e, dict) and "theta_d" in e
                                                     for e in envs) else "theta_h")
                floored = all(isinstance(e, dict) and "floor" in e for e in envs)
                under = (f", and under the samples' envelope over {over}"
                         + (" and above its highlight's floor" if floored else "")
                         + " (as the fit file states them)"
                         if all(isinstance(e, dict) for e in envs) else "")
                return ("Verified at every sample of its data; q > 0 and exp(p/q) <= "
                        + " / ".join(f"{v:.4g}" for v in bounds)
                        + f" (per channel){under} proved where it is evaluated (Bernstein "
                          "bounds, as the fit file records).")
            return ("Verified at every sample of its data; q > 0 proved where it is "
                    "evaluated (Bernstein bounds, as the fit file records), so exp(p/q) is "
                    "positive there; no upper bound is proved.")
        return ("Verified at every sample of its data; that the denominator has no zero "
                "between the samples was checked on a dense grid, not proved.")
    return ("Verified on its data; no pole on the domain (proved in exact arithmetic when "
            "this file was loaded).")


# ---------------------------------------------------------------------------- re-verification
def segment_check(saved: SavedFit, seg: Any) -> list[tuple[str, int, int, float]]:
    """Per channel (name, segments met, segments, worst violation) of the stored function
    on ``seg``: a fit file's record of verification is not taken on trust when data is
    at hand. Non-finite values count as violations."""
    vals = saved(seg.x)
    out = []
    for j, ch in enumerate(saved.channels):
        v = vals[:, j]
        with np.errstate(invalid="ignore"):
            viol = np.maximum(seg.lo[:, j] - v, v - seg.hi[:, j])
        viol = np.where(np.isfinite(v), viol, np.inf)
        worst = float(np.max(viol)) if viol.size else 0.0
        out.append((ch.name, int(np.sum(viol <= 0)), int(viol.size), max(worst, 0.0)))
    return out


def recorded_segments(saved: SavedFit, data: Any) -> Any:
    """The data's segments with the widths the fit file records (None when unknown)."""
    spec = saved.provenance.get("segments") if isinstance(saved.provenance, dict) else None
    if not isinstance(spec, dict) or data.n_channels != len(saved.channels):
        return None
    dt, aw = spec.get("dt"), spec.get("abs_width")
    try:
        if dt is None and aw is None:
            return data.segments() if data.lo is not None else None
        return data.segments(dt=dt, abs_width=aw)
    except (InputError, TypeError):
        return None
