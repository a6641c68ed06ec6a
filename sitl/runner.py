"""The simulation loop: plant, sea, sensors, controller, effects; samples and truth out.

Python API (what estimator tests use)::

    from onboard.sitl.runner import simulate, run_to_tlog

    for t, samples, truth in simulate("jaiabot-turns", duration=60, seed=1):
        ...   # samples: list of onboard.core.messages samples measured at t (may be empty)
              # truth: a TruthRecord every 1/truth_rate_hz seconds, else None

    summary = run_to_tlog("effect-current", "run.tlog", "truth.jsonl", duration=300, seed=1)

One tick of the loop at time ``t`` (state x(t)):

1. the truth at ``t`` (lazily, only when something needs it);
2. on a control tick: the controller gets the samples emitted since its last call, the
   truth and the reference, and returns a command; the command goes through the actuator
   model (PWM quantization, saturation, ESC deadband) and the command effects; the force
   effects are evaluated at x(t) and held for the tick;
3. every sensor due at ``t`` measures (errors from its own seeded generator), and sensors
   with latency release what is due;
4. ``(t, samples, truth)`` is yielded when there is anything to yield;
5. the plant advances to ``t + 1/tick_hz`` (RK4 sub-steps <= plant.dt).

The tick rate is the least common multiple of the integer sensor, control and truth rates
when that is at most 200 Hz, so sample times are exact multiples of the sensor periods;
otherwise it is the fastest rate (at least 100 Hz) and the other periods are rounded to
whole ticks (a 7 Hz GNSS beside a 200 Hz IMU reports at 200/29 = 6.9 Hz).

Same scenario, duration and seed: the same samples and, through the emitters, the same
bytes.

``Simulation(..., invalid_epochs=True)`` also yields the receivers' epochs without a
fix (:class:`sitl.sensors.GnssNoFix`) and the heading epochs without a heading
(:class:`sitl.sensors.HeadingInvalid`), for the outputs that send them: NMEA (GGA quality
0, RMC ``V``, VTG ``N``, an empty HDT) and the telemetry log (GPS_RAW_INT NO_FIX, as
ArduPilot logs a loss of the fix); :func:`run` asks for them when it has NMEA or MAVLink
sinks. They draw no random number and never reach the controller, so the samples, the
truth and the other outputs are the same with and without them.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Sequence

import msgspec

from onboard.core.messages import Sample, VehicleInfo
from onboard.sitl.effects import (
    FORCE_EFFECTS,
    apply_to_environment,
    apply_to_plant,
    apply_to_sensors,
    effect_params,
    external_force_ned,
)
from onboard.sitl.emitters import (
    DEFAULT_EPOCH_S,
    Channel,
    DvlJsonEncoder,
    FileSink,
    MavlinkEncoder,
    NmeaEncoder,
    Pd6Encoder,
    Sink,
    TlogSink,
)
from onboard.sitl.autopilot import SimAutopilot
from onboard.sitl.emitters import MAV_TYPE_SURFACE_BOAT
from onboard.sitl.guidance import ControlInput, Controller
from onboard.sitl.plants.base import Command
from onboard.sitl.scenarios import Scenario, get
from onboard.sitl.sensors import (
    GeoOrigin,
    GnssNoFix,
    HeadingInvalid,
    Sensor,
    WorldView,
    build_sensors,
)
from onboard.sitl.truth import TruthRecord

Step = tuple[float, list[Sample], "TruthRecord | None"]
"""What :func:`simulate` yields: (t in s, samples measured at t, truth or None)."""

MAX_TICK_HZ = 200

TRUTH_LATLON_BATCH = 100
"""Truth records converted to latitude/longitude in one pymap3d call by :func:`simulate`
and :func:`run` (10 s of truth at 10 Hz): ~2 us a record, where a call per record costs
~110 us (docs/sitl.md "Speed")."""


def _tick_rate(rates: Sequence[float]) -> int:
    """The loop rate (Hz) for the given event rates (see the module docstring): their
    least common multiple when they are whole numbers and it is at most 200 Hz, else the
    fastest rate (at least 100 Hz), the others then rounded to whole ticks."""
    ints = [int(round(r)) for r in rates]
    if all(abs(r - i) < 1e-9 and i > 0 for r, i in zip(rates, ints)):
        lcm = 1
        for i in ints:
            lcm = math.lcm(lcm, i)
        if lcm <= MAX_TICK_HZ:
            return lcm
    return max(100, int(math.ceil(max(rates) - 1e-9)))


INVALID_EPOCHS = (GnssNoFix, HeadingInvalid)
"""The simulator-only samples of epochs without a fix or heading (``invalid_epochs``)."""


class _Heartbeat:
    """The autopilot's HEARTBEAT (1 Hz) and, once at start, its SERVOn_FUNCTION parameters."""

    name = "autopilot"
    rate_hz = 1.0

    def __init__(self, sc: Scenario) -> None:
        self.sc = sc
        self.params = sc.vehicle.parameters()
        self._sent_params = False

    def measure(self, world: WorldView) -> list[Sample]:
        v = self.sc.vehicle
        out: list[Sample] = [VehicleInfo(t=world.t, source=self.name, system_id=self.sc.system_id,
                                         component_id=1, mav_type=v.mav_type, autopilot=3)]
        if not self._sent_params:
            self._sent_params = True
            out += [msgspec.structs.replace(p, t=world.t) for p in self.params]
        return out

    def due(self, t: float) -> list[Sample]:
        return []

    def error_state(self) -> dict[str, float]:
        return {}


