"""Two-dimensional dominance queries over samples, in O(N log^2 N) array passes.

The BRDF envelopes (:mod:`ratfit.brdf.validity`) ask, for each sample, questions
like "the smallest upper end among the samples nearer the normal and nearer
grazing" or "is there an earlier sample with theta_h as large and theta_d as
small". A loop over samples with a mask each is O(N^2): on a full MERL table
(1.1e6 cells) it ran for hours. Both kinds of question are a prefix of one order
and a threshold on one key, answered here by a merge-sort tree: for each power of
two, the elements in blocks of that width sorted by key with a running maximum of
the value; a prefix is the union of one block per set bit of its length.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["first_of_groups", "groups", "prefix_max"]


def prefix_max(key: ArrayLike, value: ArrayLike, count: ArrayLike,
               bound: ArrayLike) -> NDArray[np.float64]:
    """For each query q: the largest ``value[k]`` over the first ``count[q]`` elements
    (in the order given) with ``key[k] <= bound[q]``; -inf where there is none.

    Exact: keys are compared as given (no tolerance). ``key`` must be free of NaN."""
    key_a = np.asarray(key, dtype=float).ravel()
    val_a = np.asarray(value, dtype=float).ravel()
    cnt = np.asarray(count, dtype=np.int64).ravel()
    bnd = np.asarray(bound, dtype=float).ravel()
    n = key_a.size
    if val_a.size != n or bnd.size != cnt.size or np.any(cnt < 0) or np.any(cnt > n):
        raise ValueError("prefix_max needs one value per key and counts within 0..N")
    out = np.full(cnt.size, -np.inf)
    if n == 0 or cnt.size == 0:
        return out
    uniq = np.unique(key_a)
    n_ranks = uniq.size
    rank = np.searchsorted(uniq, key_a)
    q_rank = np.searchsorted(uniq, bnd, side="right") - 1  # -1: no key is small enough
    size = 1 << max(0, int(n - 1).bit_length())
    # padding: the rank past every key, the value below every value
    rank_p = np.full(size, n_ranks, dtype=np.int64)
    rank_p[:n] = rank
    val_p = np.full(size, -np.inf)
    val_p[:n] = val_a
    stride = np.int64(n_ranks + 1)
    width = 1
    while width <= size:
        take = (cnt & width) != 0
        if np.any(take):
            # the prefix's block of this width: the one just below count's lower bits
            comp = (np.arange(size, dtype=np.int64) // width) * stride + rank_p
            order = np.argsort(comp, kind="stable")
            running = np.maximum.accumulate(val_p[order].reshape(-1, width), axis=1).ravel()
            block = cnt[take] // width - 1
            at = np.searchsorted(comp[order], block * stride + q_rank[take], side="right")
            found = at > block * width
            got = np.where(found, running[np.maximum(at - 1, 0)], -np.inf)
            out[take] = np.maximum(out[take], got)
        width *= 2
    return out


def groups(*keys: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The distinct points of ``keys`` (arrays of one length, the first the most
    significant), each as the index of its first element, in sorted order, and each
    element's point."""
    cols = [np.asarray(k) for k in keys]
    order = np.lexsort(cols[::-1])  # stable: within a point, the elements' own order
    new = np.ones(order.size, dtype=bool)
    new[1:] = False
    for c in cols:
        s = c[order]
        new[1:] |= s[1:] != s[:-1]
    label = np.empty(order.size, dtype=np.intp)
    label[order] = np.cumsum(new) - 1
    return order[new], label


def first_of_groups(order: ArrayLike, *keys: ArrayLike) -> NDArray[np.intp]:
    """The first element of ``order`` (indices) in each group of equal ``keys``
    (arrays over all indices), as indices, in the order of ``order``."""
    idx = np.asarray(order, dtype=np.intp)
    if idx.size == 0:
        return idx
    # groups' sort is stable, so each group's first element is its first position
    first, _ = groups(*(np.asarray(k)[idx] for k in keys))
    return idx[np.sort(first)]
