"""Several vehicles at once in one current field that varies in space and time.

A :class:`Fleet` is a sea (:class:`sitl.current_field.SeaField`), a start time (UTC) and
its :class:`FleetVehicle` s: boats and AUVs, each with its own pattern (lawnmower,
loiter, transects) over a few hundred metres, its own protocol besides MAVLink (NMEA
fixes and headings for a boat, Water Linked DVL JSON for an AUV), its own clock (its
launch time, its autopilot's boot time, its logging computer's clock offset), its own
vehicle id, MAVLink system id and onboard config. :func:`vehicle_scenario` makes each
one an ordinary :class:`sitl.scenarios.Scenario` whose plant takes its current from the
field at its own position and time (:class:`sitl.current_field.VehicleCurrent`), so the
runner, the sensors and the encoders are the single-vehicle simulator's.

:func:`write_fleet` is the offline mode (``onboard sitl --fleet NAME --out DIR``): one
telemetry log, truth file, native-protocol capture and onboard config per vehicle, the
truth of the current at every vehicle (``truth-current.csv``), the field on a grid
(``field-grid.json``) and ``fleet.json`` tying them together (docs/sitl.md "A fleet").
:func:`vehicle_scenario` is also what the live mode runs per vehicle (``onboard demo
--fleet``).

Named fleets: :data:`FLEETS` (``fleet-channel``: two boats and a torpedo AUV in a tidal
channel with a drifting eddy and a moving front, 600 s; ``fleet-demo``: the same sea with
its tide compressed to a 20 min period, so that a short demo sees it turn, and the
vehicles on shorter lines, launched 10 s apart; ``fleet-survey``: six vehicles an operator
would fly to survey a box of a tidal channel, interleaved, for 15 minutes;
``fleet-survey-seas``: the same vehicles in a sea drawn from the seed, so that many seeds
measure the field on many seas, not on one).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from onboard.core.errors import UsageError
from onboard.sitl.current_field import (
    LambOseenEddy, SeaField, TanhFront, TidalChannel, UniformFlow, VehicleCurrent)
from onboard.sitl.emitters import DEFAULT_EPOCH_S, FileSink, TlogSink
from onboard.sitl.environment import Environment
from onboard.sitl.guidance import (
    AuvAutopilot, BoatAutopilot, ControlInput, Controller, HeadingSchedule, Leg)
from onboard.sitl.plants.base import Command
from onboard.sitl.plants.twin_thruster import TwinThrusterParams
from onboard.sitl.scenarios import (
    NOMINAL_BOAT, Initial, Scenario, SCENARIOS, _auv, _effect_sensors, _rudder_boat,
    _speed_to_command, _twin_thruster)

DEG = math.pi / 180.0

KINDS = ("rudder-boat", "twin-thruster", "torpedo-auv")
"""Vehicle kinds a fleet may hold."""
PATTERNS = ("lawnmower", "loiter", "transects")
"""Patterns a fleet vehicle may fly."""
BASE_CONFIGS = {"rudder-boat": "sitl-rudder-boat", "twin-thruster": "sitl-twin-thruster",
                "torpedo-auv": "torpedo-auv"}
"""The bundled config each kind's onboard config starts from (its overlay adds the
vehicle's identity)."""
NATIVE_PROTOCOL = {"rudder-boat": "nmea", "twin-thruster": "mavlink", "torpedo-auv": "dvl-json"}
"""Each kind's own protocol besides MAVLink: what its live mode sends its fixes,
headings or DVL reports on, and the capture written beside its log."""
GRID_STEP_M = 25.0
"""Spacing (m) of the truth grid of the field."""
GRID_PERIOD_S = 60.0
"""Time step (s) of the truth grid."""
GRID_MARGIN_M = 50.0
"""The grid covers the vehicles' tracks plus this margin (m)."""
AUV_DEPTH_M = 5.0


