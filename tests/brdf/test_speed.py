"""The speedups of big BRDF fits change the time, never the answer."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import ratfit.core.qp as qp
from ratfit.brdf.fitter import fit_brdf
from ratfit.brdf.io import brdf_dataset
from ratfit.fitting.search import RationalFitter


def _exr(shared_data: Path, points: int):
    path = shared_data / "alta" / "data-example-01.exr"
    if not path.exists():
        pytest.skip(f"{path} not found")
    return brdf_dataset(path, None, channels=["B"], max_points=points)


@pytest.mark.slow
def test_warm_start_and_subset_bases_give_the_cold_answer(shared_data: Path,
                                                          monkeypatch) -> None:
    ds = _exr(shared_data, 800)
    cold_fitter = fit_brdf  # same call, speedups switched off below
    monkeypatch.setattr(qp, "BASIS_POINTS", 10**9)
    cold, seg, _ = cold_fitter(ds, dt=0.22, jobs=1, warm_start=False)
    # 800 points > 4 x 160: bases on 160 spread points, rows elsewhere on demand
    monkeypatch.setattr(qp, "BASIS_POINTS", 160)
    warm, _, _ = fit_brdf(ds, dt=0.22, jobs=1)
    c, w = cold.results_[0], warm.results_[0]
    assert c.success and w.success
    assert (w.n, w.m) == (c.n, c.m)
    assert w.n + w.m >= 10  # a real search, not a constant
    # verified on every sample: the fit lies in every segment
    r = w.rational(seg.x)
    assert np.all((seg.lo[:, 0] <= r) & (r <= seg.hi[:, 0]))
    assert w.verification.n_points == 800 and w.verification.max_violation == 0.0


@pytest.mark.slow
def test_subset_fit_says_so_in_its_status(shared_data: Path) -> None:
    """--max-points: the status is "verified on a subset of K of N samples", never
    plain "verified", in the table, the result's message and the JSON."""
    import json

    from conftest import run_cli

    path = shared_data / "alta" / "data-example-01.exr"
    if not path.exists():
        pytest.skip(f"{path} not found")
    args = ["brdf", "fit", path, "--dt", "0.22", "--channel", "B", "--max-points", "300"]
    res = run_cli(*args, "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    want = "verified on a subset of 300 of 262144 samples only"
    assert doc["status"].startswith(want)
    assert doc["subset"] == {"points": 300, "of": 262144, "by": "samples"}
    assert doc["n_points"] == 300
    assert doc["channels"][0]["message"].startswith(want)
    assert "not checked at the other 261844" in doc["channels"][0]["message"]
    text = run_cli(*args)
    assert text.exit_code == 0, text.output
    row = next(ln for ln in text.stdout.splitlines() if ln.strip().startswith("B "))
    assert " subset " in row and " yes " not in row
    assert f"status: {want}" in text.stdout
    # the library's result says it too
    ds = _exr(shared_data, 300)
    fitter, _, meta = fit_brdf(ds, dt=0.22)
    assert fitter.results_[0].message.startswith("verified on a subset of 300 of 262144")
    # and keeps what the search said after it (a time limit would say "may not be minimal")
    assert "; verified fit found" in fitter.results_[0].message
    assert meta["verified_on"] == "a random subset of 300 of 262144 samples"


@pytest.mark.slow
def test_channels_side_by_side_give_each_channel_its_own_answer(shared_data: Path,
                                                                monkeypatch,
                                                                channel_threads) -> None:
    """Large multi-channel data is searched a channel per thread (splits one at a
    time, no hint between channels, validity points kept per channel while it runs):
    each channel's answer is the one it gets fitted alone, whatever the timing, and
    every channel is verified on all samples."""
    import ratfit.fitting.search as search

    path = shared_data / "alta" / "data-example-01.exr"
    if not path.exists():
        pytest.skip(f"{path} not found")
    ds = brdf_dataset(path, None, max_points=600)
    seen = channel_threads
    monkeypatch.setattr(search, "CHANNEL_THREADS_POINTS", 500)
    both, seg, meta = fit_brdf(ds, dt=0.22, jobs=2)
    assert seen == [2] and both.success_
    import pickle

    assert not hasattr(both, "_cancel")
    assert pickle.loads(pickle.dumps(both)).results_[0].n == both.results_[0].n
    for j, name in enumerate(seg.names):
        alone, seg1, _ = fit_brdf(brdf_dataset(path, None, channels=[name], max_points=600),
                                  dt=0.22, jobs=1)
        a, b = alone.results_[0], both.results_[j]
        assert (b.n, b.m) == (a.n, a.m), name
        # polished and proved in its thread beside the other searches: the same numbers
        assert np.array_equal(b.rational.p, a.rational.p), name
        assert np.array_equal(b.rational.q, a.rational.q), name
        r = b.rational(seg.x)
        assert np.all((seg.lo[:, j] <= r) & (r <= seg.hi[:, j]))
        assert meta["validity"][j].startswith("proved: ")
    assert seen == [2]  # the single-channel fits ran in turn


def test_an_interrupted_channel_thread_stops_the_others() -> None:
    """Ctrl-C while channels run side by side: the other channels stop at their next
    split (KeyboardInterrupt), not after their whole search."""
    import threading

    from ratfit.core.bases import PolynomialSpace
    from ratfit.core.segments import Segments
    from ratfit.fitting.search import SearchEngine

    x = np.linspace(0.0, 1.0, 50)
    seg = Segments.from_widths(x, np.exp(x), dt=0.01)
    fitter = RationalFitter(jobs=1)
    space = fitter.prepare(seg)
    assert space.domain.tolist() == PolynomialSpace("legendre", [[0.0, 1.0]]).domain.tolist()
    cancel = threading.Event()
    run = SearchEngine(fitter.options_, fitter.search_parts(space, seg), space, seg, 0,
                       cancel=cancel)
    run.test_many([(3, 1)])  # runs while not cancelled
    assert (3, 1) in run.cache
    cancel.set()
    with pytest.raises(KeyboardInterrupt):
        run.test_many([(4, 2)])


@pytest.mark.slow
def test_kept_rows_change_the_time_not_the_fit(shared_data: Path, monkeypatch) -> None:
    """Large data: a split's rows at every point are kept per chunk only as far as the
    process's DESIGN_BUDGET goes, the rest computed again each round. With nothing
    kept, everything kept or a few chunks kept, the same coefficients come out, and the
    budget is all given back."""
    ds = _exr(shared_data, 800)
    monkeypatch.setattr(qp, "BASIS_POINTS", 160)  # 800 > 4 x 160: rows on demand
    monkeypatch.setattr(qp, "_CHUNK", 64)  # 13 chunks
    fits = {}
    kept = []
    real_keep = qp._ChunkStore.keep

    def keep(self, i, pair):
        real_keep(self, i, pair)
        kept.append(i in self.chunks)

    monkeypatch.setattr(qp._ChunkStore, "keep", keep)
    for limit in (1 << 40, 0, 3 * 64 * 8 * 40):
        monkeypatch.setattr(qp._DESIGN_BUDGET, "limit", limit)
        kept.clear()
        fitter, seg, _ = fit_brdf(ds, dt=0.22, jobs=1)
        res = fitter.results_[0]
        assert res.success
        fits[limit] = (res.n, res.m, res.rational.p, res.rational.q)
        assert qp._DESIGN_BUDGET.used == 0
        # what the budget allowed: every chunk, none, some
        assert kept and (all(kept) if limit == 1 << 40 else not all(kept))
        assert any(kept) == (limit != 0)
    (a, *others) = fits.values()
    for b in others:
        assert b[:2] == a[:2] and np.array_equal(b[2], a[2]) and np.array_equal(b[3], a[3])
