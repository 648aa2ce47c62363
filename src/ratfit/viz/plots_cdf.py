"""Figure of a CDF fit: density, histogram of samples, CDF with its segments."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ratfit.cdf.sampling import RationalCDF
from ratfit.core.segments import Segments
from ratfit.viz._figures import plain
from ratfit.viz.plots import _figure, _save

__all__ = ["plot_cdf_fit"]


def plot_cdf_fit(
    model: RationalCDF,
    seg: Segments,
    samples: NDArray[np.float64],
    path: str | Path,
    *,
    true_pdf: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None,
    true_cdf: Callable[[NDArray[np.float64]], NDArray[np.float64]] | None = None,
    title: str = "",
    xlabel: str = "x",
) -> Path:
    """Three panels: pdf (fitted r' and the truth), histogram of samples, CDF and segments."""
    plt = _figure()
    # Show where the probability is: a lobe squeezed into the last tenth of the domain
    # would leave most of each panel empty.
    grid = np.linspace(model.a, model.b, 4001)
    F = model.cdf(grid)
    lo_i = int(np.searchsorted(F, 1e-4)) - 1
    hi_i = int(np.searchsorted(F, 1.0 - 1e-4))
    a = grid[max(lo_i, 0)]
    b = grid[min(hi_i, grid.size - 1)]
    if b - a < 0.8 * (model.b - model.a) and b > a:
        pad = 0.05 * (b - a)
        a, b = max(model.a, a - pad), min(model.b, b + pad)
    else:
        a, b = model.a, model.b
    x = np.linspace(a, b, 2000)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    ax = axes[0]
    if true_pdf is not None:
        ax.plot(x, true_pdf(x), color="0.6", lw=3, label="true pdf")
    ax.plot(x, model.pdf(x), color="C0", lw=1.2, label="fitted pdf r'(x)")
    ax.set_title("density")
    ax.set_ylabel("probability density p(x)")
    ax.legend(fontsize=8)
    ax = axes[1]
    ax.hist(samples, bins=120, range=(a, b), density=False,
            weights=np.full(samples.size, 120.0 / ((b - a) * max(samples.size, 1))),
            color="C1", alpha=0.6, label=f"{samples.size} samples")
    ax.plot(x, model.pdf(x), color="C0", lw=1, label="fitted pdf")
    ax.set_title("histogram of samples")
    ax.set_ylabel("samples per bin / (N * bin width)")
    ax.legend(fontsize=8)
    ax = axes[2]
    xs = seg.x[:, 0]
    ax.vlines(xs, seg.lo[:, 0], seg.hi[:, 0], color="0.5", lw=2, label="segments")
    if true_cdf is not None:
        ax.plot(x, true_cdf(x), color="0.3", lw=1, ls="--", label="true cdf")
    ax.plot(x, model.rational(x), color="C3", lw=1, label="fitted r(x)")
    ax.set_title("CDF and its vertical segments")
    ax.set_ylabel("F(x) = P(X <= x)")
    ax.legend(fontsize=8)
    for axx in axes:
        axx.set_xlabel(plain(xlabel))
        axx.set_xlim(a, b)
    if (a, b) != (model.a, model.b):
        title = (title + "; " if title else "") + (
            f"shown: x in [{a:.3g}, {b:.3g}] (outside: < 0.01 % of the probability)")
    if title:
        fig.suptitle(plain(title))
    fig.tight_layout()
    return _save(fig, Path(path))