class Simulation:
    """One run of a scenario with one seed. Iterate :meth:`steps` once."""

    def __init__(self, scenario: Scenario | str, seed: int = 0, *,
                 controller: Controller | None = None, truth_rate_hz: float = 10.0,
                 truth_latlon: bool = True, invalid_epochs: bool = False) -> None:
        """``truth_latlon``: :meth:`steps` fills each emitted truth record's latitude and
        longitude (one pymap3d call each); False leaves them None for the caller to fill
        in batches (:func:`with_truth_latlon`). ``invalid_epochs``: also yield the
        receivers' epochs without a fix or heading (module docstring)."""
        sc = get(scenario) if isinstance(scenario, str) else scenario
        self.scenario = sc
        self.seed = seed
        # no geo origin on the sea: the plant's truth comes without latitude/longitude, and
        # the runner converts only the records it emits (self.geo, batched or one by one)
        self.env = dataclasses.replace(apply_to_environment(sc.injected, sc.environment()),
                                       origin_lat_deg=None, origin_lon_deg=None)
        self.plant = sc.vehicle.make_plant()
        apply_to_plant(sc.injected, self.plant)
        i = sc.initial
        self.plant.reset(north=i.north, east=i.east, down=i.down, yaw=i.yaw, u=i.u)
        cfg = apply_to_sensors(sc.injected, sc.sensors)
        self.sensor_config = dataclasses.replace(cfg, actuators=dataclasses.replace(
            cfg.actuators, channels=sc.vehicle.channels))
        self.geo = GeoOrigin(*sc.origin)
        self.truth_latlon = truth_latlon
        sensors, self.actuators = build_sensors(self.sensor_config, self.geo, seed)
        self.invalid_epochs = invalid_epochs
        for sensor in sensors:
            if hasattr(sensor, "report_invalid"):
                sensor.report_invalid = invalid_epochs  # type: ignore[attr-defined]
        self.heartbeat = _Heartbeat(sc)
        self.sensors: list[Sensor] = [self.heartbeat, *sensors]
        self.controller = controller if controller is not None else sc.controller()
        self.truth_rate_hz = truth_rate_hz
        self.force_effects = tuple(e for e in sc.injected if e.name in FORCE_EFFECTS)
        self.surge_mass = sc.vehicle.surge_mass(self.plant)
        self.effects_truth = effect_params(sc.injected)
        rates = [s.rate_hz for s in self.sensors] + [self.controller.rate_hz, truth_rate_hz]
        self.tick_hz = _tick_rate(rates)
        self.periods = [max(1, int(round(self.tick_hz / s.rate_hz))) for s in self.sensors]
        self.control_period = max(1, int(round(self.tick_hz / self.controller.rate_hz)))
        self.truth_period = max(1, int(round(self.tick_hz / truth_rate_hz)))
        self.command = Command()
        self.plant_command = Command()

    def _truth(self, t: float) -> TruthRecord:
        return self.plant.truth(t, self.env)

    def steps(self, duration: float | None = None) -> Iterator[Step]:
        """Yield ``(t, samples, truth)`` from t = 0 to ``duration`` (s, default the
        scenario's), whenever there are samples or a truth record."""
        sc = self.scenario
        duration = sc.duration_s if duration is None else float(duration)
        n_ticks = int(math.floor(duration * self.tick_hz + 1e-9))
        dt = 1.0 / self.tick_hz
        plant, env = self.plant, self.env
        sensors, periods = self.sensors, self.periods
        vehicle = sc.vehicle
        pending: list[Sample] = []
        bottom = sc.bottom_depth_m
        reference = sc.reference
        for k in range(n_ticks + 1):
            t = k / self.tick_hz  # exact for whole-number rates (0.3, not 0.30000000000000004)
            truth: TruthRecord | None = None
            if k % self.control_period == 0:
                truth = self._truth(t)
                ref = reference(t) if reference is not None else None
                self.command = self.controller(ControlInput(t, pending, truth, ref))
                pending = []
                eff = self.actuators.apply(vehicle.to_channels(self.command))
                self.plant_command = vehicle.from_channels(eff, self.command)
            if self.force_effects:
                x = plant.x  # [N, E, D, phi, theta, psi, u_r, v_r, w_r, p, q, r, ...]
                f = external_force_ned(self.force_effects, float(x[6]), float(x[11]),
                                       float(x[5]), self.surge_mass)
                self.plant_command = dataclasses.replace(self.plant_command,
                                                         external_force_world=f)
            samples: list[Sample] = []
            view: WorldView | None = None
            for s, per in zip(sensors, periods):
                if k % per == 0:
                    if view is None:
                        view = self._view(t, truth, bottom)
                    samples.extend(s.measure(view))
                else:
                    late = s.due(t)
                    if late:
                        samples.extend(late)
            if view is not None and view._truth is not None:
                truth = view._truth
            out_truth = None
            if k % self.truth_period == 0:
                if truth is None:
                    truth = self._truth(t)
                truth.effects = self._truth_effects()
                if self.truth_latlon:
                    truth.lat_deg, truth.lon_deg = self.geo.to_latlon(truth.north, truth.east)
                out_truth = truth
            if samples:
                if self.invalid_epochs:
                    pending.extend(s for s in samples if type(s) not in INVALID_EPOCHS)
                else:
                    pending.extend(samples)
            if samples or out_truth is not None:
                yield t, samples, out_truth
            if k < n_ticks:
                plant.step(dt, self.plant_command, env, t)

    def _view(self, t: float, truth: TruthRecord | None, bottom: float | None) -> WorldView:
        plant = self.plant
        w = plant.angular_rate_body().tolist()
        cmd = self.plant_command
        vehicle = self.scenario.vehicle

        def sf() -> tuple[float, float, float]:
            f = plant.specific_force_body().tolist()
            return (f[0], f[1], f[2])

        return WorldView(
            t, truth, angular_rate=(w[0], w[1], w[2]),
            thrust=vehicle.thrust_level(cmd), shaft_rpm=vehicle.shaft_rpm(plant, cmd),
            truth_fn=lambda: self._truth(t), specific_force_fn=sf, bottom_depth=bottom)

    def _truth_effects(self) -> dict[str, float]:
        d = dict(self.effects_truth)
        for s in self.sensors:
            d.update(s.error_state())
        return d


