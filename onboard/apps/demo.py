"""``onboard demo``: a simulated vehicle, the service and a shore view, on loopback.

What runs (all on 127.0.0.1, nothing to install beyond the package)::

    SITL child process (python -m onboard.apps.demo --sitl-child: sitl.runner.Simulation,
    paced to the shared clock)
       MAVLink 2 over UDP  (IMU, attitude, servo outputs, heartbeat, pressure ...)  --+
       NMEA over a pty     (GGA/RMC/VTG fixes, HDT headings: a serial GPS/compass)    +--> service
       DVL JSON over TCP   (Water Linked A50 reports; vehicles with a DVL)          --+   (in-process)
    service  -> in-process Zenoh router (tcp/127.0.0.1:7447, or a free port when taken)
             -> MAVLink out (udpout:127.0.0.1:14550: a ground station there sees it)
             -> recording + adaptive state in ./demo-out/
    shore subscriber (onboard.apps.shore.ShoreView) on the router: the live line (progress,
    position, speed, heading and the water current with its sigma), and at the end the
    estimates it received scored against the simulator's hidden truth
    (:mod:`onboard.apps.demo_truth`).

What it shows by default (``DEFAULT_SCENARIO``, ``DEFAULT_DURATION_S``): the effect
scenarios' rudder boat flying straight legs, circles and speed steps in a 0.29 m/s water
current it is not told about. The input estimators (``aie``, ``kf``) track speed and
heading from the first second; the current is unknown on the first straight leg (the
current along the track cannot be told from the boat's own speed without a surge model)
and converges, its sigma shrinking, once the boat has turned; the end compares it with the
simulated current.

Clock: by default the simulator and the service share a clock running ``SPEED`` (10)
times faster than the wall clock, so the default 150 simulated seconds take about 15 s
plus start-up. Everything else is real: the bytes on the links, the fixed-rate ticks
(on the scaled clock), Zenoh, the recorder. ``--realtime`` runs at wall-clock speed; the
live line comes at most :data:`LIVE_LINES` times a run, so a long run shows its progress
without flooding the terminal.

Config: the scenario's calibrated config (``SCENARIO_CONFIGS``) or the bundled config of
its vehicle class; for the effect family (the default among them), whose sensors the
bundled configs do not describe, with ``[sensors]`` set to the simulated sensors' noise
(:func:`with_sensor_noise`: what a user copies from the datasheets).

The recording (``demo-out/recordings``) replays exactly with ``onboard replay``. The
adaptive state goes to a fresh temporary directory, deleted at the end, so every demo
starts from the configuration alone; ``--keep-state`` keeps it in ``demo-out/state`` and
restores it in the next run.

The truth table puts each estimate beside the raw measurement it improves on (``aie.speed``
and ``kf.speed`` beside the GNSS ``nav.speed``, positions beside the fix, heading beside the
compass) and the mean sigma it published, and says what each truth is; notes below it say
what a row that looks bad means. A quantity the estimator cannot know yet (the water
current before its sigma is small) is printed as unknown, from the pipeline's own
published sigma, never as a number.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import json
import math
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import textwrap
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import msgspec

from onboard.apps.demo_truth import (CURRENT_KNOWN_STD, CURRENT_SETTLE_S, LEGEND, ScoreRow,
                                     current_known, current_story, format_scores, notes,
                                     score)
from onboard.apps.shore import fmt_bearing
from onboard.core.config import Config, SourceConfig, load
from onboard.core.errors import UsageError
from onboard.core.outputs import Output, check as check_outputs
from onboard.core.messages import EstimateRecord

__all__ = ["CURRENT_KNOWN_STD", "CURRENT_SETTLE_S", "ScoreRow", "current_known",
           "format_scores", "score", "run_demo", "main"]

DEFAULT_SCENARIO = "effect-current"
DEFAULT_DURATION_S = 150.0
"""Simulated seconds of the default demo: the first straight leg (30 s, current unknown),
the first circle (the current becomes observable) and four more legs with it known."""
SPEED = 10.0
"""Default clock speed-up of the demo (simulated seconds per wall second)."""
LIVE_LINES = 20
"""The live line is printed every wall second, or this many times a run when that is
less often (a long ``--realtime`` run)."""
LATE_WARN_S = 1.0
"""Simulated seconds the simulator may fall behind the shared clock before the demo warns
that the machine could not keep up (the samples then reach the service that late)."""
DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
OUT_DIR = Path("demo-out")
SCENARIO_CONFIGS = {"jaiabot-turns": "sitl-jaiabot"}
"""Scenarios with a calibrated config (models identified from a held-out seed)."""
SENSORS_FROM_SCENARIO = ("clean", "effect-", "cat-")
"""Names (prefixes) of the scenarios whose sensors the bundled configs do not describe:
the effect family's good GNSS (0.5 m white, 0.3 m drift, 0.05 m/s) and quiet compass
(0.015 rad), where the boat configs state a consumer receiver (1.5 m) and compass
(0.03 rad). The demo sets ``[sensors]`` to the simulated ones for them
(:func:`with_sensor_noise`); the other scenarios fly sensors their configs state."""
WRAP = 88
"""Width (characters) the notes under the table are wrapped to."""
MAX_DRIFT_SHARE = 0.9
"""The largest ``[sensors.gnss] drift_share`` the config accepts."""


def config_for(vehicle_class: str, scenario: str | None = None) -> str:
    """The bundled config name of a scenario (its calibrated config) or vehicle class."""
    return SCENARIO_CONFIGS.get(scenario or "", vehicle_class)


def with_sensor_noise(base: Config, sensors: Any) -> Config:
    """``base`` with its ``[sensors]`` GNSS, IMU and compass noise and rates those of the
    simulator's sensor suite ``sensors`` (``sitl.sensors.SensorSuiteConfig``; a sensor it
    lacks keeps the config's figures): the GNSS position one-sigma is the white and the
    drift part together, ``drift_share`` the drift's share of its variance and
    ``drift_tau_s`` its correlation time."""
    s = base.sensors
    gnss, imu, compass = s.gnss, s.imu, s.compass
    if sensors.gnss is not None:
        g = sensors.gnss
        total = math.hypot(g.position_std_m, g.drift_std_m)
        share = min(MAX_DRIFT_SHARE, (g.drift_std_m / total) ** 2) if total > 0 else 0.0
        gnss = msgspec.structs.replace(
            gnss, position_std_m=total, velocity_std_mps=g.velocity_std_mps,
            rate_hz=g.rate_hz, drift_share=share, drift_tau_s=g.drift_tau_s)
    if sensors.imu is not None:
        i = sensors.imu
        imu = msgspec.structs.replace(imu, accel_std_mps2=i.accel_noise_std,
                                      gyro_std_rps=i.gyro_noise_std, rate_hz=i.rate_hz)
    if sensors.compass is not None:
        c = sensors.compass
        compass = msgspec.structs.replace(compass, heading_std_rad=c.noise_std_rad,
                                          rate_hz=c.rate_hz)
    return msgspec.structs.replace(base, sensors=msgspec.structs.replace(
        s, gnss=gnss, imu=imu, compass=compass))


def demo_base_config(scenario: Any, vehicle_class: str) -> tuple[Config, str]:
    """The config the demo's service starts from, and a line saying which: the scenario's
    calibrated config (``SCENARIO_CONFIGS``), else the bundled config of its vehicle
    class, with the simulated sensors' noise for :data:`SENSORS_FROM_SCENARIO`
    (:func:`with_sensor_noise`)."""
    name = config_for(vehicle_class, scenario.name)
    if scenario.name in SCENARIO_CONFIGS:
        return load(name), f"bundled {name} (models identified on a held-out seed)"
    if scenario.name.startswith(SENSORS_FROM_SCENARIO):
        return (with_sensor_noise(load(name), scenario.sensors),
                f"bundled {name}, [sensors] set to the simulated sensors' noise")
    return load(name), f"bundled {name}"


# --------------------------------------------------------------------------- SITL child


@dataclass
class LinkPlan:
    """What the SITL child emits where (picklable: it crosses a process boundary)."""

    scenario: str
    duration_s: float
    seed: int
    speed: float
    mavlink_udp_port: int
    dvl_tcp_port: int | None
    truth_path: str
    nmea: bool = True
    routes: dict[str, str] = field(default_factory=dict)
    stream_unasked: bool = False
    """The simulated autopilot streams everything unasked (no stream negotiation)."""
    others: bool = False
    """A ground station and a camera share the MAVLink link (sitl.autopilot)."""
    reboot_at: list[float] = field(default_factory=list)
    """Simulated times (s) at which the autopilot reboots."""
    fleet: str = ""
    """A fleet's name (:mod:`sitl.fleet`): ``scenario`` is then the id of one of its
    vehicles, stamped with its own UTC, its truth flushed record by record (the fleet
    demo reads it live)."""
    fleet_seed: int = 0
    """The fleet's seed (its sea where the fleet draws one: ``Fleet.at_seed``); ``seed``
    is the vehicle's own."""


