"""Pipelines declare their roles, vehicle classes have their traits in one module, and the
rooms that read them never match names (onboard/pipelines/base.py, onboard/core/vehicles.py;
docs/architecture.md §3)."""

from __future__ import annotations

import ast
from pathlib import Path
from typing import get_args

import msgspec
import pytest

from onboard.core import config as configmod
from onboard.core.vehicles import CLASSES, TRAITS, VehicleClass, traits
from onboard.estimators.current_kf import FilterCounters
from onboard.estimators.eseso_filter import Outcome
from onboard.estimators.vehicle_models import RegressionModel, kind_for_class
from onboard.pipelines import MODULES, build
from onboard.pipelines.base import Pipeline
from onboard.pipelines.current import HEADING_DEPENDENT
from onboard.pipelines.current_samples import SampleCounters
from onboard.pipelines.eseso import EsesoCounters
from onboard.service.mavlink_session import needed_streams

REPO = Path(__file__).resolve().parents[1]
PIPELINE_NAMES = frozenset(MODULES)
"""The registered pipeline names (``aie``, ``kf``, ``current``, ``eseso``, ``nav``)."""
NAME_FREE = ("onboard/monitor", "onboard/engine")
"""The rooms that read roles and must never match a pipeline by name."""
CLASS_FREE = ("onboard/monitor", "onboard/engine", "onboard/pipelines",
              "onboard/estimators", "onboard/service", "drivers")
"""The rooms that read vehicle traits and must never list a vehicle class by name."""
NAMED_CLASSES = set(CLASSES) - {"unknown"}
"""The vehicle classes by name (``unknown``, no class, is also a word of other meanings)."""


def _docstrings(tree: ast.AST) -> set[int]:
    """The ids of the string constants of ``tree`` that stand alone as a statement: the
    docstrings of the module, classes, functions and attributes."""
    return {id(node.value) for node in ast.walk(tree)
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
            and isinstance(node.value.value, str)}


def literals_in(source: str, names: frozenset[str] | set[str]) -> list[tuple[int, str]]:
    """``(line, literal)`` of each string constant of ``source`` that is one of ``names``
    (docstrings left out): a comparison, a table key or member, a default, any use."""
    tree = ast.parse(source)
    docs = _docstrings(tree)
    return [(node.lineno, node.value) for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str)
            and node.value in names and id(node) not in docs]


ROLE_ATTRIBUTES = frozenset({"position", "speed", "heading_dependent", "frame",
                             "frame_offset", "events"})
"""What the Pipeline protocol declares (or, for ``events``, replaced by ``take_events``)."""


def probed_roles(source: str) -> list[tuple[int, str]]:
    """``(line, attribute)`` of each ``getattr``/``hasattr`` of ``source`` that probes a
    role by name: a role is declared on the protocol, so it is read as an attribute."""
    return [(node.lineno, node.args[1].value) for node in ast.walk(ast.parse(source))
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
            and node.func.id in ("getattr", "hasattr") and len(node.args) >= 2
            and isinstance(node.args[1], ast.Constant)
            and node.args[1].value in ROLE_ATTRIBUTES]


def _sources(rooms: tuple[str, ...]) -> list[Path]:
    return sorted(p for room in rooms for p in (REPO / room).rglob("*.py"))


def test_the_name_check_finds_a_table_a_comparison_and_a_default_but_not_prose() -> None:
    """Negative control of the checks below: each way of matching on a name is found."""
    source = '''"""Checks "aie" and "kf" (prose)."""
POSITION_PIPELINES = ("aie", "kf", "eseso")
WITHHELD = {"current": ("north",)}


def f(rec, name="nav"):
    """Only "aie" here (prose)."""
    return rec.pipeline == "eseso"
'''
    found = literals_in(source, PIPELINE_NAMES)
    assert [lit for _, lit in found] == ["aie", "kf", "eseso", "current", "nav", "eseso"]
    assert literals_in('"""rudder-boat"""\nx = "bluerov2"\n', NAMED_CLASSES) == [
        (2, "bluerov2")]


