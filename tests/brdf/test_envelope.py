"""Scattered measurements leave most direction pairs unsampled (every Cornell sample lies
in the plane of incidence), and a log fit's proved ceiling is its channel's highlight:
the default fits rose to 28-1 681 1/sr off the highlight (theta_h > 0.3, where no sample
exceeds 0.06) at pairs away from the plane, the renders' fireflies. The search's and the
polish's validity rows keep p / q under the samples' envelope instead, and the validity
proof proves it (with twice the slack) on the whole evaluated region. Over theta_h alone
that envelope is the grazing peak at the mirror direction at every incidence (cayman G
rose to 1 210 1/sr at 70 degrees, its sample 16), so where the frame has theta_d it is
over (theta_h, theta_d): the highlight grows toward grazing no faster than its samples
show."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import above_horizon
from test_log_ceiling import _spike
from test_log_values import WIDTHS, _material

from ratfit.brdf.fitter import (
    CEILING_ROW_MARGIN,
    ENVELOPE_PROOF_SLACK,
    ENVELOPE_SLACK,
    LOG_CEILING_FACTOR,
    LOG_FLOOR_FACTOR,
    BRDFFitter,
    brdf_segments,
    fit_brdf,
    theta_d_column,
    theta_h_column,
)
from ratfit.brdf.io import read_brdf, samples_dataset
from ratfit.brdf.parametrizations import get_parametrization
from ratfit.brdf.validity import (
    ENVELOPE_D_STEP,
    FLOOR_LOG_MIN,
    SampleCeiling,
    SampleFloor,
    StepCeiling,
    envelope_from_dict,
    grazing,
    reprove_saved,
    theta_d_growth,
)
from ratfit.core.polish import _positivity_rows
from ratfit.core.positivity import prove_below
from ratfit.core.segments import Segments
from ratfit.io.fitfile import load_fit, scope_text


def _by_hand(theta_h, top, t, slack):
    """log(2 x the largest top among the samples with theta_h >= t - slack), the
    farthest sample's past them all: the envelope, one point at a time."""
    th, top = np.asarray(theta_h, float), np.asarray(top, float)
    out = []
    for v in np.atleast_1d(t):
        near = th >= v - slack
        out.append(np.log(LOG_CEILING_FACTOR * (top[near].max() if near.any()
                                                else top[np.argmax(th)])))
    return np.array(out)


def _by_hand2(theta_h, theta_d, top, t, d, slack, growth, step=None, highlight=0.01):
    """The largest log(2 top_i) - growth x max(0, g(theta_d_i - slack) - g(d)), g = -log cos
    (no fall for the samples under ``highlight`` of the largest), among the
    samples with theta_h_i >= t - slack (past the farthest: that one's), with d taken at
    the theta_d step at or below it (``step`` apart from 0 to pi / 2; None: d
    itself): the envelope over (theta_h, theta_d), one point at a time."""
    th, td, top = (np.asarray(a, float) for a in (theta_h, theta_d, top))
    v = np.log(LOG_CEILING_FACTOR * top)
    grows = top >= highlight * top.max()

    def g(a):  # -log cos, 0 below 0
        return -np.log(np.cos(np.clip(a, 0.0, np.pi / 2)))

    out = []
    for u, w in zip(np.atleast_1d(t), np.atleast_1d(d), strict=True):
        near = th >= min(u, th.max() + slack) - slack
        if step is not None:  # the step at or below w from 0 to pi / 2
            w = step * np.clip(np.floor(w / step), 0, round(np.pi / 2 / step))
        fall = growth * np.maximum(0.0, g(td[near] - slack) - g(w)) * grows[near]
        out.append(np.max(v[near] - fall))
    return np.array(out)


def test_the_envelope_is_the_largest_upper_end_at_least_as_far_from_the_mirror() -> None:
    env = StepCeiling.of_samples(0, [1.0, 0.0, 0.5, 0.1], [0.5, 100.0, 1.0, 10.0],
                                 ENVELOPE_SLACK, LOG_CEILING_FACTOR)
    t = np.array([0.0, 0.16, 0.3, 0.56, 2.0])
    # theta_h >= t - 0.05: all four; 0.5 and 1.0 (0.1 lies below 0.11); 0.5 and 1.0;
    # 1.0 alone; past the farthest sample, that sample's
    expect = LOG_CEILING_FACTOR * np.array([100.0, 1.0, 1.0, 0.5, 0.5])
    np.testing.assert_allclose(np.exp(env.at(t)), expect, rtol=1e-12)
    # a point within the slack of a sample counts it
    assert np.exp(env.at(0.14)) == pytest.approx(LOG_CEILING_FACTOR * 10.0)
    assert ENVELOPE_SLACK == 0.05


