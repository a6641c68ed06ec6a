"""Shared fixtures and the ``unit`` marker.

Real field logs are looked up in $ONBOARD_DATA or ../shared/data. Every test not marked
``integration`` is marked ``unit``, so ``-m unit`` and ``-m integration`` split the suite
(markers in pyproject.toml).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def shared_data_dir() -> Path | None:
    """The directory of real field logs, or None when it is not present."""
    env = os.environ.get("ONBOARD_DATA")
    for cand in ([Path(env)] if env else []) + [REPO.parent / "shared" / "data"]:
        if cand.is_dir():
            return cand
    return None


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path to ../shared/data; skips the test with a clear reason when it is absent."""
    d = shared_data_dir()
    if d is None:
        pytest.skip("real field logs not found: set ONBOARD_DATA or place shared/data beside the repo")
    return d


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark every test that is not an integration test as a unit test."""
    for item in items:
        if item.get_closest_marker("integration") is None:
            item.add_marker(pytest.mark.unit)
