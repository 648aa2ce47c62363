"""Rational BRDF fits (Pacanowski et al. 2012): segments from measured values,
one verified rational function per channel in a chosen parametrization.

Options the field uses, all applied before the segments are built:

- cosine weighting: fit f * cos(theta_l) instead of f (the product is bounded
  at grazing angles, where measured BRDFs blow up); evaluation divides it out;
- clamping: values below ``clamp`` are raised to it (measured zeros and noise
  would give zero-width or sign-flipped segments);
- relative segments [(1-dt) y, (1+dt) y] widened by an absolute floor
  ``abs_width`` (or ``floor_rel`` times the channel's largest value), each
  segment taking the larger of the two, so near-zero values stay fittable.

The fit file records the parametrization under the top-level key ``"brdf"``,
so :func:`load_brdf_fit` gives back a function of directions.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, Self

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ratfit.brdf.options import (
    BRDF_SOLVER,
    NOISE_FLOOR,
    UNKNOWN_PARAMETRIZATION,
    BRDFOptions,
)
from ratfit.brdf.parametrizations import (
    check_dirs,
    find_parametrization,
    fold_phi_d,
    get_parametrization,
    is_folded,
    reciprocal_order,
)
from ratfit.core.bases import PolynomialSpace
from ratfit.core.options import DEFAULT_MAX_TOTAL, DEFAULT_TIME_LIMIT
from ratfit.core.polish import bound_rows
from ratfit.core.qp import ArnoldiSystem
from ratfit.core.rational import RationalFunction, ratio_values
from ratfit.core.results import FitResult
from ratfit.core.segments import Segments
from ratfit.core.systems import AppendedRows, LazyRows, RowSystem, spread_indices
from ratfit.core.validation import check_width
from ratfit.core.verify import Verification, verify
from ratfit.core.work import WorkBudget
from ratfit.errors import FileFormatError, InputError
from ratfit.fitting.search import RationalFitter, SearchParts, SystemFactory
from ratfit.io.data import Dataset
from ratfit.io.fitfile import SavedFit, fit_document, load_fit, save_fit

if TYPE_CHECKING:  # scipy.spatial and scipy.sparse load when segments are reconciled
    from ratfit.brdf.consistency import Neighbours
    from ratfit.brdf.validity import Envelope

__all__ = ["AUTO_FLOOR", "BRDF_SOLVER", "DEFAULT_DT", "DEFAULT_FLOOR_REL", "BRDFFit",
           "BRDFFitter", "NOISE_NEAR", "NOISE_QUANTILE", "close_pairs", "is_auto_floor",
           "noise_floors", "log_floor_default", "scattered_log", "fitted_frame",
           "HALF_VECTOR", "HALF_VECTOR_FLOOR_REL", "candidate_parametrizations",
           "default_floor_rel", "brdf_metrics", "fit_coefficients", "widened_dt", "brdf_segments",
           "check_floor_rel", "cos_theta_l", "default_dt", "fit_brdf", "fit_brdf_auto",
           "alta_brdf_fit", "load_brdf_fit", "nonnegative_segments", "prepare_values",
           "resolve_values",
           "resolve_widths",
           "save_brdf_fit",
           "subset_status", "valid_grid"]

Array = NDArray[np.float64]
# (i, j) index pairs of samples closer than a fraction of each axis (close_pairs)
Pairs = tuple[NDArray[np.intp], NDArray[np.intp]]
#: An absolute floor: one number, one per channel, or "auto" (:func:`noise_floors`).
AbsWidth = float | str | Sequence[float] | Array | None
# Segments when neither the command nor the file gives any: 5 % of each value, the
# order of a gonioreflectometer's noise, widened where nearby samples need it, with a
# floor for near-zero values. For a table of every cell (MERL) the floor is the noise
# level NOISE_FLOOR (1e-3 1/sr, brdf/options.py), so relative accuracy holds through the
# whole dynamic range: a known Lambert + 2 GGX table comes back within 2 % median, 4 %
# at the 95th percentile (at 0.2 % of the peak: 112-683 % median, too bright). Scattered
# measurements keep a floor of 0.2 % of each channel's peak (0.1 % in the half-vector
# frame) for now: at the noise floor garnet_red's G and B have no candidate in the
# reciprocal frame below +-48 % and +-72 % (its reciprocal pairs differ 10x at 80
# degrees, its diffuse G/B vary 12-19 % between neighbours) and the default fit ran
# 15 min to exit 1 (2026-11-26); see docs/howto/brdf.md.
DEFAULT_DT = 0.05
DEFAULT_FLOOR_REL = 0.002
#: ``abs_width`` that asks for each channel's noise level estimated from the data
#: (:func:`noise_floors`): ``ratfit brdf fit --abs-width auto``.
AUTO_FLOOR = "auto"
#: :func:`noise_floors` reads the pairs of samples closer than this fraction of each
#: axis's span (a goniometer's repeated or nearly repeated directions) ...
NOISE_NEAR = 0.01
#: ... and takes this quantile of their half differences as a channel's noise level.
NOISE_QUANTILE = 0.9
# For tables, default_dt widens DEFAULT_DT to what this quantile of nearly coincident
# sample pairs needs to overlap (the pairs above it are widened one by one:
# brdf/consistency.py); a network-encoded RGL table differs 10x over phi_d at
# theta_h = 0, where every phi_d is the same pair of directions. Scattered data: all pairs.
CLOSE_PAIR_QUANTILE = 0.9
_NEEDS_THETA_L = ("full", "isotropic", "tv_tl")
# The half-vector frame, tried before an isotropic angle set when the user names no
# parametrization: a specular peak (theta_h = 0) and a retro-reflection peak
# (theta_d = 0) lie along its axes, so peaks cost few coefficients there (Cornell at
# the same segments: cayman 39 -> 25 coefficients, krylon_blue 128 -> 54, all five
# smaller); the retro files have no fit up to 100 in their own angles and one here.
HALF_VECTOR = "RUSIN_TH_TD_SYM"
# Its default floor for scattered data is half as wide: measured on the five Cornell
# materials against lambert+ggx / lambert+beckmann, it wins all three errors in 12 of 15
# channels at 0.1 % (5 of 15 at 0.2 %), with 7-34 coefficients per channel.
HALF_VECTOR_FLOOR_REL = 0.001
# Valid points of a grid of the coordinate box (faces included) that join the angle grid
# as validity rows: the proof covers the whole evaluated region, and the angle grid
# leaves the band next to the mirror direction (theta_h -> 0) nearly empty.
BOX_POINTS = 8000
# Pieces the validity proof may examine per polynomial while the search runs (the
# chosen fit's proof may examine 40 000): a short proof that finds a negative value
# rejects a candidate at once, one that runs out only defers to the final proof.
SEARCH_PROOF_BOXES = 4000
# A default fit this small (per channel, at most) whose floor covers most samples has
# accuracy to spare: its segments are absolute widths almost everywhere, as wide as
# the floor. The floor is then halved (at most FLOOR_REFINEMENTS times) while the fit
# stays verified and small (mystique: most of its values lie under 1e-3 1/sr).
SMALL_FIT_TOTAL = 12
FLOOR_REFINEMENTS = 2
# When no split of a default fit has any candidate (every QP infeasible: found out in
# seconds, nothing was cut short by the work or time limit), the default relative width is
# widened by WIDEN_FACTOR, at most up to MAX_DEFAULT_DT, and that parametrization
# fitted again. The dense retro files: gray-tape-dense has no candidate up to 100
# coefficients at 0.28 and 0.42 in the half-vector frame (a 100x retro peak within a
# few % of the theta_d span) and a verified fit at 0.63.
WIDEN_FACTOR = 1.5
MAX_DEFAULT_DT = 0.9
# A log fit at noise-level widths (no width and no size given) searches each channel up
# to NOISE_LOG_MAX_TOTAL coefficients; a channel with no candidate there, or whose
# candidates all fail the verifier, is widened alone as above. Measured 2026-11-27
# (Cornell, log values, noise floors): every channel of garnet_red, krylon_blue and
# acryl_blue fits in 36-71, while cayman's G needs 83-90 at
# +-12 % and its walk below that total (every split a QP of 90 columns whose candidates
# are repaired and proved) ran past 40 min; cayman and mystique did not finish in 25-50.
NOISE_LOG_MAX_TOTAL = 72
_HAS_HALF_VECTOR_ALTERNATIVE = ("ISOTROPIC_TV_TL_DPHI", "ISOTROPIC_TL_TV_PROJ_DPHI")
# A repair (a candidate that meets every segment but is negative or through a pole
# between the samples, polished under the validity rows) adds the points where the
# dense check still finds q <= 0 or r < 0 and polishes again, up to REPAIR_ROUNDS
# times (a round: 0.1-0.5 s at retro-3M-jaune-dense's 60-100 coefficients, where
# q's dips shrank from 1e-4 to 1e-9 of max|q| over the rounds and 12 of 26 repairs
# that succeeded needed more than 3 rounds, up to 9). Each round adds ROUND_POINTS of the
# check's bad points, and each rejected candidate SEARCH_POINTS to every later
# split's rows: spread over all of them, not the first ones in grid order (one
# corner of the domain).
REPAIR_ROUNDS = 10
ROUND_POINTS = 500
SEARCH_POINTS = 200
# The polish of a valid fit whose first answer is refuted tries the points a half and a
# quarter of the way to it, kept where no later round (the refuting points added) is: every
# linear row (segments, q > 0, ceiling, floor) holds on that whole line, q there is a
# mix of two positive-at-the-data denominators, and one proof costs about a tenth of a
# polish round. RGL's satin_rosaline G (113, 112): four refuted polish rounds, 82 of the
# fit's 160 s, for no polish at all.
BLEND_STEPS = (0.5, 0.25)
# Every part of a channel's fit is bounded by QP solves, not seconds, so that the same
# command gives the same fit on any load and with any --jobs: the search (its repairs
# included) by ``work_limit``; the polish after it and the final proof's repair by
# POLISH_WORK_SHARE of it; the search again with the full proof on every candidate
# (when the chosen fit was refuted) by RESEARCH_WORK_SHARE of it, like the second
# search of fitting.search (a quarter).
POLISH_WORK_SHARE = 0.25
RESEARCH_WORK_SHARE = 0.25
# The search again goes up to this many times the refuted fit's total (not to 100): it
# replaces a fit the short proofs accepted. Solves grow with n + m and with the validity
# rows every rejection adds: cayman's R searched again up to 100 galloped to (50, 50),
# where one split's active set reached 32 000 of 147 000 rows (minutes of DAQP a solve).
RESEARCH_TOTAL_FACTOR = 2
# the lower end of a log segment is at least this share of its channel's smallest upper
# end (a value of 0 is met as 1e-3 of the lowest floor: exp(p / q) cannot reach 0)
LOG_LOW = 1e-3
#: A fit of log values, exp(p / q), is proved to stay at most this many times the largest
#: upper end of its channel's segments everywhere it is evaluated (p / q <= C, C the log
#: of that bound). exp(p / q) is positive by construction but otherwise bounded by
#: nothing the samples say: default log fits of the Cornell files reached 1e71 (garnet_red
#: G), 7e135 (B) and overflowed to inf (acryl_blue) between their samples, at a data peak
#: of 30-740 1/sr.
LOG_CEILING_FACTOR = 2.0
#: A log fit under an envelope over theta_h and theta_d is held above its highlight's
#: floor too (:class:`~ratfit.brdf.validity.SampleFloor`): the lower end of each of those
#: samples divided by this, nearer the mirror direction and nearer grazing than it.
LOG_FLOOR_FACTOR = 2.0
# The search's and the polish's rows keep p / q this far (in log: 5 %) below the ceiling
# at their points, the check and the proof hold it to the ceiling itself: a least-squares
# fit that wants to rise past the box's samples (a lobe's grazing tail) otherwise touches
# the ceiling at the points, crosses it between them, and is refused round after round (a
# lambert+ggx lobe's log fit: no polish in 4 rounds).
CEILING_ROW_MARGIN = 0.05
#: Between scattered samples a log fit's only bound is that ceiling, its channel's
#: highlight: the default fits of the Cornell files rose to 28-1 681 1/sr off the
#: highlight (theta_h > 0.3, where no sample exceeds 0.06) at random pairs away from the
#: plane of incidence, the renders' fireflies. There the search's and the polish's rows
#: hold p / q under a local envelope instead: at each validity point of half-vector
#: elevation t, :data:`LOG_CEILING_FACTOR` times the largest upper end among the samples
#: with theta_h >= t - ENVELOPE_SLACK (radians), as far from the mirror direction or
#: farther (a lobe falls off away from it; retro-reflection and grazing peaks are samples
#: at large theta_h, so they raise the envelope where they lie). Over theta_h alone the
#: envelope at the mirror direction is the file's grazing peak at every incidence, and
#: three of the five Cornell fits rose 10-1000x above their 10-70 degree mirror samples
#: between them (cayman G 1 210 1/sr at 70 degrees, its sample 16; acryl_blue G 65 at 30
#: degrees, its samples below 0.1). Where the frame has theta_d too, the envelope takes
#: each sample's value less its growth from d + ENVELOPE_SLACK to its theta_d, at the
#: fastest rate toward grazing the samples show (a highlight grows toward grazing:
#: Fresnel and 1 / cos theta_d; :class:`~ratfit.brdf.validity.SampleCeiling`).
ENVELOPE_SLACK = 0.05
#: The proof holds each fit under the same envelope with twice the slack (both
#: :class:`~ratfit.brdf.validity.StepCeiling`): its pieces are proved against the
#: envelope's value at their far end in theta_h, so the rows' envelope, met at points up
#: to a slack apart, is proved wherever a piece spans at most one slack.
ENVELOPE_PROOF_SLACK = 2 * ENVELOPE_SLACK
#: The search finds the fewest coefficients that meet every segment; there the feasible
#: set is thin and the polish cannot move (acryl_blue's B at +-65 %: no inner band even at
#: 0.1 % of each width, diffuse fit / data 0.62). With :attr:`BRDFFitter.held_out_size`
#: the smallest fit is also polished at these multiples of its n and m (padded with
#: zeros: the same function, so a feasible start), each size scored by
#: :data:`GROWTH_FOLDS`-fold cross-validation of that polish, and the size with the
#: lowest held-out error is kept when it beats the smallest by :data:`GROWTH_MIN_GAIN`
#: and is proved valid like any fit. The samples held out all lie where the others were
#: measured (Cornell's in the plane of incidence): mystique's R at twice its size scored
#: 20 % better there but rose to 0.04-0.06 1/sr in a ring off that plane (its renders'
#: diffuse part: 0.001-0.007). A larger size is therefore kept only where,
#: off the highlight, it rises no further above the samples near it than the smallest
#: does (:func:`local_excess`): at twice its size garnet_red's G drew an arc across the
#: point-light render (0.05 1/sr where its samples are 0.002), and measures 11.8 there
#: against the smallest's 3.1.
GROWTH_FACTORS = (1.25, 1.5, 2.0)
#: Where a fit is compared with the samples near it: theta_h above this (rad), the
#: diffuse part of the issue's colour measure, at :data:`LOCAL_PAIRS` seeded random
#: direction pairs inside the fit's box, each against the largest of its
#: :data:`LOCAL_SAMPLES` nearest samples (coordinates scaled to the box), the
#: :data:`LOCAL_QUANTILE` quantile of the ratios.
OFF_HIGHLIGHT = 0.3
LOCAL_PAIRS = 100_000
LOCAL_SAMPLES = 8
LOCAL_QUANTILE = 0.999
#: A larger size's measure may exceed the smallest's by this factor, and is never
#: refused while it is at most :data:`LOCAL_EXCESS_FREE`: on a smooth lobe measured with
#: +-20 % scatter the larger sizes measure 1.35-1.45 where the smallest measures 1.10,
#: and acryl_blue's B at 1.5 times its size 2.34 where the smallest measures 1.63 (its
#: held-out error 0.27 against 2.97, its diffuse part 0.62x the data's at the smallest).
LOCAL_EXCESS_TOL = 1.25
LOCAL_EXCESS_FREE = 3.0
GROWTH_FOLDS = 5
GROWTH_MIN_GAIN = 0.02
GROWTH_PROOF_ROUNDS = 3
GROWTH_STEPS = 3


def cos_theta_l(coords: ArrayLike, param: str) -> Array:
    """cos(theta_l) of coordinates; refused where the parametrization does not fix theta_l."""
    p = get_parametrization(param)
    if p.invariant not in _NEEDS_THETA_L:
        raise InputError(
            f"{p.name} does not determine the light elevation theta_l, so cosine weighting is "
            "undefined there; use an isotropic or full parametrization"
        )
    L, _ = p.to_dirs(coords)
    return L[:, 2]


def prepare_values(ds: Dataset, *, cosine: bool = False, clamp: float | None = None) -> Array:
    """The values to fit (N, k): y, times cos(theta_l) if ``cosine``, raised to ``clamp``."""
    if ds.y is None:
        raise InputError(f"{ds.source} has no values to fit")
    y = np.array(ds.y, dtype=float)
    if cosine:
        y = y * cos_theta_l(ds.x, str(ds.meta.get("param_in")))[:, None]
    if clamp is not None:
        if not np.isfinite(clamp) or clamp < 0:
            raise InputError(f"clamp must be a finite number >= 0, got {clamp!r}")
        y = np.maximum(y, clamp)
    return y


def default_dt(x: ArrayLike, y: ArrayLike, floor: float | ArrayLike = NOISE_FLOOR,
               near: float = 0.01, quantile: float = 1.0,
               pairs: Pairs | None = None) -> float:
    """The relative width the defaults use: :data:`DEFAULT_DT`, widened where the data
    itself needs more. Two samples closer than ``near`` (a fraction of each axis's
    span) are, for a smooth function, the same point measured twice: their segments
    should overlap, so dt is at least 1.1 x the ``quantile`` (1: the largest) of
    |y_i - y_j| / (y_i + y_j) over such pairs (the absolute ``floor``, per channel or
    one for all, taken off), rounded up to a hundredth. Resampled slices (ALTA's EXR:
    nearest-neighbour jumps) get dt 0.22 this way; scattered goniometer data keeps 0.05.
    Below 1, the pairs beyond the quantile are
    :func:`~ratfit.brdf.consistency.consistent_segments`' to reconcile one by one.
    ``pairs``: :func:`close_pairs` of ``x`` at ``near``, when the caller has them.
    """
    ya = np.abs(np.asarray(y, dtype=float))
    if ya.ndim == 1:
        ya = ya[:, None]
    first, second = close_pairs(x, near) if pairs is None else pairs
    if not first.size:
        return DEFAULT_DT
    a, b = ya[first], ya[second]
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.maximum(np.abs(a - b) - 2 * np.asarray(floor, dtype=float), 0.0) / (a + b)
    need = np.where(np.isfinite(need), need, 0.0).max(axis=1)
    typical = float(np.quantile(need, quantile))
    # rounded up to a hundredth: a width a user can read and type
    return float(min(max(DEFAULT_DT, np.ceil(110.0 * typical) / 100.0), 0.9))


def close_pairs(x: ArrayLike, near: float) -> Pairs:
    """(i, j): each sample i whose nearest other sample j lies closer than ``near``, a
    fraction of each axis's span (for a smooth function, one point measured twice)."""
    from scipy.spatial import cKDTree

    xa = np.asarray(x, dtype=float)
    if xa.ndim == 1:
        xa = xa[:, None]
    none = np.zeros(0, dtype=np.intp)
    if xa.shape[0] < 2:
        return none, none
    lo, hi = xa.min(axis=0), xa.max(axis=0)
    t = (xa - lo) / np.where(hi > lo, hi - lo, 1.0)
    d, i = cKDTree(t).query(t, k=2, workers=-1)
    close = d[:, 1] < near
    return np.flatnonzero(close).astype(np.intp), i[close, 1].astype(np.intp)