def test_theta_h_is_found_among_the_kept_coordinates() -> None:
    assert theta_h_column("RUSIN_TH_TD_SYM", None) == 0
    assert theta_h_column("RUSIN_TH_TD_PD", (1, 0, 2)) == 1
    assert theta_h_column("RUSIN_TH_TD_PD", (1, 2)) is None  # theta_h dropped as constant
    assert theta_h_column("ISOTROPIC_TV_TL_DPHI", None) is None
    assert theta_d_column("RUSIN_TH_TD_SYM", None) == 1
    assert theta_d_column("RUSIN_TH_TD_PD", (1, 0, 2)) == 0
    assert theta_d_column("RUSIN_TH_TD_PD", (0, 2)) is None
    assert theta_d_column("RUSIN_TH", None) is None


def test_the_envelope_over_theta_d_grows_toward_grazing_as_the_samples_do() -> None:
    """cayman's grazing mirror sample (80 degrees, 737 1/sr) made the theta_h envelope
    allow twice that at the mirror direction at every incidence; over (theta_h,
    theta_d) it allows a sample's value nearer the normal only less the growth toward
    grazing, as a power of 1 / cos theta_d, that the samples show."""
    # mirror samples at 40, 60 and 80 degrees and a diffuse one far from the mirror
    th = [0.01, 0.01, 0.01, 0.8]
    td = np.radians([40.0, 60.0, 80.0, 30.0])
    top = [4.0, 9.0, 700.0, 0.05]
    # the fastest growth within 0.01 of theta_h, among the samples above 1 % of the peak
    # (60 -> 80 degrees; the 40-degree one is below 7), in powers of 1 / cos
    g = theta_d_growth(th, td, np.array(top)[:, None])
    cos = np.cos(np.radians([60.0, 80.0]))
    assert g == pytest.approx(np.log(700.0 / 9.0) / np.log(cos[0] / cos[1]))
    assert 4.0 < g < 4.2
    assert theta_d_growth(th, td, np.array([top, top]).T) == g  # channels alike
    assert theta_d_growth([0.0, 0.5], [0.2, 0.9], np.array([[1.0], [50.0]])) == 0.0
    np.testing.assert_allclose(grazing([-0.1, 0.0, np.pi / 3]), [0.0, 0.0, np.log(2.0)])
    env = SampleCeiling.of_samples(0, 1, th, td, top, ENVELOPE_SLACK, LOG_CEILING_FACTOR, g)
    assert env.growth == g
    d = np.radians([40.0, 60.0, 70.0, 80.0, 30.0])
    at = np.exp(env.at2([0.0, 0.0, 0.0, 0.0, 0.5], d))
    exact = np.exp(_by_hand2(th, td, top, [0.0] * 4 + [0.5], d, ENVELOPE_SLACK, g))
    # the staircase is never above the formula, and at most one step's growth under it
    assert np.all(at <= exact * (1 + 1e-12))
    step = g * (grazing(d + ENVELOPE_D_STEP) - grazing(d))
    assert np.all(at >= exact * np.exp(-step) * (1 - 1e-12))
    # 60 and 70 degrees: the 80-degree sample divided by (cos 80 - slack / cos d)^g
    for k in (1, 2):
        assert exact[k] == pytest.approx(1400.0 * (np.cos(np.radians(80.0) - ENVELOPE_SLACK)
                                                   / np.cos(d[k])) ** g)
    assert 18.0 < exact[1] < 60.0 and exact[2] < 250.0  # 50 and 239, not 1 400
    assert exact[3] == pytest.approx(1400.0)
    # the theta_h envelope allows the grazing peak at every incidence
    steps = StepCeiling.of_samples(0, th, top, ENVELOPE_SLACK, LOG_CEILING_FACTOR)
    assert np.exp(steps.at(0.0)) == pytest.approx(1400.0)
    # C falls with theta_h and rises with theta_d, and is its staircase everywhere
    rng = np.random.default_rng(0)
    t, d = rng.uniform(-0.1, 1.6, 400), rng.uniform(-0.3, 1.5, 400)
    h = ENVELOPE_D_STEP
    np.testing.assert_allclose(
        env.at2(t, d), _by_hand2(th, td, top, t, d, ENVELOPE_SLACK, g, step=h), rtol=1e-12)
    assert np.all(env.at2(t + 0.05, d) <= env.at2(t, d))
    assert np.all(env.at2(t, d + 0.05) >= env.at2(t, d))
    # a non-finite coordinate allows nothing (C q - p is then -inf: a violation)
    assert np.all(env.at2([np.nan, 0.1, np.inf], [0.5, np.nan, 0.5]) == -np.inf)
    # growth 0: the theta_h envelope
    flat = SampleCeiling.of_samples(0, 1, th, td, top, ENVELOPE_SLACK, LOG_CEILING_FACTOR, 0.0)
    np.testing.assert_allclose(flat.at2(t, d), steps.at(t), rtol=1e-12)
    # the samples under 1 % of the peak (7) do not grow: the diffuse one's value at
    # theta_h 0.8 holds at every theta_d, down to the normal
    assert env.grows.tolist() == [False, True, True, False]
    np.testing.assert_allclose(np.exp(env.at2([0.8, 0.8], [0.0, 1.5])), 0.1, rtol=1e-12)
    every = SampleCeiling(0, 1, env.theta_h, env.theta_d, env.log_ceiling, ENVELOPE_SLACK, g)
    assert np.exp(every.at2(0.8, 0.0)) < 0.09  # had it grown


