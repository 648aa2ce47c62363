"""The bracket gallops in steps growing by half: a feasible probe far above the answer
is the most expensive test of a big search. The walk below still proves the minimum."""

from __future__ import annotations

import numpy as np
import pytest

from ratfit.core.segments import Segments
from ratfit.fitting.search import RationalFitter


@pytest.mark.slow
def test_gallop_steps_grow_by_half_and_the_answer_is_the_exhaustive_one() -> None:
    x = np.linspace(-1.0, 1.0, 400)
    seg = Segments.from_relative(x, np.exp(np.sin(4 * x)) / (1.2 + x), 1e-3)
    walk = RationalFitter(jobs=1).fit(seg).result_
    every = RationalFitter(jobs=1, strategy="exhaustive").fit(seg).result_
    assert (walk.n, walk.m) == (every.n, every.m) == (10, 4)
    probes = [(h["n"], h["m"]) for h in walk.history[:6]]
    # balanced splits at totals 2, 3, 5, 8, 12, 18 (doubling steps: 2, 3, 5, 9, 17, 33)
    assert probes == [(1, 1), (2, 1), (3, 2), (4, 4), (6, 6), (9, 9)]
    assert walk.history[5]["status"] == "feasible"
    # the walk below 15 tests column m at 15 first ((14, 1), (13, 2), (12, 3) infeasible
    # rule out (13, 1), (12, 2), (11, 3)); (11, 4) verifies there, then (10, 4) at 14
    # too: one split more than a walk straight down column 4, where the seed's data
    # saves 11 (no split of the total below the bracket fits)
    assert len(walk.history) == 21 < len(every.history) == 91
    assert [(h["n"], h["m"]) for h in walk.history[9:14]] == [
        (14, 1), (13, 2), (12, 3), (11, 4), (10, 4)]
