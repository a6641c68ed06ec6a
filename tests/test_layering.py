"""The layering of the code, enforced from its imports.

Every module belongs to a room (its longest matching prefix in :data:`ROOMS`); a room may
import only the rooms listed for it. Imports are read from the source with :mod:`ast`,
inside functions too (a lazy import is still a dependency at run time), and so are the
module names given to ``importlib.import_module`` as string literals. Imports under
``if TYPE_CHECKING:`` are type hints only and do not count.

The rooms, from the bottom up (docs/architecture.md §2 has the picture):

* ``onboard.core``: messages, configuration, errors, geometry, vehicle classes,
  statistics. Imports nothing of ours.
* ``onboard.estimators``: the estimation mathematics, pure; only the core.
* ``onboard.pipelines``: the registered pipelines, thin adapters over the estimators.
* ``drivers``: bytes to samples; only the core.
* ``sitl``: the simulator; the core and the drivers' MAVLink and log writers. Its
  closed-loop runner (``sitl.closed_loop``) also runs the onboard engine, because the
  closed loop is the experiment.
* ``onboard.monitor``: the innovations' summary, integrity, the warnings; only the core.
* ``onboard.engine``: the stages of a sample's way in (time line, checks, declination,
  corrections, depth, sources, inputs) on the core alone; the GNSS latency's horizon on the
  pipelines; the engine itself (queue and tick) on all of them and the monitors.
* ``onboard.service``: the asyncio daemon, intake, recorder, publishers.
* ``onboard.offline``: the offline commands: replay (its estimates.csv writer on the
  engine), autodetection, exports, the track figure; the model closure above them and
  ``onboard diagnose`` above it.
* ``onboard.fleet``: the fleet's current field (shore side), pure on the core; its Zenoh
  service (``onboard.fleet.service``) also on the Zenoh session's configuration, the web
  page and the drivers' MCAP import; its set and drift for chart plotters
  (``onboard.fleet.chartplot``) on the vehicles' UDP senders and formats.
* ``onboard.cli``: parses arguments, dispatches by module name.
* ``onboard.apps``: demo, shore view, benchmarks, gain design, installer; may use
  everything, the simulator included.
* ``validation`` (the checkout's docs machinery, not installed): everything.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests.helpers.imports import REPO, imports_of, module_name

CORE = {"onboard.core"}
MATH = CORE | {"onboard.estimators"}
PIPELINES = MATH | {"onboard.pipelines"}
MONITOR = CORE | {"onboard.monitor"}
ENGINE = PIPELINES | MONITOR | {"onboard.engine"}
SERVICE = ENGINE | {"onboard.drivers", "onboard.service"}
OFFLINE = ENGINE | {"onboard.drivers", "onboard.service.recorder", "onboard.offline.replay",
                    "onboard.offline.estimates_csv", "onboard.offline.autodetect",
                    "onboard.offline.exports", "onboard.offline.plots"}
CLOSURE = OFFLINE | {"onboard.offline.closure"}
EVERYTHING = SERVICE | CLOSURE | {"onboard.offline", "onboard.apps", "onboard.cli",
                                  "onboard.sitl", "onboard.fleet"}

ROOMS: dict[str, set[str]] = {
    "onboard.core": CORE,
    "onboard.estimators": MATH,
    "onboard.pipelines": PIPELINES,
    "onboard.drivers": CORE | {"onboard.drivers"},
    "onboard.sitl": CORE | {"onboard.drivers", "onboard.sitl"},
    "onboard.sitl.closed_loop": CORE | {"onboard.drivers", "onboard.sitl", "onboard.engine"},
    "onboard.monitor": MONITOR,
    "onboard.engine": CORE | {"onboard.engine"},  # the package and its stages
    "onboard.engine.latency": PIPELINES,
    "onboard.engine.engine": ENGINE,
    "onboard.service": SERVICE,
    "onboard.offline": set(),  # the package's docstring
    "onboard.offline.estimates_csv": ENGINE,
    "onboard.offline.autodetect": CORE,
    "onboard.offline.exports": CORE,
    "onboard.offline.plots": CORE,
    "onboard.offline.replay": OFFLINE,
    "onboard.offline.closure": CLOSURE,
    "onboard.offline.diagnose": CLOSURE,
    "onboard.offline.batch": CLOSURE | {"onboard.offline.diagnose", "onboard.offline.batch",
                                        "onboard.offline.batch_tables"},
    "onboard.offline.batch_tables": OFFLINE,
    "onboard.fleet": CORE | {"onboard.fleet"},  # the fleet's field, pure
    "onboard.fleet.chartplot": CORE | {"onboard.fleet", "onboard.service.publishers"},
    "onboard.fleet.service": CORE | {"onboard.fleet", "onboard.service.publishers",
                                     "onboard.service.web", "onboard.drivers"},
    "onboard.cli": CORE | {"onboard"},
    "onboard.apps": EVERYTHING,
    "validation": EVERYTHING | {"validation"},
    "onboard": {"onboard"},  # the package's __init__ and __main__
}
"""Room -> the rooms it may import. Keys and values are module-name prefixes."""

COMMANDS_INTO_SITL = {"sitl": "onboard.sitl.cli:main"}
"""The only command the CLI dispatches into the simulator."""


def _room(module: str, rooms: dict[str, set[str]] = ROOMS) -> str:
    """The longest prefix of ``module`` in ``rooms``."""
    best = ""
    for name in rooms:
        if (module == name or module.startswith(name + ".")) and len(name) > len(best):
            best = name
    if not best:
        raise AssertionError(f"{module} is in no room: add it to ROOMS")
    return best


def _allowed(target: str, allowed: set[str]) -> bool:
    return any(target == a or target.startswith(a + ".") for a in allowed)


def _sources() -> list[Path]:
    return sorted(p for top in ("onboard", "drivers", "sitl", "validation")
                  for p in (REPO / top).rglob("*.py"))


@pytest.mark.parametrize("path", _sources(), ids=lambda p: str(p.relative_to(REPO)))
def test_each_module_imports_only_the_rooms_below_it(path: Path) -> None:
    module = module_name(path)
    allowed = ROOMS[_room(module)]
    own_room = _room(module)
    wrong = [f"line {line}: {target}" for line, target in imports_of(path)
             if not _allowed(target, allowed | {own_room})]
    assert not wrong, f"{module} (room {own_room}) imports outside {sorted(allowed)}: {wrong}"


def test_only_the_apps_validation_and_the_closed_loop_runner_import_the_simulator() -> None:
    importers = {module_name(p) for p in _sources()
                 if any(_allowed(t, {"onboard.sitl"}) for _, t in imports_of(p))}
    outside = {m for m in importers
               if not m.startswith(("onboard.sitl", "onboard.apps", "validation"))}
    assert not outside, f"modules outside the tools importing sitl: {sorted(outside)}"


ESTIMATOR_FORMULAS = {"onboard.core.geo", "onboard.core.so3", "onboard.estimators",
                      "onboard.pipelines"}
"""The estimators' geodesy, rotations and mathematics: the simulator computes its own
(onboard.sitl.frames: pymap3d, scipy's Rotation; docs/sitl.md)."""
SIM_EVALUATION = {"onboard.sitl.closed_loop"}
"""Simulator modules that run or score the estimators (the closed loop is the experiment)."""


def _formula_imports(path: Path, module: str | None = None) -> list[str]:
    return [f"line {line}: {t}" for line, t in imports_of(path, module)
            if _allowed(t, ESTIMATOR_FORMULAS)]


def test_the_simulator_shares_no_formula_module_with_the_estimators() -> None:
    wrong = {module_name(p): _formula_imports(p) for p in sorted((REPO / "sitl").rglob("*.py"))
             if module_name(p) not in SIM_EVALUATION}
    wrong = {m: w for m, w in wrong.items() if w}
    assert not wrong, f"simulator modules importing the estimators' formulas: {wrong}"


def test_the_formula_check_sees_a_shared_rotation(tmp_path: Path) -> None:
    """A negative control: a plant that rotates with the estimators' so3 is caught."""
    fake = tmp_path / "probe.py"
    fake.write_text("from onboard.core.so3 import euler_to_matrix\n"
                    "from onboard.core import geo\nfrom onboard.core.messages import Imu\n")
    assert len(_formula_imports(fake, "onboard.sitl.plants.probe")) == 2


PROTOCOL_DECODERS = {"onboard.drivers.nmea", "onboard.drivers.dvl_json", "onboard.drivers.pd6"}
"""The drivers that read back what the simulator writes on NMEA, DVL JSON and PD6 links:
the simulator writes with its own encoders (pynmeagps; the protocols' documents), so an
encoder and a decoder cannot agree on a mistake (docs/sitl.md)."""


def test_the_simulator_writes_nmea_dvl_json_and_pd6_without_their_drivers(
        tmp_path: Path) -> None:
    def decoders(path: Path, module: str | None = None) -> list[str]:
        return [f"line {line}: {t}" for line, t in imports_of(path, module)
                if _allowed(t, PROTOCOL_DECODERS)]

    wrong = {module_name(p): decoders(p) for p in sorted((REPO / "sitl").rglob("*.py"))}
    wrong = {m: w for m, w in wrong.items() if w}
    assert not wrong, f"simulator modules importing the protocols' decoders: {wrong}"
    probe = tmp_path / "probe.py"  # a negative control: each form of import is caught
    probe.write_text("from onboard.drivers import nmea\n"
                     "from onboard.drivers.pd6 import Pd6Parser\n"
                     "def f():\n    import onboard.drivers.dvl_json\n"
                     "from onboard.drivers.tlog import TlogWriter\n")
    assert len(decoders(probe, "onboard.sitl.probe")) == 3


def test_the_cli_dispatches_only_the_sitl_command_into_the_simulator() -> None:
    from onboard.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    handlers = {name: p.get_default("handler") for name, p in sub.choices.items()}
    into_sitl = {name: h for name, h in handlers.items() if h.startswith("onboard.sitl")}
    assert into_sitl == COMMANDS_INTO_SITL
    for name, handler in handlers.items():
        module = handler.partition(":")[0]
        if name not in COMMANDS_INTO_SITL:
            assert _room(module) in {"onboard.service", "onboard.apps", "onboard.offline.replay",
                                     "onboard.offline.diagnose", "onboard.offline.batch",
                                     "onboard.fleet.service"}, \
                (name, handler)


def test_the_layering_check_sees_a_violation(tmp_path: Path) -> None:
    """A negative control: the parser finds plain, lazy, relative and importlib imports."""
    fake = tmp_path / "probe.py"
    fake.write_text(
        "import importlib\n"
        "from onboard.core import geo\n"
        "def f():\n"
        "    from onboard.service import daemon\n"
        "    return importlib.import_module('onboard.sitl.runner')\n"
        "from ..engine import Engine\n")
    found = {t for _, t in imports_of(fake, "onboard.estimators.probe")}
    assert found == {"onboard.core.geo", "onboard.service.daemon", "onboard.sitl.runner",
                     "onboard.engine"}
    assert not any(_allowed(t, ROOMS["onboard.estimators"]) for t in found - {"onboard.core.geo"})


def test_test_modules_share_helpers_only_through_tests_helpers() -> None:
    """A test module never imports another test module: what tests share is in
    ``tests/helpers`` (or ``tests/fuzz``'s corpora and targets)."""
    wrong = []
    for path in sorted((REPO / "tests").rglob("test_*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            wrong += [f"{path.relative_to(REPO)}: {n}" for n in names
                      if n.split(".")[-1].startswith("test_")]
    assert not wrong, wrong