def test_samples_that_never_decide_the_envelope_are_dropped_without_changing_it() -> None:
    rng = np.random.default_rng(1)
    th, td = rng.uniform(0, 1.4, 500), rng.uniform(0.1, 1.4, 500)
    top = np.exp(rng.normal(0.0, 2.0, 500)) * np.exp(-3 * th + 2 * td)
    env = SampleCeiling.of_samples(0, 1, th, td, top, 0.1, 2.0, 3.0)
    assert 0 < env.theta_h.size < 100  # 500 samples, the rest dominated
    t, d = rng.uniform(-0.2, 1.6, 2000), rng.uniform(-0.2, 1.6, 2000)
    np.testing.assert_allclose(env.at2(t, d),
                               _by_hand2(th, td, top, t, d, 0.1, 3.0, step=ENVELOPE_D_STEP),
                               rtol=1e-12)
    # C at a piece's (largest theta_h, smallest theta_d) corner is its smallest value,
    # and where the opposite corner has it too, C is that value all over the piece
    from ratfit.core.bases import PolynomialSpace

    space = PolynomialSpace("legendre", [[0.0, 1.4], [0.1, 1.4]])
    bound = env.of_pieces(space)
    lo = rng.uniform(-1, 1, (300, 2))
    hi = np.minimum(lo + rng.uniform(0, 0.5, (300, 2)), 1.0)
    c, exact = bound(lo, hi)
    for k in range(300):
        u = rng.uniform(lo[k], hi[k], (50, 2))
        x = space.from_window(u)
        inside = env.at2(x[:, 0], x[:, 1])
        assert np.all(inside >= c[k])
        if exact[k]:
            assert np.all(inside == c[k])
    assert exact.any() and not exact.all()
    # a file's entry round-trips; a malformed one is no ceiling of either kind
    back = envelope_from_dict({"envelope": env.to_dict()})
    assert isinstance(back, SampleCeiling) and back.d_column == 1
    np.testing.assert_array_equal(back.at2(t, d), env.at2(t, d))
    assert StepCeiling.from_dict({"envelope": env.to_dict()}) is None
    for bad in ({"d_column": 0}, {"d_column": True}, {"theta_d": [0.1]},
                {"slack": -1.0}, {"growth": -1.0}, {"growth": None}, {"grows": [True]},
                {"grows": [1] * env.theta_h.size}, {"grows": None},
                {"log_ceiling": [np.nan] * env.theta_h.size}):
        assert envelope_from_dict({"envelope": env.to_dict() | bad}) is None


def _floor_by_hand(theta_h, theta_d, lo, hi, t, d, factor=2.0, highlight=0.01):
    """The floor one point at a time: the largest log(lo_i / factor), lowered to
    log(hi_k / factor) of every sample k with theta_h_k <= theta_h_i and theta_d_k >=
    theta_d_i, over the highlight samples i (hi_i >= highlight x the largest hi, lo_i > 0)
    with theta_h_i >= t and theta_d_i <= d, d taken at the theta_d step at or below it;
    FLOOR_LOG_MIN where there is none."""
    th, td, lo, hi = (np.asarray(a, float) for a in (theta_h, theta_d, lo, hi))
    bright = (hi >= highlight * hi.max()) & (lo > 0)
    v = np.full(th.size, -np.inf)
    for i in np.flatnonzero(bright):
        region = (th <= th[i]) & (td >= td[i])
        v[i] = min(np.log(lo[i] / factor), np.log(hi[region] / factor).min())
    out = []
    for u, w in zip(np.atleast_1d(t), np.atleast_1d(d), strict=True):
        w = ENVELOPE_D_STEP * np.clip(np.floor(w / ENVELOPE_D_STEP), 0,
                                      round(np.pi / 2 / ENVELOPE_D_STEP)) if w >= 0 else -1.0
        near = bright & (th >= u) & (td <= w)
        out.append(max(FLOOR_LOG_MIN, v[near].max()) if near.any() else FLOOR_LOG_MIN)
    return np.array(out)


