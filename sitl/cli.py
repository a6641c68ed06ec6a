"""``onboard sitl``: run a scenario and emit its sensor streams on real protocols.

Examples::

    onboard sitl --list
    onboard sitl --scenario jaiabot-turns --duration 300 --seed 1 \\
        --tlog run.tlog --truth run.truth.jsonl          # as fast as possible, to files
    onboard sitl --scenario jaiabot-turns --realtime --link udp:127.0.0.1:14550
    onboard sitl --scenario bluerov2-circle --realtime --link tcp:0.0.0.0:5760 \\
        --dvl tcp:0.0.0.0:16171                           # Water Linked DVL JSON server
    onboard sitl --scenario gavia-tidal --realtime --link pty --nmea-pty --dvl pty
    onboard sitl --fleet fleet-channel --out fleet-out --seed 1  # a fleet, offline (sitl.fleet)
    onboard sitl --glider --out glider-out --seed 1 --dives 4  # a Slocum's .dbd (sitl.glider)

On ``--link`` the simulated autopilot behaves as ArduPilot's MAVLink side
(:mod:`sitl.autopilot`): HEARTBEAT only until the receiver asks for streams
(SET_MESSAGE_INTERVAL, REQUEST_DATA_STREAM), parameters on request. ``--stream-unasked``
streams everything unasked instead; ``--reboot-at S`` reboots the autopilot at S seconds
(repeatable); ``--other-components`` adds a ground station (system 255) and a camera
(component 100) sending look-alike messages on the same link. The live outputs send each
frame on its simulation time; ``--link-delay tether`` sends them late as over a real link
(:mod:`sitl.link`: a delay that wanders as the ArduSub tlog's did, each output its own).

Outputs: ``--tlog`` (MAVLink telemetry log; the scenario metadata an estimator may read is
written beside it as ``<name>.scenario.json``), ``--truth`` (hidden truth, JSON lines),
``--link`` (MAVLink over ``udp:HOST:PORT``, a ``tcp:HOST:PORT`` server, or ``pty``),
``--nmea-pty`` (GGA/RMC/VTG/HDT on a pseudo-terminal), ``--dvl tcp:HOST:PORT`` (Water
Linked A50 JSON server) or ``--dvl pty`` (PD6 on a pseudo-terminal). Pseudo-terminal
paths and server ports are printed before the run starts. With no output at all, MAVLink
goes to ``udp:127.0.0.1:14550`` (where a ground station listens).

``--controller pid|nmpc|nmpc-of|ampc`` flies ``bluerov2-circle`` with a controller of
:mod:`sitl.controllers` fed by the ESESO (:class:`sitl.closed_loop.EsesoPolicy`);
``--report FILE`` writes the run summary (with the tracking error for reference-tracking
scenarios, and the controller's closed-loop figures under ``controller_report``, its
``tracking_rmse_m`` and ``disturbance_error_n`` also at the top level) as JSON.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

from onboard.core.errors import OutputFailed, UsageError
from onboard.core.outputs import Output, check as check_outputs
from onboard.sitl.emitters import PtySink, Sink, TcpServerSink, TlogSink, open_link
from onboard.sitl.guidance import Controller
from onboard.sitl.link import ARDUSUB_TETHER, DelayedSink
from onboard.sitl.runner import jsonable, run
from onboard.sitl.scenarios import SCENARIOS, Scenario, get

DEFAULT_LINK = "udp:127.0.0.1:14550"


def list_scenarios() -> str:
    """One line per scenario: name, vehicle class, default duration, description; then one
    per fleet (:mod:`sitl.fleet`): name, vehicles, duration, description; then the glider
    (:mod:`sitl.glider`)."""
    from onboard.sitl.fleet import FLEETS

    w = max(len(n) for n in SCENARIOS)
    lines = [f"{sc.name:<{w}}  {sc.vehicle.vehicle_class:<18}  {sc.duration_s:5.0f} s  "
             f"{sc.description}" for sc in SCENARIOS.values()]
    lines += [f"{f.name:<{w}}  {len(f.vehicles)} vehicles{'':<8}  {f.duration_s:5.0f} s  "
              f"fleet (--fleet): {f.description}" for f in FLEETS.values()]
    lines.append(f"{'slocum-glider':<{w}}  {'glider':<18}  {'':>7}  --glider --out DIR "
                 "[--dives N]: a Slocum's dives as its own .dbd flight log, each dive's "
                 "true depth-averaged current beside it")
    return "\n".join(lines)


def run_fleet(args: argparse.Namespace) -> int:
    """``onboard sitl --fleet NAME --out DIR``: every vehicle of the fleet written offline
    (:func:`sitl.fleet.write_fleet`). The live fleet runs under ``onboard demo --fleet``."""
    from onboard.sitl.fleet import get_fleet, write_fleet

    fleet = get_fleet(args.fleet)
    if not args.out:
        raise UsageError("--fleet writes its vehicles' logs offline: give --out DIR "
                         "(the live fleet: onboard demo --fleet NAME)")
    if args.scenario or args.tlog or args.truth or args.link or args.nmea_pty or args.dvl:
        raise UsageError("--fleet takes --out, --duration and --seed only")
    duration = fleet.duration_s if args.duration is None else float(args.duration)
    if not (duration > 0 and math.isfinite(duration)):
        raise UsageError(f"--duration must be a positive number of seconds, got {args.duration}")
    check_outputs([Output("--out", Path(args.out), "dir", ("fleet.json",))],
                  force=bool(getattr(args, "force", False)))
    t0 = time.process_time()
    manifest = write_fleet(fleet, args.out, args.seed, duration)
    cpu = time.process_time() - t0
    for v in manifest["vehicles"]:
        base, own = v["configs"]
        print(f"{v['id']}: {v['kind']} {v['pattern']}, {v['duration_s']:.0f} s from utc "
              f"{v['utc_start']:.0f}, {v['samples']} samples -> "
              f"onboard replay {Path(args.out) / v['files']['tlog']} --config {base} "
              f"--config {Path(args.out) / own}", flush=True)
    print(f"{fleet.name}: {len(manifest['vehicles'])} vehicles, {duration:.0f} s, "
          f"{cpu:.1f} s CPU; truth in {Path(args.out) / 'fleet.json'}", flush=True)
    return 0


def run_glider(args: argparse.Namespace) -> int:
    """``onboard sitl --glider --out DIR``: a Slocum glider's dives as its ``.dbd`` flight
    log and the truth of each dive's depth-averaged current (:func:`sitl.glider.fly`)."""
    from onboard.sitl.glider import fly, log_stem

    if not args.out:
        raise UsageError("--glider writes the glider's .dbd offline: give --out DIR")
    if args.scenario or args.fleet or args.tlog or args.truth or args.link \
            or args.nmea_pty or args.dvl or args.duration is not None:
        raise UsageError("--glider takes --out, --dives and --seed only")
    dives = 4 if args.dives is None else args.dives
    if not 1 <= dives <= 1000:
        raise UsageError(f"--dives must be 1 to 1000, got {dives}")
    stem = log_stem(args.seed)
    check_outputs([Output("--out", Path(args.out), "dir",
                          (f"{stem}.dbd", f"{stem}.truth.json"))],
                  force=bool(getattr(args, "force", False)))
    t0 = time.process_time()
    run = fly(args.out, args.seed, dives=dives)
    cpu = time.process_time() - t0
    for d in run.dives:
        print(f"dive {d['t_start']:.0f}-{d['t_end']:.0f} UTC: true depth-averaged current "
              f"{d['north']:+.3f} north, {d['east']:+.3f} east (m/s)", flush=True)
    print(f"{run.path}: {len(run.dives)} dives, {cpu:.1f} s CPU -> onboard replay "
          f"{run.path}; truth in {run.path.with_suffix('.truth.json')}", flush=True)
    return 0


