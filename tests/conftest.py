"""Shared fixtures, the ``unit`` marker and the parallel groups.

Real field logs are looked up in $ONBOARD_DATA or ../shared/data. Every test not marked
``integration`` is marked ``unit``, so ``-m unit`` and ``-m integration`` split the suite
(markers in pyproject.toml).

``make test`` runs the suite on every core (pytest-xdist, ``--dist loadscope``). One worker
runs each module whole (its module-scoped fixtures are computed once), and the modules of
``FIGURE_RUN_MODULES`` together (they read the same memoised simulator runs,
``validation.reports.runs``, which a second worker would fly again). The units are handed
out longest first (``LONGEST_FIRST``, then by their number of tests), so that a long
module does not start last and leave the other workers idle at the end.
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

LONGEST_FIRST = ("test_compiled", FIGURE_RUN_GROUP, "test_batch", "test_faults",
                 "test_real_logs", "test_demo", "test_fleet_history", "test_autopilot_streams",
                 "test_service", "test_diagnose_real", "test_closure_synthetic", "test_bench",
                 "test_wheel", "test_diagnose_robust", "test_service_sitl")
"""The units of work that take longest, longest first (the default suite's
``--durations=0`` summed per unit, 2026-12-03: test_compiled 129 s, its wheel built in
its setup; test_faults and the figure runs 58 s each; test_batch 55 s; the rest 18-42 s),
handed out first; the others follow by their number of tests, as pytest-xdist orders
them. test_faults, whose flights run in real time and are flown again when the service
falls behind, starts after the figure runs and the batch, not beside the compiler (its
fixtures took 45-57 s beside it against 20-30 s before)."""


def _unit(item: pytest.Item) -> str:
    """The unit of work an item belongs to: its module, or the figure runs' group."""
    stem = Path(str(item.fspath)).stem
    return FIGURE_RUN_GROUP if stem in FIGURE_RUN_MODULES else stem


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
    """Mark every test that is not an integration test as a unit test; order the units of
    work longest first (``LONGEST_FIRST``; a stable sort: the tests within a unit keep
    their order)."""
    for item in items:
        if item.get_closest_marker("integration") is None:
            item.add_marker(pytest.mark.unit)
    counts: dict[str, int] = {}
    for item in items:
        counts[_unit(item)] = counts.get(_unit(item), 0) + 1
    rank = {u: i for i, u in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda it: (rank.get(_unit(it), len(rank)), -counts[_unit(it)], _unit(it)))


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log):
    """With ``--dist loadscope`` (pytest-xdist): each module one unit of work, the modules of
    ``FIGURE_RUN_MODULES`` one unit together (see the module docstring)."""
    if config.getvalue("dist") != "loadscope":
        return None
    from xdist.scheduler import LoadScopeScheduling

    config.option.loadscopereorder = False  # the collection is in order already

    class _Scheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            return FIGURE_RUN_GROUP if Path(module).stem in FIGURE_RUN_MODULES else module

    return _Scheduling(config, log)