def test_a_tables_cells_at_one_angle_pair_are_one_point() -> None:
    """A MERL table's phi_d cells share (theta_h, theta_d) up to rounding: the growth, the
    ceiling and the floor are those of the cells' values at exact angles, and no sample
    the ceiling or the floor keeps is dominated by another it keeps."""
    rng = np.random.default_rng(7)
    t_grid = (np.arange(12) / 12) ** 2 * 1.4
    d_grid = np.linspace(0.0, 1.4, 10)
    th = np.repeat(np.repeat(t_grid, 10), 15)
    td = np.repeat(np.tile(d_grid, 12), 15)
    y = np.exp(-6 * th + 2 * td) * np.exp(rng.normal(0.0, 0.3, th.size))
    noisy_t = th * (1 + rng.uniform(-1e-15, 1e-15, th.size)) + rng.uniform(0, 1e-12, th.size)
    noisy_d = td + rng.uniform(-1e-12, 1e-12, td.size)
    g = theta_d_growth(th, td, y)
    assert g > 0 and theta_d_growth(noisy_t, noisy_d, y) == pytest.approx(g, rel=1e-9)
    env = SampleCeiling.of_samples(0, 1, th, td, y, 0.05, 2.0, g)
    assert env.theta_h.size < 120 * 2  # at most one a point and kind (1800 samples)
    t, d = rng.uniform(-0.1, 1.5, 1000), rng.uniform(-0.1, 1.5, 1000)
    np.testing.assert_allclose(env.at2(t, d),
                               _by_hand2(th, td, y, t, d, 0.05, g, step=ENVELOPE_D_STEP),
                               rtol=1e-12)
    kt, kd, kv, kg = env.theta_h, env.theta_d, env.log_ceiling, env.grows
    for i in range(kt.size):
        others = np.arange(kt.size) != i
        over = others & (kt >= kt[i]) & (kv >= kv[i]) & (~kg | (kg[i] & (kd <= kd[i])))
        assert not over.any()
    lo, hi = 0.7 * y, 1.3 * y
    floor = SampleFloor.of_samples(0, 1, th, td, lo, hi, 2.0)
    np.testing.assert_array_equal(floor.at2(t, d), _floor_by_hand(th, td, lo, hi, t, d))
    ft, fd, fv = floor.theta_h, floor.theta_d, floor.log_floor
    assert 0 < ft.size < 120
    for i in range(ft.size):
        others = np.arange(ft.size) != i
        assert not np.any(others & (ft >= ft[i]) & (fd <= fd[i]) & (fv >= fv[i]))