def noise_floors(x: ArrayLike, y: ArrayLike, *, near: float = NOISE_NEAR,
                 quantile: float = NOISE_QUANTILE, least: float = NOISE_FLOOR,
                 pairs: Pairs | None = None) -> Array:
    """Each channel's absolute noise level (k,), estimated from the data.

    Two samples closer than ``near`` (a fraction of each axis's span) are one point
    measured twice, so half their difference is noise: the level is the ``quantile`` of
    those half differences, at least ``least`` (the level under which relative errors
    stop counting), and ``least`` where no two samples are that close. Cornell's
    garnet_red gives R/G/B 2.3e-3/1.5e-3/2.0e-3 1/sr, the order of its diffuse G and B
    values (median 3e-3), which a fixed 1e-3 floor asked to follow within 10 %.
    ``pairs``: :func:`close_pairs` of ``x`` at ``near``, when the caller has them.
    """
    ya = np.asarray(y, dtype=float)
    if ya.ndim == 1:
        ya = ya[:, None]
    first, second = close_pairs(x, near) if pairs is None else pairs
    if not first.size:
        return np.full(ya.shape[1], float(least))
    half = np.abs(ya[first] - ya[second]) / 2
    return np.maximum(np.quantile(half, quantile, axis=0), float(least))


def is_auto_floor(abs_width: Any) -> bool:
    """``abs_width`` asks for the noise level estimated from the data (:data:`AUTO_FLOOR`)."""
    return isinstance(abs_width, str) and abs_width.strip().lower() == AUTO_FLOOR


def default_floor_rel(param: str) -> float:
    """The default floor of scattered data in a parametrization, a fraction of each
    channel's peak: :data:`HALF_VECTOR_FLOOR_REL` in the half-vector frames,
    :data:`DEFAULT_FLOOR_REL` elsewhere (tables use :data:`NOISE_FLOOR`)."""
    p = find_parametrization(param)
    return HALF_VECTOR_FLOOR_REL if p is not None and p.name in (HALF_VECTOR, "RUSIN_TH_TD_PD") \
        else DEFAULT_FLOOR_REL


def is_table(ds: Dataset) -> bool:
    """A table of every cell (MERL): its default segments have the noise floor."""
    return str(ds.meta.get("format", "")).lower() == "merl"


def check_floor_rel(dt: float | None, abs_width: AbsWidth,
                    floor_rel: float | None) -> None:
    """Refuse a floor under no width: ``floor_rel`` alone makes every segment
    [y - f max, y + f max] with no relative part (``--floor-rel 1e-4`` gave segments
    of relative width ~0 at the peak: 177 s and no fit)."""
    if floor_rel is not None and dt is None and abs_width is None:
        raise InputError(
            f"--floor-rel {floor_rel:g} without --dt: a floor under no relative width "
            "makes every segment [y - f*max, y + f*max] (nearly 0 relative width at the "
            f"peak); give --dt too (e.g. --dt 0.05 --floor-rel {floor_rel:g}), or "
            "--abs-width for absolute segments")


def resolve_widths(ds: Dataset, dt: float | None, abs_width: AbsWidth,
                   floor_rel: float | None, *, cosine: bool = False,
                   clamp: float | None = None
                   ) -> tuple[float | None, AbsWidth, float | None, bool]:
    """(dt, abs_width, floor_rel, defaulted): the widths as given, or, when none is
    given and the file has no intervals of its own (``defaulted`` True),
    :func:`default_dt` with the absolute floor :data:`NOISE_FLOOR` for a table
    (:func:`is_table`), else with the parametrization's :func:`default_floor_rel`."""
    if dt is None and abs_width is None and floor_rel is None and (
            ds.lo is None or ds.hi is None):
        # resolved once per dataset and weighting: kept in its meta (a KD-tree pass)
        key = f"default_widths(cosine={bool(cosine)}, clamp={clamp!r})"
        if key not in ds.meta:
            y = prepare_values(ds, cosine=cosine, clamp=clamp)
            if is_table(ds):
                ds.meta[key] = (default_dt(ds.x, y, NOISE_FLOOR, quantile=CLOSE_PAIR_QUANTILE),
                                NOISE_FLOOR, None)
            else:
                floor = default_floor_rel(str(ds.meta.get("param_in", "UNKNOWN")))
                top = np.abs(y).max(axis=0)
                ds.meta[key] = (default_dt(ds.x, y, floor * top), None, floor)
        dt_default, absw, floor_rel = ds.meta[key]
        return dt_default, absw, floor_rel, True
    if isinstance(abs_width, str):
        if not is_auto_floor(abs_width):
            raise InputError(f"abs_width must be a number >= 0 or {AUTO_FLOOR!r} (each "
                             f"channel's noise level, from the data), got {abs_width!r}")
        # the estimate, kept in the dataset's meta like the defaults
        key = _auto_key(dt, cosine, clamp)
        if key not in ds.meta:
            y = prepare_values(ds, cosine=cosine, clamp=clamp)
            pairs = close_pairs(ds.x, NOISE_NEAR)  # one KD-tree pass for all of them
            floors = noise_floors(ds.x, y, pairs=pairs)
            # each channel's own need (fit_brdf starts each channel there); the
            # narrowest is the fit's dt
            starts = None if dt is not None else [
                default_dt(ds.x, y[:, j], floors[j], near=NOISE_NEAR,
                           quantile=close_pair_quantile(ds), pairs=pairs)
                for j in range(y.shape[1])]
            ds.meta[key] = (dt if starts is None else min(starts), floors, starts)
        dt, abs_width, _ = ds.meta[key]
    return dt, abs_width, floor_rel, False


def _auto_key(dt: float | None, cosine: bool, clamp: float | None) -> str:
    """The dataset meta key of ``abs_width="auto"``'s estimate (the "default_widths"
    prefix makes a subset of the samples estimate it afresh)."""
    return f"default_widths:auto(dt={dt!r}, cosine={bool(cosine)}, clamp={clamp!r})"


def brdf_segments(
    ds: Dataset,
    *,
    dt: float | None = None,
    abs_width: AbsWidth = None,
    floor_rel: float | None = None,
    cosine: bool = False,
    clamp: float | None = None,
) -> Segments:
    """Segments for a BRDF dataset; with several widths each segment takes the largest.

    ``floor_rel`` is an absolute half-width per channel: floor_rel x max |y_j|.
    Without any width the file's own intervals (ALTA #VS 1/2) are used, and
    without those the defaults of :func:`resolve_widths`.
    """
    dt, abs_width, floor_rel, _ = resolve_widths(ds, dt, abs_width, floor_rel,
                                                 cosine=cosine, clamp=clamp)
    if dt is None and abs_width is None and floor_rel is None:
        if cosine or clamp is not None:
            raise InputError("cosine weighting and clamping need --dt/--abs-width "
                             "segments, not the file's own intervals")
        return ds.segments()
    y = prepare_values(ds, cosine=cosine, clamp=clamp)
    floor_rel = check_width(floor_rel, "floor_rel")
    w = channel_floors(y, abs_width, floor_rel)
    return Segments.from_widths(ds.x, y, dt=dt, abs_width=w, names=ds.output_names)


def channel_floors(y: Array, abs_width: AbsWidth, floor_rel: float | None) -> Array | None:
    """Each channel's absolute floor: the larger of ``abs_width`` and ``floor_rel`` times
    the channel's largest |y| (None without either)."""
    if abs_width is None and floor_rel is None:
        return None
    w = np.zeros(y.shape[1])
    if isinstance(abs_width, (list, tuple, np.ndarray)):  # one per channel
        per = np.asarray(abs_width, dtype=float)
        if per.shape != w.shape or not np.all(np.isfinite(per) & (per >= 0)):
            raise InputError(f"abs_width per channel must be {w.size} finite numbers >= 0, "
                             f"got {list(np.ravel(per))}")
        w = np.maximum(w, per)
    elif abs_width is not None:
        w = np.maximum(w, check_width(abs_width, "abs_width") or 0.0)
    if floor_rel is not None:
        w = np.maximum(w, floor_rel * np.abs(y).max(axis=0))
    return w


