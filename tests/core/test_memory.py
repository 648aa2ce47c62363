"""Handing free heap memory back: asked where glibc can, a no-op elsewhere."""

from __future__ import annotations

import sys

import numpy as np

import ratfit.core.memory as memory
import ratfit.core.qp as qp


def test_release_free_memory_asks_glibc_on_linux_only(monkeypatch) -> None:
    asked = memory.release_free_memory()
    assert asked == (memory._trim() is not None)
    if sys.platform.startswith("linux"):
        import platform

        if platform.libc_ver()[0] == "glibc":
            assert asked
    monkeypatch.setattr(memory, "_TRIM", None)
    monkeypatch.setattr(memory, "_LOOKED", True)
    assert memory.release_free_memory() is False


def test_a_large_split_hands_memory_back_after_its_full_pass(monkeypatch) -> None:
    """ArnoldiSystem.release trims the heap after a pass over every point (large data),
    not after a split decided on the spread subset."""
    from ratfit.core.bases import PolynomialSpace
    from ratfit.core.segments import Segments

    calls: list[int] = []
    monkeypatch.setattr(memory, "release_free_memory", lambda: calls.append(1) or True)
    monkeypatch.setattr(qp, "BASIS_POINTS", 40)
    rng = np.random.default_rng(0)
    x = rng.uniform(-1, 1, (400, 2))
    seg = Segments.from_widths(x, 1.0 / (2.0 + x[:, 0] + 0.5 * x[:, 1]), dt=0.01)
    space = PolynomialSpace("legendre", seg.bounds())
    q0 = qp.sk_denominator(space, seg, 0, 3, 3, as_function=True)
    system = qp.ArnoldiSystem(space, seg, 0, 3, 3, q0)
    assert system.sub is not None  # 400 > 4 x 40: rows on demand
    system.release()
    assert calls == []  # nothing was computed at every point
    system.residuals(3, 3, np.ones(6))
    system.release()
    assert calls == [1]
    assert qp._DESIGN_BUDGET.used == 0


def test_prefer_small_pages_turns_numpy_huge_pages_off() -> None:
    """The command's process asks numpy for small pages: numpy's switch returns its
    previous state, which is off after prefer_small_pages."""
    core = getattr(np, "_core", None) or np.core
    switch = core.multiarray._set_madvise_hugepage
    before = switch(True)
    try:
        assert memory.prefer_small_pages() is True
        assert switch(False) is False
    finally:
        switch(before)
