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
    shore subscriber (onboard.apps.shore.ShoreView) on the router: the live line every
    second, and at the end the estimates it received scored against the simulator's
    hidden truth (RMSE per quantity).

Clock: by default the simulator and the service share a clock running ``SPEED`` (10)
times faster than the wall clock, so the default 60 simulated seconds take about 6 s
plus start-up. Everything else is real: the bytes on the links, the fixed-rate ticks
(on the scaled clock), Zenoh, the recorder. ``--realtime`` runs at wall-clock speed.

The recording (``demo-out/recordings``) replays exactly with ``onboard replay``. The
adaptive state goes to a fresh temporary directory, deleted at the end, so every demo
starts from the configuration alone; ``--keep-state`` keeps it in ``demo-out/state`` and
restores it in the next run.

The truth table puts each estimate beside the raw measurement it improves on (``aie.speed``
and ``kf.speed`` beside the GNSS ``nav.speed``, positions beside the fix, heading beside the
compass). A quantity the estimator cannot know yet (the water current before its sigma is
small: the along-track current on a straight run without a model) is printed as unknown,
from the pipeline's own published sigma, never as a number.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import json
import math
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, TextIO

import msgspec

from onboard.core.config import Config, SourceConfig, load
from onboard.core.errors import UsageError
from onboard.core.outputs import Output, check as check_outputs
from onboard.core.geo import wrap_pi
from onboard.core.messages import EstimateRecord

DEFAULT_SCENARIO = "jaiabot-turns"
SPEED = 10.0
"""Default clock speed-up of the demo (simulated seconds per wall second)."""
DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
OUT_DIR = Path("demo-out")
SCENARIO_CONFIGS = {"jaiabot-turns": "sitl-jaiabot"}
"""Scenarios with a calibrated config (models identified from a held-out seed)."""
CURRENT_KNOWN_STD = 0.1
"""A current estimate is shown as known when its published one-sigma (the larger of
``std_north`` and ``std_east``, m/s) has been at most this for ``CURRENT_SETTLE_S``."""
CURRENT_SETTLE_S = 10.0


def config_for(vehicle_class: str, scenario: str | None = None) -> str:
    """The bundled config name of a scenario (its calibrated config) or vehicle class."""
    return SCENARIO_CONFIGS.get(scenario or "", vehicle_class)


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


