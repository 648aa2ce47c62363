"""Packaging facts that tools rely on: one version source, type information shipped,
the slow marker registered (``-m "not slow"`` is the quick suite)."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import ratfit

ROOT = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_the_version_is_written_once() -> None:
    project = PYPROJECT["project"]
    assert "version" not in project and "version" in project["dynamic"]
    attr = PYPROJECT["tool"]["setuptools"]["dynamic"]["version"]["attr"]
    assert attr == "ratfit._version.__version__"
    assert re.fullmatch(r"\d+\.\d+\.\d+", ratfit.__version__)
    hits = [p for p in (ROOT / "src").rglob("*.py")
            if re.search(r"__version__\s*=", p.read_text())]
    assert hits == [ROOT / "src" / "ratfit" / "_version.py"]


def test_type_information_ships_with_the_package() -> None:
    assert (ROOT / "src" / "ratfit" / "py.typed").is_file()
    assert "py.typed" in PYPROJECT["tool"]["setuptools"]["package-data"]["ratfit"]
    assert any(d.startswith("mypy") for d in PYPROJECT["project"]["optional-dependencies"]
               ["test"])


def test_the_slow_marker_is_registered() -> None:
    markers = PYPROJECT["tool"]["pytest"]["ini_options"]["markers"]
    assert any(m.startswith("slow:") for m in markers)