@dataclass(frozen=True)
class FleetVehicle:
    """One vehicle of a fleet (see the module docstring). ``start_north``/``start_east``
    (m) on the fleet's plane; ``heading`` (rad) orients its pattern; ``leg_s`` and
    ``step_s`` (s) size it (a lawnmower's lines and the steps between them, a transect's
    length, a loiter's lap); ``speed`` (m/s) through the water; ``start_delay_s`` after
    the fleet's start; ``clock_offset_s``: its logging computer's clock minus UTC (the
    telemetry log's stamps; GNSS time stays true); ``boot_age_s``: its autopilot booted
    that long before its start; ``surface_s`` (an AUV): it starts at the surface and
    runs there that long, its GNSS antenna out of the water, before it dives (0: it
    starts at its depth, with no fix ever)."""

    id: str
    kind: str
    pattern: str
    system_id: int
    start_north: float = 0.0
    start_east: float = 0.0
    heading: float = 0.0
    leg_s: float = 100.0
    step_s: float = 20.0
    speed: float = 1.5
    start_delay_s: float = 0.0
    clock_offset_s: float = 0.0
    boot_age_s: float = 0.0
    surface_s: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise UsageError(f"fleet vehicle {self.id}: kind {self.kind!r} not in {KINDS}")
        if self.pattern not in PATTERNS:
            raise UsageError(f"fleet vehicle {self.id}: pattern {self.pattern!r} not in {PATTERNS}")


@dataclass(frozen=True)
class Fleet:
    """A named fleet: its sea, its start (UTC, s), its duration (s) and its vehicles."""

    name: str
    description: str
    sea: SeaField
    vehicles: tuple[FleetVehicle, ...]
    duration_s: float = 600.0
    utc0: float = DEFAULT_EPOCH_S
    draw_sea: Callable[[int], SeaField] | None = None
    """A sea per seed (None: :attr:`sea` for every seed); :attr:`sea` is seed 0's."""

    def at_seed(self, seed: int) -> Fleet:
        """The fleet as seed ``seed`` flies it: its sea drawn from the seed where it has
        :attr:`draw_sea`, else itself."""
        if self.draw_sea is None:
            return self
        return dataclasses.replace(self, sea=self.draw_sea(seed))

    def vehicle(self, vid: str) -> FleetVehicle:
        """The vehicle called ``vid``."""
        for v in self.vehicles:
            if v.id == vid:
                return v
        raise UsageError(f"fleet {self.name} has no vehicle {vid!r}")

    def utc_start(self, v: FleetVehicle) -> float:
        """UTC (s) of the vehicle's t = 0."""
        return self.utc0 + v.start_delay_s


# --------------------------------------------------------------------------- patterns


def boat_legs(v: FleetVehicle) -> tuple[Leg, ...]:
    """A boat's pattern as heading legs (:class:`sitl.guidance.Leg`): a lawnmower (lines of
    ``leg_s`` along ``heading`` and back, stepping ``step_s`` to starboard between them),
    a loiter (a circle of ``leg_s`` a lap) or transects (``leg_s`` out along ``heading``
    and back)."""
    h, s = v.heading, v.speed
    if v.pattern == "lawnmower":
        return (Leg(v.leg_s, h, speed_mps=s), Leg(v.step_s, h + 90 * DEG, speed_mps=s),
                Leg(v.leg_s, h + math.pi, speed_mps=s), Leg(v.step_s, h + 90 * DEG, speed_mps=s))
    if v.pattern == "loiter":
        return (Leg(v.leg_s, h, 2.0 * math.pi / v.leg_s, speed_mps=s),)
    return (Leg(v.leg_s, h, speed_mps=s), Leg(v.leg_s, h + math.pi, speed_mps=s))


def auv_schedule(v: FleetVehicle) -> HeadingSchedule:
    """An AUV's pattern as a heading schedule: transects (out and back, ``leg_s`` each) or
    a lawnmower (line, step, line back, step)."""
    h = v.heading
    if v.pattern == "lawnmower":
        return HeadingSchedule((h, h + 90 * DEG, h + math.pi, h + 90 * DEG), v.leg_s)
    return HeadingSchedule((h, h + math.pi), v.leg_s)