def fit_brdf(ds: Dataset, *, dt: float | None = None, abs_width: AbsWidth = None,
             floor_rel: float | None = None, cosine: bool = False, clamp: float | None = None,
             positive_q: bool = False, consistent: bool | None = None,
             shared_denominator: bool = False, values: str = "auto",
             widen_alone: bool = False, **fitter_params: Any):
    """Fit every channel of a BRDF dataset; returns (fitter, segments, brdf_meta).

    ``abs_width="auto"``: each channel's floor is its noise level (:func:`noise_floors`),
    the segments are made consistent, and without ``dt`` each channel starts at the width
    its nearby samples need and is widened alone while it has no candidate.
    ``fitter_params`` go to :class:`ratfit.fitting.search.RationalFitter` (basis,
    index_set, max_total, n, m, jobs...). ``positive_q``: see
    :attr:`BRDFFitter.positive_q`. ``consistent``: samples within
    :data:`~ratfit.brdf.consistency.CONSISTENT_NEAR` of each other whose segments are
    disjoint get the hull of the two (:func:`~ratfit.brdf.consistency.consistent_segments`);
    None: when the widths are ratfit's defaults (segments a user gave are the user's).
    ``shared_denominator``: one q for every channel
    (:class:`ratfit.brdf.shared.SharedBRDFFitter`; ``max_total`` then bounds each
    numerator; no channel is widened alone). ``values="log"``: fit log values, so the fit
    is exp(p / q) (:data:`~ratfit.brdf.options.VALUES`; "auto": :func:`resolve_values`),
    with noise-level floors when no width is given (:func:`log_floor_default`).
    ``widen_alone``: the widths given are ratfit's (a MERL table's defaults), so a channel
    with no verified fit is widened alone as default widths are, at a given size too.
    ``brdf_meta`` is the ``"brdf"`` block of the fit file.
    """
    from ratfit.brdf.consistency import consistent_segments
    from ratfit.core.columns import constant_axes

    full = ds
    # a log fit's floor is each channel's noise level unless widths are given (as in
    # fit_brdf_auto, which passes them on resolved); noise floors alone ("auto", as
    # log_floor_default gives them) are ratfit's widths
    widths_given = _widths_given(dt, abs_width, floor_rel)
    abs_width = log_floor_default(ds, {"values": values, "dt": dt, "abs_width": abs_width,
                                       "floor_rel": floor_rel,
                                       "shared_denominator": shared_denominator})["abs_width"]
    check_floor_rel(dt, abs_width, floor_rel)
    # each channel's noise level from the data; a dt of ratfit's choice is then widened
    # channel by channel where a channel has no candidate, as a default one is
    noise = is_auto_floor(abs_width)
    dt_chosen = noise and dt is None
    dt, abs_width, floor_rel, default_widths = resolve_widths(
        ds, dt, abs_width, floor_rel, cosine=cosine, clamp=clamp)
    # each channel's own start (abs_width="auto" without a dt)
    own_starts = ds.meta[_auto_key(None, cosine, clamp)][2] if dt_chosen else None
    dropped = constant_axes(ds.x) if ds.n_points > 1 else np.arange(0)
    keep = np.setdiff1d(np.arange(ds.x.shape[1]), dropped)
    if dropped.size:
        if keep.size == 0:
            raise InputError(f"{ds.source}: every coordinate is constant: nothing to fit")
        # A constant coordinate carries no information (Cornell's L lies in one plane):
        # fit the others; the fit file records the dropped ones so evaluation ignores them.
        ds = replace(ds, x=ds.x[:, keep],
                     input_names=tuple(ds.input_names[i] for i in keep) if ds.input_names
                     else ())
    seg = nonnegative_segments(brdf_segments(full if cosine else ds, dt=dt,
                                             abs_width=abs_width, floor_rel=floor_rel,
                                             cosine=cosine, clamp=clamp))
    if cosine and dropped.size:
        seg = Segments(ds.x, seg.lo, seg.hi, seg.y, seg.names)
    starts: list[float] | None = None
    floors = channel_floors(seg.center, abs_width, floor_rel)
    if own_starts is not None and floors is not None and seg.n_channels > 1:
        # each channel from what its own noise needs
        seg, starts = _channel_widths(seg, floors, own_starts)
    merged = 0
    if consistent is None:  # ratfit's floors are noise levels: reconcile repeated points
        consistent = (default_widths and is_table(ds)) or noise
    # the samples consistent_segments reconciles: the same at every width tried below,
    # and at every width a default ladder tries (fit_brdf_auto's _widen)
    around = _neighbours(full, keep, seg.x) if consistent else None
    if around is not None:
        seg, merged = consistent_segments(seg, neighbours=around)
    known = find_parametrization(str(ds.meta.get("param_in", UNKNOWN_PARAMETRIZATION)))
    frame = UNKNOWN_PARAMETRIZATION if known is None else known.name
    # (the fitter's options check the word; a shared denominator refuses "log")
    values = resolve_values(values, ds, frame, shared_denominator, widths_given)
    if fitter_params.get("held_out_size") and (shared_denominator or values != "log"):
        form = ("p_c / q with a shared denominator: drop it" if shared_denominator
                else "the values themselves (p / q): drop it, or fit log values "
                     "(--values log)")
        raise InputError("held_out_size (--held-out-size) chooses the size of a fit of log "
                         f"values; this fit is of {form}")
    size_given = any(fitter_params.get(k) is not None for k in ("max_total", "n", "m", "total"))
    max_given = fitter_params.get("max_total") is not None
    fitter_params = {**fitter_params, "values": values}
    if dt_chosen and values == "log" and not size_given and not shared_denominator:
        # widths at the noise level, sized by ratfit: a channel that needs more than this
        # is widened alone (below) rather than searched for an hour
        fitter_params["max_total"] = NOISE_LOG_MAX_TOTAL
        if fitter_params.get("held_out_size") is None and not is_table(ds):
            # the size the samples held out prefer, not the smallest that meets them
            fitter_params["held_out_size"] = True
    if fitter_params.get("polish_error", "auto") == "auto":
        # relative errors mean something where small values have a noise-level floor
        fitter_params = {**fitter_params,
                         "polish_error": "relative" if abs_width is not None else "absolute"}
    used = None if not dropped.size else tuple(int(k) for k in keep)
    fitter: Any
    if shared_denominator:
        from ratfit.brdf.shared import SharedBRDFFitter

        fitter = SharedBRDFFitter(parametrization=frame, used_coords=used,
                                  positive_q=bool(positive_q), **fitter_params)
    else:
        # scattered measurements leave most pairs unsampled: a log fit keeps under the
        # samples' envelope there (a table's cells leave no such room)
        if fitter_params.get("envelope") is None:
            fitter_params["envelope"] = values == "log" and not is_table(ds)
        fitter = BRDFFitter(parametrization=frame, positive_q=bool(positive_q),
                            used_coords=used, **fitter_params)
    fitter.fit(seg)
    channel_dt = starts if starts is not None and len(set(starts)) > 1 else None
    # (one channel at default widths is widened with its frame: fit_brdf_auto's _widen)
    if (((default_widths and seg.n_channels > 1) or dt_chosen or widen_alone)
            and dt is not None and not max_given and not shared_denominator):
        # not under a size bound of the caller's (as in fit_brdf_auto's widening)
        seg, channel_dt = _widen_channels(fitter, seg, starts or dt, floors, around,
                                          failed_too=widen_alone)
        fitter.segments_ = seg
    sub = ds.meta.get("subset")
    if sub:
        # a subset fit is verified on that subset only: its status says so first,
        # and keeps what the search said (a time limit: "may not be minimal")
        note = subset_status(int(sub["points"]), int(sub["of"]))
        fitter.results_ = [replace(r, message=f"{note}; {r.message}") if r.success else r
                           for r in fitter.results_]
    meta = {
        "parametrization": str(ds.meta.get("param_in", "UNKNOWN")),
        "cosine_weighted": bool(cosine),
        "positive_q": bool(positive_q),
        "polish": bool(fitter.polish),
        "polish_error": str(fitter.polish_error) if fitter.polish else None,
        "clamp": clamp,
        "fold_phi_d": bool(ds.meta.get("fold_phi_d", False)),
        "param_out": ds.meta.get("param_out"),
        "channel_names": list(seg.names),
        "segments": {"dt": dt,
                     "abs_width": (None if abs_width is None else
                                   np.asarray(abs_width, dtype=float).tolist()),
                     "floor_rel": floor_rel,
                     "default": default_widths, "merged": merged,
                     # abs_width is each channel's noise level, estimated from the data
                     "noise_estimated": noise,
                     # per channel where a channel alone was widened (None: all at dt)
                     "channel_dt": channel_dt},
        # a fit of a random subset is verified on that subset only
        "verified_on": ("all samples" if not ds.meta.get("subset") else
                        f"a random subset of {ds.meta['subset']['points']} of "
                        f"{ds.meta['subset']['of']} samples"),
        "subset": ({"points": int(sub["points"]), "of": int(sub["of"]),
                    "by": str(sub.get("by", "samples"))} if sub else None),
        "dropped_coords": {str(int(i)): float(full.x[0, i]) for i in dropped},
        # what "verified" covered beyond the samples, per channel
        "validity": [_validity_line(v, pr) for v, pr in
                     zip(fitter.validity_, fitter.proofs_, strict=True)],
        # the proof of q > 0 and p >= 0 where the fit is evaluated, per channel
        "proof": [None if v is None else v.to_dict() for v in fitter.proofs_],
        # one q for every channel: each channel is stored as p_c / q with the same q
        "shared_denominator": bool(shared_denominator),
        # "log": each channel's value is exp(p / q) of its stored p and q
        "values": values,
        # the local ceiling the search and the polish kept at the validity points, and
        # the proof on the whole region with proof_slack (each channel's proof entry
        # holds its samples or steps)
        "envelope": _envelope_block(fitter.__dict__.get("_envelopes")),
    }
    sizes = fitter.__dict__.get("_sizes")
    if sizes:
        # per channel: the searched size, the sizes scored on held-out folds, the kept one
        meta["held_out_size"] = [sizes.get(j) for j in range(seg.n_channels)]
    if shared_denominator:
        meta["shared"] = _shared_block(fitter)
    return fitter, seg, meta


# The dataset meta key under which _neighbours keeps its answer (the "default_widths"
# prefix: a fold of the samples, brdf/holdout.py, finds its own).
_NEIGHBOURS_KEY = "default_widths:neighbours"


def _neighbours(full: Dataset, keep: ArrayLike, x: Array) -> Neighbours:
    """:func:`~ratfit.brdf.consistency.sample_neighbours` of ``x``, the coordinates
    ``keep`` of ``full``, kept in ``full``'s meta for the next fit of the same samples: a
    default ladder refits one dataset at each width it tries (RGL's spectralon, a full
    MERL table: 2.6 s of a 5.7 s try, 16 tries). Kept with the coordinate array itself,
    so a dataset with other samples and the same meta computes its own."""
    from ratfit.brdf.consistency import sample_neighbours

    axes = tuple(int(k) for k in np.ravel(keep))
    kept = full.meta.get(_NEIGHBOURS_KEY)
    if kept is not None and kept[0] is full.x and kept[1] == axes:
        return kept[2]
    around = sample_neighbours(x)
    full.meta[_NEIGHBOURS_KEY] = (full.x, axes, around)
    return around


def _shared_block(fitter: Any) -> dict[str, Any]:
    """The sizes of a shared-denominator fit, its coefficients with q counted once and
    as stored (q in every channel)."""
    res = fitter.results_
    return {"n": [int(r.n) for r in res], "m": int(res[0].m),
            "coefficients": fit_coefficients(fitter),
            "stored_coefficients": int(sum(r.n + r.m for r in res)),
            "proven_minimal": bool(fitter.result_.proven)}


def fit_coefficients(fitter: Any) -> int:
    """The numbers a fit is made of: sum(n + m) over its channels, with a shared
    denominator counted once (sum(n_c) + m)."""
    res = fitter.results_
    if getattr(fitter, "shared_denominator", False):
        return int(sum(r.n for r in res) + res[0].m)
    return int(sum(r.n + r.m for r in res))


def _validity_line(check: Any, proof: Any) -> str | None:
    """What the dense check and the proof said about a channel's fit, in one line."""
    parts = [x.summary() for x in (proof, check) if x is not None]
    return "; dense check: ".join(parts) if parts else None


def resolve_values(values: str, ds: Dataset, frame: str,
                   shared_denominator: bool = False, widths_given: bool = False) -> str:
    """The value form (:data:`~ratfit.brdf.options.VALUES`) a fit of ``ds`` in ``frame``
    uses: ``values`` itself unless it is "auto"; then "log" in :data:`HALF_VECTOR` for a
    full table of every cell (MERL, :func:`is_table`) and for scattered measurements with
    ratfit's widths (none given, or the noise floors alone: :func:`scattered_log`,
    :func:`log_floor_default`), else "linear".

    Measured on the known Lambert + two GGX MERL table (errors against its closed form
    at 1e5 random pairs, so away from the cells): in the half-vector frame log values
    take 44 coefficients a channel against 48-51, median / p95 relative error 1.5 /
    4.1 % against 1.4-2.0 / 3.9-4.3 %, 84 s against 346 s. In RUSIN_TH_TD_PD log values
    were no smaller (83-90 a channel after 11 min). On scattered measurements (Cornell,
    2026-11-27) log values with noise floors predict held-out samples better: 5-fold
    relative RMSE below the better analytic model's in 12 of 12 channels of garnet_red,
    krylon_blue, cayman and mystique, where the linear fit with a floor of 0.1 % of the
    peak is below it in 0 of 12; the diffuse colour within 10 % in 7 of 15 channels
    (linear: 2-3x too bright in garnet_red's G and B, 16-99x in cayman and mystique). A
    shared denominator fits p_c / q (linear)."""
    if values != "auto":
        return values
    if is_table(ds):
        return "log" if frame == HALF_VECTOR and not shared_denominator else "linear"
    return "log" if _auto_is_log(ds, values, shared_denominator, widths_given) else "linear"


def _widths_given(dt: float | None, abs_width: AbsWidth, floor_rel: float | None) -> bool:
    """A width of the caller's: noise floors alone ("auto") are ratfit's widths."""
    return (dt is not None or floor_rel is not None
            or (abs_width is not None and not is_auto_floor(abs_width)))


def scattered_log(ds: Dataset) -> bool:
    """``ds`` is scattered measurements (not a table, no intervals of its own) in
    :data:`HALF_VECTOR`, where ratfit fits light and view angles first (Cornell, ALTA's
    retro files): with no width given, "auto" fits their log values with each channel's
    noise level as its floor, in the half-vector frame and in the frames
    :func:`fit_brdf_auto` tries after it. Data in other frames (an EXR slice in STARK_2D,
    a ``--param`` of the caller's) keep linear values and the fraction of the peak: log
    values there are not measured."""
    return (not is_table(ds) and (ds.lo is None or ds.hi is None)
            and str(ds.meta.get("param_in", UNKNOWN_PARAMETRIZATION)) == HALF_VECTOR)


def _auto_is_log(ds: Dataset, values: str, shared_denominator: bool,
                 widths_given: bool) -> bool:
    """``values`` "auto" means log values for scattered measurements ``ds``: the rule
    :func:`resolve_values` applies to one frame and :func:`fit_brdf_auto` to every frame
    it tries (no shared denominator, ratfit's widths, :func:`scattered_log`)."""
    return (values == "auto" and not shared_denominator and not widths_given
            and scattered_log(ds))


def candidate_parametrizations(param: str, cosine: bool = False,
                               table: bool = False) -> tuple[str, ...]:
    """The parametrizations :func:`fit_brdf_auto` tries for data in ``param``, in
    order: the half-vector frame first for isotropic 3-D angle sets, else ``param``.
    ``cosine``: f cos(theta_l) is not reciprocal, so the half-vector frame is then
    RUSIN_TH_TD_PD (which fixes theta_l), not the symmetric :data:`HALF_VECTOR`.
    ``table``: a full MERL table (RUSIN_TH_TD_PD) is tried in :data:`HALF_VECTOR` first
    (the known MERL table: 44 coefficients a channel with log values in 84 s, against
    88-94 in RUSIN_TH_TD_PD in 487 s)."""
    p = find_parametrization(param)
    if p is not None and p.name in _HAS_HALF_VECTOR_ALTERNATIVE:
        return ("RUSIN_TH_TD_PD" if cosine else HALF_VECTOR, p.name)
    if p is not None and table and p.name == "RUSIN_TH_TD_PD" and not cosine:
        return (HALF_VECTOR, p.name)
    return (str(param),)


def _band(ds: Dataset, kw: dict[str, Any]) -> tuple[float, float]:
    """(dt, floor) a fit of ``ds`` with options ``kw`` uses: how wide its segments are
    (the floor: the absolute width, else the fraction of the peak a user gave)."""
    dt, absw, floor_rel, _ = resolve_widths(ds, kw.get("dt"), kw.get("abs_width"),
                                            kw.get("floor_rel"), cosine=bool(kw.get("cosine")),
                                            clamp=kw.get("clamp"))
    return _band_of(dt, absw, floor_rel)


def _band_of(dt: float | None, abs_width: AbsWidth,
             floor_rel: float | None) -> tuple[float, float]:
    """(dt, floor) of segments of these widths: the floor is the absolute width when
    there is one, else the fraction of the peak."""
    floor = np.max(abs_width) if abs_width is not None else floor_rel or 0.0
    return float(dt or 0.0), float(floor)


