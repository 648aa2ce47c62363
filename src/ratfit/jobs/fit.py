"""The job behind ``ratfit fit`` and each batch task on a data file: one request in,
one report out (results, segments, timings, messages, the fit file's document)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ratfit.core.options import SEGMENT_OPTIONS, FitOptions
from ratfit.core.results import FitResult
from ratfit.core.segments import Segments
from ratfit.core.validation import check_choice
from ratfit.errors import InputError, RatfitError
from ratfit.fitting.shared_denominator import SharedDenominatorFitter, SharedFit, SharedOptions
from ratfit.jobs.common import (
    Clock,
    as_path,
    check_channels,
    check_count,
    check_flag,
    monomial_forms,
    results_summary,
)

__all__ = ["FitReport", "FitRequest", "fit_file"]

#: The request's own keys in a flat settings mapping (the rest are fit options).
REQUEST_KEYS = ("format", "dim", "dt", "abs_width", "channels", "monomial", "output",
                "shared_denominator", "between")
#: Rounds of --between: each adds the points where the excursion check failed, then refits.
BETWEEN_ROUNDS = 8
#: The rows between samples get this share of the --between widening; the check allows all
#: of it, so r has room to bend between the rows and still pass (measured: with the whole
#: margin on the rows, Thurber --dt 1e-2 --between 0.05 ended 71.4 > 70.2 after 8 rounds).
BETWEEN_ROW_SHARE = 0.5
# Without --max-total, the largest numerator of a shared-denominator search.
SHARED_MAX_N = 60


@dataclass(frozen=True)
class FitRequest:
    """What a fit of a data file asks for: which file, which segments, which options.

    Parameters
    ----------
    input : path
        The data file (ALTA text, CSV, .npz, NIST StRD).
    options : FitOptions, default FitOptions()
        The checked fit options; a :class:`~ratfit.fitting.shared_denominator.SharedOptions`
        asks for one denominator shared by every channel.
    format, dim : optional
        How to read the file (default: from its content).
    dt, abs_width : float, optional
        Segment widths around the file's y values (default: the file's own intervals).
    channels : tuple of int or str
        The channels to fit, by 0-based index or name (default: all).
    monomial : bool, default True
        Store each channel's monomial form in the fit file.
    output : path, optional
        The fit file to write, only when every channel is verified.
    between : float, optional
        1-D only: also bound r between neighbouring samples, to the envelope of the two
        neighbours' segments widened by ``between`` times the data's range (max hi -
        min lo); see :func:`ratfit.core.between.between_segments`.
    """

    input: Path
    options: FitOptions = field(default_factory=FitOptions)
    format: str | None = None
    dim: int | None = None
    dt: float | None = None
    abs_width: float | None = None
    channels: tuple[int | str, ...] = ()
    monomial: bool = True
    output: Path | None = None
    between: float | None = None

    def __post_init__(self) -> None:
        from ratfit.io.data import FORMATS

        fix = object.__setattr__
        fix(self, "input", as_path(self.input, "input"))
        fix(self, "output", as_path(self.output, "output", allow_none=True))
        if not isinstance(self.options, FitOptions):
            raise InputError(f"options must be FitOptions, got {type(self.options).__name__}")
        if self.format is not None:
            fix(self, "format", check_choice(str(self.format).lower(), "format", FORMATS))
        fix(self, "dim", check_count(self.dim, "dim", 1))
        for key, opt in SEGMENT_OPTIONS.items():
            fix(self, key, opt.check(getattr(self, key)))
        fix(self, "channels", check_channels(self.channels))
        fix(self, "monomial", check_flag(self.monomial, "monomial"))
        if self.between is not None:
            b = self.between
            if isinstance(b, bool) or not isinstance(b, (int, float)) or not 0 <= b < 1e6:
                raise InputError(f"between must be a number >= 0 (a fraction of the data's "
                                 f"range), got {b!r}")
            if self.shared_denominator:
                raise InputError("between is not available with a shared denominator")
            fix(self, "between", float(b))

    @property
    def shared_denominator(self) -> bool:
        return isinstance(self.options, SharedOptions)

    def with_progress(self, callback: Any) -> FitRequest:
        """The same request, reporting each tested split to ``callback`` (progress)."""
        return replace(self, options=self.options.replace(callback=callback))

    @classmethod
    def from_settings(cls, input: str | Path, settings: Mapping[str, Any], *,
                      where: str | None = None) -> FitRequest:
        """The request of flat settings: the CLI's option names and a batch manifest's
        keys (:data:`REQUEST_KEYS` plus fit options), checked. With
        ``shared_denominator``, ``max_total`` is the largest numerator (default 60)."""
        rest = dict(settings)
        own = {k: rest.pop(k) for k in REQUEST_KEYS if k in rest}
        options: FitOptions
        if own.pop("shared_denominator", False):
            if "max_total" in rest:
                top = rest.pop("max_total")
                rest["max_n"] = SHARED_MAX_N if top is None else top
            options = SharedOptions.from_params(rest, where=where)
        else:
            options = FitOptions.from_params(rest, where=where)
        return cls(input=Path(input), options=options, **own)


@dataclass
class FitReport:
    """What a fit job did: one result per channel and how to write it down.

    ``document()`` builds the fit file's JSON document (verified fits only),
    ``summary()`` the one JSON object of ``ratfit fit --json``; ``messages``
    holds warnings (digits lost in a monomial form, ...), ``seconds`` the time
    of each phase (read, segments, fit, document, write).
    """

    request: FitRequest
    results: list[FitResult]
    segments: Segments
    input_sha256: str
    shared: SharedFit | None = None
    monomials: list[dict[str, Any] | None] | None = None
    messages: list[str] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    written: Path | None = None
    excursions: list[Any] = field(default_factory=list)  # per channel: Excursion or None

    @property
    def success(self) -> bool:
        """Every channel has a verified fit."""
        return bool(self.results) and all(r.success for r in self.results)

    @property
    def message(self) -> str:
        if self.shared is not None:
            return self.shared.message
        return "; ".join(f"{r.channel}: {r.message}" for r in self.results)

    def document(self) -> dict[str, Any]:
        """The fit file's document (InputError for an unverified fit)."""
        from ratfit.io.fitfile import fit_document

        req = self.request
        segdesc: dict[str, Any] = {"dt": req.dt, "abs_width": req.abs_width,
                                   "explicit": req.dt is None and req.abs_width is None}
        prov: dict[str, Any] = {
            "input": str(req.input), "input_sha256": self.input_sha256,
            "n_points": self.segments.n_points, "segments": segdesc,
            "solver": req.options.solver,
        }
        if any(e is not None for e in self.excursions):
            prov["between"] = self.between_summary()
        return fit_document(self.results, monomial=self.monomials, provenance=prov)

    def between_summary(self) -> dict[str, Any]:
        """r between neighbouring samples (1-D): the method, the margin asked for, and
        per channel the excursion (null where none was computed: n-D, unverified)."""
        done = [e for e in self.excursions if e is not None]
        return {"method": done[0].method if done else None, "margin": self.request.between,
                "channels": [None if e is None else e.to_dict() for e in self.excursions]}

    def summary(self) -> dict[str, Any]:
        """The ``--json`` object: per-channel summaries, and the shared sizes."""
        doc = results_summary(self.results, self.written)
        if self.excursions:
            doc["between"] = self.between_summary()
        if self.shared is not None:
            doc.update(shared_denominator=True, m_shared=self.shared.m, total=self.shared.total,
                       proven_minimal=self.shared.proven)
        return doc