def _route(sample: Any, dvl: bool, nmea: bool) -> str:
    from onboard.core.messages import DvlPosition, DvlVelocity, GnssFix, Heading
    from onboard.sitl.runner import INVALID_EPOCHS

    if nmea and isinstance(sample, (GnssFix, Heading, *INVALID_EPOCHS)):
        return "nmea"
    if dvl and isinstance(sample, (DvlVelocity, DvlPosition)):
        return "dvl"
    return "mavlink"


def sitl_child(plan: LinkPlan, inp: TextIO = sys.stdin, outp: TextIO = sys.stdout) -> None:
    """Run in a child process: emit the scenario on the links of ``plan``, paced to the
    shared clock. Protocol on stdin/stdout, one JSON object per line: the child writes
    ``{"nmea_pty": path, "dvl": bool, "vehicle_class": str}``; the parent answers
    ``{"start": s}`` (the time.monotonic() instant of simulated t = 0); the child writes
    ``{"done": frames, "late_s": s}`` at the end (``late_s``: how far, in simulated seconds,
    its emission fell behind the shared clock at worst: a loaded machine). Closing stdin
    stops it early."""
    import os
    import select

    from onboard.sitl.emitters import Channel, DvlJsonEncoder, NmeaEncoder, PtySink, TcpServerSink, UdpSink
    from onboard.sitl.runner import autopilot_for

    def send(obj: dict) -> None:
        outp.write(json.dumps(obj) + "\n")
        outp.flush()

    sim, epoch = _child_simulation(plan)
    channels: dict[str, Any] = {
        "mavlink": autopilot_for(sim, [UdpSink("127.0.0.1", plan.mavlink_udp_port)], epoch,
                                 stream_unasked=plan.stream_unasked, others=plan.others,
                                 reboot_at=plan.reboot_at)}
    pty = None
    if plan.nmea:
        pty = PtySink()
        channels["nmea"] = Channel(NmeaEncoder(epoch), [pty])
    dvl_cfg = sim.sensor_config.dvl
    dvl = plan.dvl_tcp_port is not None and dvl_cfg is not None
    if dvl:
        channels["dvl"] = Channel(DvlJsonEncoder(epoch, period_s=1.0 / dvl_cfg.rate_hz),  # type: ignore[union-attr]
                                  [TcpServerSink("127.0.0.1", plan.dvl_tcp_port)])  # type: ignore[arg-type]
    send({"nmea_pty": pty.path if pty else None, "dvl": dvl,
          "vehicle_class": sim.scenario.vehicle.vehicle_class})
    line = inp.readline()
    if not line:
        return
    start = float(json.loads(line)["start"])
    enc = msgspec.json.Encoder()
    frames = {k: 0 for k in channels}
    fd = inp.fileno()
    late = 0.0
    with open(plan.truth_path, "wb") as truth_f:
        for t, samples, truth in sim.steps(plan.duration_s):
            delay = start + t / plan.speed - time.monotonic()
            if -delay > late:
                late = -delay
            # stdin is watched also when behind the clock (delay <= 0: not waiting)
            r, _, _ = select.select([fd], [], [], max(delay, 0.0))
            if r and not os.read(fd, 4096):
                break  # the parent closed stdin: stop
            if samples:
                split: dict[str, list] = {}
                for s in samples:
                    split.setdefault(_route(s, dvl, plan.nmea), []).append(s)
                for k, ss in split.items():
                    frames[k] += channels[k].emit(t, ss)
            if truth is not None:
                truth_f.write(enc.encode(truth) + b"\n")
                if plan.fleet:
                    truth_f.flush()
    for ch in channels.values():
        ch.close()
    send({"done": frames, "late_s": late * plan.speed})


