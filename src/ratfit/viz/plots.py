"""Headless PNG figures (matplotlib figures on their own Agg canvas), written atomically."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ratfit._atomic import atomic_path
from ratfit.core.rational import RationalFunction
from ratfit.core.segments import Segments
from ratfit.viz._figures import plain

__all__ = ["plot_errors", "plot_fits", "plot_function"]


def _figure():
    """Figure factory on a private Agg canvas: the user's pyplot backend is left alone."""
    from ratfit.viz import _figures

    return _figures


def _save(fig, path: Path) -> Path:
    plt = _figure()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    return path


def _dense(seg: Segments, factor: int = 10) -> NDArray[np.float64]:
    x = seg.x[:, 0]
    return np.linspace(x.min(), x.max(), factor * x.size)


def plot_function(x: NDArray, y: NDArray, path: str | Path) -> Path:
    plt = _figure()
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot(x, y, lw=1.2)
    ax.set_xlabel("x")
    ax.set_ylabel("f(x)")
    ax.set_title("Figure 1: the test function")
    return _save(fig, Path(path))


def plot_fits(seg: Segments, fits: dict[str, RationalFunction | None], path: str | Path) -> Path:
    """Fits over the vertical-segment envelope (1-D, first channel), full and zoomed."""
    plt = _figure()
    x = seg.x[:, 0]
    xd = _dense(seg)
    fig, axes = plt.subplots(1, 2, figsize=(13, 5))
    for ax in axes:
        ax.fill_between(x, seg.lo[:, 0], seg.hi[:, 0], color="0.8", label="segments")
        for name, rf in fits.items():
            if rf is not None:
                ax.plot(xd, rf(xd), lw=1, label=plain(name))
        ax.set_xlabel("x")
        ax.set_ylabel("y = f(x) and r(x)")
    span = seg.hi.max() - min(0.0, seg.lo.min())
    axes[0].set_ylim(min(0.0, seg.lo.min()) - 0.02 * span, seg.hi.max() + 0.05 * span)
    axes[0].set_xlim(x.min(), x.max())
    axes[0].set_title("Figure 2: fits and the segment envelope")
    # zoom on where the last quarter of the domain has something to show
    zoom = x > x.min() + 0.75 * (x.max() - x.min())
    xz, hz = x[zoom], seg.hi[zoom, 0]
    busy = hz > hz.min() + 0.02 * (hz.max() - hz.min())
    a, b = (xz[busy].min(), xz[busy].max()) if busy.any() else (xz.min(), xz.max())
    pad = 0.3 * (b - a) if b > a else 0.05 * (x.max() - x.min())
    axes[1].set_xlim(max(a - pad, xz.min()), min(b + pad, x.max()))
    lo, hi = seg.lo[zoom, 0].min(), seg.hi[zoom, 0].max()
    axes[1].set_ylim(lo - 0.05 * (hi - lo), hi + 0.1 * (hi - lo))
    axes[1].set_title(f"zoom: x in [{axes[1].get_xlim()[0]:.3g}, {axes[1].get_xlim()[1]:.3g}]")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, Path(path))


def plot_errors(seg: Segments, fits: dict[str, RationalFunction | None], path: str | Path) -> Path:
    """Signed error r - y at the data, with the allowed band (segment bounds - y)."""
    plt = _figure()
    x = seg.x[:, 0]
    y = seg.center[:, 0]
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.fill_between(x, seg.lo[:, 0] - y, seg.hi[:, 0] - y, color="0.85", label="allowed")
    for name, rf in fits.items():
        if rf is not None:
            ax.plot(x, rf(seg.x) - y, lw=1, label=plain(name))
    ax.set_yscale("symlog", linthresh=1e-2)
    ax.set_xlabel("x")
    ax.set_ylabel("r(x) - f(x)")
    ax.set_title("Figure 3: signed error of each fit")
    ax.legend(fontsize=8)
    return _save(fig, Path(path))