def fit_brdf_auto(datasets: list[Dataset], **kw: Any):
    """Fit the same measurements in each parametrization of ``datasets`` in turn;
    returns (fitter, seg, meta) of the best verified fit.

    Best: the narrower segments (default widths depend on the parametrization:
    :func:`default_dt`), then the fewest coefficients over
    all channels. After a verified fit, a parametrization whose segments would not
    be narrower is searched only up to that fit's largest channel total (it must be
    smaller to win), and one whose segments would be wider is not tried.
    ``meta["candidates"]`` records every parametrization; with no verified fit the
    last try's result is returned.

    With default widths (no width, no size and no ``max_total`` given) and no
    verified fit, each parametrization whose search had no candidate at all (every
    split infeasible, nothing cut short by the work or time limit: known in seconds) is fitted
    again at :func:`widened_dt` widths until a try has candidates (:func:`_widen`);
    of the verified ones the same rule keeps the best, and
    ``meta["segments"]["widened_from"]`` lists the widths that had none.
    """
    if not datasets:
        raise InputError("fit_brdf_auto needs at least one dataset")
    if _auto_is_log(datasets[0], kw.get("values", "auto"), bool(kw.get("shared_denominator")),
                    _widths_given(kw.get("dt"), kw.get("abs_width"), kw.get("floor_rel"))):
        # the value form is the measurements', not the frame's: a frame tried after the
        # half-vector one fits log values at noise floors too (p / q at those floors was
        # still searching cayman's own angles after 13 CPU min; log values: 113
        # coefficients in 3.7 min)
        kw = {**kw, "values": "log"}
    kw = log_floor_default(datasets[0], kw)
    tried: list[dict[str, Any]] = []
    last = best = None
    most: tuple | None = None  # the try with the most verified channels, while none has all
    for ds in datasets:
        name = str(ds.meta.get("param_in", "UNKNOWN"))
        opts = dict(kw)
        if best is not None and best[2]["parametrization"] == HALF_VECTOR:
            # reciprocal, mirror-symmetric and phi_d-free at the mirror by construction:
            # a fit in other coordinates is none of these, whatever its size
            tried.append({"parametrization": name, "verified": None, "coefficients": None,
                          "dt": None, "floor": None, "searched_up_to": None,
                          "skipped": f"{HALF_VECTOR} verified, and its fits are reciprocal "
                                     "by construction"})
            continue
        if best is not None:
            band = _band(ds, kw)  # before fitting: it may make the fit needless
            if band > best[3]:
                tried.append({"parametrization": name, "verified": None, "coefficients": None,
                              "dt": band[0], "floor": band[1], "searched_up_to": None,
                              "skipped": "its segments would be wider than the kept fit's"})
                continue
            if band == best[3]:
                cap = max(r.n + r.m for r in best[0].results_)
                opts["max_total"] = min(cap, int(kw.get("max_total") or cap))
        fitter, seg, meta = fit_brdf(ds, **opts)
        segs = meta["segments"]
        band = _band_of(segs["dt"], segs["abs_width"], segs["floor_rel"])
        # a channel widened alone (fit_brdf) went as far as the ladder would
        entry = _tried(fitter, meta, band, opts.get("max_total"),
                       no_candidate=_no_candidate(fitter)
                       and not meta["segments"].get("channel_dt"))
        tried.append(entry)
        last = (fitter, seg, meta)
        most = _more_verified(most, last)
        total = entry["coefficients"]
        if entry["verified"] and (best is None or (band, total) < (best[3], best[4])):
            best = (fitter, seg, meta, band, total)
    assert last is not None
    if best is None and _widths_defaulted(kw) and kw.get("max_total") is None:
        # no verified fit at the default widths: widen each parametrization whose
        # search had no candidate; the narrowest verified fit, then the smallest, is
        # kept (as above), and a ladder stops where it would only be wider than that
        # (orange-tape-dense: the half-vector frame verifies at 0.9, its own angles at
        # 0.84). Not under a size bound of the caller's: widening to meet it would
        # trade accuracy for a size the caller chose (mystique at --max-total 16 and
        # --max-points 300 was widened eight times).
        for ds in datasets:
            widened = _widen(ds, tried, kw, None if best is None else best[3])
            if widened is None:
                continue
            last = widened[:3]
            most = _more_verified(most, last)
            if widened[0].success_ and (best is None or (widened[3], widened[4])
                                        < (best[3], best[4])):
                best = widened
    if best is not None and _widths_defaulted(kw):
        best = _narrow_floor(best, datasets, tried, kw)
    # no try verified every channel: keep the one that verified the most (a channel
    # that verified in one frame is not discarded because another failed in a later one)
    fitter, seg, meta = (most or last) if best is None else best[:3]
    meta["candidates"] = tried
    return fitter, seg, meta


def fitted_frame(datasets: Sequence[Dataset], brdf_meta: dict[str, Any]) -> Dataset:
    """Of the frames :func:`fit_brdf_auto` was given, the one its fit is in (``brdf_meta``:
    the fit's ``"brdf"`` block)."""
    return next(d for d in datasets
                if str(d.meta.get("param_in", "UNKNOWN")) == brdf_meta["parametrization"])


def log_floor_default(ds: Dataset, kw: dict[str, Any]) -> dict[str, Any]:
    """``kw`` with ``abs_width="auto"`` when it asks for log values of scattered data
    (``values`` "log", or "auto", which is log there: :func:`resolve_values`) with
    ratfit's widths (no width given, no intervals in the file, not a table) and without
    a shared denominator.

    A log fit keeps relative accuracy through the whole dynamic range; a floor of a
    fraction of the peak, the linear fit's, asks for none below it. Each channel's noise
    level is the floor instead, as ``--abs-width auto`` sets it. Measured 2026-11-27 on
    garnet_red: 167 coefficients in 2.6 min, relative RMS at its samples R/G/B
    0.04 / 0.30 / 0.47, where a floor of 0.1 % of the peak gave 63 coefficients in 27 s
    and 0.39 / 0.59 / 0.59; its renders' relative image RMSE is 0.136 (window) and 0.121
    (point light) against 0.249 and 0.265 for lambert+ggx*2, which the old floor's log
    fit did not beat. A table keeps its absolute floor (:func:`resolve_widths`)."""
    values = kw.get("values", "auto")
    if (values not in ("log", "auto") or kw.get("shared_denominator")
            or any(kw.get(k) is not None for k in ("dt", "abs_width", "floor_rel"))
            or is_table(ds) or (ds.lo is not None and ds.hi is not None)
            or (values == "auto" and not scattered_log(ds))):
        return kw
    return {**kw, "abs_width": AUTO_FLOOR}


def _more_verified(kept: tuple | None, new: tuple) -> tuple:
    """Of two tries (fitter, seg, meta), the one with more verified channels (the
    earlier one on a tie: the preferred frame)."""
    def count(t: tuple) -> int:
        return sum(bool(r.success) for r in t[0].results_)

    return new if kept is None or count(new) > count(kept) else kept


def _widths_defaulted(kw: dict[str, Any]) -> bool:
    """No width and no size from the caller: the defaults are ratfit's to choose."""
    return all(kw.get(k) is None for k in ("dt", "abs_width", "floor_rel", "n", "m", "total"))


def _tried(fitter: RationalFitter, meta: dict[str, Any], band: tuple[float, float],
           searched_up_to: int | None, **extra: Any) -> dict[str, Any]:
    """One entry of ``meta["candidates"]``: a fit tried at segments ``band``
    (dt, floor); ``coefficients`` over all channels when verified; ``unverified_dt``: the
    width of each channel without a verified fit (a channel widened alone at its own)."""
    ok = bool(fitter.success_)
    widths = meta["segments"].get("channel_dt") or [band[0]] * len(fitter.results_)
    return {"parametrization": meta["parametrization"], "verified": ok,
            "coefficients": fit_coefficients(fitter) if ok else None,
            "dt": band[0], "floor": band[1], "searched_up_to": searched_up_to,
            "unverified_dt": [float(w) for w, r in zip(widths, fitter.results_, strict=True)
                              if not r.success],
            **extra}


def _no_candidate(fitter: RationalFitter) -> bool:
    """Every channel without a verified fit had no candidate at all: each split the
    search tested was infeasible (status 1) and the work or time limit cut nothing short.
    Widening the segments is then the only way to a fit, and a cheap one to try."""
    failed = [r for r in fitter.results_ if not r.success]
    return bool(failed) and all(r.status == 1 and not r.time_limited for r in failed)


def _widen_channels(fitter: BRDFFitter, seg: Segments, dt: float | Sequence[float],
                    floors: Array | None, around: Neighbours | None, *,
                    failed_too: bool = False) -> tuple[Segments, list[float] | None]:
    """Default widths: each channel whose search had no candidate at all (every split it
    tested infeasible, nothing cut short) is fitted again alone at :func:`widened_dt`
    widths until it has one, up to :data:`MAX_DEFAULT_DT` (under ratfit's size bound,
    :data:`NOISE_LOG_MAX_TOTAL`, also one whose candidates all failed the verifier:
    cayman's G at +-27 %); the channels that verified
    keep their fits and their width. Returns the segments (each widened channel's column
    replaced) and the width of each channel, or None when none was widened. ``floors``:
    each channel's absolute floor (from the noise level or the fraction of its peak).
    ``around``: the samples' :func:`~ratfit.brdf.consistency.sample_neighbours` when
    the segments are made consistent, else None. ``failed_too``: a channel whose
    candidates all failed is widened under any size (a MERL table's defaults, whose
    size is fixed: ilm_solo_m_68's R at +-22 % has a candidate whose q dips below 0
    inside the box, and verifies at the next width, +-33 %).

    Measured noise differs by channel: garnet_red's R verifies at 0.06 with a 1e-3 floor
    while its G and B (noise 12-19 % of their diffuse values) have no candidate up to
    100 coefficients there; widening all three refitted R at every step (13 min)."""
    from ratfit.brdf.consistency import consistent_segments

    starts = [float(v) for v in np.broadcast_to(np.asarray(dt, dtype=float), seg.n_channels)]
    widths = list(starts)
    # ratfit's size bound (a caller's turns widening off): within it, a channel whose
    # candidates all failed (status 2) is widened too, as the search would have gone on
    # to larger sizes without the bound
    params = fitter.get_params()
    cap, n, m = params.get("max_total"), params.get("n"), params.get("m")
    up_to = (f" up to {int(cap)} coefficients" if cap is not None else
             f" at n = {n}, m = {m}" if n is not None else "")
    lo, hi = seg.lo.copy(), seg.hi.copy()
    for j, res in enumerate(fitter.results_):
        d = widths[j]
        while (not res.success and not res.time_limited and d < MAX_DEFAULT_DT
               and (res.status == 1 or ((cap is not None or failed_too)
                                         and res.status == 2))):
            why = "no candidate" if res.status == 1 else "no verified fit"
            d = widened_dt(d)
            one = _one_channel(seg, j, d, floors)
            if around is not None:
                one, _ = consistent_segments(one, neighbours=around)
            alone = type(fitter)(**params).fit(one)
            res = replace(alone.results_[0],
                          message=f"{alone.results_[0].message}; segments widened to "
                                  f"+- {d:.3g} y for this channel alone ({why} at "
                                  f"{widths[j]:.3g}{up_to})")
            widths[j] = d
            fitter.results_[j] = res
            fitter.validity_[j] = alone.validity_[0]
            fitter.proofs_[j] = alone.proofs_[0]
            sized = alone.__dict__.get("_sizes", {})
            fitter.__dict__.setdefault("_sizes", {}).pop(j, None)
            if 0 in sized:
                fitter.__dict__["_sizes"][j] = sized[0]
            lo[:, j], hi[:, j] = one.lo[:, 0], one.hi[:, 0]
    if len(set(widths)) == 1 and widths == starts:
        return seg, None
    return Segments(seg.x, lo, hi, seg.y, seg.names), widths


def close_pair_quantile(ds: Dataset) -> float:
    """The share of nearly coincident pairs :func:`default_dt` makes overlap: all of them
    for scattered data, :data:`CLOSE_PAIR_QUANTILE` for a table (its other pairs are
    reconciled one by one)."""
    return CLOSE_PAIR_QUANTILE if is_table(ds) else 1.0


def _channel_widths(seg: Segments, floors: Array, widths: Sequence[float]
                    ) -> tuple[Segments, list[float]]:
    """Each channel at the width its own repeated points need over its noise ``floors``
    (``widths``: :func:`default_dt` per channel, from :func:`resolve_widths`); returns
    the segments and the widths. garnet_red's G needs 0.19 and B 0.57 over its noise
    where R needs 0.05: started at 0.05, its search ran 40 min without a verified fit."""
    widths = [float(d) for d in widths]
    lo, hi = seg.lo.copy(), seg.hi.copy()
    for j, d in enumerate(widths):
        one = _one_channel(seg, j, d, floors)
        lo[:, j], hi[:, j] = one.lo[:, 0], one.hi[:, 0]
    return Segments(seg.x, lo, hi, seg.y, seg.names), widths


def _one_channel(seg: Segments, j: int, dt: float, floors: Array | None) -> Segments:
    """Channel ``j``'s segments alone at width ``dt`` over its floor, lo raised to 0."""
    return nonnegative_segments(Segments.from_widths(
        seg.x, seg.center[:, j:j + 1], dt=dt,
        abs_width=None if floors is None else floors[j:j + 1], names=(seg.names[j],)))


def widened_dt(dt: float) -> float:
    """The next default width after ``dt`` had no candidate: :data:`WIDEN_FACTOR`
    times wider, rounded up to a hundredth, at most :data:`MAX_DEFAULT_DT`."""
    return float(min(np.ceil(100.0 * WIDEN_FACTOR * dt - 1e-9) / 100.0, MAX_DEFAULT_DT))


def _widen(ds: Dataset, tried: list[dict[str, Any]], kw: dict[str, Any],
           beat: tuple[float, float] | None = None) -> tuple | None:
    """No verified default fit, and the fit of ``ds`` had no candidate at all: refit
    it at :func:`widened_dt` widths while each try still has none (each such try
    takes seconds), up to :data:`MAX_DEFAULT_DT`, and only while its (dt, floor)
    stays at most ``beat`` (a verified fit's, which a wider one cannot win against).
    Returns (fitter, seg, meta, band, total) of the last try, or None when nothing
    was widened. Each try is recorded in ``tried`` with ``widened_from``."""
    name = str(ds.meta.get("param_in", "UNKNOWN"))
    first = next((c for c in tried if c["parametrization"] == name), None)
    if first is None or not first.get("no_candidate"):
        return None
    dt, floor = float(first["dt"]), float(first["floor"])
    out = None
    steps: list[float] = []
    while dt < MAX_DEFAULT_DT:
        steps.append(dt)
        new = widened_dt(dt)
        if beat is not None and (new, floor) > beat:
            break
        f2, seg2, meta2 = fit_brdf(ds, **{**kw, "dt": new, **_default_floor(ds, floor)})
        none = _no_candidate(f2)
        entry = _tried(f2, meta2, (new, floor), None, no_candidate=none, widened_from=dt)
        tried.append(entry)
        meta2["segments"]["default"] = True
        # every width that had no candidate, narrowest first
        meta2["segments"]["widened_from"] = list(steps)
        out = (f2, seg2, meta2, (new, floor), entry["coefficients"])
        if entry["verified"] or not none:
            break
        dt = new
    return out


def _default_floor(ds: Dataset, floor: float) -> dict[str, Any]:
    """The options of a default refit of ``ds`` at ``floor``: absolute and with
    consistent segments for a table, a fraction of the peak for scattered data."""
    table = is_table(ds)
    return {"abs_width" if table else "floor_rel": floor, "consistent": table}


def _floor_covers_most(seg: Segments, floor: float, relative: bool) -> bool:
    """More than half of some channel's samples lie under the floor (``relative``: a
    fraction of each channel's largest value, else absolute)."""
    top = np.max(np.abs(seg.center), axis=0) if relative else 1.0
    return bool(np.any(np.mean(np.abs(seg.center) < floor * top, axis=0) > 0.5))


def _narrow_floor(best: tuple, datasets: list[Dataset], tried: list[dict[str, Any]],
                  kw: dict[str, Any]) -> tuple:
    """The kept default fit, refitted with its floor halved while it is small
    (:data:`SMALL_FIT_TOTAL`) and its floor covers most samples: narrower segments,
    kept only when verified. Each refit is recorded in ``tried``."""
    for _ in range(FLOOR_REFINEMENTS):
        fitter, seg, meta, band, total = best
        ds = fitted_frame(datasets, meta)
        table = is_table(ds)
        if (max(r.n + r.m for r in fitter.results_) > SMALL_FIT_TOTAL
                or not band[1] or not _floor_covers_most(seg, band[1], not table)):
            break
        floor = band[1] / 2
        f2, seg2, meta2 = fit_brdf(ds, **{**kw, "dt": band[0], **_default_floor(ds, floor)})
        entry = _tried(f2, meta2, (band[0], floor), kw.get("max_total"),
                       narrowed_floor_from=band[1])
        tried.append(entry)
        if not entry["verified"]:
            break
        meta2["segments"]["default"] = True
        meta2["segments"]["narrowed_floor_from"] = float(meta["segments"].get(
            "narrowed_floor_from") or band[1])
        if meta["segments"].get("widened_from"):  # the dt kept came from a widening
            meta2["segments"]["widened_from"] = list(meta["segments"]["widened_from"])
        best = (f2, seg2, meta2, (band[0], floor), entry["coefficients"])
    return best


def subset_status(points: int, of: int) -> str:
    """The status of a fit verified on ``points`` of the ``of`` samples only."""
    return (f"verified on a subset of {points} of {of} samples only (--max-points); "
            f"not checked at the other {of - points}")