def _child_simulation(plan: LinkPlan) -> tuple[Any, float]:
    """The simulation a SITL child runs and the UTC (s) of its t = 0: the scenario's on
    the default epoch, or a fleet vehicle's (:func:`sitl.fleet.vehicle_scenario`) on its
    own launch time."""
    from onboard.sitl.emitters import DEFAULT_EPOCH_S
    from onboard.sitl.runner import Simulation

    if not plan.fleet:
        return Simulation(plan.scenario, plan.seed, invalid_epochs=plan.nmea), DEFAULT_EPOCH_S
    from onboard.sitl.fleet import get_fleet, vehicle_scenario

    fleet = get_fleet(plan.fleet).at_seed(plan.fleet_seed)
    v = fleet.vehicle(plan.scenario)
    return (Simulation(vehicle_scenario(fleet, v), plan.seed, invalid_epochs=plan.nmea),
            fleet.utc_start(v))


# --------------------------------------------------------------------------- the demo


def _free_port(kind: int) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def demo_config(base: Config, *, mav_port: int, nmea_pty: str | None, dvl_port: int | None,
                zenoh_endpoint: str, mavlink_out: str = "udpout:127.0.0.1:14550",
                state_file: str = "state/adaptive.json") -> Config:
    """The vehicle's config with the demo's inputs, a Zenoh client to the demo router,
    MAVLink out, the recorder under the demo directory and the adaptive state in
    ``state_file`` (relative: under the demo directory)."""
    srcs = [SourceConfig(kind="mavlink", url=f"udp:127.0.0.1:{mav_port}", name="autopilot")]
    if nmea_pty:
        srcs.append(SourceConfig(kind="nmea", url=f"pty:{nmea_pty}", name="gps"))
    if dvl_port is not None:
        srcs.append(SourceConfig(kind="dvl-json", url=f"tcp:127.0.0.1:{dvl_port}", name="dvl"))
    s = base.service
    service = msgspec.structs.replace(
        s, sources=srcs,
        zenoh=msgspec.structs.replace(s.zenoh, enabled=True, mode="client",
                                      connect=[zenoh_endpoint], listen=[]),
        mavlink=msgspec.structs.replace(s.mavlink, enabled=True, url=mavlink_out),
        recorder=msgspec.structs.replace(s.recorder, enabled=True, directory="recordings"),
        state_file=state_file, state_save_interval_s=10.0)
    return msgspec.structs.replace(base, service=service)


