"""The documentation runs: README's Python section and the public API's examples.

The README's Python section is executed as written (in a scratch folder), and
every public entry point carries a numpydoc docstring whose Examples pass.
"""

from __future__ import annotations

import doctest
import importlib
import inspect
import re
from pathlib import Path

import pytest

import ratfit

README = Path(__file__).resolve().parents[2] / "README.md"

# Main entry points of the subpackages, besides ratfit.__all__.
ENTRY_POINTS = [
    "ratfit.cdf.MonotoneFitter",
    "ratfit.brdf.BRDFFitter",
    "ratfit.fitting.SharedDenominatorFitter",
    "ratfit.io.save_fit",
    "ratfit.io.load_fit",
    "ratfit.io.read_data",
    "ratfit.cdf.fit_cdf",
    "ratfit.core.segments.Segments.from_widths",
    "ratfit.core.estimator.Estimator",
    "ratfit.core.options.FitOptions",
    "ratfit.jobs.fit_file",
]
PUBLIC = [f"ratfit.{name}" for name in ratfit.__all__
          if name not in ("__version__", "FAMILIES")] + ENTRY_POINTS


def _python_blocks(text: str) -> list[str]:
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def test_readme_python_section_runs_as_written(tmp_path: Path, monkeypatch) -> None:
    sections = {part.split("\n", 1)[0].strip(): part
                for part in ("\n" + README.read_text()).split("\n## ")[1:]}
    blocks = _python_blocks(sections["Python"])
    assert blocks, "README.md's Python section has no ```python block"
    monkeypatch.chdir(tmp_path)
    ns: dict = {"__name__": "__readme__"}
    for i, code in enumerate(blocks):
        exec(compile(code, f"README.md python block {i + 1}", "exec"), ns)  # noqa: S102
    # What the quick Python example promises in its comments.
    res = ns["res"]
    assert res.success and res.verification.max_violation == 0.0
    assert ns["r"] is ns["fitter"].rational_
    report = ns["report"]
    assert report.success and (report.results[0].n, report.results[0].m) == (1, 2)
    assert (tmp_path / "pole.json").is_file()


def _resolve(dotted: str):
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for attr in parts[cut:]:
            obj = getattr(obj, attr)
        return obj
    raise ImportError(dotted)


@pytest.mark.parametrize("dotted", PUBLIC)
def test_public_api_has_numpydoc_and_its_examples_pass(dotted: str) -> None:
    obj = _resolve(dotted)
    doc = inspect.getdoc(obj) or ""
    assert doc, f"{dotted} has no docstring"
    if isinstance(obj, type) and issubclass(obj, Exception):
        return  # exceptions: a sentence on when they are raised is the whole story
    assert "Examples\n--------" in doc, f"{dotted}: no Examples section"
    target = obj.__init__ if isinstance(obj, type) else obj
    takes = [p.name for p in inspect.signature(target).parameters.values()
             if p.name not in ("self", "cls") and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    if takes:  # a dataclass's fields may be documented as its Attributes
        assert "Parameters\n----------" in doc or "Attributes\n----------" in doc, (
            f"{dotted}: no Parameters section")
    if isinstance(obj, type) and hasattr(obj, "fit"):
        assert "Attributes\n----------" in doc, f"{dotted}: no Attributes section"
    finder = doctest.DocTestFinder(recurse=False)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    tests = finder.find(obj, dotted, globs={})
    assert any(t.examples for t in tests), f"{dotted}: Examples without doctest lines"
    for t in tests:
        runner.run(t)
    assert runner.failures == 0, f"{dotted}: {runner.failures} example(s) failed"
