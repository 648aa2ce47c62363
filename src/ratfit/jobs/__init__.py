"""Jobs: one library function per thing a user asks ratfit to do with files.

Each job takes one request (a frozen, checked dataclass: input, widths, options,
output) and returns one report (results, timings, messages, and the fit file's
document). The CLI parses, builds a request, calls the job and prints; a batch
manifest builds the same requests; from Python the same calls give the same fits.

The names below are imported from their modules on first use: ``ratfit fit`` (and
anything that needs only ``ratfit.jobs.common``) does not load the BRDF package.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ratfit._lazy import lazy_names

if TYPE_CHECKING:
    from ratfit.jobs.brdf import (
        BRDFFitReport,
        BRDFFitRequest,
        BRDFMergeReport,
        BRDFMergeRequest,
        fit_brdf_file,
        merge_brdf_fits,
    )
    from ratfit.jobs.fit import FitReport, FitRequest, fit_file
    from ratfit.jobs.render import RenderReport, RenderRequest, render_fit

_WHERE = {
    "BRDFFitReport": "brdf", "BRDFFitRequest": "brdf", "fit_brdf_file": "brdf",
    "BRDFMergeReport": "brdf", "BRDFMergeRequest": "brdf", "merge_brdf_fits": "brdf",
    "FitReport": "fit", "FitRequest": "fit", "fit_file": "fit",
    "RenderReport": "render", "RenderRequest": "render", "render_fit": "render",
}

__all__ = ["BRDFFitReport", "BRDFFitRequest", "BRDFMergeReport", "BRDFMergeRequest",
           "FitReport", "FitRequest", "RenderReport", "RenderRequest", "fit_brdf_file",
           "fit_file", "merge_brdf_fits", "render_fit"]


__getattr__, __dir__ = lazy_names(globals(), _WHERE)