@dataclass
class DemoResult:
    """What a demo run produced (for the tests and the printout)."""

    scenario: str
    vehicle: str
    duration_s: float
    wall_s: float
    estimates: list[EstimateRecord]
    health: Any
    """The last HealthRecord (after the simulator stopped: rates 0)."""
    healths: list[Any]
    """Every HealthRecord of the run (1 Hz on the simulated clock)."""
    scores: list[ScoreRow]
    frames: dict[str, int]
    recording: list[str]
    events: list[str]
    mavlink_sent: int
    sources: dict[str, str]
    state_file: str = ""
    """Where the adaptive state was saved (a deleted temporary file unless kept)."""
    state_saved: bool = False
    """Whether the service saved its adaptive state there during the run."""
    sim_late_s: float = math.nan
    """How far (simulated s) the simulator's emission fell behind the shared clock at
    worst (NaN: not reported). Above a fraction of a second the machine could not keep
    up with ``speed``: the samples reached the service late."""
    service_late_s: float = math.nan
    """The service's largest tick lateness (service s; ``ServiceStats.tick_late_max_s``)."""


def _live_nav(rec: EstimateRecord) -> str:
    v = rec.values
    if "north" not in v or "east" not in v:
        return ""
    return f"nav N {v['north']:+.1f} E {v['east']:+.1f} m"