def test_the_floor_is_the_highlight_samples_lower_ends_nearer_mirror_and_grazing() -> None:
    rng = np.random.default_rng(4)
    th, td = rng.uniform(0, 1.4, 400), rng.uniform(0.1, 1.4, 400)
    y = np.exp(rng.normal(0.0, 1.0, 400)) * np.exp(-4 * th + 2 * td)
    lo, hi = 0.6 * y, 1.4 * y
    lo[:5] = 0.0  # no floor from a segment that reaches 0
    floor = SampleFloor.of_samples(0, 1, th, td, lo, hi, LOG_FLOOR_FACTOR)
    # dominated samples dropped: fewer terms, the same floor
    assert 0 < floor.theta_h.size < 60
    t, d = rng.uniform(-0.2, 1.6, 3000), rng.uniform(-0.2, 1.6, 3000)
    np.testing.assert_allclose(floor.at2(t, d), _floor_by_hand(th, td, lo, hi, t, d),
                               rtol=1e-12)
    # never above a sample's own upper end / factor, so the segments stay feasible
    assert np.all(floor.at2(th, td) <= np.log(hi / LOG_FLOOR_FACTOR) + 1e-12)
    # a dim sample (under 1 % of the largest) sets no floor
    dim = SampleFloor.of_samples(0, 1, [0.5, 0.1], [0.5, 1.0], [0.001, 50.0], [0.002, 60.0],
                                 2.0)
    assert dim.theta_h.tolist() == [0.1]
    # a non-finite coordinate allows no value: a violation wherever it is checked
    assert floor.at2([np.nan, 0.1], [0.5, np.inf])[0] == np.inf
    # F's largest value on a piece is at its (smallest theta_h, largest theta_d) corner
    from ratfit.core.bases import PolynomialSpace

    space = PolynomialSpace("legendre", [[0.0, 1.4], [0.1, 1.4]])
    bound = floor.of_pieces(space)
    lo_w = rng.uniform(-1, 1, (300, 2))
    hi_w = np.minimum(lo_w + rng.uniform(0, 0.5, (300, 2)), 1.0)
    top, exact = bound(lo_w, hi_w)
    for k in range(300):
        x = space.from_window(rng.uniform(lo_w[k], hi_w[k], (50, 2)))
        inside = floor.at2(x[:, 0], x[:, 1])
        assert np.all(inside <= top[k])
        if exact[k]:
            assert np.all(inside == top[k])
    assert exact.any() and not exact.all()
    # stored with its ceiling; a floor the file states but that cannot be read: nothing
    env = SampleCeiling.of_samples(0, 1, th, td, hi, 0.1, 2.0, 3.0, floor=floor)
    back = envelope_from_dict({"envelope": env.to_dict()})
    assert isinstance(back, SampleCeiling) and back.floor is not None
    np.testing.assert_array_equal(back.floor.at2(t, d), floor.at2(t, d))
    assert "above the floor of" in back.describe()
    for bad in ({"column": 1}, {"theta_d": [0.1]}, {"log_floor": None}, {"d_column": True}):
        stated = env.to_dict()
        stated["floor"] = stated["floor"] | bad
        assert envelope_from_dict({"envelope": stated}) is None
    with pytest.raises(ValueError):
        SampleCeiling.of_samples(0, 2, th, td, hi, 0.1, 2.0, 3.0, floor=floor)


def test_the_rows_hold_the_floor_where_it_is_set() -> None:
    ds = _material(300)
    fitter, _seg, _meta = fit_brdf(ds, values="log", **WIDTHS)
    assert fitter.success_
    floor = fitter._envelopes[0].floor
    assert floor is not None and floor.theta_h.size > 0
    pts = ds.x[:50]
    rows = fitter._row_floor(0, pts)
    f = floor.at_points(pts)
    set_ = f > FLOOR_LOG_MIN
    assert set_.any() and not set_.all()
    np.testing.assert_allclose(rows[set_], f[set_] + CEILING_ROW_MARGIN)
    assert np.all(rows[~set_] == -np.inf)
    # the polish's rows: one p - F q row for each point with a floor
    rf = fitter.results_[0].rational
    G, _inv = _positivity_rows(rf, pts, numerator=False, ceiling=np.zeros(50), floor=rows)
    assert G.shape[0] == 50 + 50 + int(set_.sum())


def test_the_polish_rows_take_one_ceiling_per_point() -> None:
    rf = _spike(1000.0)
    pts = np.array([[0.01, 0.6, 1.0], [1.0, 1.0, 2.0], [0.5, 0.8, 0.5]])
    ceil = np.array([2000.0, 50.0, -3.0])
    grid, inv = _positivity_rows(rf, pts, numerator=False, ceiling=ceil)
    c = np.concatenate([rf.p, rf.q])
    bound = grid[3:] @ c / inv[3:]
    np.testing.assert_allclose(bound, ceil * rf.denominator(pts) - rf.numerator(pts),
                               rtol=1e-12, atol=1e-12)
    assert bound[0] > 0  # 1000 at the spike, under its own 2000