def _controller(v: FleetVehicle) -> Callable[[], Controller]:
    if v.kind == "rudder-boat":
        speed = _speed_to_command(NOMINAL_BOAT.steady_speed)
        return lambda: BoatAutopilot(boat_legs(v), speed, initial_heading=v.heading)
    if v.kind == "twin-thruster":
        p = TwinThrusterParams()
        speed = _speed_to_command(lambda c: p.steady_speed(2.0 * p.thrust(c * p.n_max)))
        return lambda: BoatAutopilot(boat_legs(v), speed, steering="skid", kp=0.8, ki=0.02,
                                     kd=0.3, steer_limit=0.6, initial_heading=v.heading)
    def auv() -> Controller:
        pilot = AuvAutopilot(rpm=1500.0 * v.speed / 1.5, depth_m=AUV_DEPTH_M,
                             schedule=auv_schedule(v))
        return SurfaceThenDive(pilot, v.surface_s) if v.surface_s > 0 else pilot
    return auv


class SurfaceThenDive:
    """An AUV's mission start as a real one flies it: afloat at the surface, propeller
    stopped and fins centred, for ``surface_s`` seconds (its GNSS antenna out of the
    water: fixes), then its autopilot, which dives it. (Started at cruise speed at the
    surface, the simulated torpedo pitches up and planes instead of diving.)"""

    def __init__(self, pilot: AuvAutopilot, surface_s: float) -> None:
        self.pilot, self.surface_s = pilot, surface_s
        self.rate_hz = pilot.rate_hz

    def __call__(self, inp: ControlInput) -> Command:
        if inp.t < self.surface_s:
            return Command(propeller_rpm=0.0, rudder_rad=0.0, stern_plane_rad=0.0)
        return self.pilot(inp)


def vehicle_scenario(fleet: Fleet, v: FleetVehicle) -> Scenario:
    """The vehicle as a scenario: its hull, sensors and autopilot, starting at its place
    on the fleet's plane (origin: the field's), its current from the field at its own
    position and UTC."""
    current = VehicleCurrent(fleet.sea, 0.0, 0.0, fleet.utc_start(v))
    if v.kind == "torpedo-auv":
        base = SCENARIOS["gavia-tidal"]
        vehicle, sensors = _auv("torpedo"), base.sensors
        afloat = v.surface_s > 0
        initial = Initial(north=v.start_north, east=v.start_east,
                          down=0.0 if afloat else AUV_DEPTH_M, yaw=v.heading,
                          u=0.0 if afloat else v.speed)
        bottom = base.bottom_depth_m
    else:
        vehicle = _rudder_boat(NOMINAL_BOAT) if v.kind == "rudder-boat" else _twin_thruster()
        sensors = _effect_sensors()
        initial = Initial(north=v.start_north, east=v.start_east, yaw=v.heading)
        bottom = None
    return Scenario(
        name=f"{fleet.name}/{v.id}",
        description=f"{v.kind} flying {v.pattern} in fleet {fleet.name}",
        reproduces=f"issue 33: a fleet vehicle in a current field ({fleet.description})",
        vehicle=vehicle, sensors=sensors, controller=_controller(v),
        duration_s=fleet.duration_s - v.start_delay_s,
        environment=lambda: Environment(current=current),
        initial=initial, origin=fleet.sea.origin, bottom_depth_m=bottom,
        system_id=v.system_id)


# --------------------------------------------------------------------------- named fleets


