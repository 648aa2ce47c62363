"""Segments at one repeated x that do not overlap: no function fits, said at once (issue 26)."""

from __future__ import annotations

import numpy as np
from conftest import run_cli, write_file

from ratfit.core.segments import Segments
from ratfit.fitting.search import RationalFitter, disjoint_repeats


def _repeats(width: float) -> Segments:
    # Chwirut2's shape: several readings at each x, up to 20 % apart
    x = np.repeat(np.linspace(0.5, 6.0, 12), 3)
    y = np.exp(-0.2 * x) * 100 * (1 + 0.1 * np.tile([-1.0, 0.0, 1.0], 12))
    return Segments.from_relative(x, y, width)


def test_disjoint_repeats_exit_1_before_any_search():
    r = RationalFitter(jobs=1).fit(_repeats(0.01)).result_
    assert r.status == 1 and not r.success
    assert r.message.startswith("no function fits: at x = 0.5 ")
    assert "do not overlap" in r.message and "12 repeated x" in r.message
    assert r.qp_solves == 0 and r.history == ()


def test_overlapping_repeats_are_searched():
    seg = _repeats(0.2)  # +-20 %: the three readings at each x overlap
    assert disjoint_repeats(seg, 0) is None
    r = RationalFitter(jobs=1).fit(seg).result_
    assert r.success


def test_disjoint_in_two_dimensions():
    x = np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 0.0], [0.0, 1.0]])
    lo = np.array([0.0, 1.0, 2.0, 1.5])
    seg = Segments.from_bounds(x, lo, lo + 0.2)
    assert "rows 1 and 3" in disjoint_repeats(seg, 0)
    seg = Segments.from_bounds(x, lo, lo + 0.6)
    assert disjoint_repeats(seg, 0) is None


def test_cli_says_it_in_one_line(tmp_path):
    seg = _repeats(0.01)
    y = 0.5 * (seg.lo[:, 0] + seg.hi[:, 0])
    rows = "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(seg.x[:, 0], y, strict=True))
    path = write_file(tmp_path, "rep.csv", "x,y\n" + rows)
    res = run_cli("fit", path, "--dt", "0.01", "--jobs", "1")
    assert res.exit_code == 1, res.output
    lines = [ln for ln in res.output.splitlines() if "no function fits" in ln]
    assert lines, res.output
    assert "Traceback" not in res.output


def test_give_up_says_what_was_covered():
    """Noise no small rational meets (Gauss1's kind): the status-1 message counts the
    splits of the totals searched that infeasible splits rule out, that gave no
    verdict and that were not tested; the three add up to every split."""
    rng = np.random.default_rng(0)
    x = np.linspace(0, 1, 120)
    seg = Segments.from_relative(x, 10 + rng.normal(size=x.size), 1e-3)
    r = RationalFitter(jobs=1, max_total=12).fit(seg).result_
    assert r.status == 1
    import re

    total = re.search(r"of the (\d+) splits of these totals, (\d+) are ruled out", r.message)
    assert total is not None, r.message
    assert int(total.group(1)) == sum(t - 1 for t in range(2, 13))
    counts = [int(total.group(2))]
    for pat in (r"(\d+) tested gave no verdict", r"(\d+) were not tested"):
        hit = re.search(pat, r.message)
        counts.append(int(hit.group(1)) if hit else 0)
    assert sum(counts) == int(total.group(1)), r.message