def _live_speed_heading(rec: EstimateRecord) -> str:
    v = rec.values
    parts = [f"{v['speed']:.2f} m/s"] if "speed" in v else []
    if "heading" in v:
        parts.append(f"{fmt_bearing(math.degrees(v['heading']), 0)}°")
    return f"{rec.pipeline} " + " ".join(parts) if parts else ""


def _live_current(rec: EstimateRecord) -> str:
    """The current's components, each with its one-sigma, or unknown with its sigma."""
    parts = []
    for q, label in (("north", "N"), ("east", "E"), ("down", "D")):
        sd = rec.std.get(q)
        if q in rec.values:
            sigma = f" ± {sd:.3f}" if sd is not None else ""
            parts.append(f"{label} {rec.values[q]:+.3f}{sigma}")
        elif sd is not None:
            parts.append(f"{label} unknown (sigma {sd:.2f})")
    return "current " + " ".join(parts) + " m/s" if parts else ""


def _live_eseso(rec: EstimateRecord) -> str:
    v = rec.values
    qs = [q for q in ("dist_x", "dist_y", "dist_z") if q in v]
    return ("eseso disturbance " + " ".join(f"{v[q]:+.1f}" for q in qs) + " N") if qs else ""


_LIVE = (("nav", _live_nav), ("aie", _live_speed_heading), ("kf", _live_speed_heading),
         ("current", _live_current), ("eseso", _live_eseso))
"""The live line's parts: pipeline and how its newest record is shown."""


def live_line(view: Any, vehicle: str, duration_s: float) -> str:
    """One line of the run so far, from the shore view ``view``
    (:class:`onboard.apps.shore.ShoreView`): the simulated time of the ``duration_s``
    total, the position, the speed and heading of ``aie`` and ``kf``, the water current
    with its one-sigma (a component not published reads unknown with its sigma), the
    ESESO's disturbance, and the rejected and dropped inputs with the mode."""
    with view.lock:
        est = {p: r for (v, p), r in view.estimates.items() if v == vehicle}
        h = view.health.get(vehicle)
    if not est:
        return "waiting for estimates ..."
    t = max(r.t for r in est.values())
    parts = [f"t={t:4.0f} of {duration_s:.0f} s"]
    for pipe, show in _LIVE:
        text = show(est[pipe]) if pipe in est else ""
        if text:
            parts.append(text)
    if h is not None:
        parts.append(f"rej {sum(h.rejected.values())} drop {sum(h.dropped.values())} {h.mode}")
    return " | ".join(parts)