def log_segments(seg: Segments) -> Segments:
    """The segments of log values: [log lo, log hi], with lo raised to
    :data:`LOG_LOW` of the channel's smallest hi first (a value of 0 would put the lower
    end at minus infinity; exp(p / q) is never 0). A fit inside them is inside the value
    segments, and positive by construction. One raised end per channel keeps segments
    that share values sharing them: raised to 1e-3 of each one's own hi, [0, 4.3] and
    [0, 1.4e-3] (one point measured twice) became disjoint."""
    if np.any(~(seg.hi > 0)):
        i, j = (int(v) for v in np.argwhere(~(seg.hi > 0))[0])
        raise InputError(
            f"a fit of log values needs every segment's upper end above 0 (row {i}, "
            f"channel {seg.names[j]}: hi = {float(seg.hi[i, j])!r}); give the segments "
            "a floor (--abs-width)")
    lo = np.maximum(seg.lo, LOG_LOW * np.min(seg.hi, axis=0))  # > 0: hi > 0
    center = None if seg.y is None else np.log(np.clip(seg.y, lo, seg.hi))
    return Segments(seg.x, np.log(lo), np.log(seg.hi), center, seg.names)


def log_ceilings(seg: Segments) -> Array:
    """Each channel's C of a fit of log values (value segments ``seg``): the log of
    :data:`LOG_CEILING_FACTOR` times the channel's largest upper end."""
    top = np.nanmax(np.where(np.isfinite(seg.hi), seg.hi, np.nan), axis=0)
    return np.log(LOG_CEILING_FACTOR * np.asarray(top, dtype=float))


def theta_h_column(param: str, used_coords: Sequence[int] | None) -> int | None:
    """The column of theta_h among a fit's coordinates (``used_coords``: the frame's
    columns it keeps), or None where the frame has none."""
    return _coordinate_column(param, used_coords, "theta_h")


def theta_d_column(param: str, used_coords: Sequence[int] | None) -> int | None:
    """The column of theta_d among a fit's coordinates, or None (as :func:`theta_h_column`)."""
    return _coordinate_column(param, used_coords, "theta_d")


def _coordinate_column(param: str, used_coords: Sequence[int] | None,
                       name: str) -> int | None:
    p = find_parametrization(param)
    if p is None or name not in p.coords:
        return None
    col = p.coords.index(name)
    if used_coords is None:
        return col
    kept = list(used_coords)
    return kept.index(col) if col in kept else None


def _envelope_block(envelopes: Sequence[Envelope] | None) -> dict[str, Any] | None:
    """The fit file's summary of the envelopes a fit kept (None: none)."""
    if not envelopes:
        return None
    growth = getattr(envelopes[0], "growth", None)
    floored = getattr(envelopes[0], "floor", None) is not None
    return {"coordinate": "theta_h" if growth is None else "theta_h, theta_d",
            "slack": ENVELOPE_SLACK, "proof_slack": ENVELOPE_PROOF_SLACK,
            **({} if growth is None else {"growth": growth}),
            "factor": LOG_CEILING_FACTOR,
            **({"floor_factor": LOG_FLOOR_FACTOR} if floored else {}), "proved": True}


def nonnegative_segments(seg: Segments) -> Segments:
    """Segments with lo raised to 0: a BRDF value is never negative, so a fit that
    goes below 0 at a sample (allowed by a wide absolute floor) is not a fit."""
    if not np.any(seg.lo < 0):
        return seg
    if np.any(seg.hi <= 0):
        i, j = (int(v) for v in np.argwhere(seg.hi <= 0)[0])
        raise InputError(
            f"{int(np.sum(seg.hi <= 0))} segment(s) lie at or below 0 (first: row {i}, "
            f"channel {seg.names[j]}, hi = {float(seg.hi[i, j])!r}); a BRDF is non-negative: "
            "raise the values with --clamp 0 and give the segments a floor (--abs-width)"
        )
    return Segments(seg.x, np.maximum(seg.lo, 0.0), seg.hi, seg.y, seg.names)