def make_controller(name: str, sc: Scenario) -> Controller:
    """The closed-loop controller ``name`` (``pid``, ``nmpc``, ``nmpc-of``, ``ampc``) for scenario ``sc``:
    :class:`sitl.closed_loop.EsesoPolicy`, the controller fed by the ESESO running on the
    scenario's samples. UsageError for another scenario or when the controller cannot be
    built (the MPCs need the ``mpc`` extra)."""
    if sc.name != "bluerov2-circle":
        raise UsageError(f"--controller applies to bluerov2-circle, not {sc.name}")
    from onboard.sitl.closed_loop import EsesoPolicy

    try:
        return EsesoPolicy(name, sc)
    except (ImportError, ValueError) as err:
        raise UsageError(f"controller {name!r} not available: {err}") from None


def _server(url: str) -> tuple[str, int]:
    kind, _, rest = url.partition(":")
    host, _, port = rest.rpartition(":")
    if kind != "tcp" or not host or not port.isdigit():
        raise UsageError(f"--dvl expects tcp:HOST:PORT or pty, got {url!r}")
    return host, int(port)


def planned_outputs(args: argparse.Namespace) -> list[Output]:
    """The files ``onboard sitl`` writes (:func:`onboard.core.outputs.check`): ``--tlog``
    and the scenario's metadata beside it, ``--truth``, ``--report``."""
    outs = []
    if args.tlog:
        p = Path(args.tlog)
        outs += [Output("--tlog", p),
                 Output("--tlog (its metadata)", p.with_name(p.stem + ".scenario.json"))]
    for flag, value in (("--truth", args.truth), ("--report", getattr(args, "report", None))):
        if value:
            outs.append(Output(flag, Path(value)))
    return outs


