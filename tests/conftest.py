"""Shared fixtures, the ``unit`` marker and the parallel groups.

Real field logs are looked up in $ONBOARD_DATA or ../shared/data. Every test not marked
``integration`` is marked ``unit``, so ``-m unit`` and ``-m integration`` split the suite
(markers in pyproject.toml).

``make test`` runs the suite on every core (pytest-xdist, ``--dist loadscope``). One worker
runs each module whole (its module-scoped fixtures are computed once), and the modules of
``FIGURE_RUN_MODULES`` together (they read the same memoised simulator runs,
``validation.reports.runs``, which a second worker would fly again).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

FIGURE_RUN_MODULES = frozenset({"test_figures", "test_aie_sitl", "test_closed_loop",
                                "test_current_sitl", "test_diagnose_sitl"})
"""Test modules that share the runs memoised in ``validation.reports.runs`` (the
default suite's figures recompute the AIE, current, closed-loop and diagnosis runs these
modules assert on): one unit of work for pytest-xdist, so each run is flown once."""
FIGURE_RUN_GROUP = "figure-runs"


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


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """With ``--dist loadscope`` (pytest-xdist): each module one unit of work, the modules of
    ``FIGURE_RUN_MODULES`` one unit together (see the module docstring)."""
    if config.getvalue("dist") != "loadscope":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class _Scheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            return FIGURE_RUN_GROUP if Path(module).stem in FIGURE_RUN_MODULES else module

    return _Scheduling(config, log)
