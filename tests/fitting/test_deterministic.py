"""The same command gives the same answer on any load, with any --jobs, in any channel
order (issue 26): the default budget counts QP solves, not seconds."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from ratfit.core.options import DEFAULT_TIME_LIMIT, DEFAULT_WORK_LIMIT
from ratfit.core.segments import Segments
from ratfit.fitting.search import RationalFitter
from ratfit.io.data import read_data


def _three_channels() -> Segments:
    x = np.linspace(0.0, 3.0, 400)
    y = np.stack([np.exp(-x) * np.cos(3 * x), 1 / (1.2 + np.sin(2 * x)), np.sqrt(1 + x)], 1)
    return Segments.from_widths(x, y, dt=1e-3, abs_width=1e-4)


def _same(a, b) -> None:
    assert len(a) == len(b)
    for r, s in zip(a, b, strict=True):
        assert (r.status, r.n, r.m) == (s.status, s.n, s.m), (r.message, s.message)
        assert r.qp_solves == s.qp_solves
        if r.rational is not None:
            assert np.array_equal(r.rational.p, s.rational.p)
            assert np.array_equal(r.rational.q, s.rational.q)


def test_defaults_are_a_work_budget_not_a_clock():
    assert DEFAULT_TIME_LIMIT is None and DEFAULT_WORK_LIMIT > 0
    r = RationalFitter().fit(_three_channels()).results_[0]
    assert r.work_limit == DEFAULT_WORK_LIMIT and r.summary()["work_limit"] == r.work_limit


def test_jobs_and_channel_order_do_not_change_the_answer():
    seg = _three_channels()
    one = RationalFitter(jobs=1).fit(seg).results_
    two = RationalFitter(jobs=2).fit(seg).results_
    assert all(r.success for r in one)
    _same(one, two)
    # channels reversed: each channel's answer is its own, not the neighbour's
    back = Segments(seg.x, seg.lo[:, ::-1].copy(), seg.hi[:, ::-1].copy())
    rev = RationalFitter(jobs=2).fit(back).results_[::-1]
    for r, s in zip(one, rev, strict=True):
        assert (r.n, r.m) == (s.n, s.m)
        assert np.array_equal(r.rational.p, s.rational.p)
    # every split of one total in threads: the same candidates as one at a time
    t = one[1].n + one[1].m
    _same(RationalFitter(jobs=1, total=t).fit(seg).results_,
          RationalFitter(jobs=2, total=t).fit(seg).results_)


def test_a_fixed_size_fits_channels_side_by_side_with_the_same_answer(channel_threads):
    """One fixed (n, m) is one split a channel: with two jobs the channels run in
    threads instead (small data too), and each keeps the answer it gets in turn."""
    seg = _three_channels()
    seen = channel_threads
    one = RationalFitter(jobs=1, n=6, m=5).fit(seg).results_
    two = RationalFitter(jobs=2, n=6, m=5).fit(seg).results_
    assert seen == [1, 2]
    assert [(r.n, r.m) for r in one] == [(6, 5)] * 3
    assert sum(r.success for r in one) >= 2  # real fits compared, not three failures
    _same(one, two)
    # a fixed total still tests its splits in threads, one channel after another
    RationalFitter(jobs=2, total=11).fit(seg)
    assert seen[-1] == 1


def _kirby2(shared_data) -> Segments:
    return read_data(shared_data / "nist" / "Kirby2.dat").segments(dt=1e-3)


def test_the_budget_stops_at_the_same_split_under_a_cpu_hog(shared_data):
    """A budget that ends the search half way: the same stop, the same fit, idle or
    with busy-loop processes on every core, with one thread or two; and the same
    complete fits of three channels."""
    seg = _kirby2(shared_data)
    three = _three_channels()
    idle = RationalFitter(jobs=1, work_limit=40).fit(seg).results_
    assert idle[0].time_limited and "work limit of 40 QP solves" in idle[0].message
    full_idle = RationalFitter(jobs=1).fit(three).results_
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(3)]
    try:
        busy = RationalFitter(jobs=2, work_limit=40).fit(seg).results_
        full_busy = RationalFitter(jobs=2).fit(three).results_
    finally:
        for h in hogs:
            h.kill()
            h.wait()
    _same(idle, busy)
    assert all(r.success and not r.time_limited for r in full_idle)
    _same(full_idle, full_busy)


@pytest.mark.slow
def test_brdf_channels_do_not_depend_on_jobs(shared_data):
    from ratfit.brdf.fitter import fit_brdf
    from ratfit.brdf.io import brdf_dataset

    path = shared_data / "alta" / "data-example-01.exr"
    if not path.exists():
        pytest.skip(f"{path} not found")
    ds = brdf_dataset(path, None, max_points=400)
    one, _, _ = fit_brdf(ds, dt=0.22, jobs=1)
    two, _, _ = fit_brdf(ds, dt=0.22, jobs=2)
    assert one.success_
    _same(one.results_, two.results_)