def channel_sea(origin: tuple[float, float], utc0: float, tide_period_s: float) -> SeaField:
    """The named fleets' sea: a tidal channel 1.2 km wide running toward 30 deg (0.35 m/s
    on its axis at flood, 6 m deep), an eddy of 80 m core turning clockwise at 0.15 m/s
    drifting east-north-east at 5 cm/s, and a front 150 m north of the origin moving
    north at 2 cm/s across which the current gains 0.12 m/s toward the east."""
    return SeaField(origin, (
        TidalChannel(amplitude=0.35, direction=30 * DEG, width=1200.0, centre_east=-150.0,
                     period=tide_period_s, phase=-0.6, t_ref=utc0, water_depth=12.0),
        LambOseenEddy.with_peak(-0.15, 80.0, north0=-120.0, east0=60.0, t_ref=utc0,
                                drift_north=0.02, drift_east=0.045),
        TanhFront(b_east=0.12, normal=0.0, half_width=25.0, north0=150.0, t_ref=utc0,
                  speed=0.02),
        UniformFlow(north=0.03, east=-0.02),
    ))


CHANNEL_VEHICLES = (
    FleetVehicle("boat-1", "rudder-boat", "lawnmower", 11, start_north=-150.0,
                 start_east=-100.0, heading=0.0, leg_s=100.0, step_s=20.0, speed=1.5,
                 clock_offset_s=0.0, boot_age_s=35.0),
    FleetVehicle("boat-2", "twin-thruster", "loiter", 12, start_north=120.0,
                 start_east=150.0, heading=90 * DEG, leg_s=60.0, speed=1.2,
                 start_delay_s=20.0, clock_offset_s=-2.5, boot_age_s=610.0),
    FleetVehicle("auv-1", "torpedo-auv", "lawnmower", 13, start_north=-50.0,
                 start_east=200.0, heading=-60 * DEG, leg_s=40.0, speed=1.5,
                 start_delay_s=40.0, clock_offset_s=1.25, boot_age_s=120.0, surface_s=30.0),
)


DEMO_VEHICLES = (
    dataclasses.replace(CHANNEL_VEHICLES[0], leg_s=40.0, step_s=15.0),
    dataclasses.replace(CHANNEL_VEHICLES[1], leg_s=45.0, start_delay_s=10.0),
    dataclasses.replace(CHANNEL_VEHICLES[2], start_delay_s=20.0, surface_s=10.0),
)
"""fleet-demo's vehicles: fleet-channel's with shorter lines and launches 10 s apart, so
that every current is known within the first two minutes of a demo (its AUV 10 s afloat
for a fix, not 30: placed, so that the demo's field has it)."""


def survey_sea(origin: tuple[float, float], utc0: float) -> SeaField:
    """fleet-survey's sea, at the scales an operator surveying a coastal channel meets: a
    tidal channel 1.2 km wide running toward 30 deg (0.5 m/s on its axis at flood, 12 m
    deep), its shear across the survey box (0.12 m/s from the axis to 300 m off it); an
    eddy of 150 m core (0.15 m/s at its fastest ring, 170 m out) turning clockwise and
    drifting east-north-east at 5 cm/s; a front 100 m wide (half-width 50 m) 20 m north
    of the origin, moving north at 2 cm/s, across which the current gains 0.12 m/s toward
    the east; a weak uniform drift."""
    return SeaField(origin, (
        TidalChannel(amplitude=0.5, direction=30 * DEG, width=1200.0, centre_east=-100.0,
                     period=12.4206012 * 3600.0, phase=-0.6, t_ref=utc0, water_depth=12.0),
        LambOseenEddy.with_peak(-0.15, 150.0, north0=-100.0, east0=-50.0, t_ref=utc0,
                                drift_north=0.02, drift_east=0.045),
        TanhFront(b_east=0.12, normal=0.0, half_width=50.0, north0=20.0, t_ref=utc0,
                  speed=0.02),
        UniformFlow(north=0.03, east=-0.02),
    ))


SEA_DRAW_STREAM = 0x5EA
"""Mixed into a seed for the drawn seas' generator, apart from the vehicles' (seed + i)."""
SURVEY_BOX_CENTRE_M = (0.0, -50.0)
"""fleet-survey's box centre (north, east; m from the origin), about which a drawn sea's
eddy and front are placed."""


