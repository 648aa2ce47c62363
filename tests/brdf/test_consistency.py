"""Default segments describe the measurement: samples at nearly the same point whose
segments are disjoint get the hull of the two; a user's segments are never changed."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ratfit.brdf.consistency import CONSISTENT_NEAR, SAME_POINT, consistent_segments
from ratfit.brdf.fitter import HALF_VECTOR, brdf_segments, fit_brdf, nonnegative_segments
from ratfit.brdf.io import brdf_dataset
from ratfit.core.segments import Segments
from ratfit.fitting.search import disjoint_repeats


def test_disjoint_neighbours_get_their_hull_and_nothing_else_moves() -> None:
    x = np.array([[0.0, 0.0], [0.005, 0.0], [1.0, 1.0], [0.5, 0.5], [0.505, 0.5]])
    y = np.array([[1.0], [2.0], [1.0], [1.0], [1.05]])
    seg = Segments.from_widths(x, y, dt=0.1)
    out, n = consistent_segments(seg)
    assert n == 2  # rows 0 and 1: [0.9, 1.1] and [1.8, 2.2] are disjoint
    assert out.lo[0, 0] == out.lo[1, 0] == 0.9 and out.hi[0, 0] == out.hi[1, 0] == 2.2
    # rows 3 and 4 are as close but overlap; row 2 has no neighbour: unchanged
    assert np.array_equal(out.lo[2:], seg.lo[2:]) and np.array_equal(out.hi[2:], seg.hi[2:])
    assert np.array_equal(out.center, seg.center)  # the data are the data
    # farther apart than CONSISTENT_NEAR (axes scaled to [0, 1]): left alone
    far = x.copy()
    far[1, 0] = 2.5 * CONSISTENT_NEAR
    same, n_far = consistent_segments(Segments.from_widths(far, y, dt=0.1))
    assert n_far == 0 and np.array_equal(same.lo, Segments.from_widths(far, y, dt=0.1).lo)


def test_each_channel_is_made_consistent_on_its_own() -> None:
    """A pair disjoint in channel a only: a takes the hull, b keeps its segments (a
    channel's segments, hence its fit, do not depend on which channels come with it)."""
    x = np.array([[0.0, 0.0], [0.005, 0.0], [1.0, 1.0]])
    y = np.array([[1.0, 1.0], [2.0, 1.05], [1.0, 1.0]])
    seg = Segments.from_widths(x, y, dt=0.1)
    out, n = consistent_segments(seg)
    assert n == 2
    assert out.lo[0, 0] == out.lo[1, 0] == 0.9 and out.hi[0, 0] == out.hi[1, 0] == 2.2
    assert np.array_equal(out.lo[:, 1], seg.lo[:, 1]) and np.array_equal(out.hi[:, 1],
                                                                          seg.hi[:, 1])
    alone, _ = consistent_segments(Segments.from_widths(x, y[:, 1:], dt=0.1))
    assert np.array_equal(alone.lo[:, 0], out.lo[:, 1])


def test_a_chain_of_disjoint_neighbours_ends_consistent_in_one_pass() -> None:
    x = np.array([[0.0], [0.01], [0.025], [1.0]])
    y = np.array([[1.0], [3.0], [9.0], [1.0]])
    seg = Segments.from_widths(x, y, dt=0.05)
    out, n = consistent_segments(seg)
    assert n == 3
    # nearest neighbours: 0 <-> 1, 2 -> 1; 1 takes the union of both hulls
    assert np.allclose([out.lo[1, 0], out.hi[1, 0]], [0.95, 9.45], rtol=1e-15)
    assert np.allclose([out.lo[0, 0], out.hi[0, 0]], [0.95, 3.15], rtol=1e-15)
    assert np.allclose([out.lo[2, 0], out.hi[2, 0]], [2.85, 9.45], rtol=1e-15)
    again, n_again = consistent_segments(out)
    assert n_again == 0 and np.array_equal(again.lo, out.lo)


def test_samples_at_one_point_share_a_value() -> None:
    """Six samples at one point (a MERL table's phi_d cells at theta_h = 0), two of
    them 1e-16 apart (phi_d and pi - phi_d), with values 1..32: nearest-neighbour hulls
    alone chain them pairwise and leave no common value; the group gets its hull. A
    point nearby but not the same keeps its own pairwise treatment."""
    x = np.zeros((8, 3))
    x[:, 1] = 0.5
    x[1, 2] = 1e-16
    x[6] = [0.3, 0.5, 0.0]  # elsewhere: untouched
    x[7] = [1.0, 1.0, 1.0]
    y = np.array([[1.0], [2.0], [4.0], [8.0], [16.0], [32.0], [5.0], [5.0]])
    seg = Segments.from_widths(x, y, dt=0.1)
    out, n = consistent_segments(seg)
    assert n == 6
    assert np.all(out.lo[:6, 0] == 0.9) and np.all(out.hi[:6, 0] == 35.2)
    assert np.array_equal(out.lo[6:], seg.lo[6:]) and np.array_equal(out.hi[6:], seg.hi[6:])
    assert disjoint_repeats(out, 0) is None
    # groups whose segments already share a value are left as they are
    close = Segments.from_widths(x, np.array([[1.0], [1.1], [1.05], [1.0], [1.1], [1.0],
                                              [5.0], [5.0]]), dt=0.1)
    same, n_same = consistent_segments(close)
    assert n_same == 0 and np.array_equal(same.lo, close.lo)
    # farther apart than SAME_POINT: a pair for the nearest-neighbour pass, not a group
    apart = x.copy()
    apart[1, 2] = 10 * SAME_POINT
    again, _ = consistent_segments(Segments.from_widths(apart, y, dt=0.1))
    assert disjoint_repeats(again, 0) is None
    again2, n2 = consistent_segments(again)
    assert n2 == 0


def test_garnet_red_noise_level_segments_are_made_consistent(shared_data: Path) -> None:
    """garnet_red in the half-vector frame at +-6 % with a 1e-3 1/sr floor: some samples
    conflict with their nearest neighbour (at 80 degrees the light and the viewer nearly
    exchanged give values 10x apart); only those are widened, and a user's --dt segments
    are left as given."""
    ds = brdf_dataset(shared_data / "cornell" / "garnet_red.brdf", HALF_VECTOR)
    seg = brdf_segments(ds, dt=0.06, abs_width=1e-3)
    out, n = consistent_segments(seg)
    assert 0 < n < 0.2 * ds.n_points
    again, n_again = consistent_segments(out)
    assert n_again == 0 and np.array_equal(again.lo, out.lo)
    # the fit records how many it widened; a user's widths are the user's
    _, user_seg, meta = fit_brdf(ds, dt=0.1, abs_width=1e-3, max_total=2, polish=False)
    assert meta["segments"]["merged"] == 0
    given = nonnegative_segments(brdf_segments(ds, dt=0.1, abs_width=1e-3))
    assert np.array_equal(user_seg.lo, given.lo) and np.array_equal(user_seg.hi, given.hi)


def test_a_channel_with_no_candidate_is_widened_alone() -> None:
    """Default widths of a table: channel b has one point measured twice, 1.0 and 1.2 (disjoint at
    +-5 %), so it has no candidate; it is refitted alone at 0.08, then 0.12, where the
    two overlap, while channel a keeps its fit at 0.05."""
    from ratfit.io.data import Dataset

    g = np.linspace(0.0, 1.0, 6)
    x = np.stack([c.ravel() for c in np.meshgrid(g, g)], axis=1)
    x = np.concatenate([x, x[:10], x[20:21]])  # ten repeats with equal values, one not
    a = 1.0 + 0.5 * x[:, 0]
    b = np.where(x[:, 1] > 0.9, 0.0, 1.0)  # measured zeros on one edge
    b[20] = 1.0
    b[-1] = 1.2
    ds = Dataset(x, np.stack([a, b], axis=1), None, None, ("u", "v"), ("a", "b"),
                 {"param_in": "UNKNOWN", "format": "merl"})  # a table: noise-level floor
    fitter, seg, meta = fit_brdf(ds, consistent=False, polish=False)
    assert meta["segments"]["dt"] == 0.05
    assert meta["segments"]["channel_dt"] == [0.05, 0.12]
    assert fitter.success_ and "widened to +- 0.12 y for this channel alone" in \
        fitter.results_[1].message
    # the widened channel's segments are in the returned segments; a's are as they were
    assert np.isclose(seg.hi[-1, 1], 1.2 * 1.12) and np.isclose(seg.hi[0, 0], 1.05 * a[0])
    assert fitter.results_[0].n + fitter.results_[0].m <= 3
    # the widened channel keeps its floor: measured zeros keep segments of nonzero width
    zeros = b == 0.0
    assert zeros.any() and np.allclose(seg.hi[zeros, 1], 1e-3)


def test_a_ladder_finds_its_samples_neighbours_once(monkeypatch) -> None:
    """A table's default fit refitted at a wider width (fit_brdf_auto's ladder refits
    the same dataset) reuses the first fit's nearest-neighbour search, and gets the same
    segments as a search of its own; a dataset with other samples but the same meta
    dict (a subset built with dataclasses.replace) searches its own."""
    from dataclasses import replace

    import ratfit.brdf.consistency as consistency
    from ratfit.io.data import Dataset

    calls: list[int] = []
    search = consistency.sample_neighbours

    def counted(x, *a, **k):
        calls.append(len(x))
        return search(x, *a, **k)

    monkeypatch.setattr(consistency, "sample_neighbours", counted)
    g = np.linspace(0.0, 1.0, 8)
    x = np.stack([c.ravel() for c in np.meshgrid(g, g, g)], axis=1)
    y = (1.0 + x[:, 0] + x[:, 1] * x[:, 2])[:, None]
    # twenty cells measured twice, one of them 30 % apart (disjoint at +-5 %: merged)
    x, y = np.concatenate([x, x[:20]]), np.concatenate([y, y[:20]])
    y[-1] *= 1.3
    ds = Dataset(x, y, None, None, ("u", "v", "w"), ("a",), {"param_in": "UNKNOWN",
                                                               "format": "merl"})
    _, seg1, meta1 = fit_brdf(ds, max_total=6, polish=False)
    _, seg2, meta2 = fit_brdf(ds, dt=0.08, abs_width=1e-3, consistent=True, max_total=6,
                              polish=False)
    assert calls == [len(x)]
    fresh = Dataset(x.copy(), y, None, None, ds.input_names, ("a",),
                    {"param_in": "UNKNOWN", "format": "merl"})
    _, seg3, meta3 = fit_brdf(fresh, dt=0.08, abs_width=1e-3, consistent=True,
                              max_total=6, polish=False)
    assert calls == [len(x)] * 2
    assert np.array_equal(seg2.lo, seg3.lo) and np.array_equal(seg2.hi, seg3.hi)
    assert meta1["segments"]["merged"] > 0 and meta2["segments"]["merged"] == \
        meta3["segments"]["merged"]
    half = replace(ds, x=x[::2], y=y[::2])  # other samples, the same meta dict
    assert half.meta is ds.meta
    _, seg4, _ = fit_brdf(half, dt=0.08, abs_width=1e-3, consistent=True, max_total=6,
                          polish=False)
    assert calls == [len(x)] * 2 + [len(x[::2])] and seg4.lo.shape[0] == len(x[::2])