def report(history: list[EstimateRecord], truth: list[Any], rows: list[ScoreRow],
           cfg: Config, *, health: Any = None, sim_late_s: float = math.nan,
           speed: float = SPEED) -> list[str]:
    """The end of the demo: the table against the truth with its legend, the notes on
    the rows that look bad, the water current's story, the rejected inputs, and a warning
    when the simulator fell more than :data:`LATE_WARN_S` behind the shared clock."""
    out = ["", f"estimates vs the simulator's truth ({len(history)} records received "
           "over Zenoh):", LEGEND, format_scores(rows)]
    models = {"surge": cfg.pipelines.aie.surge.a, "heading": cfg.pipelines.aie.heading.a}
    said = notes(rows, models)
    if said:
        out += ["", "what the rows that look bad mean:"]
        out += [textwrap.fill(n, WRAP, initial_indent="* ", subsequent_indent="  ")
                for n in said]
    story = current_story(history, truth, cfg.pipelines.current.unknown_above_std_mps)
    if story:
        out += [""] + [textwrap.fill(s, WRAP, subsequent_indent="  ") for s in story]
    out.append("")
    if health is not None:
        rej = ", ".join(f"{k}={n}" for k, n in sorted(health.rejected.items())) or "none"
        out.append(f"rejected inputs: {rej}")
    if math.isfinite(sim_late_s) and sim_late_s > LATE_WARN_S:
        out.append(textwrap.fill(
            f"warning: the simulator fell up to {sim_late_s:.1f} s (simulated) behind the "
            f"shared clock: this machine could not keep up with {speed:g}x, samples reached "
            "the service that late and the figures above are worse for it; rerun on a "
            "quieter machine or with --realtime", WRAP))
    return out


