"""Standalone source (C, GLSL, Python) that evaluates a saved fit.
"""

from ratfit.export.code import (
    LANGS,
    ChannelForm,
    ExportResult,
    export_fit,
    export_source,
    plan_forms,
)

__all__ = [
    "ChannelForm",
    "ExportResult",
    "LANGS",
    "export_fit",
    "export_source",
    "plan_forms",
]