def simulate(scenario: Scenario | str, duration: float | None = None, seed: int = 0, *,
             controller: Controller | None = None,
             truth_rate_hz: float = 10.0) -> Iterator[Step]:
    """Run ``scenario`` (a name or a :class:`Scenario`) for ``duration`` simulated seconds
    (default: the scenario's) with the sensor errors of ``seed``.

    Yields ``(t, samples, truth)``: ``t`` in seconds since the start; ``samples`` the
    :mod:`onboard.core.messages` samples measured at ``t`` (HEARTBEAT-like VehicleInfo and the
    SERVOn_FUNCTION Parameters included); ``truth`` a :class:`~sitl.truth.TruthRecord`
    every ``1/truth_rate_hz`` s (with the injected effects' parameters and the sensors'
    hidden error states in ``truth.effects``), else None. ``controller`` replaces the
    scenario's own (see :class:`sitl.guidance.Controller`).
    """
    sim = Simulation(scenario, seed, controller=controller, truth_rate_hz=truth_rate_hz,
                     truth_latlon=False)
    return with_truth_latlon(sim.steps(duration), sim.geo)


def engine_ticks(engine: Any, steps: Iterator[Step], tick_s: float = 0.1
                 ) -> Iterator[tuple[float, list[Any], TruthRecord]]:
    """Feed ``engine`` (an :class:`onboard.engine.Engine`) every sample of ``steps`` and tick
    it at the truth records at most every ``tick_s`` s apart; yields ``(t, records,
    truth)`` per tick, the records its ``tick(t)`` returned."""
    next_tick: float | None = None
    for t, samples, truth in steps:
        for s in samples:
            engine.push(s)
        if next_tick is None:
            next_tick = t
        if t + 1e-9 < next_tick or truth is None:
            continue
        next_tick = t + tick_s
        yield t, engine.tick(t), truth