async def run_demo(scenario: str = DEFAULT_SCENARIO, duration_s: float = DEFAULT_DURATION_S, *,
                   speed: float = SPEED, seed: int = 1, out_dir: Path = OUT_DIR,
                   router_endpoint: str | None = None, mavlink_out: str = "udpout:127.0.0.1:14550",
                   out: TextIO | None = sys.stdout, keep_state: bool = False,
                   config: Config | None = None, nmea: bool = True,
                   autopilot: dict[str, Any] | None = None) -> DemoResult:
    """Run the whole demo; print the live line (:func:`live_line`, every wall second or
    :data:`LIVE_LINES` times a run) and the comparison with the truth (:func:`report`) to
    ``out`` (None: silent). ``config`` None: :func:`demo_base_config`. ``router_endpoint`` None: 7447, or a free port when taken.
    ``keep_state``: the adaptive state in ``out_dir/state``, restored from the previous
    run; otherwise a fresh temporary directory, deleted at the end. ``nmea`` False sends
    the GNSS fixes and headings over MAVLink too; ``autopilot`` sets :class:`LinkPlan`'s
    ``stream_unasked``, ``others`` and ``reboot_at``."""
    from onboard.service.daemon import Service, ServiceClock
    from onboard.service.publishers.zenoh_pub import open_router
    from onboard.apps.shore import ShoreView, open_session
    from onboard.sitl.runner import read_truth
    from onboard.sitl.scenarios import get

    def say(text: str) -> None:
        if out is not None:
            print(text, file=out, flush=True)

    try:
        sc = get(scenario)
    except (KeyError, ValueError) as err:
        raise UsageError(f"unknown scenario {scenario!r}: {err}") from None
    out_dir = Path(out_dir)
    shutil.rmtree(out_dir / "recordings", ignore_errors=True)
    out_dir.mkdir(parents=True, exist_ok=True)
    state_tmp = None if keep_state else Path(tempfile.mkdtemp(prefix="onboard-demo-state-"))
    state_file = (out_dir / "state" / "adaptive.json" if state_tmp is None
                  else state_tmp / "adaptive.json").resolve()
    endpoint = router_endpoint
    if endpoint is None:
        endpoint = DEFAULT_ROUTER if _port_free(7447) else f"tcp/127.0.0.1:{_free_port(socket.SOCK_STREAM)}"
    t_wall0 = time.monotonic()
    router = open_router(endpoint)
    shore = None
    sub = None
    proc = None
    svc = None
    view = ShoreView(keep_history=True)
    plan = LinkPlan(scenario=sc.name, duration_s=duration_s, seed=seed, speed=speed,
                    mavlink_udp_port=_free_port(socket.SOCK_DGRAM),
                    dvl_tcp_port=_free_port(socket.SOCK_STREAM) if sc.sensors.dvl else None,
                    truth_path=str(out_dir / "truth.jsonl"), nmea=nmea, **(autopilot or {}))
    frames: dict[str, int] = {}
    sim_late = math.nan
    service_late = math.nan
    try:
        shore = open_session([endpoint], None, "client")
        proc = subprocess.Popen(
            [sys.executable, "-m", "onboard.apps.demo", "--sitl-child",
             json.dumps(dataclasses.asdict(plan))],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1)
        hello = await _read_json(proc, 60.0)
        if hello is None:
            raise RuntimeError(f"the simulator did not start (exit status {proc.poll()})")
        base, cfg_note = ((config, "given") if config is not None
                          else demo_base_config(sc, hello["vehicle_class"]))
        cfg = demo_config(base, mav_port=plan.mavlink_udp_port, nmea_pty=hello["nmea_pty"],
                          dvl_port=plan.dvl_tcp_port if hello["dvl"] else None,
                          zenoh_endpoint=endpoint, mavlink_out=mavlink_out,
                          state_file=str(state_file))
        vid = cfg.vehicle.id
        sub = shore.declare_subscriber(f"onboard/{vid}/**", view.on_sample)
        start = time.monotonic() + 1.0  # simulated t = 0, one wall second from now
        clock = ServiceClock(speed=speed, origin=0.0, start=start)
        healths: list[Any] = []
        svc = Service(cfg, state_dir=out_dir, clock=clock, on_health=healths.append)
        await svc.start()
        say(f"onboard demo: scenario {sc.name} ({sc.vehicle.vehicle_class}: "
            f"{sc.description}), {duration_s:g} s simulated at {speed:g}x, vehicle id {vid!r}")
        say(f"  config: {cfg_note}")
        say("  inputs: " + ", ".join(f"{s.name}={s.kind} over {s.url}" for s in cfg.service.sources))
        say(f"  Zenoh router {endpoint}; MAVLink out {cfg.service.mavlink.url}; "
            f"recording in {svc.recorder_dir}")
        say(f"  adaptive state: {state_file}" + (" (kept between runs)" if keep_state else
                                                  " (fresh, deleted at the end)"))
        for e in list(svc.events):
            say(f"  {e}")
        assert proc.stdin is not None
        proc.stdin.write(json.dumps({"start": start}) + "\n")
        proc.stdin.flush()
        done_task = asyncio.ensure_future(_read_json(proc, duration_s / speed + 60.0))
        period = max(1.0, duration_s / speed / LIVE_LINES)
        next_print = time.monotonic() + 1.0
        deadline = start + duration_s / speed + 60.0
        while time.monotonic() < deadline:
            if done_task.done():
                msg = done_task.result()
                frames = msg.get("done", {}) if isinstance(msg, dict) else {}
                sim_late = float(msg.get("late_s", math.nan)) if isinstance(msg, dict) else math.nan
                break
            if time.monotonic() >= next_print:
                next_print += period
                say("  " + live_line(view, vid, duration_s))
            await asyncio.sleep(0.05)
        await asyncio.sleep(max(0.3, 2.0 / speed))  # the last ticks reach the shore
        await stop_service(svc, STOP_TIMEOUT_S)
        health = svc.latest_health
        events = list(svc.events)
        rec_files = [str(p) for p in (svc.recorder.files if svc.recorder else [])]
        mav_sent = svc.mavlink.sent if svc.mavlink else 0
        service_late = svc.stats.tick_late_max_s
        svc = None
    finally:
        if svc is not None and not await stop_service(svc, STOP_TIMEOUT_S):
            print(f"the service: not stopped after {STOP_TIMEOUT_S:g} s, left behind",
                  file=sys.stderr, flush=True)
        if proc is not None:
            try:
                if proc.stdin is not None:
                    proc.stdin.close()  # tells the simulator to stop
            except OSError:
                pass
            try:
                proc.wait(10.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
            if proc.stdout is not None:
                proc.stdout.close()
        if sub is not None:
            sub.undeclare()
        if shore is not None:
            shore.close()
        router.close()
        state_saved = state_file.exists()
        if state_tmp is not None:
            shutil.rmtree(state_tmp, ignore_errors=True)
    truth = read_truth(plan.truth_path) if Path(plan.truth_path).exists() else []
    with view.lock:
        history = list(view.history)
    rows = score(history, truth)
    for line in report(history, truth, rows, cfg, health=health, sim_late_s=sim_late,
                       speed=speed):
        say(line)
    if rec_files:
        say(f"recording: {', '.join(rec_files)} (replay it: onboard replay {rec_files[0]})")
    wall = time.monotonic() - t_wall0
    say(f"done in {wall:.1f} s wall")
    return DemoResult(scenario=sc.name, vehicle=vid, duration_s=duration_s, wall_s=wall,
                      estimates=history, health=health, healths=healths, scores=rows, frames=frames,
                      recording=rec_files, events=events, mavlink_sent=mav_sent,
                      sources={s.name: s.kind for s in cfg.service.sources},
                      state_file=str(state_file), state_saved=state_saved,
                      sim_late_s=sim_late, service_late_s=service_late)


STOP_TIMEOUT_S = 20.0
"""Wall seconds the service is given to shut down."""


async def stop_service(svc: Any, timeout_s: float) -> bool:
    """Stop ``svc`` (:meth:`Service.shutdown`) within ``timeout_s`` wall seconds; False
    when it did not (its inputs' reads end on cancellation:
    :meth:`drivers.transports.Transport._idle`)."""
    svc.request_stop()
    try:
        async with asyncio.timeout(timeout_s):
            await svc.shutdown()
    except TimeoutError:
        return False
    return True


async def _read_json(proc: subprocess.Popen, timeout_s: float) -> dict | None:
    """The next JSON line from the child's stdout (None on EOF, timeout or garbage)."""
    loop = asyncio.get_running_loop()
    try:
        line = await asyncio.wait_for(loop.run_in_executor(None, proc.stdout.readline),  # type: ignore[union-attr]
                                      timeout_s)
    except (asyncio.TimeoutError, ValueError, OSError):
        return None
    try:
        obj = json.loads(line) if line else None
    except ValueError:
        return None
    return obj if isinstance(obj, dict) else None


def main(args: argparse.Namespace) -> int:
    """``onboard demo [--duration S] [--scenario NAME] [--realtime] [--keep-state]``
    (``--fleet`` goes to :func:`onboard.apps.demo_fleet.main`)."""
    duration = DEFAULT_DURATION_S if args.duration is None else float(args.duration)
    if not (duration > 0 and math.isfinite(duration)):
        raise UsageError(f"--duration must be a positive number of seconds, got {args.duration}")
    scenario = args.scenario or DEFAULT_SCENARIO
    speed = 1.0 if args.realtime else SPEED
    # the demo's own folder, reused each run (its recordings replaced): writable first
    check_outputs([Output("the demo's folder", OUT_DIR, "dir")])
    res = asyncio.run(run_demo(scenario, duration, speed=speed,
                               keep_state=bool(getattr(args, "keep_state", False))))
    return 0 if res.estimates else 1


if __name__ == "__main__":  # pragma: no cover - the simulator child of run_demo
    if len(sys.argv) == 3 and sys.argv[1] == "--sitl-child":
        # Ctrl-C reaches the whole process group: the parent stops the child (it closes
        # its stdin) after the service the child feeds, so the child ignores it
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        sitl_child(LinkPlan(**json.loads(sys.argv[2])))
    else:
        print("usage: onboard demo [--duration S] [--scenario NAME] [--realtime] [--keep-state]",
              file=sys.stderr)
        sys.exit(2)