def _read_fit_data(req: FitRequest) -> Any:
    """The request's data file; a measured BRDF file (MERL, EXR, Cornell, ASTM) is
    refused with the command that fits it (the BRDF package is imported only then)."""
    from ratfit.io.data import read_data

    try:
        return read_data(req.input, fmt=req.format, dim=req.dim)
    except RatfitError:
        if req.format is not None:
            raise
        from ratfit.brdf.io import measured_brdf_format

        kind = measured_brdf_format(req.input)
        if kind is None:
            raise
    raise InputError(
        f"{req.input}: a measured BRDF file ({kind}), not x/y data: fit it with "
        f"`ratfit brdf fit {req.input}`")


def fit_file(request: FitRequest | str | Path, *, data: Any = None) -> FitReport:
    """Fit a data file as ``request`` says; the one path of ``ratfit fit`` and batch tasks.

    The file is parsed once, its segments built once; with ``request.output`` the
    fit file is written when (only when) every channel is verified.

    Parameters
    ----------
    request : FitRequest or path
        What to fit; a bare path is ``FitRequest(path)`` (every default).
    data : Dataset, optional
        ``request.input`` already parsed with the request's format and dim (a
        batch worker parses an input once for all its channels' tasks).

    Returns
    -------
    FitReport
        The results, the seconds of each phase, messages, and the document.

    Examples
    --------
    >>> import tempfile, os, numpy as np
    >>> from ratfit.io.data import write_csv
    >>> from ratfit.jobs import FitRequest, fit_file
    >>> path = os.path.join(tempfile.mkdtemp(), "d.csv")
    >>> x = np.linspace(0, 1, 30)
    >>> write_csv(path, x[:, None], (1 / (2 + x))[:, None])
    >>> report = fit_file(FitRequest(path, dt=1e-3))
    >>> report.success, [(r.n, r.m) for r in report.results]
    (True, [(1, 2)])
    """
    from ratfit.fitting.search import RationalFitter
    from ratfit.io.fitfile import file_sha256, save_fit

    req = request if isinstance(request, FitRequest) else FitRequest(Path(request))
    clock = Clock()
    with clock.phase("read"):
        if data is None:
            data = _read_fit_data(req)
        digest = file_sha256(req.input)
    with clock.phase("segments"):
        seg = _segments(req, data)
    shared = None
    with clock.phase("fit"):
        if isinstance(req.options, SharedOptions):
            shared = SharedDenominatorFitter.from_options(req.options).fit(seg).result_
            results = list(shared.results)
        elif req.between is not None:
            results = _fit_between(req, seg)
        else:
            results = RationalFitter.from_options(req.options).fit(seg).results_
    report = FitReport(req, results, seg, digest, shared=shared)
    if seg.dim == 1:
        with clock.phase("between"):
            report.excursions = _excursions(results, seg, req.between)
            report.messages.extend(w for e in report.excursions
                                   if e is not None and (w := e.warning()) is not None)
    if report.success and req.monomial:
        with clock.phase("document"):
            report.monomials, notes = monomial_forms(results, seg.x)
            report.messages.extend(notes)
    if report.success and req.output is not None:
        with clock.phase("write"):
            save_fit(req.output, report.document())
        report.written = req.output
    report.seconds = clock.seconds
    return report