def drawn_survey_sea(origin: tuple[float, float], utc0: float) -> Callable[[int], SeaField]:
    """fleet-survey-seas' sea for a seed: fleet-survey's kind of sea (a tidal channel with
    its shear, an eddy, a front, a drift), each feature's size, place and motion drawn
    uniformly from the ranges below, so that where the field's errors fall is not a
    choice of ours. Ranges (about fleet-survey's own values): the channel's flood 0.3-0.7
    m/s toward 10-50 deg, 0.8-1.6 km wide, its axis 0-300 m west of the box, at any phase
    of its M2 tide; the eddy's peak 0.08-0.20 m/s either way round, its core 80-200 m,
    its centre anywhere within 150 m of the box centre, drifting at up to 5 cm/s per axis;
    the front's jump 0.06-0.15 m/s toward any direction, its line at any angle within 150 m
    of the box centre, 25-80 m half-width, moving at up to 3 cm/s; a drift of up to 5 cm/s
    per axis."""
    cn, ce = SURVEY_BOX_CENTRE_M

    def draw(seed: int) -> SeaField:
        rng = np.random.default_rng([seed, SEA_DRAW_STREAM])
        u = rng.uniform
        jump, jump_dir, normal = u(0.06, 0.15), u(0.0, 2 * math.pi), u(0.0, 2 * math.pi)
        offset = u(-150.0, 150.0)
        eddy_r, eddy_a = 150.0 * math.sqrt(u(0.0, 1.0)), u(0.0, 2 * math.pi)
        turn = float(rng.choice((-1.0, 1.0)))
        return SeaField(origin, (
            TidalChannel(amplitude=u(0.3, 0.7), direction=u(10.0, 50.0) * DEG,
                         width=u(800.0, 1600.0), centre_east=ce - u(0.0, 300.0),
                         centre_north=cn, period=12.4206012 * 3600.0,
                         phase=u(-math.pi, math.pi), t_ref=utc0, water_depth=12.0),
            LambOseenEddy.with_peak(turn * u(0.08, 0.20), u(80.0, 200.0),
                                    north0=cn + eddy_r * math.cos(eddy_a),
                                    east0=ce + eddy_r * math.sin(eddy_a), t_ref=utc0,
                                    drift_north=u(-0.05, 0.05), drift_east=u(-0.05, 0.05)),
            TanhFront(b_north=jump * math.cos(jump_dir), b_east=jump * math.sin(jump_dir),
                      normal=normal, half_width=u(25.0, 80.0),
                      north0=cn + offset * math.cos(normal),
                      east0=ce + offset * math.sin(normal), t_ref=utc0,
                      speed=u(-0.03, 0.03)),
            UniformFlow(north=u(-0.05, 0.05), east=u(-0.05, 0.05)),
        ))
    return draw