def with_truth_latlon(steps: Iterator[Step], geo: GeoOrigin,
                      batch: int = TRUTH_LATLON_BATCH) -> Iterator[Step]:
    """``steps`` with every truth record's ``lat_deg``/``lon_deg`` filled by ``geo``,
    ``batch`` records per pymap3d call: the steps are held back until the last truth
    record of their batch is computed (the simulation runs up to ``batch`` truth periods
    ahead of what is yielded; nothing yielded feeds back into it)."""
    held: list[Step] = []
    records: list[TruthRecord] = []
    for step in steps:
        held.append(step)
        if step[2] is not None:
            records.append(step[2])
            if len(records) >= batch:
                _fill_latlon(records, geo)
                yield from held
                held.clear()
                records.clear()
    _fill_latlon(records, geo)
    yield from held


def _fill_latlon(records: list[TruthRecord], geo: GeoOrigin) -> None:
    """Set ``lat_deg``, ``lon_deg`` of ``records`` from their north/east (one call)."""
    if not records:
        return
    lats, lons = geo.to_latlon_many([r.north for r in records], [r.east for r in records])
    for r, lat, lon in zip(records, lats, lons):
        r.lat_deg, r.lon_deg = lat, lon


# --------------------------------------------------------------------------- running to sinks


@dataclass
class RunSummary:
    """What a run produced: counts of samples by type and of frames per output, the
    simulated and wall-clock durations (s), and the paths written."""

    scenario: str
    seed: int
    duration_s: float
    wall_s: float = 0.0
    samples: Counter[str] = field(default_factory=Counter)
    frames: dict[str, int] = field(default_factory=dict)
    truth_records: int = 0
    outputs: dict[str, str] = field(default_factory=dict)
    tracking: dict[str, float] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """The summary as JSON-ready values (the ``--report`` file of ``onboard sitl``)."""
        return {"scenario": self.scenario, "seed": self.seed, "duration_s": self.duration_s,
                "wall_s": round(self.wall_s, 3), "samples": dict(sorted(self.samples.items())),
                "frames": self.frames, "truth_records": self.truth_records,
                "outputs": self.outputs, "tracking": self.tracking}


