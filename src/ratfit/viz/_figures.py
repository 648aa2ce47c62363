"""Figures without pyplot: a ``Figure`` on an Agg canvas, never ``matplotlib.use``.

pyplot keeps global state and its backend choice is global too: a library that
switches it (``matplotlib.use("Agg")``) breaks a notebook user's inline or
interactive figures. Files are written through the figure's own Agg canvas, so
nothing global is touched, and nothing is imported until a picture is drawn.
"""

from __future__ import annotations

from typing import Any

__all__ = ["close", "plain", "subplots"]

_FIGURE_KEYS = ("figsize", "dpi", "facecolor", "edgecolor", "layout", "constrained_layout",
                "tight_layout")


def subplots(*args: Any, **kw: Any) -> tuple[Any, Any]:
    """Like ``pyplot.subplots``: a new (figure, axes) on its own Agg canvas."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(**{k: kw.pop(k) for k in _FIGURE_KEYS if k in kw})
    FigureCanvasAgg(fig)
    return fig, fig.subplots(*args, **kw)


def plain(text: Any) -> str:
    """``text`` shown as written: every ``$`` escaped, so a channel or file name never
    becomes mathtext markup (an even count of ``$`` would switch it on, and a malformed
    formula such as ``$\\nope$`` would stop the picture with an error)."""
    return str(text).replace("$", r"\$")


def close(fig: Any) -> None:
    """Release a figure (nothing global to unregister: it never joined pyplot)."""
    fig.clear()