SURVEY_VEHICLES = (
    FleetVehicle("boat-1", "rudder-boat", "lawnmower", 21, start_north=-75.0,
                 start_east=-150.0, heading=0.0, leg_s=100.0, step_s=20.0, speed=1.5,
                 boot_age_s=35.0),
    FleetVehicle("boat-2", "rudder-boat", "lawnmower", 22, start_north=-75.0,
                 start_east=-135.0, heading=0.0, leg_s=100.0, step_s=20.0, speed=1.5,
                 start_delay_s=10.0, clock_offset_s=-2.5, boot_age_s=610.0),
    FleetVehicle("boat-3", "rudder-boat", "lawnmower", 23, start_north=90.0,
                 start_east=-150.0, heading=90 * DEG, leg_s=100.0, step_s=20.0, speed=1.5,
                 start_delay_s=20.0, clock_offset_s=0.75, boot_age_s=90.0),
    FleetVehicle("keeper", "twin-thruster", "loiter", 24, start_north=0.0, start_east=-40.0,
                 heading=0.0, leg_s=90.0, speed=0.8, start_delay_s=5.0, boot_age_s=300.0),
    FleetVehicle("auv-1", "torpedo-auv", "lawnmower", 25, start_north=-220.0,
                 start_east=-140.0, heading=-60 * DEG, leg_s=40.0, speed=1.5,
                 start_delay_s=30.0, clock_offset_s=1.25, boot_age_s=120.0, surface_s=30.0),
    FleetVehicle("auv-2", "torpedo-auv", "lawnmower", 26, start_north=200.0,
                 start_east=60.0, heading=120 * DEG, leg_s=40.0, speed=1.5,
                 start_delay_s=40.0, clock_offset_s=-0.5, boot_age_s=200.0, surface_s=30.0),
)
"""fleet-survey's vehicles, flying one survey box about 250 m square with interleaved
tracks, each pattern one its current estimator learns from (turns every 1-2 minutes:
docs/sitl.md): two boats on north-south lawnmower lines (150 m, 30-m steps east) offset
15 m, so each line of one lies between two of the other's; a third on east-west lines
across them (stepping south); a station-keeper circling (18 m across) in the box; two
AUVs at 5 m zig-zagging across the box along the channel, one each way (40-s legs, the
lawnmower fleet-channel's AUV flies)."""


def _build() -> dict[str, Fleet]:
    origin = (50.3500, -4.1500)  # Plymouth Sound
    utc0 = DEFAULT_EPOCH_S
    draw = drawn_survey_sea(origin, utc0)
    return {f.name: f for f in (
        Fleet("fleet-channel", "a tidal channel (M2) with a drifting eddy and a moving front",
              channel_sea(origin, utc0, 12.4206012 * 3600.0), CHANNEL_VEHICLES, 600.0, utc0),
        Fleet("fleet-demo", "fleet-channel's sea with its tide compressed to a 20 min period, "
              "shorter lines", channel_sea(origin, utc0, 1200.0), DEMO_VEHICLES, 600.0, utc0),
        Fleet("fleet-survey", "six vehicles surveying a box of a tidal channel with an eddy "
              "and a front: interleaved lawnmowers, a station-keeper, two AUV transects",
              survey_sea(origin, utc0), SURVEY_VEHICLES, 900.0, utc0),
        Fleet("fleet-survey-seas", "fleet-survey's vehicles in a sea drawn from the seed: "
              "the channel, eddy, front and drift of fleet-survey's kind, each placed and "
              "sized at random", draw(0), SURVEY_VEHICLES, 900.0, utc0, draw_sea=draw),
    )}


FLEETS: dict[str, Fleet] = _build()
"""Every named fleet."""


def get_fleet(name: str) -> Fleet:
    """The fleet called ``name``; UsageError if there is none."""
    try:
        return FLEETS[name]
    except KeyError:
        raise UsageError(f"unknown fleet {name!r}; fleets: {', '.join(FLEETS)}") from None


# --------------------------------------------------------------------------- offline


def vehicle_config_toml(fleet: Fleet, v: FleetVehicle) -> str:
    """The vehicle's onboard config: an overlay on its kind's bundled config
    (:data:`BASE_CONFIGS`) giving its identity."""
    base = BASE_CONFIGS[v.kind]
    return (f"# fleet {fleet.name}, vehicle {v.id}: apply after the bundled config {base}\n"
            f"#   onboard replay {v.id}.tlog --config {base} --config {v.id}.toml\n\n"
            f"[vehicle]\nid = \"{v.id}\"\nclass = \"{vehicle_class(v)}\"\n"
            f"system_id = {v.system_id}\n"
            f"description = \"{v.kind} of fleet {fleet.name} flying {v.pattern}\"\n")


