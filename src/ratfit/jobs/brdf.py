"""The job behind ``ratfit brdf fit`` and each batch task on a BRDF file: the file read
once, its frames chosen as the command always chose them, one report out."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from shlex import quote
from typing import Any

import numpy as np

from ratfit.brdf.options import UNKNOWN_PARAMETRIZATION, BRDFOptions
from ratfit.core.rational import ratio_values
from ratfit.core.results import FitResult
from ratfit.core.segments import Segments
from ratfit.core.validation import check_choice
from ratfit.errors import InputError
from ratfit.io.data import Dataset
from ratfit.jobs.common import (
    Clock,
    as_path,
    check_channels,
    check_count,
    check_flag,
    check_nonnegative,
    results_summary,
)

__all__ = ["BRDFFitReport", "BRDFFitRequest", "BRDFMergeReport", "BRDFMergeRequest",
           "fit_brdf_file", "merge_brdf_fits"]

#: The request's own keys in a flat settings mapping (the rest are BRDF fit options).
REQUEST_KEYS = ("format", "parametrization", "dt", "abs_width", "floor_rel", "cosine", "clamp",
                "channels", "color", "max_points", "subset_by", "holdout", "shared_denominator",
                "output")
COLORS = ("rgb", "xyz", "spectral")
# 6-D Cartesian pairs of an isotropic material (Cornell files): 3-D angles carry the
# same information with no constant column and far fewer coefficients.
ISOTROPIC_DEFAULT = {"CARTESIAN": "ISOTROPIC_TV_TL_DPHI"}
#: The parts of :class:`TableDefaults`, each replaced by the options a request gives.
TABLE_GROUPS = ("frame", "subset", "values", "widths", "size")


@dataclass(frozen=True)
class TableDefaults:
    """How a full MERL table is fitted where the request leaves it open.

    A measured table is rough where no smooth rational follows it (cells of 0 and steps
    next to the horizon, phi_d dependence at the mirror direction, no mirror symmetry:
    docs/benchmarks/brdf.md, "RGL materials as MERL tables"), so fitting every cell, the
    default for other files, verified none of RGL's tables at any width. A subset drawn
    where uniformly random direction pairs fall, in a frame that keeps reciprocity and
    isotropy at the mirror but not mirror symmetry, with log values and the networks'
    size (675 numbers in three channels), verified and proved 10 of 11 RGL tables tried
    (2026-12-01); a channel with no verified fit is then widened alone, at the same
    size, as ratfit's widths always are. Each group of options a request gives
    replaces its part: ``--param`` the frame, ``--max-points`` the subset,
    ``--values`` the value form, any width the widths, any size the size.
    """

    parametrization: str = "RUSIN_TH_TD_FOLD"
    max_points: int = 5000
    subset_by: str = "pairs"
    values: str = "log"
    dt: float = 0.22
    abs_width: float = 1e-3
    n: int = 113
    m: int = 112

    def words(self, groups: tuple[str, ...] = TABLE_GROUPS) -> str:
        """The defaults of ``groups`` as ``ratfit brdf fit`` options."""
        said = {"frame": f"--param {self.parametrization}",
                "subset": f"--max-points {self.max_points} --subset-by {self.subset_by}",
                "values": f"--values {self.values}",
                "widths": f"--dt {self.dt:g} --abs-width {self.abs_width:g}",
                "size": f"--n {self.n} --m {self.m}"}
        return " ".join(said[g] for g in groups)

    def apply(self, req: BRDFFitRequest) -> tuple[BRDFFitRequest, tuple[str, ...]]:
        """``req`` with what it leaves open filled in, and the groups filled ("frame",
        "subset", "values", "widths", "size")."""
        o = req.options
        filled: list[str] = []
        changes: dict[str, Any] = {}
        opts: dict[str, Any] = {}
        if req.parametrization is None:
            filled.append("frame")
            changes["parametrization"] = self.parametrization
        if req.max_points is None:
            filled.append("subset")
            changes["max_points"] = self.max_points
            changes["subset_by"] = self.subset_by
        shared = req.shared_denominator  # one q refuses log values and n
        if o.values == "auto" and not shared:
            filled.append("values")
            opts["values"] = self.values
        if req.dt is None and req.abs_width is None and req.floor_rel is None:
            filled.append("widths")
            changes["dt"], changes["abs_width"] = self.dt, self.abs_width
        if o.n is None and o.total is None and o.max_total is None and not shared:
            filled.append("size")
            opts["n"], opts["m"] = self.n, self.m
        if opts:
            changes["options"] = o.replace(**opts)
        return replace(req, **changes), tuple(filled)


#: What ``ratfit brdf fit`` fits a full MERL table with by default.
TABLE_DEFAULTS = TableDefaults()
#: The table defaults as options (a fit of every cell with no verified fit names them).
TABLE_SUBSET_OPTIONS = TABLE_DEFAULTS.words()
TABLE_SUBSET_HINT = (
    "a subset of the table drawn where random direction pairs fall, in a frame that is "
    f"not mirror-symmetric, may (ratfit's default for a MERL table, {TABLE_SUBSET_OPTIONS}: "
    "675 numbers, verified on those 5000 cells only and proved valid at every pair of "
    "directions; RGL's satin_rosaline fits so in about 5 minutes on two cores)")


@dataclass(frozen=True)
class BRDFFitRequest:
    """What a fit of a measured BRDF file asks for.

    Parameters
    ----------
    input : path
        A MERL, ALTA, Cornell/pbrt, ASTM or EXR file.
    options : BRDFOptions, default BRDFOptions()
        The checked fit options (solver, sizes, time limit, ``polish``,
        ``positive_q``, ``physical``); the job sets the parametrization.
    format : str, optional
        The file's format (default: from its content).
    parametrization : str, optional
        The frame to fit in (ALTA name); default: the file's own
        (ISOTROPIC_TV_TL_DPHI for Cartesian pairs), and for isotropic angles the
        half-vector frame first, keeping the better verified fit.
    dt, abs_width, floor_rel : float, optional
        Segment widths (default: the file's intervals, else ratfit's defaults);
        ``abs_width="auto"``: each channel's noise level, estimated from the data.
    cosine, clamp
        Fit BRDF x cos(theta_l); raise values below ``clamp`` to it.
    channels : tuple of str or int
        Channels by name or 0-based index (default: all).
    color : {"rgb", "xyz", "spectral"}, default "rgb"
        How spectral (Cornell) data becomes channels.
    max_points : int, optional
        Fit a random subset of this many samples (verified on that subset only).
    subset_by : {"samples", "pairs", "energy"}, default "samples"
        How ``max_points`` draws: every sample alike; (a MERL table) each cell as
        often as uniformly random direction pairs fall in it
        (:func:`ratfit.brdf.io.merl_cell_measure`); or "energy": half so, half weighted
        by the table's luminance, so a narrow highlight, where a renderer that samples
        the BRDF evaluates it most, is drawn too (:func:`ratfit.brdf.io.samples_dataset`).
    holdout : int, optional
        K >= 2: also fit K times without one of K folds of the samples and record
        the held-out errors (:func:`ratfit.brdf.holdout.cross_validate`) in the
        report and the fit file.
    shared_denominator : bool, default False
        One q for every channel, one p_c per channel
        (:class:`~ratfit.brdf.shared.SharedBRDFFitter`): the fewest numbers
        sum(n_c) + m, each channel proved valid as p_c / q. ``max_total`` bounds
        each numerator; ``n``, ``total`` and a single channel are refused.
    output : path, optional
        The fit file to write, only when every channel is verified. When some are,
        they are kept in a new file beside it (``NAME.partial.json``, never over an
        existing file) for ``ratfit brdf merge`` with the others, fitted alone.
    """

    input: Path
    options: BRDFOptions = field(default_factory=BRDFOptions)
    format: str | None = None
    parametrization: str | None = None
    dt: float | None = None
    abs_width: float | str | None = None
    floor_rel: float | None = None
    cosine: bool = False
    clamp: float | None = None
    channels: tuple[int | str, ...] = ()
    color: str = "rgb"
    max_points: int | None = None
    subset_by: str = "samples"
    holdout: int | None = None
    shared_denominator: bool = False
    output: Path | None = None

    def __post_init__(self) -> None:
        from ratfit.brdf.io import BRDF_FORMATS
        from ratfit.brdf.parametrizations import get_parametrization

        fix = object.__setattr__
        fix(self, "input", as_path(self.input, "input"))
        fix(self, "output", as_path(self.output, "output", allow_none=True))
        if not isinstance(self.options, BRDFOptions):
            raise InputError(f"options must be BRDFOptions, got {type(self.options).__name__}")
        if (self.options.parametrization != UNKNOWN_PARAMETRIZATION
                or self.options.used_coords is not None):
            raise InputError("the job chooses the options' parametrization and coordinates: "
                             "give the frame as the request's parametrization")
        if self.format is not None:
            fix(self, "format", check_choice(str(self.format).lower(), "format", BRDF_FORMATS))
        if self.parametrization is not None:
            fix(self, "parametrization", get_parametrization(self.parametrization).name)
        from ratfit.brdf.fitter import AUTO_FLOOR, is_auto_floor

        for key in ("dt", "abs_width", "floor_rel", "clamp"):
            if key == "abs_width" and is_auto_floor(self.abs_width):
                fix(self, key, AUTO_FLOOR)  # each channel's noise level, from the data
                continue
            fix(self, key, check_nonnegative(getattr(self, key), key))
        from ratfit.brdf.fitter import check_floor_rel

        check_floor_rel(self.dt, self.abs_width, self.floor_rel)
        fix(self, "cosine", check_flag(self.cosine, "cosine"))
        fix(self, "channels", check_channels(self.channels))
        fix(self, "color", check_choice(self.color, "color", COLORS))
        fix(self, "max_points", check_count(self.max_points, "max_points", 2))
        from ratfit.brdf.io import SUBSET_BY

        fix(self, "subset_by", check_choice(self.subset_by, "subset_by", SUBSET_BY))
        if self.subset_by != "samples" and self.max_points is None:
            raise InputError(f"subset_by {self.subset_by!r} says how max_points draws a "
                             "subset: give max_points too")
        fix(self, "holdout", check_count(self.holdout, "holdout", 2))
        fix(self, "shared_denominator", check_flag(self.shared_denominator,
                                                   "shared_denominator"))
        if self.shared_denominator:
            self._check_shared()

    def _check_shared(self) -> None:
        """The combinations a shared denominator refuses, before the file is read."""
        from ratfit.brdf.shared import SharedBRDFFitter

        o = self.options
        for key, flag in (("n", "--n"), ("total", "--total")):
            if getattr(o, key) is not None:
                raise InputError(f"--shared-denominator searches the numerator sizes itself: "
                                 f"drop {flag} (--m fixes the shared denominator)")
        if len(self.channels) == 1:
            raise InputError(f"--shared-denominator needs at least two channels, got one "
                             f"(--channel {self.channels[0]}): drop one of the two options")
        # the rest (positive_q, search options a shared search has no use for)
        SharedBRDFFitter(**{k: v for k, v in o.params().items()
                            if k not in ("parametrization", "used_coords")}).options(3)

    @classmethod
    def from_settings(cls, input: str | Path, settings: Mapping[str, Any], *,
                      where: str | None = None) -> BRDFFitRequest:
        """The request of flat settings (the CLI's option names, a batch manifest's keys):
        :data:`REQUEST_KEYS` plus BRDF fit options, checked."""
        rest = dict(settings)
        own = {k: rest.pop(k) for k in REQUEST_KEYS if k in rest}
        return cls(input=Path(input), options=BRDFOptions.from_params(rest, where=where), **own)

    def with_progress(self, callback: Any) -> BRDFFitRequest:
        """The same request, reporting each tested split to ``callback`` (progress)."""
        return replace(self, options=self.options.replace(callback=callback))


@dataclass
class BRDFFitReport:
    """What a BRDF fit job did.

    ``meta`` is the fit file's ``"brdf"`` block (parametrization, widths, the
    candidates tried); ``notes()`` explains the choices ratfit made for the
    request (the frame, the default widths), ``hint()`` what may give a fit
    when none verified; ``document()`` and ``summary()`` as for
    :class:`~ratfit.jobs.FitReport`.
    """

    request: BRDFFitRequest
    results: list[FitResult]
    segments: Segments
    meta: dict[str, Any]
    input_sha256: str
    file_parametrization: str
    frames_tried: int
    subset: dict[str, int] | None = None
    table: bool = False  # the input is a full MERL table
    metrics: dict[str, dict[str, float]] | None = None
    holdout: Any = None  # ratfit.brdf.holdout.HoldoutResult with --holdout
    messages: list[str] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    written: Path | None = None
    input_channels: tuple[str, ...] = ()  # every channel of the input, in its order
    kept: Path | None = None  # the verified channels of a fit that did not all verify
    # the groups of TABLE_DEFAULTS a MERL table's request left open ("frame", "size", ...)
    table_defaults: tuple[str, ...] = ()

    @property
    def verified_channels(self) -> list[int]:
        """Indices of the channels with a verified fit."""
        return [j for j, r in enumerate(self.results) if r.success]

    @property
    def kept_names(self) -> list[str]:
        """The names of the channels in :attr:`kept` (none when nothing was kept)."""
        return [] if self.kept is None else [self.segments.names[j]
                                             for j in self.verified_channels]

    @property
    def success(self) -> bool:
        return bool(self.results) and all(r.success for r in self.results)

    @property
    def parametrization(self) -> str:
        return str(self.meta["parametrization"])

    def status(self) -> str | None:
        """What "verified" covers for a subset fit (None for a fit of every sample)."""
        from ratfit.brdf.fitter import subset_status

        if not self.subset:
            return None
        if not self.success:
            return "no verified fit"
        return subset_status(self.subset["points"], self.subset["of"])

    def document(self, channels: list[int] | None = None) -> dict[str, Any]:
        """The fit file's document (InputError for an unverified fit); ``channels``
        (indices) keeps those channels only, with the brdf block cut to them."""
        from ratfit.brdf.merge import channel_meta
        from ratfit.io.fitfile import fit_document

        req = self.request
        results, meta = self.results, self.meta
        if channels is not None:
            results = [self.results[j] for j in channels]
            meta = channel_meta(self.meta, channels)
        return fit_document(results, extra={"brdf": meta}, provenance={
            "input": str(req.input), "input_sha256": self.input_sha256,
            "n_points": self.segments.n_points, "solver": req.options.solver,
            "segments": {"dt": req.dt, "abs_width": req.abs_width, "floor_rel": req.floor_rel},
            # what ratfit brdf merge orders the channels of separate runs by
            "input_channels": list(self.input_channels),
        })

    def summary(self) -> dict[str, Any]:
        """The ``ratfit brdf fit --json`` object."""
        doc = results_summary(self.results, self.written)
        # the verified channels of a fit that did not all verify, in a file of their own
        doc["kept"] = None if self.kept is None else {"path": str(self.kept),
                                                      "channels": self.kept_names}
        doc["parametrization"] = self.parametrization
        doc["parametrization_candidates"] = self.meta["candidates"]
        doc["n_points"] = self.segments.n_points
        doc["verified_on"] = self.meta["verified_on"]
        # the options a MERL table's defaults filled in (None: none)
        doc["table_defaults"] = (TABLE_DEFAULTS.words(self.table_defaults)
                                 if self.table_defaults else None)
        if self.subset:
            doc["subset"] = dict(self.subset)
            doc["status"] = self.status()
        doc["metrics"] = self.metrics
        if self.holdout is not None:
            doc["holdout"] = self.holdout.to_dict()
        doc["shared_denominator"] = bool(self.meta.get("shared_denominator"))
        # "log": each channel's value is exp(p / q) of the n and m above
        doc["values"] = str(self.meta.get("values", "linear"))
        # wall seconds of each phase of the job ("seconds" above sums the channels'
        # searches, which run side by side on large data)
        doc["phase_seconds"] = {k: round(v, 3) for k, v in self.seconds.items()}
        if self.meta.get("shared"):
            doc["shared"] = dict(self.meta["shared"])
        return doc

    def notes(self) -> list[str]:
        """Why this frame and these widths, when ratfit chose them (one line each)."""
        out = []
        own, chosen = self.file_parametrization, ISOTROPIC_DEFAULT.get(self.file_parametrization)
        if self.frames_tried == 1 and chosen and self.request.parametrization is None:
            out.append(f"parametrization: {chosen} (chosen for the file's {own}; "
                       "--param overrides)")
        if self.table_defaults:
            out.append(f"a MERL table: {TABLE_DEFAULTS.words(self.table_defaults)} (ratfit's "
                       "table defaults; verified on the subset's cells only; each option "
                       "given replaces its part)")
        if self.frames_tried > 1:
            out.append(f"parametrization: {self.parametrization} ("
                       + "; ".join(_candidate_note(c) for c in self.meta["candidates"])
                       + "; narrower segments, then fewer coefficients win; --param fixes one)")
        if self.meta["segments"]["default"]:
            out.append(_widths_note(self.meta["segments"]))
        elif self.meta["segments"].get("noise_estimated"):
            out.append(_noise_note(self.meta["segments"], self.meta["channel_names"]))
        if self.meta.get("held_out_size"):
            out.append(_held_out_size_note(self.meta["held_out_size"],
                                           self.meta["channel_names"]))
        return out

    def hint(self) -> str | None:
        """What may give a verified fit: which channels have none (when others
        verified), and wider segments when none did at the default widths."""
        if self.success:
            return None
        widths = self.meta["segments"]
        names = list(self.segments.names)
        failed = [n for n, r in zip(names, self.results, strict=True) if not r.success]
        parts = []
        if len(failed) < len(names):
            alone = " ".join(f"--channel {n}" for n in failed)
            if self.kept is not None:
                # paths quoted as a shell reads them: the commands are for copying
                part, out = quote(str(self.kept)), str(self.request.output)
                rest = quote(str(_sibling(Path(out), "rest")))
                kept = (f" (kept in {part}); refit {', '.join(failed)} alone "
                        f"({alone} -o {rest}), then join them with ratfit brdf merge "
                        f"{part} {rest} -o {quote(out)}")
            else:
                kept = (f"; no verified fit for {', '.join(failed)} (refit "
                        f"{'it' if len(failed) == 1 else 'them'} alone with {alone})")
            parts.append(f"channels {', '.join(n for n in names if n not in failed)} verified "
                         f"in {self.parametrization}" + kept)
        noise = bool(widths.get("noise_estimated")) and widths["dt"] is not None
        exhausted = (_ladder_exhausted(self.meta.get("candidates", []))
                     if widths["default"] or noise else None)
        if exhausted:
            # widening went as far as it goes: "wider ones may give one" would be false
            parts.append(exhausted)
        elif widths["default"] or noise:
            limited = [r.message for r in self.results if r.time_limited]
            out_of = ("or a larger --work-limit (the search ran out of QP solves) "
                      if any("work limit of" in m for m in limited) else
                      "or a longer --time-limit (the search ran out of time) "
                      if limited else "")
            dt, wider = float(widths["dt"]), f"{min(2 * float(widths['dt']), 1.0):.2g}"
            if noise:
                # a width given makes "auto" values linear: a log fit's hint keeps them log
                log = "--values log " if self.meta.get("values") == "log" else ""
                said = (f"no verified fit at the segments of each channel's noise level "
                        f"(y +- {dt:.3g} y or wider); wider ones ({log}--abs-width auto "
                        f"--dt {wider}) ")
            else:
                said = (f"no verified fit at the default segments (y +- {dt:.3g} y); "
                        f"wider ones (--dt {wider}) ")
            parts.append(said + out_of + "may give one")
        if self.table and not self.subset:
            parts.append(TABLE_SUBSET_HINT)
        elif self.table_defaults:
            parts.append(self._table_hint())
        return "hint: " + "; ".join(parts) if parts else None

    def _table_hint(self) -> str:
        """What may fit a MERL table where its defaults did not: more time or QP solves
        when the search was cut short, else more coefficients (a channel at ratfit's
        widths was already widened alone as far as they go)."""
        from ratfit.brdf.fitter import MAX_DEFAULT_DT

        failed = [r for r in self.results if not r.success]
        if any(r.time_limited for r in failed):
            return ("the search was cut short: a longer --time-limit or a larger "
                    "--work-limit may give one")
        o = self.request.options
        widened = (f", each such channel widened alone up to y +- {MAX_DEFAULT_DT:g} y"
                   if "widths" in self.table_defaults else "")
        size = (f"n = {o.n}, m = {o.m}" if o.n is not None else
                f"up to {o.max_total} coefficients" if o.max_total is not None else
                "the size searched")
        more = (f"--n {o.n + 40} --m {o.m + 40}" if o.n is not None and o.m is not None
                else "--max-total N")
        return (f"no verified fit at the table defaults ({size}{widened}): more "
                f"coefficients ({more}) or more cells (--max-points) may give one")


def _held_out_size_note(sizes: list[dict[str, Any] | None], names: list[str]) -> str:
    """Which channels a held-out score made larger than their searched size, and why
    the others kept it."""
    grown, kept = [], []
    for name, rec in zip(names, sizes, strict=True):
        if rec is None:
            continue
        searched, chosen = sum(rec["searched"]), sum(rec["chosen"])
        if rec["chosen"] != rec["searched"]:
            grown.append(f"{name} {searched} -> {chosen}")
        else:
            kept.append(f"{name} {searched} ({_why_smallest(rec)})")
    folds = next(int(r["folds"]) for r in sizes if r is not None)
    said = (f"size: {', '.join(grown)} coefficients, chosen by {folds}-fold held-out "
            "relative error" if grown else "size:")
    if kept:
        said += (f"{'; ' if grown else ' '}the smallest verified kept: {', '.join(kept)}")
    return said + "; --smallest-size keeps the fewest coefficients"


def _why_smallest(rec: Mapping[str, Any]) -> str:
    """Why a channel kept its searched size: no larger size scored lower held out, or
    those that did were not proved valid or rose above the samples near them (each size
    proved has an entry in ``local_excess``, None where the frame has no theta_h)."""
    from ratfit.brdf.fitter import GROWTH_MIN_GAIN, sizes_scored_better

    sizes = rec["sizes"]
    better = [str(sum(sizes[i])) for i in sizes_scored_better(rec["held_out_rel_rmse"])]
    if not better:
        return (f"no larger size had a {rec['folds']}-fold held-out relative error "
                f"{GROWTH_MIN_GAIN:.0%} lower")
    excess = rec.get("local_excess", {})
    risen = [f"{t}: {excess[t]:.3g}x" for t in better if excess.get(t) is not None]
    unproved = [t for t in better if t not in excess]
    why = []
    if risen:
        smallest = excess.get(str(sum(sizes[0])))
        why.append(f"{', '.join(risen)} the samples near it off the highlight, against "
                   f"{smallest:.3g}x")
    if unproved:
        why.append(f"{', '.join(unproved)} not proved valid")
    return "the larger sizes that scored lower: " + "; ".join(why)


def fit_brdf_file(request: BRDFFitRequest | str | Path) -> BRDFFitReport:
    """Fit a measured BRDF file as ``request`` says: what ``ratfit brdf fit`` does.

    The file is read once; each frame tried is a conversion of those samples,
    and each frame's default widths are resolved once. ``fit_brdf_file(path)``
    gives the fit of ``ratfit brdf fit path``, coefficient for coefficient
    (a Cornell file in a 3-D angle frame, not its 6-D Cartesian pairs).
    """
    from ratfit.brdf.fitter import (
        candidate_parametrizations,
        fit_brdf_auto,
        fitted_frame,
        is_table,
    )
    from ratfit.brdf.io import channel_names_of, read_brdf, samples_dataset
    from ratfit.io.fitfile import file_sha256, save_fit

    req = request if isinstance(request, BRDFFitRequest) else BRDFFitRequest(Path(request))
    clock = Clock()
    with clock.phase("read"):
        samples = read_brdf(req.input, fmt=req.format)
        digest = file_sha256(req.input)
    filled: tuple[str, ...] = ()
    if samples.meta.get("format") == "merl":
        # a full table: what the request leaves open, ratfit's table defaults fill
        req, filled = TABLE_DEFAULTS.apply(req)
    with clock.phase("frames"):
        def frame(name: str | None) -> Dataset:
            return samples_dataset(samples, name, channels=list(req.channels) or None,
                                   color=req.color, max_points=req.max_points,
                                   subset_by=req.subset_by)

        own_ds = frame(None)
        own, table = str(own_ds.meta.get("param_in")), is_table(own_ds)
        first = req.parametrization or ISOTROPIC_DEFAULT.get(own, own)
        o = req.options
        # No frame and no fixed size given: the half-vector frame first, then the angles.
        names = (first,) if req.parametrization or o.n is not None or o.total is not None \
            else candidate_parametrizations(first, cosine=req.cosine, table=table)
        datasets = [own_ds if name == own else frame(name) for name in names]
    with clock.phase("fit"):
        kw = {k: v for k, v in o.params().items() if k not in ("parametrization", "used_coords")}
        if "widths" in filled:
            # ratfit's widths: a channel with no verified fit is widened alone
            kw["widen_alone"] = True
        fitter, seg, meta = fit_brdf_auto(datasets, dt=req.dt, abs_width=req.abs_width,
                                          floor_rel=req.floor_rel, cosine=req.cosine,
                                          clamp=req.clamp,
                                          shared_denominator=req.shared_denominator, **kw)
    ds = fitted_frame(datasets, meta)
    report = BRDFFitReport(req, fitter.results_, seg, meta, digest, own, len(datasets),
                           subset=ds.meta.get("subset"), table=table,
                           input_channels=channel_names_of(samples, req.color),
                           table_defaults=filled)
    if req.holdout is not None:
        from ratfit.brdf.holdout import cross_validate

        with clock.phase("holdout"):
            report.holdout = cross_validate(datasets, req.holdout, dt=req.dt,
                                            abs_width=req.abs_width, floor_rel=req.floor_rel,
                                            cosine=req.cosine, clamp=req.clamp,
                                            shared_denominator=req.shared_denominator, **kw)
        meta["holdout"] = report.holdout.to_dict()
    if report.success:
        with clock.phase("metrics"):
            report.metrics = _metrics(report)
    if report.success and req.output is not None:
        with clock.phase("write"):
            save_fit(req.output, report.document())
        report.written = req.output
    elif report.verified_channels and req.output is not None and not req.shared_denominator:
        with clock.phase("write"):
            report.kept = _keep_verified(report, req.output)
    report.seconds = clock.seconds
    return report


def _keep_verified(report: BRDFFitReport, output: Path) -> Path | None:
    """Write the verified channels of a fit that did not all verify to a new file beside
    ``output`` (NAME.partial.json, NAME.partial-2.json, ...: never over a file that is
    there). None when ``output`` is not a file path (standard output, a stream)."""
    import os

    from ratfit._atomic import output_kind
    from ratfit.io.fitfile import save_fit

    if output_kind(output)[1] not in ("new", "file"):
        return None
    doc = report.document(report.verified_channels)
    output.parent.mkdir(parents=True, exist_ok=True)  # as every output's folder is made
    for k in range(1, 1000):
        path = _sibling(output, "partial" if k == 1 else f"partial-{k}")
        try:  # claimed before it is written: nothing there is ever replaced
            os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
        except FileExistsError:
            continue
        try:
            save_fit(path, doc)
        except BaseException:
            path.unlink(missing_ok=True)
            raise
        return path
    raise InputError(f"{_sibling(output, 'partial')} .. partial-999.json all exist; "
                     "remove some to keep the verified channels")


def _sibling(output: Path, tag: str) -> Path:
    """NAME.TAG.json beside ``output`` (NAME.json), as the path was given (a link's own
    folder, not its target's)."""
    stem = output.name[:-len(output.suffix)] if output.suffix else output.name
    return output.with_name(f"{stem}.{tag}.json")


@dataclass(frozen=True)
class BRDFMergeRequest:
    """What ``ratfit brdf merge`` asks for.

    Parameters
    ----------
    inputs : sequence of paths
        Two or more fit files of ``ratfit brdf fit`` of the same input, frame, value form,
        subset and domain, with no channel in two of them (a ``NAME.partial.json`` a fit
        kept, the other channels refitted alone).
    output : path, optional
        The merged fit file to write.
    """

    inputs: tuple[Path, ...]
    output: Path | None = None

    def __post_init__(self) -> None:
        fix = object.__setattr__
        if isinstance(self.inputs, (str, Path)) or not hasattr(self.inputs, "__iter__"):
            raise InputError(f"inputs must be a sequence of fit file paths, got "
                             f"{self.inputs!r}")
        fix(self, "inputs", tuple(as_path(p, "inputs") for p in self.inputs))
        if len(self.inputs) < 2:
            raise InputError("give two or more fit files to merge")
        fix(self, "output", as_path(self.output, "output", allow_none=True))


@dataclass
class BRDFMergeReport:
    """What a merge did: the sealed ``document`` (checked, each proof made again) and
    the path it was ``written`` to (None without an output)."""

    request: BRDFMergeRequest
    document: dict[str, Any]
    written: Path | None = None

    @property
    def channels(self) -> list[str]:
        return [str(c["name"]) for c in self.document["channels"]]


def merge_brdf_fits(request: BRDFMergeRequest) -> BRDFMergeReport:
    """What ``ratfit brdf merge`` does: the channels of BRDF fit files of the same data,
    fitted in separate runs, as one sealed document (:mod:`ratfit.brdf.merge`), written
    to the request's output when it has one. Each file is read and checked as
    ``load_fit`` checks it (its digest included) before anything is joined."""
    from ratfit.brdf.merge import merge_fit_documents
    from ratfit.io.fitfile import (
        DIGEST_KEY,
        content_digest,
        parse_fit,
        read_fit_document,
        save_fit,
    )

    docs = []
    for path in request.inputs:  # each read once
        doc = read_fit_document(path)
        parse_fit(doc, str(path), trust_edited=False)  # format, digest, coefficients
        docs.append(doc)
    doc = merge_fit_documents(docs, [str(p) for p in request.inputs])
    doc[DIGEST_KEY] = content_digest(doc)
    _check_merged(doc)
    report = BRDFMergeReport(request, doc)
    if request.output is not None:
        save_fit(request.output, doc)
        report.written = request.output
    return report


def _check_merged(doc: dict[str, Any]) -> None:
    """The merged document loads as a fit file and each n-D channel's stored proof holds
    for its stored coefficients (the proof is made again, as ``brdf eval`` makes it)."""
    from ratfit.brdf.validity import reprove_saved
    from ratfit.io.fitfile import parse_fit

    saved = parse_fit(doc, "merged fit")
    if saved.space.dim > 1 and reprove_saved(saved) is False:
        raise InputError("the merged channels' stored proofs do not hold for their "
                         "coefficients: not written")


def _metrics(report: BRDFFitReport) -> dict[str, dict[str, float]]:
    """Per-channel errors at the fitted samples (cos-weighted where theta_l is known)."""
    from ratfit.brdf.fitter import brdf_metrics, cos_theta_l

    seg = report.segments
    pred = np.stack([r.rational(seg.x) for r in report.results  # type: ignore[misc]
                     ], axis=1)
    pred = ratio_values(pred, str(report.meta.get("values", "linear")))
    cl = None
    if report.parametrization != UNKNOWN_PARAMETRIZATION:
        try:
            cl = cos_theta_l(seg.x, report.parametrization)
        except Exception:  # parametrizations without theta_l: no cos-weighted metric
            cl = None
    return brdf_metrics(pred, seg.center, cl, seg.names)


def _ladder_exhausted(candidates: list[dict[str, Any]]) -> str | None:
    """The hint when every frame tried was widened as far as the default widths go
    (:data:`~ratfit.brdf.fitter.MAX_DEFAULT_DT`) without a verified fit, by the ladder of
    the whole fit or channel by channel (None otherwise): wider segments cannot help."""
    from ratfit.brdf.fitter import MAX_DEFAULT_DT

    tried = [c for c in candidates if not c.get("skipped") and not c.get("narrowed_floor_from")]
    if not tried or any(c["verified"] or not c.get("unverified_dt") for c in tried):
        return None
    frames = list(dict.fromkeys(str(c["parametrization"]) for c in tried))
    # each frame's widest try: the narrowest width among its unverified channels
    widest = {f: max(min(c["unverified_dt"]) for c in tried if c["parametrization"] == f)
              for f in frames}
    if min(widest.values()) < MAX_DEFAULT_DT:
        return None
    return (f"no verified fit at any width ratfit tries, up to y +- {MAX_DEFAULT_DT:g} y, in "
            + " or ".join(frames) + ", so wider segments will not give one: the samples "
            "change faster than a rational within the search's size limit can follow "
            "(measured on RGL's tables: they vary with phi_d next to the mirror direction, "
            "where the half-vector frame's points nearly coincide, and hold patches of zeros "
            "near the horizon); a larger --max-total may")


def _candidate_note(c: dict[str, Any]) -> str:
    """One frame tried, in a few words."""
    if c.get("narrowed_floor_from"):
        got = (f"{c['coefficients']} coefficients" if c["verified"]
               else "no verified fit, not kept")
        return f"floor {c['floor']:g}: {got}"
    if c.get("widened_from"):
        got = (f"{c['coefficients']} coefficients" if c["verified"] else
               "no candidate either" if c.get("no_candidate") else "no verified fit")
        return (f"{c['parametrization']} widened from {c['widened_from']:.3g} "
                f"to {c['dt']:.3g}: {got}")
    if c.get("skipped"):
        return f"{c['parametrization']}: not tried, {c['skipped']}"
    if c["verified"]:
        return f"{c['parametrization']}: {c['coefficients']} coefficients"
    up = f" up to {c['searched_up_to']} per channel" if c["searched_up_to"] else ""
    if c.get("no_candidate"):
        return (f"{c['parametrization']} at {c['dt']:.3g}: no candidate{up} "
                "(every split infeasible)")
    return f"{c['parametrization']}: no verified fit{up}"


def _noise_note(widths: dict[str, Any], names: list[str]) -> str:
    """Segments at each channel's noise level estimated from the data (--abs-width auto)."""
    from ratfit.brdf.fitter import NOISE_NEAR, NOISE_QUANTILE

    dts = widths.get("channel_dt") or [widths["dt"]] * len(names)
    per = "; ".join(f"{n} +- {d:.3g} y, floor {w:.3g}"
                    for n, d, w in zip(names, dts, widths["abs_width"], strict=True))
    alone = ("each channel from the width its nearby samples need, widened alone while "
             "it had no candidate; " if widths.get("channel_dt") else "")
    return (f"segments: {per} (floor: each channel's noise level, half the "
            f"{100 * NOISE_QUANTILE:g}th percentile of the differences between samples "
            f"within {100 * NOISE_NEAR:g} % of each axis of each other; {alone}"
            f"{widths.get('merged') or 0} samples widened to a nearby sample's segment "
            "they did not overlap)")


def _widths_note(widths: dict[str, Any]) -> str:
    """The default segments, and why they are wider or narrower than the base ones."""
    from ratfit.brdf.fitter import DEFAULT_DT

    ladder = widths.get("widened_from") or []
    base = ladder[0] if ladder else widths["dt"]
    why = "" if base == DEFAULT_DT else (
        f", widened from {DEFAULT_DT:g}" + (f" to {base:.3g}" if ladder else "")
        + " so that samples measured at nearly the same point have overlapping segments")
    if ladder:
        why += ("; then to " + ", ".join(f"{w:.3g}" for w in [*ladder[1:], widths["dt"]])
                + ": at " + ", ".join(f"{w:.3g}" for w in ladder)
                + " every split the search tested was infeasible")
    if widths.get("narrowed_floor_from"):
        why += (f"; floor narrowed from {widths['narrowed_floor_from']:g}: the fit "
                "there was small and most samples lay under the floor")
    if widths.get("channel_dt"):
        why += ("; per channel " + " / ".join(f"{w:.3g}" for w in widths["channel_dt"])
                + ": a channel with no candidate was widened alone")
    if widths.get("merged"):
        why += (f"; {widths['merged']} samples widened to the hull of a nearby sample's "
                "segment that theirs did not overlap (one point measured twice)")
    floor = widths.get("abs_width")
    floor_text = (f"an absolute floor of {floor:g} (the noise level)" if floor is not None
                  else f"a floor of {widths['floor_rel']:g} x the channel's largest value")
    return (f"segments: y +- {widths['dt']:.3g} y with {floor_text} (default{why}; "
            "--dt, --abs-width, --floor-rel override)")
