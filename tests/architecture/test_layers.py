"""The import-layer contract: a package imports only packages of lower layers.

Data flows one way (data -> segments -> QP -> fit -> verified result -> export); a
lower layer that imports an upper one (even inside a function) breaks that and
brings back import cycles. Packages on one layer are independent of each other.
The jobs (file -> request -> fit -> report) sit above everything they drive and
below the two front ends that only build requests for them: batch and the CLI.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2] / "src" / "ratfit"

# Lowest first. Packages sharing a layer must not import each other.
LAYERS: list[set[str]] = [
    {"_version", "errors", "_atomic", "_quiet", "_progress", "_lazy"},
    {"core"},
    {"fitting", "io"},
    {"cdf", "brdf"},
    {"export"},
    {"viz"},
    {"demos", "render"},
    {"jobs"},
    {"batch"},
    {"cli"},
    {"__init__", "__main__"},
]
RANK = {name: i for i, layer in enumerate(LAYERS) for name in layer}


def _unit(module: str) -> str:
    """The layer unit of a dotted ratfit module: its first component below ``ratfit``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _modules() -> list[tuple[str, Path]]:
    out = []
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC.parent).with_suffix("")
        dotted = ".".join(rel.parts)
        out.append((dotted, path))
    return out


def _imports(dotted: str, path: Path) -> list[tuple[int, str]]:
    """Every ratfit module imported anywhere in the file (function bodies included)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = dotted if path.name == "__init__.py" else dotted.rpartition(".")[0]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if node.module is None or mod == "ratfit":
                found += [(node.lineno, f"{mod}.{a.name}") for a in node.names]
            else:
                found.append((node.lineno, mod))
    return [(line, m) for line, m in found if m == "ratfit" or m.startswith("ratfit.")]


def test_every_package_has_a_layer() -> None:
    units = {_unit(d) for d, _ in _modules()}
    assert units <= set(RANK), f"packages without a layer: {sorted(units - set(RANK))}"


@pytest.mark.parametrize("dotted,path", _modules(), ids=lambda v: str(v))
def test_imports_go_down_the_layers(dotted: str, path: Path) -> None:
    me = _unit(dotted)
    bad = []
    for line, target in _imports(dotted, path):
        other = _unit(target)
        if other == "__init__" and target != "ratfit":
            other = target.split(".")[1] if target.count(".") else "__init__"
        if other == me:
            continue
        if RANK.get(other, -1) >= RANK[me]:
            bad.append(f"{path.name}:{line} imports {target} ({other}, layer {RANK.get(other)})")
    assert not bad, f"{dotted} (layer {RANK[me]}) imports upward or sideways:\n" + "\n".join(bad)


def test_jobs_are_the_floor_between_the_library_and_its_front_ends() -> None:
    """Jobs use the library (never the CLI or batch); the CLI and batch reach the
    fitting and reading code only through jobs for the three main jobs."""
    assert RANK["batch"] > RANK["jobs"] > max(RANK[p] for p in ("fitting", "io", "brdf",
                                                                "render", "export"))
    assert RANK["cli"] > RANK["batch"]
    jobs = [(d, p) for d, p in _modules() if _unit(d) == "jobs"]
    assert jobs, "no ratfit.jobs package"
    for dotted, path in jobs:
        for _, target in _imports(dotted, path):
            assert _unit(target) not in ("cli", "batch"), f"{dotted} imports {target}"
    front = {"ratfit.cli.fit": "ratfit.jobs", "ratfit.cli.brdf": "ratfit.jobs",
             "ratfit.cli.render": "ratfit.jobs", "ratfit.batch.runner": "ratfit.jobs"}
    for dotted, path in _modules():
        if dotted in front:
            targets = {t for _, t in _imports(dotted, path)}
            assert any(t.startswith(front[dotted]) for t in targets), dotted
            # no search of its own: the job runs it
            assert not targets & {"ratfit.fitting.search",
                                  "ratfit.fitting.shared_denominator"}, dotted


def test_the_contract_catches_a_violation(tmp_path: Path) -> None:
    """The checker itself: a core module importing the CLI is reported."""
    fake = tmp_path / "ratfit" / "core" / "bad.py"
    fake.parent.mkdir(parents=True)
    fake.write_text("def f():\n    from ratfit.cli.main import main\n    from . import bases\n")
    found = _imports("ratfit.core.bad", fake)
    assert found == [(2, "ratfit.cli.main"), (3, "ratfit.core.bases")]
    assert RANK[_unit("ratfit.cli.main")] > RANK[_unit("ratfit.core.bad")]


def test_no_cli_function_is_longer_than_60_lines() -> None:
    """The CLI parses, builds a request, calls a job and prints: nothing there grows
    into a pipeline again (``brdf fit``'s callback was 157 lines). Lines from ``def``
    to the end of the body; decorators (the options) not counted."""
    long = []
    for path in sorted((SRC / "cli").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                size = (node.end_lineno or node.lineno) - node.lineno + 1
                if size > 60:
                    long.append(f"{path.name}:{node.lineno} {node.name} ({size} lines)")
    assert not long, long