def test_row_ceilings_are_the_envelope_under_the_channel_ceiling() -> None:
    ds = _material(200)
    f = BRDFFitter(parametrization="RUSIN_TH_TD_SYM", values="log", envelope=True)
    seg = brdf_segments(ds, dt=WIDTHS["dt"], abs_width=WIDTHS["abs_width"])
    f._ceilings = np.log(LOG_CEILING_FACTOR * seg.hi.max(axis=0))
    f._envelopes, proof = f._theta_h_envelopes(seg)
    assert all(isinstance(e, SampleCeiling) for e in f._envelopes)
    # the proof's: the same samples and floor, at the proof's slack
    assert all(p.slack == ENVELOPE_PROOF_SLACK and p.floor is e.floor
               and np.array_equal(p.log_ceiling, e.log_ceiling)
               for e, p in zip(f._envelopes, proof, strict=True))
    pts = np.array([[0.0018, 1.4, 0.0], [0.6, 1.4, 0.0], [1.3, 1.4, 0.0],
                    [0.0018, 0.3, 0.0]])
    rows = f._row_ceiling(0, pts)
    g = theta_d_growth(seg.x[:, 0], seg.x[:, 1], seg.hi)
    assert f._envelopes[0].growth == g > 0
    env = _by_hand2(seg.x[:, 0], seg.x[:, 1], seg.hi[:, 0], pts[:, 0], pts[:, 1],
                    ENVELOPE_SLACK, g, step=ENVELOPE_D_STEP)
    np.testing.assert_allclose(rows, np.minimum(env, f._ceilings[0]) - CEILING_ROW_MARGIN)
    assert rows[0] == pytest.approx(f._ceilings[0] - CEILING_ROW_MARGIN)  # the highlight
    assert rows[2] < rows[1] < rows[0]  # the lobe falls off away from the mirror
    assert rows[3] < rows[0]  # and nearer the normal than its grazing peak
    # a frame without theta_d keeps the envelope over theta_h
    g = BRDFFitter(parametrization="RUSIN_TH_TD_PD", values="log", envelope=True,
                   used_coords=(0, 2))
    one, one_proof = g._theta_h_envelopes(Segments(seg.x[:, [0, 2]], seg.lo, seg.hi, seg.y))
    assert isinstance(one[0], StepCeiling) and isinstance(one_proof[0], StepCeiling)
    for env_t, slack in ((one[0], ENVELOPE_SLACK), (one_proof[0], ENVELOPE_PROOF_SLACK)):
        np.testing.assert_allclose(env_t.at(pts[:, 0]), _by_hand(seg.x[:, 0], seg.hi[:, 0],
                                                                 pts[:, 0], slack))
    f.envelope = False
    f._envelopes, proof = f._theta_h_envelopes(seg)
    assert proof is None
    assert f._row_ceiling(0, pts) == pytest.approx(f._ceilings[0] - CEILING_ROW_MARGIN)


def test_scattered_log_fits_keep_an_envelope_and_say_so() -> None:
    ds = _material(300)
    fitter, _seg, meta = fit_brdf(ds, values="log", **WIDTHS)
    assert fitter.success_ and fitter.envelope is True
    assert meta["envelope"] == {"coordinate": "theta_h, theta_d", "slack": ENVELOPE_SLACK,
                                "proof_slack": ENVELOPE_PROOF_SLACK,
                                "growth": fitter._envelopes[0].growth,
                                "factor": LOG_CEILING_FACTOR,
                                "floor_factor": LOG_FLOOR_FACTOR, "proved": True}
    lin = fit_brdf(ds, values="linear", **WIDTHS)
    assert lin[0].envelope is False and lin[2]["envelope"] is None
    off = fit_brdf(ds, values="log", envelope=False, **WIDTHS)
    assert off[0].envelope is False and off[2]["envelope"] is None
    assert all("envelope" not in p for p in off[2]["proof"])


def test_the_step_ceiling_falls_past_each_record_sample_by_its_slack() -> None:
    # samples at theta_h 0, 0.2, 0.2, 0.5 with upper ends 10, 1, 3, 0.1
    sc = StepCeiling.of_samples(0, [0.2, 0.0, 0.5, 0.2], [1.0, 10.0, 0.1, 3.0],
                                slack=0.1, factor=2.0)
    # the largest end at theta_h >= t - 0.1 falls from 10 past 0.1, from 3 past 0.3
    # (the two samples at 0.2 fall together) and from 0.1 never (the farthest sample)
    np.testing.assert_allclose(sc.theta_h, [0.0, 0.2])
    assert sc.slack == 0.1
    np.testing.assert_allclose(np.exp(sc.log_ceiling), [20.0, 6.0, 0.2])
    t = np.array([-1.0, 0.1, 0.1000001, 0.3, 0.31, 5.0])
    np.testing.assert_allclose(np.exp(sc.at(t)), [20.0, 20.0, 6.0, 6.0, 0.2, 0.2])
    np.testing.assert_allclose(sc.at(t), _by_hand([0.2, 0.0, 0.5, 0.2],
                                                  [1.0, 10.0, 0.1, 3.0], t, 0.1), rtol=1e-12)
    # an entry without a slack (commit a74032d wrote the steps with it added) reads as 0
    old = {"column": 0, "theta_h": [0.1, 0.3], "log_ceiling": sc.log_ceiling.tolist()}
    before = StepCeiling.from_dict({"envelope": old})
    assert before is not None and before.slack == 0.0
    np.testing.assert_array_equal(before.at(t), sc.at(t))
    # a file's entry round-trips; a rising or malformed one is no ceiling
    back = StepCeiling.from_dict({"envelope": sc.to_dict()})
    assert back is not None and back.column == 0
    np.testing.assert_array_equal(back.theta_h, sc.theta_h)
    np.testing.assert_array_equal(back.log_ceiling, sc.log_ceiling)
    bad = sc.to_dict() | {"log_ceiling": [0.0, 1.0, 2.0]}
    assert StepCeiling.from_dict({"envelope": bad}) is None
    assert StepCeiling.from_dict({"envelope": sc.to_dict() | {"column": "0"}}) is None
    assert StepCeiling.from_dict({"envelope": sc.to_dict() | {"slack": -0.1}}) is None
    assert StepCeiling.from_dict({"ceiling": 3.0}) is None