def vehicle_class(v: FleetVehicle) -> str:
    """The onboard ``[vehicle] class`` of the vehicle's kind."""
    return {"rudder-boat": "rudder-boat", "twin-thruster": "twin-thruster-boat",
            "torpedo-auv": "torpedo-auv"}[v.kind]


def write_vehicle(fleet: Fleet, v: FleetVehicle, out: Path, seed: int,
                  duration_s: float | None = None) -> dict[str, Any]:
    """Simulate one vehicle as fast as possible into ``out``: ``<id>.tlog`` (stamped by its
    logging computer's clock), ``<id>.truth.jsonl``, ``<id>.scenario.json``, its native
    capture (``<id>.nmea`` or ``<id>.dvl.jsonl``) and ``<id>.toml``; returns its entry of
    ``fleet.json``."""
    from onboard.sitl.runner import run

    sc = vehicle_scenario(fleet, v)
    dur = sc.duration_s if duration_s is None else max(0.0, duration_s - v.start_delay_s)
    utc = fleet.utc_start(v)
    files = {"tlog": f"{v.id}.tlog", "truth": f"{v.id}.truth.jsonl",
             "meta": f"{v.id}.scenario.json", "config": f"{v.id}.toml"}
    sinks: dict[str, Any] = {"mavlink": [TlogSink(out / files["tlog"], utc + v.clock_offset_s)]}
    proto = NATIVE_PROTOCOL[v.kind]
    if proto == "nmea":
        files["nmea"] = f"{v.id}.nmea"
        sinks["nmea"] = [FileSink(out / files["nmea"])]
    elif proto == "dvl-json":
        files["dvl_json"] = f"{v.id}.dvl.jsonl"
        sinks["dvl_json"] = [FileSink(out / files["dvl_json"])]
    (out / files["config"]).write_text(vehicle_config_toml(fleet, v))
    summary = run(sc, dur, seed, truth_path=out / files["truth"], meta_path=out / files["meta"],
                  epoch_s=utc, boot_age_s=v.boot_age_s, **sinks)
    return {"id": v.id, "kind": v.kind, "vehicle_class": vehicle_class(v),
            "pattern": v.pattern, "system_id": v.system_id, "protocol": proto, "seed": seed,
            "utc_start": utc, "duration_s": dur, "clock_offset_s": v.clock_offset_s,
            "boot_age_s": v.boot_age_s, "files": files,
            "configs": [BASE_CONFIGS[v.kind], files["config"]],
            "samples": sum(summary.samples.values())}


def write_fleet(fleet: Fleet, out: str | Path, seed: int = 0,
                duration_s: float | None = None, *,
                only: tuple[str, ...] = ()) -> dict[str, Any]:
    """The offline mode: every vehicle (or those named in ``only``) into ``out`` (see the
    module docstring), then ``truth-current.csv``, ``field-grid.json`` and
    ``fleet.json``, whose content is returned. Vehicle i runs with seed ``seed + i`` in
    the fleet's sea for ``seed`` (:meth:`Fleet.at_seed`): byte-identical for the same
    arguments. A vehicle launched after ``duration_s`` is
    left out."""
    from onboard.sitl.runner import jsonable

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fleet = fleet.at_seed(seed)
    dur = fleet.duration_s if duration_s is None else float(duration_s)
    entries = [write_vehicle(fleet, v, out, seed + i, dur)
               for i, v in enumerate(fleet.vehicles)
               if (not only or v.id in only) and v.start_delay_s < dur]
    rows = truth_rows(out, entries)
    write_truth_csv(out / "truth-current.csv", rows)
    grid = field_grid(fleet, rows, dur)
    (out / "field-grid.json").write_text(json.dumps(grid, separators=(",", ":")) + "\n")
    manifest = {"fleet": fleet.name, "description": fleet.description, "seed": seed,
                "utc0": fleet.utc0, "duration_s": dur, "origin_deg": list(fleet.sea.origin),
                "field": jsonable(fleet.sea.describe()), "vehicles": entries,
                "truth_current": "truth-current.csv", "field_grid": "field-grid.json"}
    (out / "fleet.json").write_text(json.dumps(manifest, indent=2) + "\n")
    return manifest


