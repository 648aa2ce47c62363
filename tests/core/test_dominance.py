"""ratfit.core.dominance against loops over every pair."""

from __future__ import annotations

import numpy as np
import pytest

from ratfit.core.dominance import first_of_groups, prefix_max


def _by_loop(key, value, count, bound):
    return np.array([max((value[k] for k in range(c) if key[k] <= b), default=-np.inf)
                     for c, b in zip(count, bound, strict=True)])


@pytest.mark.parametrize("seed", range(6))
def test_prefix_max_is_the_loop(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for n in (1, 2, 3, 7, 8, 9, 64, 100):
        key = rng.integers(0, 5, n).astype(float)  # ties on purpose
        value = rng.normal(size=n)
        count = rng.integers(0, n + 1, 50)
        bound = rng.integers(-1, 6, 50) + rng.choice([0.0, 0.5], 50)
        got = prefix_max(key, value, count, bound)
        np.testing.assert_array_equal(got, _by_loop(key, value, count, bound))


def test_prefix_max_edges() -> None:
    assert prefix_max([], [], [0, 0], [1.0, 2.0]).tolist() == [-np.inf, -np.inf]
    assert prefix_max([1.0], [3.0], [], []).size == 0
    # the whole array, a key equal to the bound, -inf keys
    got = prefix_max([2.0, -np.inf, 5.0], [1.0, 4.0, 9.0], [3, 3, 1], [2.0, -np.inf, 1.0])
    assert got.tolist() == [4.0, 4.0, -np.inf]
    with pytest.raises(ValueError):
        prefix_max([1.0, 2.0], [1.0, 2.0], [3], [0.0])


def test_first_of_groups_keeps_the_order_given() -> None:
    a = np.array([1, 0, 1, 0, 1, 2])
    b = np.array([0, 0, 0, 1, 0, 0])
    order = np.array([4, 3, 2, 1, 0, 5])
    # groups (1, 0): 4 first; (0, 1): 3; (0, 0): 1; (2, 0): 5
    assert first_of_groups(order, a, b).tolist() == [4, 3, 1, 5]
    assert first_of_groups(np.array([], dtype=int), a).size == 0