def main(args: argparse.Namespace) -> int:
    """Entry point of ``onboard sitl`` (arguments parsed by :mod:`onboard.cli`); every
    output file is checked before the run (:mod:`onboard.core.outputs`)."""
    if getattr(args, "list", False):
        print(list_scenarios())
        return 0
    if getattr(args, "fleet", None):
        return run_fleet(args)
    if getattr(args, "glider", False):
        return run_glider(args)
    if getattr(args, "dives", None) is not None:
        raise UsageError("--dives goes with --glider")
    if not args.scenario:
        raise UsageError("give --scenario NAME (see --list)")
    sc = get(args.scenario)
    duration = sc.duration_s if args.duration is None else float(args.duration)
    if not (duration > 0 and math.isfinite(duration)):
        raise UsageError(f"--duration must be a positive number of seconds, got {args.duration}")
    check_outputs(planned_outputs(args), force=bool(getattr(args, "force", False)))
    controller = make_controller(args.controller, sc) if args.controller else None

    mavlink: list[Sink] = []
    live: list[Sink] = []
    nmea: list[Sink] = []
    dvl_json: list[Sink] = []
    pd6: list[Sink] = []
    ptys: list[PtySink] = []
    meta = None
    try:
        if args.tlog:
            mavlink.append(TlogSink(args.tlog))
            p = Path(args.tlog)
            meta = p.with_name(p.stem + ".scenario.json")
        link = args.link
        if not (args.tlog or link or args.nmea_pty or args.dvl or args.truth):
            link = DEFAULT_LINK
        if link:
            try:
                sink = open_link(link)
            except (ValueError, OSError) as err:
                raise UsageError(f"--link: {err}") from None
            live.append(sink)
            if isinstance(sink, PtySink):
                ptys.append(sink)
                print(f"MAVLink on {sink.path}", flush=True)
            elif isinstance(sink, TcpServerSink):
                print(f"MAVLink TCP server on port {sink.port}", flush=True)
            else:
                print(f"MAVLink to {link}", flush=True)
        if args.nmea_pty:
            sink = PtySink()
            ptys.append(sink)
            nmea.append(sink)
            print(f"NMEA on {sink.path}", flush=True)
        if args.dvl:
            if sc.sensors.dvl is None:
                raise UsageError(f"scenario {sc.name} has no DVL")
            if args.dvl == "pty":
                sink = PtySink()
                ptys.append(sink)
                pd6.append(sink)
                print(f"DVL PD6 on {sink.path}", flush=True)
            else:
                host, port = _server(args.dvl)
                try:
                    srv = TcpServerSink(host, port)
                except OSError as err:
                    raise UsageError(f"--dvl: cannot listen on {args.dvl}: {err}") from None
                dvl_json.append(srv)
                print(f"DVL JSON TCP server on port {srv.port}", flush=True)
        if getattr(args, "link_delay", "none") == "tether":
            if not args.realtime:
                raise UsageError("--link-delay goes with --realtime")
            rng = np.random.default_rng(args.seed)
            live, nmea, dvl_json, pd6 = ([DelayedSink(s, ARDUSUB_TETHER, rng.spawn(1)[0])
                                         for s in sinks]
                                        for sinks in (live, nmea, dvl_json, pd6))
        options = {"stream_unasked": bool(getattr(args, "stream_unasked", False)),
                   "others": bool(getattr(args, "other_components", False)),
                   "reboot_at": list(getattr(args, "reboot_at", None) or [])}
        summary = run(sc, duration, args.seed, mavlink=mavlink, nmea=nmea, dvl_json=dvl_json,
                      pd6=pd6, truth_path=args.truth, meta_path=meta,
                      realtime=bool(args.realtime), controller=controller,
                      live_mavlink=live, autopilot=options)
    except OSError as err:
        raise UsageError(f"cannot write output: {err}") from None
    if args.tlog:
        summary.outputs["tlog"] = args.tlog
    if args.controller:
        summary.outputs["controller"] = args.controller
    print(f"{sc.name}: {duration:.0f} s simulated in {summary.wall_s:.2f} s, "
          f"{sum(summary.samples.values())} samples, {sum(summary.frames.values())} frames"
          + (f", tracking RMS {summary.tracking['rms_position_error_m']:.2f} m"
             if summary.tracking else ""), flush=True)
    if args.report:
        report = summary.as_dict()
        if controller is not None and hasattr(controller, "report"):
            report["controller_report"] = controller.report()
            # the headline figures also at the top level
            for key in ("tracking_rmse_m", "disturbance_error_n"):
                if key in report["controller_report"]:
                    report[key] = report["controller_report"][key]
        try:
            Path(args.report).write_text(json.dumps(jsonable(report), indent=2,
                                                    allow_nan=False) + "\n")
        except OSError as err:  # checked before the run: a full disk, a removed folder
            raise OutputFailed(f"--report {args.report}: cannot write: "
                               f"{err.strerror or err}") from None
    return 0