class BRDFFitter(RationalFitter):
    """RationalFitter whose pole check covers the physically valid configurations only.

    The box of a BRDF parametrization holds coordinates that describe no pair
    of directions (e.g. theta_h = theta_d = 80 degrees puts V below the
    horizon; STARK_2D's hp^2 + b^2 > 1). A denominator that changes sign there
    can never be evaluated on a BRDF query (``BRDFFit.eval_dirs`` only sees
    valid pairs), so in n-D a candidate that :func:`ratfit.core.verify.verify`
    rejects *only* for a sign change of q on its box grid is re-checked: q
    must keep one strict sign on the data points and on the grid points of
    the box that are valid configurations (:func:`valid_grid`: directions
    above the horizon that convert back to the same coordinates). Segment
    violations, non-finite values and 1-D poles are never relaxed, and an
    unknown parametrization keeps the plain check.

    Parameters
    ----------
    parametrization : str, default "UNKNOWN"
        ALTA name of the input coordinates (``ratfit.brdf.parametrizations``);
        "UNKNOWN" keeps the plain pole check.
    positive_q : bool, default False
        Also constrain q > 0 at the valid grid points inside the QP (rows added
        by the active set only where violated), so that candidates whose q
        changes sign between sparse measurements are not produced at all.
    polish : bool, default True
        After the search, replace each channel's fit by the least-squares fit of
        the same (n, m) whose values stay inside the inner 96 % of every segment
        and whose q > 0, p >= 0 on the valid configurations
        (:func:`ratfit.core.polish.polish_fit`), when that fit verifies
        (segments and the physical check) and has the smaller RMSE. Same size,
        same guarantees, errors several times smaller than the search's
        minimum-norm fit, which runs along the segments' edges. Each channel's
        polish (with the final proof's repair) may spend a quarter of ``work_limit``
        in QP solves (:data:`POLISH_WORK_SHARE`), and a quarter of a ``time_limit``
        when one is given; when that runs out it keeps the search's fit, saying so
        in the message.
    polish_error : {"auto", "absolute", "relative"}, default "auto"
        What the polish minimises: the plain squared errors, or the squared errors
        relative to |y| + 1e-3 1/sr (:data:`~ratfit.brdf.options.NOISE_FLOOR`), so that
        a diffuse part far below the peak counts as much as the peak. "auto": relative
        when :func:`fit_brdf`'s segments have an absolute floor, else absolute (a fitter
        given segments directly: absolute).
    values : {"auto", "linear", "log"}, default "auto"
        What p / q fits: the values, or their logarithms (the fit is exp(p / q),
        proved q > 0; :data:`~ratfit.brdf.options.VALUES`). "auto" is "linear" for a
        fitter given segments directly; :func:`fit_brdf` decides it from the dataset
        (:func:`resolve_values`: log values for a full MERL table in the half-vector
        frame and for scattered measurements with ratfit's widths).
    envelope : bool or None, default None
        A fit of log values in a frame with theta_h: keep p / q under the samples'
        envelope too, over theta_h and theta_d where the frame has both
        (:class:`~ratfit.brdf.validity.SampleCeiling`), else over theta_h
        (:class:`~ratfit.brdf.validity.StepCeiling`), at the
        search's and the polish's points (:data:`ENVELOPE_SLACK`) and by the validity
        proof on the whole region (:data:`ENVELOPE_PROOF_SLACK`). None is off here;
        :func:`fit_brdf` turns it on for scattered measurements.
    held_out_size : bool or None, default None
        A fit of log values: after the search's smallest verified fit (and its polish),
        polish it at :data:`GROWTH_FACTORS` times its n and m as well, score each size by
        the held-out error of that polish over :data:`GROWTH_FOLDS` folds of the
        samples (the RMS of log((f + e) / (y + e)), e = 1e-3 1/sr), and keep the size
        with the lowest when it is lower than the smallest's by :data:`GROWTH_MIN_GAIN`,
        the fit of that size is proved valid, and off the highlight it rises no further
        above the samples near it than the smallest does (:func:`local_excess`; else the
        next best, then the smallest is kept). The
        minimal-size fit meets its segments along their edges; a larger one can follow
        the data within them. None is off here; :func:`fit_brdf` turns it on for
        scattered measurements at ratfit's widths and sizes.
    used_coords : tuple of int, optional
        The coordinates of the parametrization that the segments' x holds, in
        order (None: all); :func:`fit_brdf` drops constant ones (Cornell's
        light lies in one plane) and says which here.
    solver : str, default "daqp"
        As for RationalFitter, but DAQP (quadprog when DAQP is not installed).
    physical : bool, default True
        Constrain q > 0 and p >= 0 (so r >= 0) on a grid of direction pairs
        above the horizon inside the domain (:func:`ratfit.brdf.validity.configurations`),
        rows entering the active set only where violated; points where the
        verification's denser check still finds q <= 0 or r < 0 join that grid
        for every later split. Verification checks validity whatever this says.
    **params
        Every other :class:`~ratfit.fitting.search.RationalFitter` parameter.

    Attributes
    ----------
    results_, result_, rational_, success_, segments_, space_, options_
        As for :class:`~ratfit.fitting.search.RationalFitter` (``options_`` is a
        :class:`~ratfit.brdf.options.BRDFOptions`).

    Examples
    --------
    >>> from ratfit.brdf import BRDFFitter
    >>> BRDFFitter(parametrization="STARK_2D", positive_q=True, max_total=30)
    BRDFFitter(parametrization='STARK_2D', positive_q=True, max_total=30)
    """

    options_type = BRDFOptions
    # the chosen fit's full validity proof is running (the polish, the final check): for
    # every channel (a re-search's own fitter, a shared denominator's helper), or for
    # the channels in _final_channels (a set of this fit's, see _full_proof)
    _final_proof: bool = False
    _final_channels: frozenset[int] | set[int] = frozenset()
    # a channel searched again with the full proof on every candidate
    _full_search: bool = False
    # every channel's validity points in one list (a shared denominator's helper: one q)
    _pooled_points: bool = False

    def __init__(self, *, parametrization: str = UNKNOWN_PARAMETRIZATION,
                 positive_q: bool = False, physical: bool = True, polish: bool = True,
                 polish_error: str = "auto",
                 used_coords: tuple[int, ...] | None = None,
                 solver: str = BRDF_SOLVER, time_limit: float | None = DEFAULT_TIME_LIMIT,
                 values: str = "auto", envelope: bool | None = None,
                 held_out_size: bool | None = None, **params: Any) -> None:
        super().__init__(solver=solver, time_limit=time_limit, **params)
        self.values = values
        self.envelope = envelope
        self.held_out_size = held_out_size
        self.parametrization = parametrization
        self.positive_q = positive_q
        self.physical = physical
        self.polish = polish
        self.polish_error = polish_error
        self.used_coords = used_coords

    @property
    def value_form(self) -> str:
        """What p / q fits here, "linear" or "log": ``values`` with "auto" read as
        "linear" (a fitter given points alone cannot tell a full MERL table;
        :func:`fit_brdf` decides "auto" from the dataset, :func:`resolve_values`)."""
        return "log" if self.values == "log" else "linear"

    def _fit_segments(self, segments: Segments) -> Self:
        """Search every channel, then polish and prove it (``fit`` ends here)."""
        if self.value_form == "log" and not self._full_search:
            # the search, the polish and the proof work on log values; the value
            # segments stay for the last check of exp(p / q) itself
            self._value_segments = segments
            self._ceilings = log_ceilings(segments)
            self._envelopes, self._step_ceilings = self._theta_h_envelopes(segments)
            segments = log_segments(segments)
        if not self._full_search:
            self._points: dict[int, list[Array]] = {}
        self._checks: dict[int, Any] = {}
        self._polish_budgets: dict[int, WorkBudget] = {}
        self._final_channels: set[int] = set()
        super()._fit_segments(segments)
        # what the dense validity check and the proof said about each channel's chosen fit
        self.validity_ = [
            self._checks.get(id(r.rational)) if r.rational is not None else None
            for r in self.results_
        ]
        proofs = self.__dict__.get("_proofs", {})
        self.proofs_ = [proofs.get(id(r.rational)) if r.rational is not None else None
                        for r in self.results_]
        if self.value_form == "log" and not self._full_search:
            self.segments_ = self._value_segments
        return self

    def _finish_channel(self, res: FitResult, seg: Segments, j: int) -> FitResult:
        """Channel ``j``'s searched fit polished, proved and (log values) checked as
        values, in the channel's thread: its polish runs while other channels search.
        Nothing here reads another channel's state, so the answer is the same with
        channels side by side or in turn."""
        searched = res
        prove = self.physical and find_parametrization(self.parametrization) is not None
        if self.polish and res.success:
            # small matrices: one BLAS thread (the search's ``one_blas_thread`` holds);
            # the polish is checked with the full proof, as the chosen fit will be
            with self._full_proof(j, prove):
                res = self._polished(res, seg, j)
        if prove:
            res = self._proved_or_searched(res, searched, seg, j)
            if (not self._full_search and not res.success and searched.rational is not None
                    and searched.success):
                res = self._search_with_full_proof(res, seg, j)
        if (self.held_out_size and prove and self.value_form == "log"
                and not self._full_search and res.success):
            res = self._held_out_sized(res, seg, j)
        if self.value_form == "log" and not self._full_search and res.success:
            res = self._values_checked(res, j)
        return res

    def _held_out_sized(self, res: FitResult, seg: Segments, j: int) -> FitResult:
        """Channel ``j``'s proved fit ``res``, or the same fit polished at a larger size
        (:data:`GROWTH_FACTORS`) when that size has the lower held-out error over
        :data:`GROWTH_FOLDS` folds, is proved valid too, and stays as close to the
        samples near it off the highlight (:func:`local_excess`; see
        :attr:`held_out_size`). The held-out samples lie where the others were measured,
        so only that check sees what a larger size does between them.
        Each fold's polish starts from ``res`` (fitted to every sample, so the smallest
        size's own score is partly in-sample: the comparison leans towards keeping it).
        Counted in QP solves (a :data:`POLISH_WORK_SHARE` of ``work_limit``), so the
        choice does not depend on the machine's load."""
        from ratfit.core.polish import polish_fit

        rf = res.rational
        y = self._value_segments.y
        if rf is None or y is None or seg.n_points < 10 * GROWTH_FOLDS:
            return res
        rf = rf.to_family()
        y = np.clip(np.asarray(y[:, j], dtype=float), 0.0, None)
        fold = np.random.default_rng(0).permutation(seg.n_points) % GROWTH_FOLDS
        pts = self._validity_points(j, rf.space.domain)
        ceiling = self._row_ceiling(j, pts)
        floor = self._row_floor(j, pts)
        work = WorkBudget(self._polish_share())

        def step(fit: RationalFunction, target: Segments, w: Array) -> RationalFunction | None:
            if work.exhausted:
                return None
            return polish_fit(fit, target, 0, weights=w, positive_at=pts, solver=self.solver,
                              numerator=False, ceiling=ceiling, floor=floor, method="qp",
                              work=work)

        sizes = [(rf.n, rf.m)] + [(int(np.ceil(g * rf.n)), int(np.ceil(g * rf.m)))
                                  for g in GROWTH_FACTORS]
        near = self._local_reference(rf.space.domain, seg.x, y)
        excess0 = local_excess(rf, near)
        scores: list[float] = []
        for n, m in sizes:
            start = _padded(rf, n, m)
            sq = 0.0
            for k in range(GROWTH_FOLDS):
                train = fold != k
                part = Segments(seg.x[train], seg.lo[train, j:j + 1], seg.hi[train, j:j + 1],
                                None, (seg.names[j],))
                fit = _relative_steps(start, part, 0, y[train], step)[0]
                sq += _relative_sq(fit(seg.x[~train]), y[~train])
            scores.append(float(np.sqrt(sq / seg.n_points)))
        record: dict[str, Any] = {
            "searched": [rf.n, rf.m], "sizes": [list(v) for v in sizes],
            "held_out_rel_rmse": scores, "folds": GROWTH_FOLDS, "chosen": [rf.n, rf.m],
            "qp_solves": work.spent, "local_excess": {str(rf.n + rf.m): _finite(excess0)}}
        self.__dict__.setdefault("_sizes", {})[j] = record
        told = ", ".join(f"{n + m}: {e:.4g}" for (n, m), e in zip(sizes, scores, strict=True))
        # the sizes that beat the smallest, best first; the next is tried when one's
        # polish does not verify, is not proved, or rises above the samples near it
        better = sizes_scored_better(scores)
        why = []
        for i in better:
            n, m = sizes[i]
            grown = self._grown_and_proved(res, _padded(rf, n, m), seg, j, y,
                                           WorkBudget(work.limit))
            if isinstance(grown, str):
                why.append(f"{n + m}: {grown}")
                continue
            assert grown.rational is not None  # a proved fit
            excess = local_excess(grown.rational, near)
            record["local_excess"][str(n + m)] = _finite(excess)
            if (near is not None and np.isfinite(excess0)
                    and not excess <= max(LOCAL_EXCESS_TOL * excess0, LOCAL_EXCESS_FREE)):
                why.append(f"{n + m}: off the highlight {excess:.3g}x the samples near it "
                           f"(the smallest: {excess0:.3g}x)")
                continue
            record["chosen"] = [n, m]
            return replace(grown, message=f"{res.message}; polished at {n + m} "
                                          f"coefficients, the size with the lowest held-out "
                                          f"relative RMSE that is proved ({told}; "
                                          f"{GROWTH_FOLDS} folds)")
        tail = f"; {'; '.join(why)}" if why else ""
        return replace(res, message=f"{res.message}; the smallest size kept (held-out "
                                    f"relative RMSE by total: {told}{tail})")

    def _local_reference(self, domain: Array, x: Array, y: Array) -> LocalReference | None:
        """Seeded random direction pairs off the highlight inside ``domain`` (the fit's
        coordinates) and the largest value ``y`` of the samples ``x`` nearest each
        (:data:`OFF_HIGHLIGHT`); None where the frame has no theta_h or too few lie there."""
        from scipy.spatial import cKDTree

        p = find_parametrization(self.parametrization)
        col = theta_h_column(self.parametrization, self.used_coords)
        if p is None or col is None or len(x) < LOCAL_SAMPLES:
            return None
        rng = np.random.default_rng(0)
        L, V = (_hemisphere(rng, LOCAL_PAIRS) for _ in range(2))
        with np.errstate(all="ignore"):
            coords = p.from_dirs(L, V)
        if self.used_coords is not None:
            coords = coords[:, list(self.used_coords)]
        dom = np.asarray(domain, dtype=float).reshape(-1, 2)
        keep = (np.all(np.isfinite(coords), axis=1)
                & np.all((coords >= dom[:, 0]) & (coords <= dom[:, 1]), axis=1)
                & (coords[:, col] > OFF_HIGHLIGHT))
        pts = coords[keep]
        if len(pts) < 1000:
            return None
        span = np.where(dom[:, 1] > dom[:, 0], dom[:, 1] - dom[:, 0], 1.0)
        _, idx = cKDTree((np.asarray(x, float) - dom[:, 0]) / span).query(
            (pts - dom[:, 0]) / span, k=LOCAL_SAMPLES)
        return LocalReference(pts, np.asarray(y, float)[idx].max(axis=1))

    @contextlib.contextmanager
    def _full_proof(self, j: int, on: bool = True) -> Iterator[None]:
        """Channel ``j``'s candidates get the full validity proof inside the block
        (the polish and the final check); the other channels' searches keep theirs."""
        if not on:
            yield
            return
        assert isinstance(self._final_channels, set)  # made by _fit_segments
        self._final_channels.add(j)
        try:
            yield
        finally:
            self._final_channels.discard(j)

    def _ceiling(self, j: int) -> float | None:
        """Channel ``j``'s C (a fit of log values: p / q <= C is kept and proved on the
        evaluated region, :func:`log_ceilings`), else None."""
        if self.value_form != "log":
            return None
        return float(self._ceilings[j])

    def _row_ceiling(self, j: int, points: Array | None = None) -> float | Array | None:
        """The ceiling the search's and the polish's rows keep at their points:
        :data:`CEILING_ROW_MARGIN` under channel ``j``'s, so that a fit is not refused
        for crossing it between them; with :attr:`envelope`, under the lower of that
        and the channel's envelope (:data:`ENVELOPE_SLACK`) at each of ``points`` (one
        value each)."""
        top = self._ceiling(j)
        if top is None:
            return None
        env = self.__dict__.get("_envelopes")
        if points is None or env is None:
            return top - CEILING_ROW_MARGIN
        local = env[j].at_points(np.asarray(points, dtype=float))
        return np.minimum(local, top) - CEILING_ROW_MARGIN

    def _row_floor(self, j: int, points: Array | None) -> Array | None:
        """The floor the search's and the polish's rows keep at ``points``:
        :data:`CEILING_ROW_MARGIN` over channel ``j``'s envelope's floor, -inf where it
        sets none; None without a floor."""
        from ratfit.brdf.validity import FLOOR_LOG_MIN

        env = self.__dict__.get("_envelopes")
        floor = None if env is None else getattr(env[j], "floor", None)
        if points is None or floor is None:
            return None
        f = floor.at_points(np.asarray(points, dtype=float))
        return np.where(np.isfinite(f) & (f > FLOOR_LOG_MIN), f + CEILING_ROW_MARGIN, -np.inf)

    def _proof_envelope(self, j: int) -> Envelope | None:
        """The envelope channel ``j``'s proof holds (:data:`ENVELOPE_PROOF_SLACK`), or None."""
        steps = self.__dict__.get("_step_ceilings")
        return None if steps is None else steps[j]

    def _theta_h_envelopes(self, segments: Segments
                           ) -> tuple[list[Envelope] | None, list[Envelope] | None]:
        """Each channel's envelope of the value ``segments`` (:attr:`envelope`, a frame
        with theta_h) for the search's and polish's rows (:data:`ENVELOPE_SLACK`) and for
        the proof (:data:`ENVELOPE_PROOF_SLACK`): over theta_h and theta_d where the
        frame has both (:class:`~ratfit.brdf.validity.SampleCeiling`, growing toward
        grazing as fast as any of ``segments``' channels' highlight does
        (:func:`~ratfit.brdf.validity.theta_d_growth`), with the highlight's
        :class:`~ratfit.brdf.validity.SampleFloor`; both built once for the two), else
        over theta_h (:class:`~ratfit.brdf.validity.StepCeiling`); None without
        :attr:`envelope`."""
        from ratfit.brdf.validity import SampleCeiling, SampleFloor, StepCeiling, theta_d_growth

        col = theta_h_column(self.parametrization, self.used_coords)
        if not self.envelope or col is None:
            return None, None
        dcol = theta_d_column(self.parametrization, self.used_coords)
        slacks = (ENVELOPE_SLACK, ENVELOPE_PROOF_SLACK)
        if dcol is None:
            steps: list[list[Envelope]] = [[StepCeiling.of_samples(
                col, segments.x[:, col], segments.hi[:, j], slack, LOG_CEILING_FACTOR)
                for j in range(segments.n_channels)] for slack in slacks]
            return steps[0], steps[1]
        th, td = segments.x[:, col], segments.x[:, dcol]
        growth = theta_d_growth(th, td, segments.hi)
        rows: list[Envelope] = []
        proof: list[Envelope] = []
        for j in range(segments.n_channels):
            floor = SampleFloor.of_samples(col, dcol, th, td, segments.lo[:, j],
                                           segments.hi[:, j], LOG_FLOOR_FACTOR)
            ceiling = SampleCeiling.of_samples(col, dcol, th, td, segments.hi[:, j],
                                               ENVELOPE_SLACK, LOG_CEILING_FACTOR, growth,
                                               floor=floor)
            rows.append(ceiling)
            proof.append(replace(ceiling, slack=ENVELOPE_PROOF_SLACK))
        return rows, proof

    def _values_checked(self, res: FitResult, j: int) -> FitResult:
        """A verified fit of log values checked as its values: exp(p / q), as every
        evaluator computes it, inside every value segment (the log segments' check
        leaves exp's rounding), with the errors the result reports those of the values."""
        rf, old = res.rational, res.verification
        assert rf is not None and old is not None
        ver = verify(rf, self._value_segments, channel=j, box_check=False, values="log")
        if ver.n_violations == 0 and np.isfinite(ver.linf):
            return replace(res, verification=replace(
                ver, verified=True, poles_in_domain=old.poles_in_domain,
                pole_locations=old.pole_locations,
                denominator_sign_changes=old.denominator_sign_changes))
        return replace(res, success=False, status=2,
                       verification=replace(ver, verified=False),
                       message=f"{res.message}; rejected: exp(p/q) misses "
                               f"{ver.n_violations} value segment(s) by up to "
                               f"{ver.max_violation:.3g}")

    def predict(self, X: ArrayLike) -> Array:
        """As :meth:`RationalFitter.predict`; for a fit of log values, exp(p / q)."""
        return ratio_values(super().predict(X), self.value_form)

    def _search_with_full_proof(self, res: FitResult, seg: Segments, j: int) -> FitResult:
        """Channel ``j`` searched again with the full proof on every candidate, when the
        fit the short proofs let through was refuted at the end (slower, and rare).

        The search again gets :data:`RESEARCH_WORK_SHARE` of the work limit (and of a
        time limit, when one is given) and goes up to :data:`RESEARCH_TOTAL_FACTOR`
        times the refuted fit's total, all of its parts counted as in any search:
        each candidate's full proof may reject it, and each rejection adds validity
        rows to every later split (cayman's R without a bound: 817 s, 97 % of the fit).
        """
        params = self.get_params()
        if params["n"] is None and params["total"] is None:
            hi = int(params["max_total"] or DEFAULT_MAX_TOTAL)
            params["max_total"] = max(min(hi, RESEARCH_TOTAL_FACTOR * (res.n + res.m)),
                                      int(params["min_total"]))
        for key, share in (("work_limit", RESEARCH_WORK_SHARE),
                           ("time_limit", RESEARCH_WORK_SHARE)):
            if params.get(key) is not None:
                params[key] = max(1, int(params[key] * share)) if key == "work_limit" \
                    else float(params[key]) * share
        again = type(self)(**params)
        again._full_search = True
        again._final_proof = True
        again._points = {0: list(self._points_of(j))}
        if self.value_form == "log":  # ``seg`` holds the log values already
            again._value_segments = self._value_segments.channel(j)
            again._ceilings = self._ceilings[j:j + 1]
            env = self.__dict__.get("_envelopes")
            again._envelopes = None if env is None else env[j:j + 1]
            steps = self.__dict__.get("_step_ceilings")
            again._step_ceilings = None if steps is None else steps[j:j + 1]
        again._fit_segments(seg.channel(j))
        out = again.results_[0]
        if not out.success:
            return replace(res, time_limited=res.time_limited or out.time_limited,
                           message=f"{res.message}; searched again with the full validity "
                                   f"proof on every candidate: {out.message}")
        self.__dict__.setdefault("_proofs", {}).update(again.__dict__.get("_proofs", {}))
        self._checks.update(again._checks)
        return replace(out, message=f"{out.message}; searched again with the full validity "
                                    "proof on every candidate")

    def _proved_or_searched(self, res: FitResult, searched: FitResult, seg: Segments,
                            j: int) -> FitResult:
        """The polished fit if it is proved, else the search's own fit if that is."""
        if not res.success:
            return res
        out = self._proved(res, seg, j)
        if out.success or searched is res or not searched.success:
            return out
        back = self._proved(searched, seg, j)
        if not back.success:
            return out
        return replace(back, message=f"{back.message}; the least-squares polish was not "
                                     "proved valid: the search's fit is kept")

    def _proved(self, res: FitResult, seg: Segments, j: int) -> FitResult:
        """``res`` with its rational in the space's own family (the coefficients a fit file
        stores and every evaluator uses), verified again at every sample and proved valid
        (q > 0, p >= 0) on the evaluated region: the proof is about exactly those numbers.
        A fit that fails either is no success."""
        from ratfit.brdf.validity import prove_validity

        rf = res.rational
        assert rf is not None
        with self._full_proof(j):
            for attempt in range(2):
                fam = rf.to_family()
                ver = verify(fam, seg, channel=j, box_check=False)
                proof = prove_validity(fam, self.parametrization, keep=self.used_coords,
                                       values=self.value_form, ceiling=self._ceiling(j),
                                       envelope=self._proof_envelope(j))
                self.__dict__.setdefault("_proofs", {})[id(fam)] = proof
                self._checks[id(fam)] = self._checks.get(id(rf))
                if ver.n_violations == 0 and np.isfinite(ver.linf) and proof.proved:
                    return replace(res, rational=fam,
                                   verification=replace(ver, verified=True))
                if attempt or not len(proof.bad_points):
                    break
                # the repair of the search, now with the full proof as the check
                self._points_of(j).append(_spread(self._around(proof, fam, j), SEARCH_POINTS))
                out = self._polish_rounds(rf, seg, j, None, rounds=REPAIR_ROUNDS,
                                          method="qp", repair=True,
                                          work=self._polish_work(j))
                if out is None:
                    break
                rf = out[0]
        why = ("misses a segment in its stored form" if ver.n_violations
               or not np.isfinite(ver.linf) else f"validity {proof.summary()}")
        return replace(res, success=False, status=2, rational=fam,
                       verification=replace(ver, verified=False),
                       message=f"{res.message}; rejected: {why}")

    def _points_of(self, j: int) -> list[Array]:
        """Validity points where channel ``j``'s candidates had q <= 0 or r < 0: its later
        splits, its polish and its final repair keep q > 0, p >= 0 there. Each channel
        keeps its own, whether the channels run in turn or side by side, so a channel's
        answer does not depend on which channels were fitted with it. Carried from
        channel to channel (in turn), garnet_red's R points had made its G splits
        systems of 10 000+ rows whose LP checks took seconds each."""
        key = 0 if self._pooled_points else j
        return self.__dict__.setdefault("_points", {}).setdefault(key, [])

    def _configurations(self, domain: Array) -> Array | None:
        """The physical-validity grid of direction pairs in ``domain`` (cached)."""
        from ratfit.brdf.validity import configurations

        key = (str(self.parametrization), np.asarray(domain, float).tobytes())
        cache = getattr(self, "_conf_cache", None)
        if cache is None or cache[0] != key:
            cache = self._conf_cache = (key, configurations(
                self.parametrization, domain, keep=self.used_coords,
                box_points=BOX_POINTS))
        return cache[1]

    def _grown_and_proved(self, res: FitResult, start: RationalFunction, seg: Segments,
                          j: int, y: Array, work: WorkBudget) -> FitResult | str:
        """The relative-error polish of ``start`` (a larger size of ``res``'s fit, ``y``
        the channel's values) proved valid, or why not. Where the proof finds q <= 0 or a
        value over the ceiling between the validity points, those points join the
        polish's rows and it runs again (up to :data:`GROWTH_PROOF_ROUNDS` times): the
        least-squares fit leans on its rows."""
        why = "its polish did not verify"
        checked: dict[int, Verification] = {}

        def step(fit: RationalFunction, target: Segments, w: Array) -> RationalFunction | None:
            out = self._polish_rounds(fit, target, j, None, weights=w, work=work)
            if out is None:
                return None
            checked[id(out[0])] = out[1]
            return out[0]

        for _ in range(GROWTH_PROOF_ROUNDS):
            fit, moved = _relative_steps(start, seg, j, y, step)
            if not moved:
                return why
            grown = self._proved(replace(res, n=start.n, m=start.m, rational=fit,
                                         verification=checked[id(fit)]), seg, j)
            if grown.success:
                return grown
            why = "not proved valid"  # (_proved added the points where it failed)
        return why

    def _polish_rounds(self, rf: RationalFunction, seg: Segments, j: int,
                       deadline: float | None, rounds: int = 4, method: str = "auto",
                       repair: bool = False, work: WorkBudget | None = None,
                       weights: Array | None = None, start_valid: bool = False
                       ) -> tuple[RationalFunction, Verification] | None:
        """The least-squares polish of ``rf`` that passes :meth:`_verify`, or None
        (also once ``work``, the QP solves it may spend, is exhausted, or once
        ``deadline``, a ``time.perf_counter()`` value, has passed).

        Where the dense validity check still finds q <= 0 or r < 0, those points
        join the polish's constraints and it runs again (constraint generation).
        ``repair``: :func:`~ratfit.core.polish.polish_fit`'s repair mode (a valid fit is
        the point; the chosen fit is polished in full after the search). ``weights``:
        each sample's weight (default :meth:`_polish_weights`). ``start_valid``: ``rf``
        verified; when the first polish is refuted, the fits part of the way to it
        (:data:`BLEND_STEPS`, :func:`_blend`) are verified, and the first that passes is
        kept for the end, where no later round verifies (accepted at once, it had cost
        the relative polish of a glossy lobe its later, full rounds: the 90th percentile
        of |log(fit/data)| over diffuse pairs 0.17 -> 0.22).
        """
        from ratfit.core.polish import polish_fit

        pts = self._validity_points(j, rf.space.domain) if self.physical else None
        kept: tuple[RationalFunction, Verification] | None = None  # a blend, as a last resort
        for _ in range(rounds):
            if _past(deadline) or (work is not None and work.exhausted):
                return kept
            cand = polish_fit(rf, seg, j, weights=(self._polish_weights(seg, j)
                                                   if weights is None else weights),
                              positive_at=pts, solver=self.solver,
                              numerator=self.value_form == "linear",
                              ceiling=self._row_ceiling(j, pts),
                              floor=self._row_floor(j, pts), deadline=deadline,
                              method=method,
                              repair=repair, work=work)
            if cand is None:
                return kept
            ver = self._verify(cand, seg, j)
            if ver.verified:
                return cand, ver
            chk = self._checks.get(id(cand))
            if start_valid:
                start_valid = False  # after the first round only
                for step in BLEND_STEPS:
                    mix = _blend(rf, cand, seg.x, step)
                    if mix is None:
                        break
                    mix_ver = self._verify(mix, seg, j)
                    if mix_ver.verified:
                        kept = mix, mix_ver
                        break
            if chk is None or not len(chk.bad_points) or pts is None:
                return kept
            pts = np.concatenate([pts, _spread(chk.bad_points, ROUND_POINTS)])
        return kept

    def _polish_weights(self, seg: Segments, j: int) -> Array | None:
        """Each sample's weight in the polish: 1/(|y| + NOISE_FLOOR) for the relative
        error, None (all 1) for the absolute one."""
        if self.polish_error != "relative" or self.value_form == "log":
            return None  # (an error of log values is a relative error already)
        return 1.0 / (np.abs(seg.center[:, j]) + NOISE_FLOOR)

    def _polish_deadline(self) -> float | None:
        """Under a user's ``time_limit``, a polish (or a repair) may take a quarter of
        it: it improves a fit already found, so it must not hold a time-limited run.
        None (no clock) by default: :meth:`_polish_work` bounds it."""
        if self.time_limit is None:
            return None
        return time.perf_counter() + 0.25 * float(self.time_limit)

    def _polish_work(self, j: int) -> WorkBudget:
        """Channel ``j``'s budget for the polish after the search and the final
        proof's repair: :data:`POLISH_WORK_SHARE` of ``work_limit`` QP solves, shared
        by both (no limit without a work limit)."""
        budgets = self.__dict__.setdefault("_polish_budgets", {})
        if j not in budgets:
            budgets[j] = WorkBudget(self._polish_share())
        return budgets[j]

    def _polish_share(self) -> int | None:
        """:data:`POLISH_WORK_SHARE` of ``work_limit`` QP solves (None: no limit), the
        budget of a polish and of each part of :meth:`_held_out_sized`."""
        limit = self.work_limit
        return None if limit is None else max(1, int(limit * POLISH_WORK_SHARE))

    def _around(self, proof: Any, rf: RationalFunction, j: int) -> Array:
        """Where ``proof`` failed, as rows: its points, and where it found q <= 0 or a
        bound broken (a pocket between the grid's points), every point of a fine grid
        around them where ``rf`` breaks it too (:func:`ratfit.brdf.validity.dips_around`)."""
        from ratfit.brdf.validity import dips_around

        if not proof.refuted or not len(proof.bad_points):
            return proof.bad_points
        return dips_around(rf, proof.bad_points, self.parametrization, self.used_coords,
                           values=self.value_form, ceiling=self._ceiling(j),
                           envelope=self._proof_envelope(j))

    def _validity_points(self, j: int, domain: Array) -> Array | None:
        """The validity grid of ``domain`` and the points channel ``j``'s candidates
        failed at (:meth:`_points_of`): where a polish keeps q > 0 and the ceiling."""
        pts = self._configurations(domain)
        if pts is not None and self._points_of(j):
            pts = np.concatenate([pts, *self._points_of(j)])
        return pts

    def _repair(self, rf: RationalFunction, seg: Segments, j: int,
                work: WorkBudget | None = None
                ) -> tuple[RationalFunction, Verification] | None:
        """A candidate that meets every segment but goes negative or through a pole
        between the samples: its least-squares polish under the validity rows is
        often valid at the same size (the minimum-norm point is the wildest one).
        ``work``: the search's QP solves left, which the repair's solves count against."""
        # the QP only: repairs run many times per search, the cone program is slower
        # (garnet_red: 103 s of Clarabel in 12 repairs, 30 s for the whole fit without)
        return self._polish_rounds(rf, seg, j, self._polish_deadline(), rounds=REPAIR_ROUNDS,
                                   method="qp", repair=True, work=work)

    def _polished(self, res: FitResult, seg: Segments, j: int) -> FitResult:
        """``res`` with its rational replaced by the least-squares polish when that
        verifies and fits the data better; otherwise ``res`` unchanged."""
        rf = res.rational
        if rf is None:
            return res
        y = seg.center[:, j]
        w = self._polish_weights(seg, j)
        w = np.ones_like(y) if w is None else w
        what = "relative RMSE" if self.polish_error == "relative" else "RMSE"

        def score(r: RationalFunction) -> float:
            with np.errstate(all="ignore"):
                return float(np.sqrt(np.mean((w * (r(seg.x) - y)) ** 2)))

        before = score(rf)
        deadline = self._polish_deadline()
        work = self._polish_work(j)
        out = self._polish_rounds(rf, seg, j, deadline, work=work, start_valid=True)
        if out is None:
            if work.exhausted:
                return replace(res, message=f"{res.message}; least-squares polish stopped "
                                            f"at its work limit of {work.limit} QP solves "
                                            "(fit unpolished)")
            if _past(deadline):
                return replace(res, message=f"{res.message}; least-squares polish "
                                            "stopped at the time limit (fit unpolished)")
            return res
        cand, ver = out
        after = score(cand)
        if not after < before:
            return res
        cut = (f" (its work limit of {work.limit} QP solves reached)" if work.exhausted
               else "")
        return replace(res, rational=cand, verification=ver,
                       message=f"{res.message}; least-squares polish: {what} "
                               f"{before:.4g} -> {after:.4g} at the same size{cut}")

    def search_parts(self, space: PolynomialSpace, seg: Segments) -> SearchParts:
        parts = super().search_parts(space, seg)
        # q > 0 is generated where a BRDF is evaluated: the valid configurations.
        # With ``physical`` or ``positive_q`` the split systems carry those rows already.
        pole_free = not (self.physical or self.positive_q)
        grid = self._valid_grid_for(space.domain) if pole_free and space.dim > 1 else None
        pole_grid = space.to_window(grid) if grid is not None and grid.size else None
        return SearchParts(systems=_BRDFSystems(self, parts.systems), verifier=self._verify,
                           pole_free=pole_free, pole_grid=pole_grid,
                           repair=self._repair if self.physical and self.polish else None,
                           constraint_points=self._constraint_points if self.physical
                           else None)

    def _constraint_points(self, j: int) -> int:
        """How many validity points the verifier has added to channel ``j``'s splits."""
        return sum(len(e) for e in self._points_of(j))

    def _split_system(self, space: PolynomialSpace, seg: Segments, j: int, n: int, m: int,
                      like: RowSystem | None = None) -> RowSystem | None:
        system = super().search_parts(space, seg).systems.split(space, seg, j, n, m, like=like)
        if not (self.physical or self.positive_q) or not isinstance(system, ArnoldiSystem):
            return system
        if self.physical:
            grid = self._configurations(space.domain)
        else:
            grid = self._valid_grid_for(space.domain) if space.dim > 1 else None
        if grid is None:
            return system
        extra = self._points_of(j)
        if extra:
            grid = np.concatenate([grid, *extra])
        if grid.size == 0:
            return system
        return _valid_rows(system, space.to_window(grid),
                           numerator=self.physical and self.value_form == "linear",
                           ceiling=self._row_ceiling(j, grid) if self.physical else None,
                           floor=self._row_floor(j, grid) if self.physical else None)

    def _valid_grid_for(self, domain: ArrayLike) -> Array | None:
        dom = np.asarray(domain, dtype=float)
        key = (str(self.parametrization).upper(), dom.tobytes())
        cache = getattr(self, "_grid_cache", None)
        if cache is None or cache[0] != key:
            cache = (key, valid_grid(self.parametrization, dom))
            self._grid_cache = cache
        return cache[1]

    def _valid_grid(self, rf: RationalFunction) -> Array | None:
        return self._valid_grid_for(rf.space.domain)

    def _verify(self, rf: RationalFunction, seg: Segments, j: int) -> Verification:
        """Segments at every sample, then q > 0 and r >= 0 on a dense, adaptive set
        of valid direction pairs (:func:`ratfit.brdf.validity.check_validity`)."""
        from ratfit.brdf.validity import check_validity, prove_validity

        known = find_parametrization(self.parametrization) is not None
        # n-D with a known parametrization: the valid direction pairs are checked
        # below, so q's sign on the whole coordinate box (mostly invalid pairs) is not.
        box_checked = not known or rf.space.dim == 1
        ver = verify(rf, seg, channel=j, box_check=box_checked)
        if ver.n_violations or not np.isfinite(ver.linf):
            return ver
        if rf.space.dim == 1 and ver.poles_in_domain:
            return ver
        keep = self.used_coords
        chk = check_validity(rf, self.parametrization, keep=keep, values=self.value_form,
                             ceiling=self._ceiling(j), envelope=self._proof_envelope(j))
        if chk is None:  # nothing says what is valid: the plain box check decides
            return ver if box_checked else verify(rf, seg, channel=j)
        if chk.valid:
            # the dense check found nothing: now the proof, on the whole evaluated region.
            # While the search runs, a short proof that finds q <= 0 or p < 0 rejects the
            # candidate and one that runs out of pieces lets it on; the chosen fit gets
            # the full proof (:meth:`_proved`), which alone makes it a success.
            final = self._final_proof or j in self._final_channels
            proof = prove_validity(rf, self.parametrization, keep=keep, values=self.value_form,
                                   ceiling=self._ceiling(j), envelope=self._proof_envelope(j),
                                   max_boxes=40_000 if final else SEARCH_PROOF_BOXES)
            self.__dict__.setdefault("_proofs", {})[id(rf)] = proof
            if not proof.proved and (final or proof.refuted):
                chk = replace(chk, valid=False, bad_points=self._around(proof, rf, j),
                              method=f"{chk.method}; {proof.summary()}")
        if not hasattr(self, "_checks"):
            self._checks = {}
        self._checks[id(rf)] = chk
        if len(chk.bad_points):
            # constraint generation: later splits keep q > 0, p >= 0 there too
            self._points_of(j).append(_spread(chk.bad_points, SEARCH_POINTS))
        if self.value_form == "log" or np.all(seg.lo[:, j] >= 0):
            # (a log fit's value exp(p / q) is positive wherever it is finite)
            # every (finite) value is inside its segment here (checked above): r >= lo >= 0
            at_samples = True
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                at_samples = bool(np.all(rf(seg.x) >= 0))
        ok = (chk.valid and at_samples and ver.poles_in_domain == 0
              and not ver.denominator_sign_changes)
        why = [f"validity {chk.summary()}"] if not chk.valid else []
        if not at_samples:
            why.append("a negative value at a sample")
        return replace(ver, verified=ok,
                       denominator_sign_changes=ver.denominator_sign_changes or chk.min_q <= 0,
                       rejected_by="; ".join(why))