def mavlink_encoder(sim: Simulation, epoch_s: float = DEFAULT_EPOCH_S,
                    boot_age_s: float = 0.0) -> MavlinkEncoder:
    """The MAVLink encoder for a simulation's vehicle (type, system id, origin, DVL);
    ``boot_age_s``: the autopilot booted that long before t = 0 (``time_boot_ms``)."""
    sc = sim.scenario
    dvl = sim.sensor_config.dvl
    enc = MavlinkEncoder(
        mav_type=sc.vehicle.mav_type, system_id=sc.system_id,
        custom_mode=sc.vehicle.custom_mode, origin=sc.origin,
        start_ne=(sc.initial.north, sc.initial.east),
        dvl_period_s=1.0 / dvl.rate_hz if dvl else 0.2,
        dvl_max_altitude_m=dvl.max_altitude_m if dvl else 50.0, epoch_s=epoch_s)
    enc.set_parameters(sim.heartbeat.params)
    enc.boot_t0 = -boot_age_s
    return enc


def autopilot_for(sim: Simulation, sinks: Sequence[Sink], epoch_s: float = DEFAULT_EPOCH_S,
                  **options: Any) -> SimAutopilot:
    """The simulated autopilot (:class:`sitl.autopilot.SimAutopilot`) of a simulation's
    vehicle on the live MAVLink ``sinks``; ``options`` go to it (``stream_unasked``,
    ``others``, ``reboot_at``)."""
    sc = sim.scenario
    frame_class = 2 if sc.vehicle.mav_type == MAV_TYPE_SURFACE_BOAT else 1
    return SimAutopilot(mavlink_encoder(sim, epoch_s), sinks, params=sim.heartbeat.params,
                        frame_class=frame_class, **options)


def run(scenario: Scenario | str, duration: float | None = None, seed: int = 0, *,
        mavlink: Sequence[Sink] = (), nmea: Sequence[Sink] = (), dvl_json: Sequence[Sink] = (),
        pd6: Sequence[Sink] = (), truth_path: str | Path | None = None,
        meta_path: str | Path | None = None, realtime: bool = False,
        controller: Controller | None = None, epoch_s: float = DEFAULT_EPOCH_S,
        truth_rate_hz: float = 10.0, live_mavlink: Sequence[Sink] = (),
        autopilot: dict[str, Any] | None = None, boot_age_s: float = 0.0) -> RunSummary:
    """Run a scenario and push its samples through the protocol encoders to the sinks.

    ``mavlink``, ``nmea``, ``dvl_json`` and ``pd6`` are lists of sinks per protocol
    (:mod:`sitl.emitters`); ``mavlink`` gets every message (a telemetry log).
    ``live_mavlink`` sinks are live links behind the simulated autopilot
    (:func:`autopilot_for`, options ``autopilot``): heartbeats only until asked.
    ``truth_path`` gets the truth as JSON lines;
    ``meta_path`` the scenario metadata (:meth:`Scenario.metadata`, what the estimator may
    read); ``realtime`` paces the loop to the wall clock; ``boot_age_s``: the autopilot
    booted that long before t = 0 (the logged ``time_boot_ms``). Sinks are closed at the end.
    """
    sim = Simulation(scenario, seed, controller=controller, truth_rate_hz=truth_rate_hz,
                     truth_latlon=False, invalid_epochs=bool(nmea or mavlink))
    sc = sim.scenario
    dur = sc.duration_s if duration is None else float(duration)
    summary = RunSummary(scenario=sc.name, seed=seed, duration_s=dur)
    channels: dict[str, Channel | SimAutopilot] = {}
    if mavlink:
        channels["mavlink"] = Channel(mavlink_encoder(sim, epoch_s, boot_age_s), list(mavlink))
    if live_mavlink:
        channels["mavlink_live"] = autopilot_for(sim, live_mavlink, epoch_s, **(autopilot or {}))
    if nmea:
        channels["nmea"] = Channel(NmeaEncoder(epoch_s), list(nmea))
    if dvl_json:
        dcfg = sim.sensor_config.dvl
        channels["dvl_json"] = Channel(
            DvlJsonEncoder(epoch_s, 1.0 / dcfg.rate_hz if dcfg else 0.2), list(dvl_json))
    if pd6:
        channels["pd6"] = Channel(Pd6Encoder(epoch_s), list(pd6))
    frames = Counter()
    truth_f = open(truth_path, "wb", buffering=1 << 16) if truth_path else None
    enc = msgspec.json.Encoder()
    err_sq = 0.0
    err_n = 0
    err_max = 0.0
    t0 = time.perf_counter()
    try:
        if meta_path:
            Path(meta_path).write_text(json.dumps(sc.metadata(), indent=2) + "\n")
            summary.outputs["meta"] = str(meta_path)
        for t, samples, truth in with_truth_latlon(sim.steps(dur), sim.geo):
            if realtime:
                lag = t - (time.perf_counter() - t0)
                if lag > 0:
                    time.sleep(lag)
            for s in samples:
                summary.samples[type(s).__name__] += 1
            for name, ch in channels.items():
                frames[name] += ch.emit(t, samples)
            if truth is not None:
                summary.truth_records += 1
                if truth_f is not None:
                    truth_f.write(enc.encode(truth))
                    truth_f.write(b"\n")
                if sc.reference is not None and hasattr(sc.reference, "__call__"):
                    e = _tracking_error(sc.reference, truth)
                    if e is not None:
                        err_sq += e * e
                        err_n += 1
                        err_max = max(err_max, e)
    finally:
        if truth_f is not None:
            truth_f.close()
        for ch in channels.values():
            ch.close()
    summary.wall_s = time.perf_counter() - t0
    summary.frames = dict(frames)
    if truth_path:
        summary.outputs["truth"] = str(truth_path)
    if err_n:
        summary.tracking = {"rms_position_error_m": math.sqrt(err_sq / err_n),
                            "max_position_error_m": err_max}
    return summary