def _excursions(results: list[FitResult], seg: Segments, margin: float | None) -> list[Any]:
    """Per channel r's largest excursion between samples (None: no verified fit)."""
    from ratfit.core.between import between_excursions, data_ranges

    widen = data_ranges(seg) * margin if margin is not None else None
    return [None if not r.success or r.rational is None else
            between_excursions(r.rational, seg, j,
                               allowed=None if widen is None else float(widen[j]))
            for j, r in enumerate(results)]


def _fit_between(req: FitRequest, seg: Segments) -> list[FitResult]:
    """``--between``: fit with extra points between samples (first the midpoints, then
    where the excursion check failed), until every verified channel passes the check on
    the original samples or :data:`BETWEEN_ROUNDS` rounds are spent. Results are
    verified again on the original segments; a channel that never passes is reported
    as not verified, with the reason."""
    import numpy as np

    from ratfit.core.between import between_segments
    from ratfit.core.verify import verify
    from ratfit.fitting.search import RationalFitter

    if seg.dim != 1:
        raise InputError(f"{req.input}: --between bounds a fit between neighbouring samples "
                         f"of 1-D data; this file has {seg.dim} input dimensions")
    assert req.between is not None
    ux = np.unique(seg.x[:, 0])
    extra = 0.5 * (ux[:-1] + ux[1:])
    results: list[FitResult] = []
    for _ in range(BETWEEN_ROUNDS):
        aug = between_segments(seg, extra, BETWEEN_ROW_SHARE * req.between)
        fitted = RationalFitter.from_options(req.options).fit(aug).results_
        note = (f" (on the segments plus {extra.size} rows between samples from "
                f"--between {req.between:g})")
        results = [replace(r, message=r.message + note) if not r.success else
                   r if r.rational is None else
                   replace(r, verification=verify(r.rational, seg, channel=j))
                   for j, r in enumerate(fitted)]
        failing = [e for e in _excursions(results, seg, req.between)
                   if e is not None and not e.ok]
        if not failing:
            return results
        new = np.concatenate([np.array(e.over) for e in failing])
        extra = np.unique(np.concatenate([extra, new[~np.isin(new, extra)]]))
    excs = _excursions(results, seg, req.between)
    return [r if e is None or e.ok else
            replace(r, success=False, status=1,
                    verification=None if r.verification is None else
                    replace(r.verification, verified=False),
                    message=f"between samples the fit exceeds --between "
                            f"({e.excursion:.3g} > {e.allowed:.3g} at x = {e.x:.6g}) after "
                            f"{BETWEEN_ROUNDS} rounds of points between samples")
            for r, e in zip(results, excs, strict=True)]


def _segments(req: FitRequest, data: Any) -> Segments:
    """The request's segments of the file's channels (messages name the file)."""
    try:
        seg = data.segments(dt=req.dt, abs_width=req.abs_width)
    except RatfitError as exc:
        msg = str(exc)
        raise type(exc)(msg if str(req.input) in msg else f"{req.input}: {msg}") from None
    if not req.channels:
        return seg
    names = list(seg.names)
    pick = []
    for c in req.channels:
        if isinstance(c, str):
            if c not in names:
                raise InputError(f"{req.input}: no channel named {c!r} (channels: "
                                 f"{', '.join(names)})")
            pick.append(names.index(c))
        else:
            seg.channel(c)  # validates the index, with the usual message
            pick.append(c)
    return Segments(seg.x, seg.lo[:, pick], seg.hi[:, pick],
                    None if seg.y is None else seg.y[:, pick], tuple(names[c] for c in pick))