def _relative_sq(g: Array, y: Array) -> float:
    """Sum of log((f + e) / (y + e))^2 over values ``y`` for a fit of log values whose
    p / q there is ``g`` (f = exp(g)), e = :data:`~ratfit.brdf.options.NOISE_FLOOR`."""
    with np.errstate(all="ignore"):
        f = np.exp(np.minimum(g, 700.0))
        err = np.log((f + NOISE_FLOOR) / (y + NOISE_FLOOR))
    return float(np.sum(np.where(np.isfinite(err), err, 700.0) ** 2))


def _relative_steps(start: RationalFunction, seg: Segments, j: int, y: Array,
                    step: Any) -> tuple[RationalFunction, bool]:
    """Gauss-Newton on the relative error of a fit of log values g (f = exp(g)):
    log(f + e) - log(y + e) is linearised at the current fit f0 as r0 + w0 (g - g0),
    w0 = f0 / (f0 + e), a weighted least-squares problem in g with weights w0 and target
    g0 - r0 / w0, which ``step(fit, segments with that target in column j, w0)`` (a
    polish inside ``seg``'s segments) solves. A value far below e (a black diffuse part)
    then barely counts, as in the error itself, and a value the fit lifts towards e
    counts again. Up to :data:`GROWTH_STEPS` steps, each kept only when the true error
    falls; returns the fit and whether any step was kept."""
    fit, moved = start, False
    g0 = fit(seg.x)
    best = _relative_sq(g0, y)
    for _ in range(GROWTH_STEPS):
        with np.errstate(all="ignore"):
            f0 = np.exp(np.minimum(g0, 700.0))
            w = f0 / (f0 + NOISE_FLOOR)
            target = g0 - np.log((f0 + NOISE_FLOOR) / (y + NOISE_FLOOR)) / w
        if not (np.all(np.isfinite(target)) and np.all(w > 0)):
            break
        center = np.array(seg.center)  # (the segments' midpoints where y is None)
        center[:, j] = target
        cand = step(fit, Segments(seg.x, seg.lo, seg.hi, center, seg.names), w)
        if cand is None:
            break
        g1 = cand(seg.x)
        err = _relative_sq(g1, y)
        if not err < best:
            break
        fit, g0, best, moved = cand, g1, err, True
    return fit, moved


def sizes_scored_better(scores: Sequence[float]) -> list[int]:
    """The indices of the larger sizes (all but the first, the smallest) whose held-out
    score is at least :data:`GROWTH_MIN_GAIN` below the smallest's, best first."""
    return [int(i) for i in np.argsort(scores, kind="stable")
            if i > 0 and scores[i] < (1.0 - GROWTH_MIN_GAIN) * scores[0]]


def _finite(value: float) -> float | None:
    """``value``, or None where it is not finite (a fit file's JSON allows no NaN)."""
    return value if np.isfinite(value) else None


@dataclass(frozen=True)
class LocalReference:
    """Points off the highlight in a fit's coordinates and, for each, the largest value
    of the samples nearest it (:meth:`BRDFFitter._local_reference`)."""

    points: Array
    nearby_max: Array


def local_excess(rf: RationalFunction, near: LocalReference | None) -> float:
    """How far a fit of log values rises above the samples near it, off the highlight:
    the :data:`LOCAL_QUANTILE` quantile of (f + e) / (m + e) over ``near``'s points,
    m the largest nearby sample, e = :data:`~ratfit.brdf.options.NOISE_FLOOR` (NaN
    without points). A thin ridge between sample rows (a q that nearly vanishes there)
    shows here and nowhere in a held-out score whose samples lie in those rows."""
    if near is None:
        return float("nan")
    with np.errstate(all="ignore"):
        f = np.exp(np.minimum(rf(near.points), 700.0))
        ratio = (f + NOISE_FLOOR) / (near.nearby_max + NOISE_FLOOR)
        ratio = np.where(np.isfinite(ratio), ratio, np.inf)
        # the quantile interpolates between neighbours: between two inf it is NaN
        q = float(np.quantile(ratio, LOCAL_QUANTILE))
    return np.inf if np.isnan(q) else q


