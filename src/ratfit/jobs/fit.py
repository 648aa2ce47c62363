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
                "shared_denominator")
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
        return fit_document(self.results, monomial=self.monomials, provenance={
            "input": str(req.input), "input_sha256": self.input_sha256,
            "n_points": self.segments.n_points, "segments": segdesc,
            "solver": req.options.solver,
        })

    def summary(self) -> dict[str, Any]:
        """The ``--json`` object: per-channel summaries, and the shared sizes."""
        doc = results_summary(self.results, self.written)
        if self.shared is not None:
            doc.update(shared_denominator=True, m_shared=self.shared.m, total=self.shared.total,
                       proven_minimal=self.shared.proven)
        return doc


def _read_fit_data(req: FitRequest) -> Any:
    """The request's data file; a measured BRDF file (MERL, EXR, Cornell, ASTM) is
    refused with the command that fits it."""
    from ratfit.brdf.io import measured_brdf_format
    from ratfit.io.data import read_data

    kind = measured_brdf_format(req.input) if req.format is None else None
    try:
        return read_data(req.input, fmt=req.format, dim=req.dim)
    except RatfitError:
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
        else:
            results = RationalFitter.from_options(req.options).fit(seg).results_
    report = FitReport(req, results, seg, digest, shared=shared)
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
