"""Jobs: one library function per thing a user asks ratfit to do with files.

Each job takes one request (a frozen, checked dataclass: input, widths, options,
output) and returns one report (results, timings, messages, and the fit file's
document). The CLI parses, builds a request, calls the job and prints; a batch
manifest builds the same requests; from Python the same calls give the same fits.
"""

from ratfit.jobs.brdf import BRDFFitReport, BRDFFitRequest, fit_brdf_file
from ratfit.jobs.fit import FitReport, FitRequest, fit_file
from ratfit.jobs.render import RenderReport, RenderRequest, render_fit

__all__ = ["BRDFFitReport", "BRDFFitRequest", "FitReport", "FitRequest", "RenderReport",
           "RenderRequest", "fit_brdf_file", "fit_file", "render_fit"]
