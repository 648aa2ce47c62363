"""BRDF fits with one denominator for every channel: r_c = p_c / q.

:class:`SharedBRDFFitter` runs the shared-denominator search of
:mod:`ratfit.fitting.shared_denominator` (one QP per sizes (n_1..n_K, m), the
fewest coefficients sum(n_c) + m) with what makes a per-channel BRDF fit
(:class:`~ratfit.brdf.fitter.BRDFFitter`) usable:

- every QP carries the validity rows q > 0 and p_c >= 0 (each channel) at the
  valid direction pairs of the domain (:func:`ratfit.brdf.validity.configurations`),
  entering the active set only where violated;
- each candidate is verified as a per-channel candidate is (segments, the dense
  check :func:`~ratfit.brdf.validity.check_validity`, a short proof
  :func:`~ratfit.brdf.validity.prove_validity`); points where q <= 0 or p_c < 0
  was found join every later QP's rows (constraint generation);
- the chosen fit is converted to the space's family (the coefficients the fit
  file stores, with the identical q in every channel) and each channel's
  p_c / q is proved valid with the full proof. Where it is not, the points the
  proof or the dense check found join the rows and the same sizes are solved
  again, at most :data:`PROOF_ROUNDS` times; then, once, the whole search runs
  again with the full proof on every candidate. No wall clock decides any of it.

The fit is not polished (the least-squares polish is a per-channel QP; a shared
one is not written): the search's fit is kept, and the fit file's ``brdf`` block
says ``"polish": false``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ratfit.brdf.options import BRDF_SOLVER, UNKNOWN_PARAMETRIZATION
from ratfit.brdf.parametrizations import find_parametrization
from ratfit.core.options import FitOptions
from ratfit.core.rational import RationalFunction
from ratfit.core.segments import Segments
from ratfit.core.systems import AppendedRows, LazyRows
from ratfit.core.verify import Verification, verify
from ratfit.errors import InputError
from ratfit.fitting.search import RationalFitter
from ratfit.fitting.shared_denominator import (
    SharedFit,
    SharedOptions,
    SharedSystem,
    _SharedSearch,
)

__all__ = ["PROOF_ROUNDS", "SEARCH_ROUNDS", "SHARED_MAX_M", "SHARED_MAX_N", "SharedBRDFFitter",
           "shared_valid_rows"]

Array = NDArray[np.float64]
#: Times the chosen sizes are solved again with the points where the full proof (or
#: the dense check) of a channel found q <= 0 or p_c < 0 added as rows.
PROOF_ROUNDS = 4
#: Times the search solves one size again with the points where its solution's validity
#: check or proof found q <= 0 or p_c < 0 added as rows (a per-channel search solves
#: such a candidate again and then repairs it by its polish, which a shared fit lacks).
SEARCH_ROUNDS = 4
#: The largest numerator per channel (without ``max_total``) and the largest shared q:
#: a shared q carries every channel's poles (garnet_red's own fits have m = 15, 17 and 22
#: at the default segments; no shared fit with n_c = m <= 30 verified there).
SHARED_MAX_N = 60
SHARED_MAX_M = 60
# Search options of the per-channel fit that the shared search has no use for: the
# BRDF path's own (handled here) and the ones a shared search refuses unless default.
# (envelope, held_out_size: of log values, which a shared denominator refuses)
_BRDF_ONLY = ("positive_q", "physical", "polish", "polish_error", "values", "envelope",
              "held_out_size")


def shared_valid_rows(system: SharedSystem, t_grid: Array) -> AppendedRows:
    """``system`` plus, per point g of ``t_grid`` (window coordinates), the row
    q(g) / |psi(g)| >= delta and, for each channel c, p_c(g) / |phi_c(g)| >= delta
    (on channel c's block of coefficients only). Like the per-channel rows, they join
    the active set only where violated."""
    K, G = system.K, len(t_grid)
    n = int(system.offsets[-1])

    def unit(d: Array) -> Array:
        return d / np.linalg.norm(d, axis=1)[:, None]

    def q_rows() -> Array:
        return unit(system.q_basis.design(t_grid, system.m, window=True))

    def p_rows() -> Array:
        out = np.zeros((K * G, n))
        for c, basis in enumerate(system.p_bases):
            lo, hi = int(system.offsets[c]), int(system.offsets[c + 1])
            out[c * G:(c + 1) * G, lo:hi] = unit(basis.design(t_grid, hi - lo, window=True))
        return out

    return AppendedRows(system, n, system.m, psi=LazyRows(q_rows, G),
                        phi=LazyRows(p_rows, K * G), start_active=False, extra_points=G)


class _BRDFSharedSearch(_SharedSearch):
    """The shared search with a BRDF fitter's validity rows and verifier."""

    def __init__(self, options: SharedOptions, space: Any, seg: Segments,
                 helper: Any) -> None:
        super().__init__(options, space, seg)
        self.helper = helper
        if helper.physical and find_parametrization(helper.parametrization) is not None:
            # q > 0 where a BRDF is evaluated (the valid pairs), not on the whole box
            # (mostly pairs of no directions): the validity rows carry it
            dim = space.dim
            self.cuts = lambda rf: np.zeros((0, dim))
            self.grid = helper._configurations(space.domain)
        else:
            self.grid = None

    def _walk(self) -> None:
        """The sizes, by a local search that never builds a QP larger than the fit
        already found (the generic walk bisects each numerator at every m with the
        others at a large bound: on garnet_red, 1439 samples, QPs of 100-170 unknowns
        at 20-60 s each, most feasible and so solved over many active-set rounds):

        1. the diagonal: the smallest s with every n_c = m = s verified (doubling,
           then bisection), each numerator then bisected down and lowered while
           the fit verifies (:meth:`_lower`): a first fit (n, s);
        2. down: m = s - 1, s - 2, ... with the kept numerators, lowered again, while
           they still verify at that m (fewer poles, same numerators: a smaller total);
        3. up: m = s + 1, s + 2, ... from the kept numerators, lowered; while that beats
           the kept total.

        The result is the smallest total this search verified, not proven minimal (a
        fixed ``m`` runs the generic walk over the numerators instead).
        """
        K = self.K
        if self.f.m is not None:
            super()._walk()
            return
        top = min(self.cap, self.f.max_m)
        s = 1
        while not self.ok((s,) * K, s) and s < top:
            s = min(2 * s, top)
        if not self.ok((s,) * K, s):
            return
        lo = s // 2 if s > 1 else 0  # known infeasible (or nothing)
        while s - lo > 1:
            mid = (lo + s) // 2
            if self.ok((mid,) * K, mid):
                s = mid
            else:
                lo = mid
        self.best = best = (self._lower((s,) * K, s), s)
        for m in range(s - 1, 0, -1):
            if not self.ok(best[0], m):
                break
            best = (self._lower(best[0], m), m)
        self.best = best
        n0 = best[0]
        for m in range(s + 1, self.f.max_m + 1):
            if m + K >= sum(best[0]) + best[1] or not self.ok(n0, m):
                break
            n = self._lower(n0, m)
            if sum(n) + m >= sum(best[0]) + best[1]:
                break
            best = (n, m)
        self.best = best

    def _lower(self, n: tuple[int, ...], m: int) -> tuple[int, ...]:
        """``n`` (verified at ``m``) with each numerator in turn bisected down to the
        smallest that verifies with the others kept, then lowered one at a time while
        that verifies (:meth:`_shrink`: verification need not be monotone)."""
        cur = list(n)
        for c in range(self.K):
            lo, hi = 0, cur[c]  # 0 coefficients: nothing
            while hi - lo > 1:
                mid = (lo + hi) // 2
                if self.ok(tuple(mid if j == c else v for j, v in enumerate(cur)), m):
                    hi = mid
                else:
                    lo = mid
            cur[c] = hi
        return self._shrink(tuple(cur), m)

    def solve(self, n: tuple[int, ...], m: int) -> Any:
        """P(n, m) as the generic search solves it; where the solution meets every
        segment but the validity check or proof found q <= 0 or p_c < 0 (those points
        have joined the rows), solved again, at most :data:`SEARCH_ROUNDS` times: the
        same size often has a valid fit once the QP sees where the last one failed."""
        before = self._points()
        trial = super().solve(n, m)
        spent = trial.att.qp_solves
        for _ in range(SEARCH_ROUNDS):
            vers = trial.verifications
            if (trial.ok or trial.rationals is None or vers is None
                    or any(v.n_violations or not np.isfinite(v.linf) for v in vers)):
                break
            now = self._points()
            if now == before:  # nothing new to constrain: the same QP, the same answer
                break
            before = now
            trial = super().solve(n, m)
            spent += trial.att.qp_solves
            trial.att.qp_solves = spent
        return trial

    def _points(self) -> int:
        return sum(len(e) for e in self.helper._points_of(0))

    def system(self, n: tuple[int, ...], m: int, q0: Array | None) -> Any:
        base = super().system(n, m, q0)
        if self.grid is None:
            return base
        extra = self.helper._points_of(0)
        grid = np.concatenate([self.grid, *extra]) if extra else self.grid
        if grid.size == 0:
            return base
        return shared_valid_rows(base, self.space.to_window(grid))

    def verify_channels(self, rats: list[RationalFunction]) -> list[Verification]:
        """Each channel as a per-channel BRDF candidate is verified; after the first
        channel that fails, the others get the segment check only (marked unverified:
        the candidate is rejected already)."""
        out: list[Verification] = []
        for j, rf in enumerate(rats):
            if out and not out[-1].verified:
                out.append(replace(verify(rf, self.seg, channel=j, box_check=False),
                                   verified=False))
                continue
            out.append(self.helper._verify(rf, self.seg, j))
        return out


class SharedBRDFFitter:
    """Fit every channel of BRDF segments with one denominator (see the module).

    The parameters are :class:`~ratfit.brdf.fitter.BRDFFitter`'s. ``max_total``
    bounds each numerator (as ``ratfit fit --shared-denominator`` does); ``m``
    fixes the shared denominator; ``n`` and ``total`` are refused, and so are
    ``min_total``, ``strategy`` and ``split_rule`` unless at their defaults.
    ``time_limit`` and ``work_limit`` are per channel, as for the per-channel
    fit: the one shared search gets K times each. ``physical=False`` and
    ``positive_q`` are refused: the validity rows and the proof are the point.

    Attributes (after :meth:`fit`)
    ------------------------------
    result_ : SharedFit
        Sizes, bounds and history of the search (its results before the proof).
    results_ : list of FitResult
        One per channel, each p_c / q in the family form, every q identical.
    validity_, proofs_ : lists
        The dense check and the proof of each channel's chosen fit.
    """

    polish = False
    polish_error = None
    shared_denominator = True

    def __init__(self, *, parametrization: str = UNKNOWN_PARAMETRIZATION,
                 used_coords: tuple[int, ...] | None = None, **params: Any) -> None:
        from ratfit.brdf.fitter import BRDFFitter

        if params.get("positive_q"):
            raise InputError("a shared denominator keeps q > 0 with validity rows at every "
                             "valid direction pair: drop positive_q")
        if params.get("physical", True) is False:
            raise InputError("a shared denominator is fitted with the physical validity "
                             "rows and proof: physical=False is not available")
        if params.get("values", "auto") not in ("auto", "linear"):
            raise InputError("a shared denominator fits the values as p_c / q: "
                             f"drop values={params['values']!r}")
        for key in ("n", "total"):
            if params.get(key) is not None:
                raise InputError(f"a shared denominator searches the numerator sizes itself: "
                                 f"drop {key} (m fixes the shared denominator)")
        self.parametrization = parametrization
        self.used_coords = used_coords
        # a BRDF fit's solver by default, then what was given
        self.params = {"solver": BRDF_SOLVER,
                       **{k: v for k, v in params.items() if k not in _BRDF_ONLY}}
        # the per-channel fitter whose verifier, validity grid and validity points the
        # shared search uses (never fitted itself)
        self.helper = BRDFFitter(parametrization=parametrization, used_coords=used_coords,
                                 solver=self.params["solver"])
        self.helper._checks = {}
        self.helper._pooled_points = True  # one q: every channel's points constrain it

    def options(self, k: int) -> SharedOptions:
        """The shared search's options for ``k`` channels (refusals as InputError)."""
        p = dict(self.params)
        top = p.pop("max_total", None)
        p["max_n"] = SHARED_MAX_N if top is None else top
        p["max_m"] = SHARED_MAX_M
        for key in ("time_limit", "work_limit"):
            if p.get(key) is not None:
                p[key] = k * p[key]
        # one thread: the validity points each test finds join the next tests' rows
        # in one order, so the fit does not depend on thread timing
        p["jobs"] = 1
        return SharedOptions.from_params(p)

    @property
    def success_(self) -> bool:
        return bool(self.results_) and all(r.success for r in self.results_)

    def fit(self, seg: Segments) -> SharedBRDFFitter:
        if seg.n_channels < 2:
            raise InputError(f"a shared denominator needs at least two channels; the data has "
                             f"{seg.n_channels} ({', '.join(seg.names)}): fit it without "
                             "--shared-denominator")
        opts = self.options(seg.n_channels)
        self.segments_ = seg
        plain = FitOptions(**{k: getattr(opts, k) for k in ("basis", "index_set", "domain",
                                                             "solver", "cross_check")})
        space = RationalFitter.from_options(plain).prepare(seg)
        if seg.dim > 1 and space.index_set != "total":
            raise InputError("a shared denominator needs index_set='total' in n-D")
        helper = self.helper
        self.prove = find_parametrization(self.parametrization) is not None
        search = _BRDFSharedSearch(opts, space, seg, helper)
        fit = search.run()
        out = self._proved(fit, search)
        if not out.success and fit.success and self.prove:
            # the chosen fit could not be proved, even re-solved with the points found:
            # once more, the whole search with the full proof on every candidate
            helper._final_proof = True
            try:
                again = _BRDFSharedSearch(opts, space, seg, helper)
                fit2 = again.run()
            finally:
                helper._final_proof = False
            out2 = self._proved(fit2, again, note="searched again with the full validity "
                                                  "proof on every candidate")
            if out2.success:
                fit, out = fit2, out2
        # the local walk proves nothing; a fixed m runs the generic walk and its bounds
        self.result_ = replace(fit, proven=fit.proven and self.params.get("m") is not None
                               and not self._rejected(search))
        self.results_ = out.results
        if not out.success and self._rejected(search):
            # not "no candidate": QPs had solutions inside every segment that the validity
            # check or proof rejected (what widening the segments is not for)
            why = ("a candidate met every segment but none was proved valid "
                   "(q > 0, p_c >= 0 on the valid direction pairs)")
            self.results_ = [replace(r, status=2, message=f"{r.message}; {why}")
                             if r.status == 1 and not r.time_limited else r
                             for r in self.results_]
        checks, proofs = helper._checks, helper.__dict__.get("_proofs", {})
        self.validity_ = [checks.get(id(r.rational)) if r.rational is not None else None
                          for r in self.results_]
        self.proofs_ = [proofs.get(id(r.rational)) if r.rational is not None else None
                        for r in self.results_]
        return self

    @staticmethod
    def _rejected(search: _SharedSearch) -> bool:
        """A QP solution was rejected by the validity check: the search's lower bounds
        assume feasibility is monotone, which such a rejection breaks."""
        return any(t.rationals is not None and t.verifications is not None and not t.ok
                   and all(v.n_violations == 0 for v in t.verifications)
                   for t in search.cache.values())

    def _proved(self, fit: SharedFit, search: _BRDFSharedSearch,
                note: str | None = None) -> SharedFit:
        """``fit`` in the family form with every channel proved, or rejected (status 2)."""
        if not fit.success:
            return fit
        rats = [r.rational for r in fit.results if r.rational is not None]
        if not self.prove or len(rats) != len(fit.results):
            return fit
        helper = self.helper
        helper._final_proof = True
        why: str | None = "no proof ran"
        try:
            for round_ in range(PROOF_ROUNDS + 1):
                fams, vers, bad, why = self._prove_all(rats)
                if why is None:
                    extra = f"; proved after {round_} re-solve(s)" if round_ else ""
                    extra += f"; {note}" if note else ""
                    results = [replace(r, rational=f, verification=v,
                                       message=f"{r.message}{extra}")
                               for r, f, v in zip(fit.results, fams, vers, strict=True)]
                    return dataclasses.replace(fit, results=results)
                if round_ == PROOF_ROUNDS or not len(bad):
                    break
                from ratfit.brdf.fitter import ROUND_POINTS, _spread

                # the same sizes again, with rows at those points (the next round
                # checks the segments and proves each channel of the new solution)
                helper._points_of(0).append(_spread(bad, ROUND_POINTS))
                try:
                    _att, new = search.solve_system(fit.n, fit.m)
                except InputError:
                    new = None
                if new is None:
                    why = f"{why}; re-solved with rows there: no solution"
                    break
                rats = new
        finally:
            helper._final_proof = False
        results = [replace(r, success=False, status=2,
                           verification=replace(r.verification, verified=False)
                           if r.verification is not None else None,
                           message=f"{r.message}; rejected: {why}")
                   for r in fit.results]
        return dataclasses.replace(fit, results=results)

    def _prove_all(self, rats: list[RationalFunction]
                   ) -> tuple[list[RationalFunction], list[Verification], Array, str | None]:
        """Every channel in the family form with the one q, checked at every sample,
        by the dense check and by the full proof. Returns (forms, verifications, points
        where q <= 0 or p_c < 0 was found, why not valid or None)."""
        from ratfit.brdf.validity import check_validity, prove_validity

        helper, seg = self.helper, self.segments_
        fams0 = [rf.to_family() for rf in rats]
        q = fams0[0].q
        fams = [RationalFunction(f.space, f.p, q) for f in fams0]
        vers: list[Verification] = []
        bad: list[Array] = []
        why: str | None = None
        proofs = helper.__dict__.setdefault("_proofs", {})
        for j, fam in enumerate(fams):
            ver = verify(fam, seg, channel=j, box_check=False)
            chk = check_validity(fam, self.parametrization, keep=self.used_coords)
            proof = prove_validity(fam, self.parametrization, keep=self.used_coords)
            proofs[id(fam)] = proof
            helper._checks[id(fam)] = chk
            ok = ver.n_violations == 0 and np.isfinite(ver.linf) and proof.proved and (
                chk is None or chk.valid)
            vers.append(replace(ver, verified=bool(ok)))
            if ok:
                continue
            name = seg.names[j]
            if ver.n_violations or not np.isfinite(ver.linf):
                why = why or f"{name} misses a segment in its stored form"
            else:
                why = why or f"{name}: validity {proof.summary()}"
                if len(proof.bad_points):
                    bad.append(proof.bad_points)
                elif chk is not None and len(chk.bad_points):
                    bad.append(chk.bad_points)
        pts = np.concatenate(bad) if bad else np.zeros((0, seg.dim))
        return fams, vers, pts, why