def test_the_probe_check_finds_a_getattr_of_a_role() -> None:
    """Negative control: the engine's way before the roles were declared."""
    source = 'pev = getattr(p, "events", None)\nf = getattr(p, "frame")\nn = getattr(p, "name")\n'
    assert probed_roles(source) == [(1, "events"), (2, "frame")]


def test_the_roles_are_read_as_declared_attributes_not_probed() -> None:
    found = {str(p.relative_to(REPO)): hits
             for p in _sources(NAME_FREE + ("onboard/service",))
             if (hits := probed_roles(p.read_text()))}
    assert found == {}


def test_integrity_and_the_engine_match_no_pipeline_name() -> None:
    """The monitor and the engine read what pipelines declare (their roles), never a
    pipeline's name (issue 31: POSITION_PIPELINES, SPEED_PIPELINES, WITHHELD_ON_HEADING
    were such tables)."""
    found = {str(p.relative_to(REPO)): hits for p in _sources(NAME_FREE)
             if (hits := literals_in(p.read_text(), PIPELINE_NAMES))}
    assert found == {}


def test_no_module_that_reads_vehicle_traits_lists_a_vehicle_class() -> None:
    """Whether a class dives, moves sideways, fits the surge/heading model, what its
    HEARTBEAT says: onboard/core/vehicles.py, and only there (the ``UNDERWATER`` sets of
    autodetect and the MAVLink session disagreed)."""
    found = {str(p.relative_to(REPO)): hits for p in _sources(CLASS_FREE)
             if (hits := literals_in(p.read_text(), NAMED_CLASSES))}
    assert found == {}


# ---------------------------------------------------------------------------- traits

def test_every_configurable_class_has_traits_and_nothing_else_does() -> None:
    assert set(TRAITS) == set(get_args(VehicleClass)) == set(CLASSES)
    assert get_args(configmod.VehicleClass) == get_args(VehicleClass)


def test_a_glider_is_no_class_of_its_own() -> None:
    """The MAVLink session's set of diving classes held "glider", which no configuration
    can name: a glider is a ``torpedo-auv`` with the current pipeline's glider model
    (config/slocum-glider-kolumbo.toml), so it dives."""
    with pytest.raises(configmod.ConfigError, match="vehicle.class"):
        configmod.from_dict({"vehicle": {"class": "glider"}})
    glider = configmod.load("slocum-glider-kolumbo")
    assert glider.pipelines.current.glider is not None
    assert traits(glider.vehicle.vehicle_class).underwater


@pytest.mark.parametrize("cls", CLASSES)
def test_a_diving_class_has_a_3d_current_and_asks_its_autopilot_for_depth(cls: str) -> None:
    """The traits agree with what follows from them: the current model's vertical axis,
    the streams asked of the autopilot, and the HEARTBEAT expected."""
    tr = traits(cls)
    nd = RegressionModel(kind_for_class(cls)).nd
    assert (nd == 3) is tr.underwater
    cfg = configmod.from_dict({"vehicle": {"class": cls}})
    src = configmod.SourceConfig(kind="mavlink", url="udp:127.0.0.1:14550")
    streams = needed_streams(cfg, src)
    assert ("SCALED_PRESSURE2" in streams) is tr.underwater
    if tr.heartbeat_mav_types:
        assert (tr.heartbeat_mav_types == {12}) is tr.underwater


@pytest.mark.parametrize("cls", CLASSES)
def test_aie_and_kf_are_built_where_the_surge_heading_model_fits(cls: str) -> None:
    cfg = configmod.from_dict({"vehicle": {"class": cls}})
    names = [p.name for p in build(cfg)]
    fits = traits(cls).surge_heading_model
    assert ("aie" in names, "kf" in names) == (fits, fits)


def test_a_twin_thruster_input_mapping_makes_a_rudder_boats_model_twin() -> None:
    assert kind_for_class("rudder-boat") == "surface-rudder"
    assert kind_for_class("rudder-boat", has_twin=True) == "surface-twin"
    assert kind_for_class("torpedo-auv", has_twin=True) == "torpedo"


# ---------------------------------------------------------------------------- roles