TRUTH_COLUMNS = ("vehicle", "utc", "t", "lat_deg", "lon_deg", "depth_m", "current_north",
                 "current_east")


def truth_rows(out: Path, entries: list[dict[str, Any]]) -> list[tuple]:
    """Every vehicle's true current at its position (:data:`TRUTH_COLUMNS`), 10 Hz."""
    from onboard.sitl.runner import read_truth

    rows = []
    for e in entries:
        for r in read_truth(out / e["files"]["truth"]):
            rows.append((e["id"], round(e["utc_start"] + r.t, 3), r.t, r.lat_deg, r.lon_deg,
                         r.down, r.current_north, r.current_east))
    return rows


def write_truth_csv(path: Path, rows: list[tuple]) -> None:
    """``truth-current.csv``: a header of :data:`TRUTH_COLUMNS`, one row a truth record."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(TRUTH_COLUMNS)
        for r in rows:
            w.writerow([r[0], f"{r[1]:.3f}", f"{r[2]:.3f}", f"{r[3]:.8f}", f"{r[4]:.8f}",
                        f"{r[5]:.3f}", f"{r[6]:.6f}", f"{r[7]:.6f}"])


def field_grid(fleet: Fleet, rows: list[tuple], duration_s: float) -> dict[str, Any]:
    """The field on a grid over the tracks (plus :data:`GRID_MARGIN_M`), every
    :data:`GRID_STEP_M` m and :data:`GRID_PERIOD_S` s, at the surface and the AUVs'
    depth (:meth:`SeaField.grid`)."""
    sea = fleet.sea
    if rows:
        n, e = sea.to_local([r[3] for r in rows], [r[4] for r in rows])
        lo_n, hi_n, lo_e, hi_e = n.min(), n.max(), e.min(), e.max()
    else:
        lo_n = hi_n = lo_e = hi_e = 0.0
    ns = _axis(lo_n - GRID_MARGIN_M, hi_n + GRID_MARGIN_M)
    es = _axis(lo_e - GRID_MARGIN_M, hi_e + GRID_MARGIN_M)
    lat, _ = sea.geo.to_latlon_many(ns, np.zeros_like(ns))
    _, lon = sea.geo.to_latlon_many(np.zeros_like(es), es)
    times = fleet.utc0 + np.arange(0.0, duration_s + 1e-9, GRID_PERIOD_S)
    grid = sea.grid(lat, lon, [0.0, AUV_DEPTH_M], times)
    grid["index"] = "north[utc][depth][lat][lon], east likewise (m/s, toward)"
    return grid


def _axis(lo: float, hi: float) -> np.ndarray:
    """Grid coordinates (m) on multiples of :data:`GRID_STEP_M` covering [lo, hi]."""
    a = math.floor(lo / GRID_STEP_M) * GRID_STEP_M
    b = math.ceil(hi / GRID_STEP_M) * GRID_STEP_M
    return np.arange(a, b + 1e-9, GRID_STEP_M)


def read_manifest(out: str | Path) -> dict[str, Any]:
    """``fleet.json`` of a fleet written by :func:`write_fleet`."""
    return json.loads((Path(out) / "fleet.json").read_text())


def read_sea(out: str | Path) -> SeaField:
    """The field of a fleet written by :func:`write_fleet`, from its ``fleet.json``: what
    a fleet evaluation predicts against, anywhere and at any time (:meth:`SeaField.at`)."""
    m = read_manifest(out)
    return SeaField.from_description(m["origin_deg"], m["field"])


def replace_vehicles(fleet: Fleet, vehicles: tuple[FleetVehicle, ...]) -> Fleet:
    """``fleet`` with other vehicles (the tests' small fleets)."""
    return dataclasses.replace(fleet, vehicles=vehicles)