def _hemisphere(rng: np.random.Generator, n: int) -> Array:
    """``n`` directions uniformly distributed over the upper hemisphere."""
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2])
    return v / np.linalg.norm(v, axis=1)[:, None]


def _padded(rf: RationalFunction, n: int, m: int) -> RationalFunction:
    """``rf`` (in its space's own family) written with ``n`` and ``m`` coefficients: the
    basis functions added have coefficient 0, so it is the same function."""
    return RationalFunction(rf.space, np.r_[rf.p, np.zeros(n - rf.n)],
                            np.r_[rf.q, np.zeros(m - rf.m)])


def _blend(start: RationalFunction, end: RationalFunction, x: Array,
           step: float) -> RationalFunction | None:
    """The fit ``step`` of the way from ``start`` to ``end`` (same size and bases), each
    scaled first to a mean q of 1 at the samples ``x`` so that ``step`` measures the
    move: a row that is linear and homogeneous in (p, q) and holds for both holds for
    it. None when either q is not positive on average at the samples."""
    ends = []
    for rf in (start, end):
        with np.errstate(all="ignore"):
            scale = float(np.mean(rf.denominator(x)))
        if not (np.isfinite(scale) and scale > 0):
            return None
        ends.append((rf.p / scale, rf.q / scale))
    (p0, q0), (p1, q1) = ends
    return RationalFunction(start.space, (1 - step) * p0 + step * p1,
                            (1 - step) * q0 + step * q1,
                            p_basis=start.p_basis, q_basis=start.q_basis)


def _spread(points: Array, k: int) -> Array:
    """At most ``k`` of ``points``, evenly over the array (the check lists them in
    grid order: the first ``k`` would all lie in one corner of the domain)."""
    return points if len(points) <= k else points[spread_indices(len(points), k)]


def _past(deadline: float | None) -> bool:
    return deadline is not None and time.perf_counter() > deadline


class _BRDFSystems:
    """The fitter's system factory with the valid-grid q > 0 rows of ``positive_q``."""

    def __init__(self, fitter: BRDFFitter, base: SystemFactory) -> None:
        self.fitter, self.base, self.per_split = fitter, base, base.per_split

    def channel(self, space: PolynomialSpace, seg: Segments, j: int):
        return self.base.channel(space, seg, j)

    def split(self, space: PolynomialSpace, seg: Segments, j: int, n: int, m: int, like=None):
        return self.fitter._split_system(space, seg, j, n, m, like=like)


def _valid_rows(base: ArnoldiSystem, t_grid: Array, numerator: bool = True,
                ceiling: float | Array | None = None,
                floor: Array | None = None) -> AppendedRows:
    """``base`` plus, per valid configuration g, the row q(g) / |psi(g)| >= delta,
    (``numerator``) the row p(g) / |phi(g)| >= delta, (``ceiling`` C, a fit of log
    values; one number, or one per point) the row (C q(g) - p(g)) / |(-phi(g), C psi(g))|
    >= delta: p / q <= C, and (``floor`` F, one per point, -inf where there is none) the
    row (p(g) - F q(g)) / |(phi(g), -F psi(g))| >= delta: p / q >= F.

    The grid counts as points, so :func:`~ratfit.core.qp.solve_fixed` always works
    on an active set that starts from the data's rows and adds grid rows where they
    are violated (a dense grid is mostly slack; all of it in one QP is slow).
    """
    def unit(basis, k: int):
        def make() -> Array:
            d = basis.design(t_grid, k, window=True)
            return d / np.linalg.norm(d, axis=1)[:, None]
        return LazyRows(make, len(t_grid))

    f = None if floor is None else np.asarray(floor, dtype=float).ravel()
    floored = np.zeros(len(t_grid), dtype=bool) if f is None else np.isfinite(f)

    def bound() -> Array:
        d = bound_rows(base.p_basis.design(t_grid, base.n, window=True),
                       base.q_basis.design(t_grid, base.m, window=True), ceiling, f)
        return d / np.linalg.norm(d, axis=1)[:, None]

    count = (0 if ceiling is None else len(t_grid)) + int(floored.sum())
    # built when a candidate reaches the grid (an infeasible split never does)
    return AppendedRows(
        base, base.n, base.m, psi=unit(base.q_basis, base.m),
        phi=unit(base.p_basis, base.n) if numerator else None,
        chi=None if count == 0 else LazyRows(bound, count),
        start_active=False, extra_points=len(t_grid))


def valid_grid(param: str, domain: ArrayLike, points: int = 200_000) -> Array | None:
    """Grid points of the box ``domain`` that are valid configurations of ``param``
    (:func:`ratfit.brdf.validity.box_configurations`); None for an unknown one."""
    from ratfit.brdf.validity import box_configurations

    return box_configurations(param, domain, points)


def save_brdf_fit(path: str | os.PathLike[str], results, brdf_meta: dict[str, Any],
                  provenance: dict[str, Any] | None = None) -> None:
    """Write verified BRDF fits (atomic; refuses unverified ones)."""
    save_fit(path, fit_document(results, provenance=provenance, extra={"brdf": brdf_meta}))


# --------------------------------------------------------------------------- metrics
def brdf_metrics(pred: ArrayLike, ref: ArrayLike, cos_l: ArrayLike | None = None,
                 names: tuple[str, ...] | None = None) -> dict[str, dict[str, float]]:
    """Per-channel errors of ``pred`` against ``ref`` (N, k).

    rmse; rel_rmse: RMS of (pred - ref)/ref over ref != 0; log_rmse: RMSE of
    log(1 + value) (the compressed error used for glossy data); linf;
    cos_rmse: RMSE of (pred - ref) cos(theta_l) when ``cos_l`` is given.
    """
    p = np.atleast_2d(np.asarray(pred, dtype=float))
    r = np.atleast_2d(np.asarray(ref, dtype=float))
    if p.shape[0] == 1 and r.shape[0] != 1:
        p, r = p.T, r.T
    if p.shape != r.shape:
        raise InputError(f"predictions {p.shape} and references {r.shape} differ in shape")
    names = names or tuple(f"y{j}" for j in range(r.shape[1]))
    out: dict[str, dict[str, float]] = {}
    for j, name in enumerate(names):
        e = p[:, j] - r[:, j]
        nz = r[:, j] != 0
        with np.errstate(invalid="ignore", divide="ignore"):
            logd = np.log1p(np.maximum(p[:, j], -0.999999)) - np.log1p(r[:, j])
        m = {
            "rmse": float(np.sqrt(np.mean(e**2))),
            "rel_rmse": float(np.sqrt(np.mean((e[nz] / r[nz, j]) ** 2))) if nz.any() else 0.0,
            "log_rmse": float(np.sqrt(np.mean(logd**2))),
            "linf": float(np.max(np.abs(e))),
        }
        if cos_l is not None:
            c = np.asarray(cos_l, dtype=float).ravel()
            m["cos_rmse"] = float(np.sqrt(np.mean((e * c) ** 2)))
        out[name] = m
    return out


# --------------------------------------------------------------------------- saved fits
@dataclass(frozen=True)
class BRDFFit:
    """A saved BRDF fit as a function of directions or of its coordinates."""

    saved: SavedFit
    parametrization: str
    cosine_weighted: bool = False
    fold_phi_d: bool = False
    dropped: tuple[int, ...] = ()  # constant coordinates the fit does not use

    @property
    def n_channels(self) -> int:
        return len(self.saved.channels)

    @property
    def values(self) -> str:
        """"log": each channel's value is exp(p / q) (:attr:`SavedFit.values`)."""
        return self.saved.values

    @property
    def channel_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.saved.channels)

    def _raw(self, coords: Array) -> Array:
        """The fit at coordinates (folded for MERL tables), clipped into its domain box:
        outside the box nothing is proved, so no evaluator goes there."""
        c = coords
        if self.fold_phi_d:
            c = c.copy()
            c[:, 2] = fold_phi_d(c[:, 2], c[:, 0], c[:, 1])
        if self.dropped:
            c = np.delete(c, list(self.dropped), axis=1)
        dom = np.asarray(self.saved.space.domain, dtype=float)
        return self.saved(np.clip(c, dom[:, 0], dom[:, 1]))

    def eval_coords(self, coords: ArrayLike) -> Array:
        """BRDF values (N, k) at coordinates of the fit's parametrization (clipped into
        the fit's domain box; :meth:`eval_dirs` first moves a pair in by symmetries)."""
        p = get_parametrization(self.parametrization)
        c = np.asarray(coords, dtype=float)
        if c.ndim == 1:
            c = c[:, None] if p.dim == 1 else c[None, :]
        if c.ndim != 2 or c.shape[1] != p.dim:
            raise InputError(
                f"{p.name} coordinates have shape (N, {p.dim}), got {np.shape(coords)}"
            )
        vals = self._raw(c)
        if self.cosine_weighted:
            with np.errstate(divide="ignore", invalid="ignore"):
                vals = vals / cos_theta_l(c, p.name)[:, None]
        return vals

    def coords(self, L: ArrayLike, V: ArrayLike) -> tuple[Array, NDArray[np.bool_]]:
        """Where the fit is evaluated for unit directions L, V (N, 3) above the horizon.

        The one definition every evaluator shares (``brdf eval``, the exports, the
        renderer): of the pair and its images under the symmetries of a BRDF, the
        first one whose coordinates are nearest to the fit's domain box, clipped into
        the box. The images, in order: for all but full parametrizations the mirror
        y -> -y (exact for an isotropic material), then reciprocity L <-> V and its
        mirror (measurements are not always reciprocal: acryl_blue's fit in
        ISOTROPIC_TV_TL_DPHI, whose box holds delta_phi >= 0 only, had a seam at
        delta_phi = 0 when the exchanged pair came first). The validity proof
        (:func:`ratfit.brdf.validity.prove_validity`) covers every point of the box
        these reach. A folded fit (RUSIN_TH_TD_FOLD, or a MERL table's phi_d folded into
        [0, pi)) takes the pair in :func:`~ratfit.brdf.parametrizations.reciprocal_order`
        first, so (L, V) and (V, L) are one computation. Also returns which rows needed
        the clip.
        """
        p = get_parametrization(self.parametrization)
        dom = np.asarray(self.saved.space.domain, dtype=float)
        la, va = check_dirs(L, V)
        if is_folded(p.name, self.fold_phi_d):
            la, va = reciprocal_order(la, va)
        cols = np.setdiff1d(np.arange(p.dim), self.dropped)
        flip = np.array([1.0, -1.0, 1.0])
        cands = [(la, va), (va, la)] if p.invariant == "full" else \
            [(la, va), (la * flip, va * flip), (va, la), (va * flip, la * flip)]
        best = dist = None
        with np.errstate(all="ignore"):
            for a, b in cands:
                c = p._from(a, b)
                if self.fold_phi_d:
                    c[:, 2] = fold_phi_d(c[:, 2], c[:, 0], c[:, 1])
                cu = c[:, cols]
                gap = np.sum(np.maximum(dom[:, 0] - cu, 0.0) + np.maximum(cu - dom[:, 1], 0.0),
                             axis=1)
                gap = np.where(np.isfinite(gap), gap, np.inf)
                if best is None or dist is None:
                    best, dist = c, gap
                    continue
                better = gap < dist - 1e-12 * (1.0 + np.abs(dom).max())
                best[better], dist[better] = c[better], gap[better]
        assert best is not None and dist is not None
        tol = 1e-9 * (1.0 + np.abs(dom).max())
        out = best.copy()
        out[:, cols] = np.clip(best[:, cols], dom[:, 0], dom[:, 1])
        return out, dist > tol

    def eval_dirs(self, L: ArrayLike, V: ArrayLike) -> Array:
        """BRDF values (N, k) for unit directions L, V (N, 3) above the horizon,
        at the coordinates :meth:`coords` defines."""
        coords, _ = self.coords(L, V)
        vals = self._raw(coords)
        if self.cosine_weighted:
            lz = np.asarray(L, dtype=float).reshape(-1, 3)[:, 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                vals = vals / lz[:, None]
        return vals


def alta_brdf_fit(saved: SavedFit) -> BRDFFit | None:
    """An ALTA function file (``load_fit`` of one) as a BRDF fit when its
    ``#PARAM_IN`` names a parametrization of its dimension, else None."""
    if saved.integrity != "alta":
        return None
    param = find_parametrization(str(saved.provenance.get("param_in", "")))
    if param is None or param.dim != saved.space.dim:
        return None
    saved = replace(saved, extra={**saved.extra, "brdf": {"parametrization": param.name}})
    return BRDFFit(saved, param.name)


def load_brdf_fit(path: str | os.PathLike[str]) -> BRDFFit:
    """Load a fit written by ``ratfit brdf fit`` (it must carry the "brdf" block), or
    an ALTA rational function file whose ``#PARAM_IN`` is a BRDF parametrization."""
    return brdf_fit_of_saved(load_fit(path), str(path))


def brdf_fit_of(results: list[FitResult], brdf_meta: dict[str, Any]) -> BRDFFit:
    """The verified results of a fit as the :class:`BRDFFit` its file would load as:
    evaluated exactly as ``ratfit brdf eval`` evaluates the saved file."""
    from ratfit.io.fitfile import parse_fit

    doc = fit_document(results, extra={"brdf": brdf_meta})
    return brdf_fit_of_saved(parse_fit(doc, "fit"), "fit")


def brdf_fit_of_saved(saved: SavedFit, path: str) -> BRDFFit:
    """A loaded fit file as a BRDF fit (it must carry the "brdf" block, or be an ALTA
    function in a BRDF parametrization)."""
    meta = saved.extra.get("brdf")
    if saved.integrity == "alta":
        bf = alta_brdf_fit(saved)
        if bf is None:
            raise FileFormatError(
                f"{path}: an ALTA function in {saved.provenance.get('param_in')!r} of "
                f"{saved.space.dim} input(s): not a BRDF parametrization ratfit knows")
        return bf
    if not isinstance(meta, dict) or "parametrization" not in meta:
        raise FileFormatError(
            f"{path}: a ratfit fit file without a 'brdf' block: not a BRDF fit "
            "(written by `ratfit fit`, not `ratfit brdf fit`)"
        )
    p = get_parametrization(str(meta["parametrization"]))
    # (load_fit has checked the block's field types: dropped_coords maps digit strings
    # to numbers)
    dropped = tuple(sorted({int(k) for k in (meta.get("dropped_coords") or {})}))
    if len(dropped) != len(meta.get("dropped_coords") or {}) or any(
            not 0 <= k < p.dim for k in dropped):
        raise FileFormatError(
            f"{path}: 'brdf.dropped_coords' names coordinates {sorted(meta['dropped_coords'])} "
            f"but {p.name} has coordinates 0..{p.dim - 1} (each at most once)"
        )
    if p.dim - len(dropped) != saved.space.dim:
        raise FileFormatError(
            f"{path}: parametrization {p.name} has {p.dim} coordinates but the fit has "
            f"{saved.space.dim} inputs"
        )
    if meta.get("shared_denominator") and any(
            not np.array_equal(c.rational.q, saved.channels[0].rational.q)
            for c in saved.channels):
        raise FileFormatError(
            f"{path}: 'brdf.shared_denominator' is true but the channels' denominators "
            "differ: each channel of a shared fit is stored as p_c / q with the same q")
    return BRDFFit(saved, p.name, bool(meta.get("cosine_weighted", False)),
                   bool(meta.get("fold_phi_d", False)), dropped)
