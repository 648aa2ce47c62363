"""Shared fixtures: where the real external data lives.

CI has ``../shared`` beside the checkout; ``RATFIT_SHARED_DATA`` overrides the
path of its ``data`` folder.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def shared_data_dir() -> Path:
    env = os.environ.get("RATFIT_SHARED_DATA")
    return Path(env) if env else REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    path = shared_data_dir()
    if not path.is_dir():
        msg = f"shared data folder not found at {path} (set RATFIT_SHARED_DATA)"
        if os.environ.get("CI"):
            pytest.fail(msg)  # CI has the data beside the checkout: never skip there
        pytest.skip(msg)
    return path