def _tracking_error(reference: Any, truth: TruthRecord) -> float | None:
    """Distance (m) from the truth to the reference position, for references that return
    a position first (like :class:`sitl.guidance.CircleReference`)."""
    try:
        pos = reference(truth.t)[0]
        return math.dist((truth.north, truth.east, truth.down), (pos[0], pos[1], pos[2]))
    except (TypeError, IndexError, KeyError):
        return None


def run_to_tlog(name: str | Scenario, path: str | Path, truth_path: str | Path | None = None,
                duration: float | None = None, seed: int = 0, *,
                epoch_s: float = DEFAULT_EPOCH_S, meta_path: str | Path | None = None,
                nmea_path: str | Path | None = None, dvl_json_path: str | Path | None = None,
                ) -> RunSummary:
    """Simulate scenario ``name`` as fast as possible into the MAVLink telemetry log
    ``path`` (and the truth JSON lines into ``truth_path``, the scenario metadata into
    ``meta_path``, NMEA and DVL JSON captures when asked). Log times are
    ``epoch_s + t``; the first record is at t = 0, so ``truth.t`` equals seconds since
    the log's first record. Byte-identical for the same arguments."""
    sinks: dict[str, Any] = {"mavlink": [TlogSink(path, epoch_s)]}
    if nmea_path:
        sinks["nmea"] = [FileSink(nmea_path)]
    if dvl_json_path:
        sinks["dvl_json"] = [FileSink(dvl_json_path)]
    summary = run(name, duration, seed, truth_path=truth_path, meta_path=meta_path,
                  epoch_s=epoch_s, **sinks)
    summary.outputs["tlog"] = str(path)
    return summary


def read_truth(path: str | Path) -> list[TruthRecord]:
    """The truth records of a truth file written by :func:`run` (JSON lines)."""
    dec = msgspec.json.Decoder(TruthRecord)
    with open(path, "rb") as f:
        return [dec.decode(line) for line in f if line.strip()]


def jsonable(obj: Any) -> Any:
    """A report as strict JSON: numpy values as Python ones, NaN and infinities as null."""
    if hasattr(obj, "tolist"):
        obj = obj.tolist()
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