def test_a_step_bound_is_proved_piece_by_piece() -> None:
    """p = -t under C = 2 for t <= 0 and 0.1 past it: p < C everywhere. On the whole
    box the bound is C's smaller value, and the corner t = -1 (p = 1) exceeds it: only a
    piece where C is one number throughout may show a counterexample."""
    q, p = np.array([1.0, 0.0]), np.array([0.0, -1.0])  # Legendre: q = 1, p = -t

    def step(lo, hi):
        c = np.where(hi[:, 0] > 0.0, 0.1, 2.0)
        return c, np.where(lo[:, 0] >= 0.0, True, hi[:, 0] <= 0.0)

    ok = prove_below(q, p, "legendre", step)
    assert ok.proved and not ok.counterexample and ok.boxes >= 3

    # under C = 0.3 past t = -0.5, p = -t exceeds it on (-0.5, -0.3): refuted there
    def low(lo, hi):
        c = np.where(hi[:, 0] > -0.5, 0.3, 2.0)
        return c, np.where(lo[:, 0] >= -0.5, True, hi[:, 0] <= -0.5)

    no = prove_below(q, p, "legendre", low)
    assert not no.proved and no.counterexample
    assert np.all((no.points[:, 0] >= -0.5) & (no.points[:, 0] <= -0.3))


def test_log_fits_prove_their_envelope_and_a_file_is_proved_again(tmp_path) -> None:
    from ratfit.brdf.fitter import save_brdf_fit

    ds = _material(300)
    fitter, _seg, meta = fit_brdf(ds, values="log", **WIDTHS)
    assert fitter.success_
    proof = fitter.proofs_[0]
    assert proof.proved and proof.envelope is not None
    assert "samples' envelope over theta_h and theta_d" in proof.summary()
    entry = meta["proof"][0]
    assert entry["envelope"]["column"] == 0 and entry["envelope"]["d_column"] == 1
    # the proved ceiling is the samples' envelope with the proof's slack
    seg = brdf_segments(ds, dt=WIDTHS["dt"], abs_width=WIDTHS["abs_width"])
    t, d = np.meshgrid(np.linspace(0.0, 1.5, 31), np.linspace(0.0, 1.5, 31))
    env = _by_hand2(seg.x[:, 0], seg.x[:, 1], seg.hi[:, 0], t.ravel(), d.ravel(),
                    ENVELOPE_PROOF_SLACK, theta_d_growth(seg.x[:, 0], seg.x[:, 1], seg.hi),
                    step=ENVELOPE_D_STEP)
    np.testing.assert_allclose(proof.envelope.at2(t.ravel(), d.ravel()), env, rtol=1e-12)
    path = tmp_path / "fit.json"
    save_brdf_fit(path, fitter.results_, meta)
    saved = load_fit(path)
    assert reprove_saved(saved) is True
    assert "under the samples' envelope over theta_h and theta_d" in scope_text(saved, True)
    # the floor is proved too, and a floor above the fit's values is not
    assert proof.floor is not None and proof.floor.proved
    assert "p - F q > 0 (F: the floor) proved" in proof.summary()
    assert entry["floor_margin"] == proof.floor.margin > 0
    rf = fitter.results_[0].rational
    stated = saved.extra["brdf"]["proof"][0]["envelope"]
    kept = dict(stated["floor"])
    stated["floor"]["log_floor"] = [float(np.max(rf(ds.x))) + 1.0] * len(kept["log_floor"])
    assert reprove_saved(saved) is False
    stated["floor"] = kept
    assert reprove_saved(saved) is True
    # a lower envelope than the fit's values is not proved from the same numbers
    stated["log_ceiling"] = [min(stated["log_ceiling"]) - 8.0] * len(stated["log_ceiling"])
    assert reprove_saved(saved) is False
    # an envelope the file states but that cannot be read proves nothing, nor one
    # over another coordinate than theta_h
    saved.extra["brdf"]["proof"][0]["envelope"] = {"column": 0}
    assert reprove_saved(saved) is False
    for column in (1, 7):
        saved.extra["brdf"]["proof"][0]["envelope"] = StepCeiling(
            column, np.array([0.5]), np.array([9.0, 8.0])).to_dict()
        assert reprove_saved(saved) is False
    for column, d_column in ((0, 2), (1, 0)):
        saved.extra["brdf"]["proof"][0]["envelope"] = SampleCeiling(
            column, d_column, np.array([0.5]), np.array([0.5]), np.array([9.0]), 0.1,
            1.0, np.array([True])).to_dict()
        assert reprove_saved(saved) is False
    # a looser one of either kind is proved from the same numbers
    saved.extra["brdf"]["proof"][0]["envelope"] = StepCeiling(
        0, np.array([0.5]), np.array([50.0, 40.0])).to_dict()
    assert reprove_saved(saved) is True
    saved.extra["brdf"]["proof"][0]["envelope"] = SampleCeiling(
        0, 1, np.array([0.5]), np.array([0.5]), np.array([50.0]), 0.1, 1.0,
        np.array([False])).to_dict()
    assert reprove_saved(saved) is True