def _route(sample: Any, dvl: bool, nmea: bool) -> str:
    from onboard.core.messages import DvlPosition, DvlVelocity, GnssFix, Heading

    if nmea and isinstance(sample, (GnssFix, Heading)):
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
    from onboard.sitl.runner import Simulation, autopilot_for

    def send(obj: dict) -> None:
        outp.write(json.dumps(obj) + "\n")
        outp.flush()

    sim = Simulation(plan.scenario, plan.seed)
    channels: dict[str, Any] = {
        "mavlink": autopilot_for(sim, [UdpSink("127.0.0.1", plan.mavlink_udp_port)],
                                 stream_unasked=plan.stream_unasked, others=plan.others,
                                 reboot_at=plan.reboot_at)}
    pty = None
    if plan.nmea:
        pty = PtySink()
        channels["nmea"] = Channel(NmeaEncoder(), [pty])
    dvl_cfg = sim.sensor_config.dvl
    dvl = plan.dvl_tcp_port is not None and dvl_cfg is not None
    if dvl:
        channels["dvl"] = Channel(DvlJsonEncoder(period_s=1.0 / dvl_cfg.rate_hz),  # type: ignore[union-attr]
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
            if delay > 0:
                r, _, _ = select.select([fd], [], [], delay)
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
    for ch in channels.values():
        ch.close()
    send({"done": frames, "late_s": late * plan.speed})


# --------------------------------------------------------------------------- scoring


_TRUTH: dict[str, Callable[[Any], float | None]] = {
    "heading": lambda tr: tr.yaw, "yaw": lambda tr: tr.yaw,
    "roll": lambda tr: tr.roll, "pitch": lambda tr: tr.pitch,
    "speed": lambda tr: math.hypot(tr.u, tr.v), "yaw_rate": lambda tr: tr.r,
    "u": lambda tr: tr.u, "v": lambda tr: tr.v, "w": lambda tr: tr.w,
    "u_r": lambda tr: tr.u_r, "v_r": lambda tr: tr.v_r, "w_r": lambda tr: tr.w_r,
    "rate_p": lambda tr: tr.p, "rate_q": lambda tr: tr.q, "rate_r": lambda tr: tr.r,
    "surge_input": lambda tr: tr.surge_input, "yaw_input": lambda tr: tr.yaw_input,
    "dist_x": lambda tr: tr.disturbance_x, "dist_y": lambda tr: tr.disturbance_y,
    "dist_z": lambda tr: tr.disturbance_z, "depth": lambda tr: tr.down,
}
_ANGLES = {"heading", "yaw", "roll", "pitch"}
_POSITIONS = {"north": "north", "east": "east", "down": "down"}
_CURRENT = {"north": "current_north", "east": "current_east", "down": "current_down"}
_RAW = {"speed": "nav.speed", "north": "nav.north", "east": "nav.east",
        "heading": "nav.heading"}
"""The raw measurement each estimated quantity improves on (pipelines other than nav)."""


@dataclass
class ScoreRow:
    """RMSE of one estimated quantity against the truth.

    ``n`` counts the samples scored; ``total`` the samples received. For the current
    pipeline only the samples it knows (:func:`current_known`) are scored, so ``n``
    may be below ``total`` and zero (``rmse`` NaN: printed as unknown). ``raw`` names the
    raw measurement the quantity improves on, ``raw_rmse`` is that one's RMSE.
    """

    column: str
    n: int
    rmse: float
    truth_std: float
    unit: str
    total: int = 0
    raw: str | None = None
    raw_rmse: float = math.nan
    max_std: float = math.nan
    """The largest published sigma among the unscored samples (current only)."""


def current_known(history: list[EstimateRecord]) -> dict[float, bool]:
    """For each ``current`` record time (s): whether its estimate is known, i.e. its
    horizontal one-sigma (``max(std_north, std_east)``, m/s) has stayed at most
    ``CURRENT_KNOWN_STD`` for ``CURRENT_SETTLE_S`` seconds. A record without sigmas is
    unknown."""
    out: dict[float, bool] = {}
    since: float | None = None
    for rec in history:
        if rec.pipeline != "current":
            continue
        sn, se = rec.std.get("north", math.inf), rec.std.get("east", math.inf)
        sd = max(sn, se)
        if math.isfinite(sd) and sd <= CURRENT_KNOWN_STD:
            if since is None:
                since = rec.t
            out[rec.t] = rec.t - since >= CURRENT_SETTLE_S
        else:
            since = None
            out[rec.t] = False
    return out


def _unit(pipeline: str, q: str) -> str:
    if pipeline == "current" and q in _CURRENT:
        return "m/s"
    if q in _ANGLES:
        return "deg"
    if q in ("yaw_rate", "rate_p", "rate_q", "rate_r"):
        return "deg/s"
    if q == "surge_input":
        return "m/s^2"
    if q == "yaw_input":
        return "rad/s^2"
    if q.startswith("dist_"):
        return "N"
    if q in _POSITIONS or q == "depth":
        return "m"
    return "m/s"


def score(history: list[EstimateRecord], truth: list[Any]) -> list[ScoreRow]:
    """RMSE of every estimated quantity that has a truth counterpart.

    Estimates are matched to the truth record nearest in time (within 60 ms). Positions
    (``north``/``east``/``down`` of pipelines other than ``current``) are compared as
    displacements from the pipeline's first estimate, as the estimators report them from
    their first fix. Current samples are scored only where :func:`current_known`; each
    row names the raw measurement it improves on (``_RAW``) with that one's RMSE.
    """
    if not truth:
        return []
    ts = [tr.t for tr in truth]
    dt = (ts[-1] - ts[0]) / max(1, len(ts) - 1) if len(ts) > 1 else 0.1

    def at(t: float) -> Any | None:
        i = int(round((t - ts[0]) / dt)) if dt > 0 else 0
        for j in (i, i - 1, i + 1):
            if 0 <= j < len(ts) and abs(ts[j] - t) <= 0.06:
                return truth[j]
        return None

    errs: dict[str, list[float]] = {}
    refs: dict[str, list[float]] = {}
    totals: dict[str, int] = {}
    max_std: dict[str, float] = {}
    first: dict[tuple[str, str], tuple[float, float]] = {}
    known = current_known(history)
    for rec in history:
        tr = at(rec.t)
        if tr is None:
            continue
        for q, v in rec.values.items():
            if q.startswith("std_") or not math.isfinite(v):
                continue
            if rec.pipeline == "current":
                col = f"current.{q}"
                totals[col] = totals.get(col, 0) + 1
                if not known.get(rec.t, False):
                    sd = max(rec.std.get("north", math.inf), rec.std.get("east", math.inf))
                    max_std[col] = max(max_std.get(col, 0.0), sd)
                    errs.setdefault(col, [])
                    refs.setdefault(col, [])
                    continue
            if rec.pipeline == "current" and q in _CURRENT:
                ref = getattr(tr, _CURRENT[q])
            elif q in _POSITIONS:
                key = (rec.pipeline, q)
                base = first.setdefault(key, (v, getattr(tr, _POSITIONS[q])))
                ref = base[0] + getattr(tr, _POSITIONS[q]) - base[1]
            elif q in _TRUTH:
                ref = _TRUTH[q](tr)
            else:
                continue
            if ref is None or not math.isfinite(ref):
                continue
            e = wrap_pi(v - ref) if q in _ANGLES else v - ref
            col = f"{rec.pipeline}.{q}"
            errs.setdefault(col, []).append(e)
            refs.setdefault(col, []).append(ref)
    rows = []
    for col, es in errs.items():
        pipe, q = col.split(".", 1)
        r = refs[col]
        rmse = math.sqrt(sum(e * e for e in es) / len(es)) if es else math.nan
        mean = sum(r) / len(r) if r else math.nan
        std = math.sqrt(sum((x - mean) ** 2 for x in r) / len(r)) if r else math.nan
        if q in _ANGLES or q in ("yaw_rate", "rate_p", "rate_q", "rate_r"):
            rmse, std = math.degrees(rmse), math.degrees(std)
        rows.append(ScoreRow(col, len(es), rmse, std, _unit(pipe, q),
                             total=totals.get(col, len(es)),
                             raw=_RAW.get(q) if pipe not in ("nav", "current") else None,
                             max_std=max_std.get(col, math.nan)))
    by_col = {row.column: row for row in rows}
    for row in rows:
        if row.raw in by_col:
            row.raw_rmse = by_col[row.raw].rmse
    return sorted(rows, key=lambda r: r.column)


def format_scores(rows: list[ScoreRow]) -> str:
    """The truth comparison as a text table: estimate, samples, RMSE, the raw
    measurement it improves on and that one's RMSE, truth std, unit. An estimate with
    no known sample reads ``unknown`` with the largest sigma it published."""
    if not rows:
        return "no estimates matched the truth (nothing to score)"
    w = max(len(r.column) for r in rows)
    out = [f"{'estimate':<{w}}  {'n':>5}  {'RMSE':>9}  {'raw':<{w}}  {'raw RMSE':>9}  "
           f"{'truth std':>9}  unit"]
    for r in rows:
        raw = r.raw if r.raw is not None and math.isfinite(r.raw_rmse) else "-"
        raw_rmse = f"{r.raw_rmse:9.3f}" if raw != "-" else f"{'':9}"
        if r.n == 0:
            note = (f"unknown: sigma up to {r.max_std:.2f} {r.unit}"
                    if math.isfinite(r.max_std) else "unknown")
            out.append(f"{r.column:<{w}}  {0:>5}  {'unknown':>9}  {'-':<{w}}  {'':9}  "
                       f"{'':9}  {r.unit}  ({note}, {r.total} samples)")
            continue
        line = (f"{r.column:<{w}}  {r.n:>5}  {r.rmse:9.3f}  {raw:<{w}}  {raw_rmse}  "
                f"{r.truth_std:9.3f}  {r.unit}")
        if r.total > r.n:
            line += f"  (known in {r.n} of {r.total} samples)"
        out.append(line)
    return "\n".join(out)


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


async def run_demo(scenario: str = DEFAULT_SCENARIO, duration_s: float = 60.0, *,
                   speed: float = SPEED, seed: int = 1, out_dir: Path = OUT_DIR,
                   router_endpoint: str | None = None, mavlink_out: str = "udpout:127.0.0.1:14550",
                   out: TextIO | None = sys.stdout, keep_state: bool = False,
                   config: Config | None = None, nmea: bool = True,
                   autopilot: dict[str, Any] | None = None) -> DemoResult:
    """Run the whole demo; print the live line every wall second and the scores to
    ``out`` (None: silent). ``router_endpoint`` None: 7447, or a free port when taken.
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
        base = config if config is not None else load(config_for(hello["vehicle_class"],
                                                                 sc.name))
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
        say(f"onboard demo: scenario {sc.name} ({sc.vehicle.vehicle_class}), "
            f"{duration_s:g} s simulated at {speed:g}x, vehicle id {vid!r}")
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
        next_print = time.monotonic() + 1.0
        deadline = start + duration_s / speed + 60.0
        while time.monotonic() < deadline:
            if done_task.done():
                msg = done_task.result()
                frames = msg.get("done", {}) if isinstance(msg, dict) else {}
                sim_late = float(msg.get("late_s", math.nan)) if isinstance(msg, dict) else math.nan
                break
            if time.monotonic() >= next_print:
                next_print += 1.0
                say("  " + view.line(vid))
            await asyncio.sleep(0.05)
        await asyncio.sleep(max(0.3, 2.0 / speed))  # the last ticks reach the shore
        svc.request_stop()
        await svc.shutdown()
        health = svc.latest_health
        events = list(svc.events)
        rec_files = [str(p) for p in (svc.recorder.files if svc.recorder else [])]
        mav_sent = svc.mavlink.sent if svc.mavlink else 0
        service_late = svc.stats.tick_late_max_s
        svc = None
    finally:
        if svc is not None:
            svc.request_stop()
            await svc.shutdown()
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
    wall = time.monotonic() - t_wall0
    say("")
    say(f"estimates vs the simulator's truth ({len(history)} records received over Zenoh):")
    say(format_scores(rows))
    if health is not None:
        rej = ", ".join(f"{k}={n}" for k, n in sorted(health.rejected.items())) or "none"
        say(f"rejected inputs: {rej}")
    if rec_files:
        say(f"recording: {', '.join(rec_files)} (replay it: onboard replay {rec_files[0]})")
    say(f"done in {wall:.1f} s wall")
    return DemoResult(scenario=sc.name, vehicle=vid, duration_s=duration_s, wall_s=wall,
                      estimates=history, health=health, healths=healths, scores=rows, frames=frames,
                      recording=rec_files, events=events, mavlink_sent=mav_sent,
                      sources={s.name: s.kind for s in cfg.service.sources},
                      state_file=str(state_file), state_saved=state_saved,
                      sim_late_s=sim_late, service_late_s=service_late)


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
    """``onboard demo [--duration S] [--scenario NAME] [--realtime] [--keep-state]``."""
    duration = float(args.duration)
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
        sitl_child(LinkPlan(**json.loads(sys.argv[2])))
    else:
        print("usage: onboard demo [--duration S] [--scenario NAME] [--realtime] [--keep-state]",
              file=sys.stderr)
        sys.exit(2)
