"""Figure of a CDF fit: density, histogram of samples, CDF with its segments."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ratfit.cdf.sampling import RationalCDF
from ratfit.core.segments import Segments
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
    x = np.linspace(model.a, model.b, 2000)
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    ax = axes[0]
    if true_pdf is not None:
        ax.plot(x, true_pdf(x), color="0.6", lw=3, label="true pdf")
    ax.plot(x, model.pdf(x), color="C0", lw=1.2, label="fitted pdf r'(x)")
    ax.set_title("density")
    ax.legend(fontsize=8)
    ax = axes[1]
    ax.hist(samples, bins=120, range=(model.a, model.b), density=True, color="C1", alpha=0.6,
            label=f"{samples.size} samples")
    ax.plot(x, model.pdf(x), color="C0", lw=1, label="fitted pdf")
    ax.set_title("histogram of samples")
    ax.legend(fontsize=8)
    ax = axes[2]
    xs = seg.x[:, 0]
    ax.vlines(xs, seg.lo[:, 0], seg.hi[:, 0], color="0.5", lw=2, label="segments")
    if true_cdf is not None:
        ax.plot(x, true_cdf(x), color="0.3", lw=1, ls="--", label="true cdf")
    ax.plot(x, model.rational(x), color="C3", lw=1, label="fitted r(x)")
    ax.set_title("CDF and its vertical segments")
    ax.legend(fontsize=8)
    for a in axes:
        a.set_xlabel(xlabel)
    if title:
        fig.suptitle(title)
    return _save(fig, Path(path))