@pytest.mark.slow
def test_mystique_stays_under_its_samples_off_the_highlight(shared_data) -> None:
    """mystique's default fit reached 1 681 (R), 28 (G) and 12 (B) 1/sr at random pairs
    with theta_h > 0.3, where its largest sample is 0.054 (green fireflies in renders).
    Under the envelope no value there exceeds twice the largest upper end of the samples
    with theta_h > 0.2 (B, at +-90 %: 0.198; its largest value there is 0.135 under the
    envelope over (theta_h, theta_d), 2026-11-29)."""
    from ratfit.brdf.fitter import brdf_fit_of
    from ratfit.jobs.brdf import fit_brdf_file

    path = shared_data / "cornell" / "mystique.brdf"
    report = fit_brdf_file(path)
    assert report.success and report.meta["envelope"] is not None
    fit = brdf_fit_of(report.results, report.meta)
    ds = samples_dataset(read_brdf(path), "RUSIN_TH_TD_SYM")
    rng = np.random.default_rng(3)
    L, V = above_horizon(rng, 200_000, z_min=0.0), above_horizon(rng, 200_000, z_min=0.0)
    coords = get_parametrization("RUSIN_TH_TD_SYM").from_dirs(L, V)
    th = coords[:, 0]
    v = fit.eval_dirs(L, V)
    off = th > 0.3
    dom = np.asarray(fit.saved.channels[0].rational.space.domain)
    x = np.clip(coords, dom[:, 0], dom[:, 1])
    widths = report.meta["segments"]
    for j in range(3):
        y_top = ds.y[ds.x[:, 0] > 0.3 - ENVELOPE_PROOF_SLACK, j].max()  # 0.05 1/sr
        top = y_top * (1 + widths["channel_dt"][j]) + widths["abs_width"][j]
        assert v[off, j].max() <= LOG_CEILING_FACTOR * top * (1 + 1e-9), j
        assert v[off, j].max() < 3 * y_top, j  # no firefly: 1 681 / 28 / 12 before
        # and everywhere under the proved envelope, at the coordinates as the fit clamps
        steps = envelope_from_dict(report.meta["proof"][j])
        assert steps is not None
        assert np.all(v[:, j] <= np.exp(steps.at_points(x)) * (1 + 1e-9)), j
    # along the mirror direction no channel dips between the incidence angles measured
    # there: B fell to 0.009 1/sr at 75 degrees between 11.9 (69 degrees) and 591 (80)
    # under the ceiling alone; above the floor it stays over half the 69-degree sample's
    # lower end
    td = np.radians(np.arange(69.5, 80.0, 0.25))
    mirror = np.stack([np.zeros_like(td), td, np.zeros_like(td)], axis=1)
    Lm, Vm = get_parametrization("RUSIN_TH_TD_PD").to_dirs(mirror)
    vm = fit.eval_dirs(Lm, Vm)
    at69 = np.flatnonzero((ds.x[:, 0] < 0.02) & (np.abs(ds.x[:, 1] - 1.212) < 0.01))
    assert at69.size == 1
    for j in range(3):
        floor = envelope_from_dict(report.meta["proof"][j]).floor
        assert floor is not None
        lo69 = ds.y[at69[0], j] * (1 - widths["channel_dt"][j])
        assert np.all(np.exp(floor.at2(0.0, td)) >= 0.5 * lo69 * (1 - 1e-9)), j
        assert np.all(vm[:, j] >= 0.5 * lo69 * (1 - 1e-9)), j
    assert vm[:, 2].min() > 0.5  # B: 0.009 at 75 degrees before