def _pipelines(cls: str) -> dict[str, Pipeline]:
    cfg = configmod.from_dict({"vehicle": {"class": cls},
                               "pipelines": {"eseso": {"enabled": True}}})
    return {p.name: p for p in build(cfg)}


def test_every_pipeline_is_a_pipeline_with_the_protocols_defaults() -> None:
    for cls in ("rudder-boat", "bluerov2"):
        for p in _pipelines(cls).values():
            assert isinstance(p, Pipeline)
            assert p.take_events() == []
            assert isinstance(p.health().flat(), dict)


@pytest.mark.parametrize("cls", ["rudder-boat", "torpedo-auv", "bluerov2"])
def test_declared_roles_are_columns_with_their_sigmas(cls: str) -> None:
    """A position or speed role names columns the pipeline has, each with its
    ``std_<q>``; a heading-dependent column is one it has."""
    for p in _pipelines(cls).values():
        for q in p.position + p.speed:
            assert q in p.columns and f"std_{q}" in p.columns, (p.name, q)
        assert set(p.heading_dependent) <= set(p.columns), p.name
        assert len(p.position) in (0, 2), p.name


def test_the_roles_of_the_registered_pipelines() -> None:
    """What each pipeline says its outputs are (docs/architecture.md §3, "Roles")."""
    boat, rov = _pipelines("rudder-boat"), _pipelines("torpedo-auv")
    roles = {name: (p.position, p.speed, p.heading_dependent, p.frame_offset)
             for name, p in {**boat, "eseso": _pipelines("bluerov2")["eseso"]}.items()}
    assert roles == {
        "nav": ((), (), (), None),
        "aie": (("north", "east"), ("speed",), (), None),
        "kf": (("north", "east"), ("speed",), (), None),
        "current": ((), (), ("north", "east", "u_r", "v_r"), None),
        "eseso": (("north", "east"), ("u", "v"), (), (0.0, 0.0)),
    }
    assert rov["current"].heading_dependent == HEADING_DEPENDENT  # with down and w_r


# ---------------------------------------------------------------------------- health

def test_health_is_typed_and_its_flat_form_round_trips_through_json() -> None:
    for cls in ("rudder-boat", "bluerov2"):
        for p in _pipelines(cls).values():
            h = p.health()
            assert isinstance(h, msgspec.Struct), p.name
            flat = h.flat()
            assert msgspec.json.decode(msgspec.json.encode(flat)) == flat


def test_the_current_pipelines_counters_that_appear_once_counted_come_in_a_fixed_order(
        ) -> None:
    """The five counters it always has, then each that has counted something, in the
    order a measurement meets them, whatever the order they first counted in."""
    p = _pipelines("rudder-boat")["current"]
    h = p.health()
    always = ["rejected_invalid_dvl", "rejected_gate", "rejected_nonfinite", "updates",
              "rls_updates"]
    assert list(h.flat())[:6] == always + ["q_scale"]
    counted = msgspec.structs.replace(
        h, filter=FilterCounters(runaway=1, restarted=2),
        samples=SampleCounters(glider_measurements=3))
    assert list(counted.flat())[:9] == always + [
        "glider_measurements", "restarted", "runaway", "q_scale"]
    assert msgspec.json.decode(msgspec.json.encode(counted))["filter"]["restarted"] == 2


def test_the_eseso_counts_a_recovered_update_as_gated_recovered_and_fused() -> None:
    """The filter returns what became of an update; the pipeline counts it, in the order
    the events happened (the order of the health record's keys)."""
    c = EsesoCounters()
    c.imu_gap()
    c.update("depth", Outcome.GATED)
    c.update("depth", Outcome.RECOVERED)
    c.downweighted()
    c.update("thrust", Outcome.FUSED)
    assert c.as_dict() == {"imu_gap": 1, "rejected.depth.gate": 2, "recovered.depth": 1,
                           "fused.depth": 1, "thrust.downweighted": 1, "fused.thrust": 1}
    assert [bool(o) for o in Outcome] == [True, False, True]  # fused, gated, recovered
