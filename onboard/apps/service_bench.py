"""Service performance figures, for ``onboard bench`` and the report.

:func:`measure` starts the real service (``python -m onboard run``) as a child process
with a notify socket of its own, feeds it the nominal sensor load over UDP in real
protocols -- 50 Hz IMU (MAVLink SCALED_IMU), 10 Hz actuator outputs (SERVO_OUTPUT_RAW),
1 Hz HEARTBEAT, 5 Hz GNSS (NMEA GGA + RMC) and 10 Hz compass (NMEA HDT) -- from a boat
turning in a circle, subscribes to its estimates through an in-process Zenoh router and
reports:

* ``service_cpu_fraction``: CPU seconds (user + system) of the service per wall second
  over the measurement window (0.03 = 3 % of one core);
* ``sensor_to_zenoh_p50_ms``/``_p99_ms``: from the receipt of the newest sample an
  estimate used (``EstimateRecord.t_sensor``, the service's CLOCK_MONOTONIC) to the
  delivery of that estimate to a Zenoh subscriber in another process (same clock). This
  includes the wait for the next fixed-rate tick (up to ``1/rate_hz``);
* ``tick_to_zenoh_p50_ms``/``_p99_ms``: from the tick time to delivery: what the service
  adds (pushing, all pipelines, encoding, Zenoh) beyond the fixed tick grid;
* ``service_rss_mb``: resident memory at the end (MB = 2^20 B), and its peak;
* ``startup_to_ready_s``: from spawning the process to READY=1 on the notify socket
  (interpreter start, imports, state restore, inputs and publishers up);
* ``service_wakeups_per_s``: the voluntary context switches of the service's main thread
  per wall second (each is a sleep of its event loop, so this counts the loop's wake-ups;
  the involuntary ones, preemptions by other processes, are ``main_thread_preemptions_per_s``).

:class:`TrafficGenerator` (the byte streams) is reused by the service tests.
"""

from __future__ import annotations

import dataclasses
import gc
import heapq
import itertools
import json
import math
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from onboard.core.geo import LocalFrame
from onboard.drivers.nmea import encode_gga, encode_hdt, encode_rmc
from onboard.sitl.link import DelayedClock, LinkDelay

EPOCH_S = 1_767_225_600.0
"""UTC of t = 0 in the generated NMEA (2026-01-01)."""
ORIGIN = (41.49, -71.42)
ORIGIN_FRAME = LocalFrame(*ORIGIN)
"""The traffic's local frame (deg origin)."""
GNSS_PHASE_S = 0.0113
"""Over a real link, the GNSS receiver's epochs lie this far (s) after the autopilot's
50 Hz grid: two devices on clocks of their own (any phase but 0 and 10 ms would do)."""


class TrafficGenerator:
    """Real-protocol bytes of a rudder boat turning a 40 m circle at 1.5 m/s.

    ``mavlink(t)`` and ``nmea(t)`` return the frames due at time ``t`` (s) for the
    nominal rates: IMU 50 Hz, servo outputs 10 Hz, heartbeat 1 Hz (MAVLink, system id
    ``system_id``), GNSS 5 Hz and heading 10 Hz (NMEA). Call them on a 50 Hz grid.
    """

    def __init__(self, system_id: int = 1, speed_mps: float = 1.5, radius_m: float = 40.0) -> None:
        self.mav = mavlink2.MAVLink(None, srcSystem=system_id, srcComponent=1)
        self.mav.robust_parsing = True
        self.speed = speed_mps
        self.radius = radius_m
        self.k = 0

    def _pack(self, msg: Any) -> bytes:
        return msg.pack(self.mav)

    def state(self, t: float) -> tuple[float, float, float, float]:
        """(north m, east m, heading rad, yaw rate rad/s) at ``t``."""
        w = self.speed / self.radius
        a = w * t
        return self.radius * math.sin(a), self.radius * (1.0 - math.cos(a)), a % (2 * math.pi), w

    def mavlink(self, t: float) -> list[bytes]:
        """MAVLink frames due at ``t`` (call at 50 Hz)."""
        k = int(round(t * 50.0))
        out: list[bytes] = []
        ms = int(t * 1000) & 0xFFFFFFFF
        _, _, hdg, w = self.state(t)
        if k % 50 == 0:
            out.append(self._pack(mavlink2.MAVLink_heartbeat_message(
                11, 3, 0, 0, mavlink2.MAV_STATE_ACTIVE, 3)))
        ay_mg = int(self.speed * w / 9.80665 * 1000)
        out.append(self._pack(mavlink2.MAVLink_scaled_imu_message(
            ms, 0, ay_mg, -1000, 0, 0, int(w * 1000), 0, 0, 0)))
        if k % 5 == 0:
            out.append(self._pack(mavlink2.MAVLink_servo_output_raw_message(
                ms * 1000 & 0xFFFFFFFF, 0, 1600, 1500, 1700, 1500, 1500, 1500, 1500, 1500)))
        return out

    def nmea(self, t: float) -> list[bytes]:
        """NMEA sentences due at ``t`` (call at 50 Hz): GGA+RMC at 5 Hz, HDT at 10 Hz."""
        k = int(round(t * 50.0))
        out: list[bytes] = []
        n, e, hdg, _ = self.state(t)
        if k % 10 == 0:
            lat, lon = ORIGIN_FRAME.to_latlon(n, e)
            out.append(encode_gga(EPOCH_S + t, lat, lon) + encode_rmc(
                EPOCH_S + t, lat, lon, self.speed, hdg))
        if k % 5 == 0:
            out.append(encode_hdt(hdg))
        return out


class LinkedTraffic:
    """:class:`TrafficGenerator`'s frames as they reach a service on two UDP ports
    (``mav_port``, ``nmea_port``) over ``link`` (:mod:`sitl.link`: the autopilot's frames
    and the NMEA each late by a wandering delay of its own, the receiver's epochs
    :data:`GNSS_PHASE_S` off the autopilot's grid), or on their grid times (None)."""

    def __init__(self, mav_port: int, nmea_port: int, link: LinkDelay | None = None) -> None:
        self.gen = TrafficGenerator()
        self.ports = (mav_port, nmea_port)
        self.arrival: tuple[Callable[[float], float], Callable[[float], float]]
        if link is None:
            self.arrival = (lambda t: t), (lambda t: t)
        else:
            mav = DelayedClock(link, np.random.default_rng(1))
            gnss = DelayedClock(link, np.random.default_rng(2))
            self.arrival = mav.arrival, (lambda t: gnss.arrival(t + GNSS_PHASE_S))
        self._due: list[tuple[float, int, int, bytes]] = []
        self._order = itertools.count()
        self._k = 0

    def until(self, t_end: float) -> Iterator[tuple[float, int, bytes]]:
        """``(arrival s, port, frame)`` of every frame arriving before ``t_end`` (s, from
        the traffic's t = 0) not yielded before, in the order they arrive."""
        while self._k / 50.0 < t_end:
            t = self._k / 50.0
            for port, frames, arrival in zip(self.ports, (self.gen.mavlink(t), self.gen.nmea(t)),
                                             self.arrival):
                for f in frames:
                    heapq.heappush(self._due, (arrival(t), next(self._order), port, f))
            self._k += 1
        while self._due and self._due[0][0] < t_end:
            t_arrival, _, port, f = heapq.heappop(self._due)
            yield t_arrival, port, f


def paced(traffic: LinkedTraffic, t_end: float) -> Iterator[tuple[float, int, bytes]]:
    """``traffic``'s frames until ``t_end`` (s), each yielded at its arrival time (s after
    the first call), sleeping until then."""
    t0 = time.monotonic()
    for t_send, port, frame in traffic.until(t_end):
        delay = t0 + t_send - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        yield t_send, port, frame


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that was free a moment ago (bound, then released)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_tcp_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago (bound, then released)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


BENCH_VEHICLE = "bench"
"""The vehicle id of the benchmarked service (its Zenoh keys are ``onboard/bench/...``)."""


def bench_config_toml(mav_port: int, nmea_port: int, zenoh_endpoint: str, mav_out_port: int,
                      vehicle: str = BENCH_VEHICLE) -> str:
    """A rudder-boat configuration reading the generator over UDP, all pipelines on."""
    from onboard.core.config import resolve

    base = resolve("rudder-boat").read_text()
    base = base.replace('id = "rudder-boat"', f'id = "{vehicle}"', 1)
    return base + f"""
[service]
state_file = "state/adaptive.json"
state_save_interval_s = 10.0

[[service.sources]]
kind = "mavlink"
url = "udp:127.0.0.1:{mav_port}"
name = "autopilot"

[[service.sources]]
kind = "nmea"
url = "udp:127.0.0.1:{nmea_port}"
name = "gps"

[service.zenoh]
mode = "client"
connect = ["{zenoh_endpoint}"]

[service.mavlink]
url = "udpout:127.0.0.1:{mav_out_port}"

[service.recorder]
directory = "recordings"
"""


def _proc_cpu_s(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        parts = f.read().rsplit(")", 1)[1].split()
    ticks = os.sysconf("SC_CLK_TCK")
    return (int(parts[11]) + int(parts[12])) / ticks


def _threads_cpu_s(pid: int) -> dict[str, float]:
    """CPU seconds per thread name (``comm``) of a process, summed over same-named threads."""
    out: dict[str, float] = {}
    ticks = os.sysconf("SC_CLK_TCK")
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            stat = (task / "stat").read_text()
        except OSError:
            continue
        comm = stat[stat.index("(") + 1:stat.rindex(")")]
        parts = stat.rsplit(")", 1)[1].split()
        out[comm] = out.get(comm, 0.0) + (int(parts[11]) + int(parts[12])) / ticks
    return out


def _switches(pid: int) -> tuple[int, int]:
    """(voluntary, involuntary) context switches of the main thread of process ``pid``:
    the voluntary ones are its sleeps, so their count is the event loop's wake-ups."""
    vol = invol = 0
    with open(f"/proc/{pid}/task/{pid}/status") as f:
        for line in f:
            if line.startswith("voluntary_ctxt_switches:"):
                vol = int(line.split()[1])
            elif line.startswith("nonvoluntary_ctxt_switches:"):
                invol = int(line.split()[1])
    return vol, invol


def _proc_rss_mb(pid: int) -> tuple[float, float]:
    rss = hwm = math.nan
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                rss = int(line.split()[1]) / 1024.0
            elif line.startswith("VmHWM:"):
                hwm = int(line.split()[1]) / 1024.0
    return rss, hwm


def _pct(xs: list[float], q: float) -> float:
    if not xs:
        return math.nan
    xs = sorted(xs)
    i = min(len(xs) - 1, max(0, int(math.ceil(q / 100.0 * len(xs))) - 1))
    return xs[i]


def _renice(n: int) -> None:
    try:
        os.nice(n)
    except OSError:  # not permitted for a negative increment without CAP_SYS_NICE
        pass


PROFILED: tuple[tuple[str, str, str], ...] = (
    ("asyncio.base_events", "BaseEventLoop._run_once", "loop: its step"),
    ("asyncio.events", "Handle._run", "loop: callbacks and task steps"),
    ("selectors", "EpollSelector.select", "select"),
    ("asyncio.selector_events", "_SelectorDatagramTransport._read_ready", "udp read"),
    ("onboard.drivers.transports", "Poller.drain", "udp read"),
    ("onboard.service.intake", "Intake.receive", "receive"),
    ("onboard.service.intake", "Intake.parse", "parse"),
    ("onboard.service.intake", "Intake._parse", "parse"),
    ("onboard.service.recorder", "Recorder.write", "record"),
    ("onboard.service.recorder", "Recorder.poll", "record"),
    ("onboard.engine.engine", "Engine.push", "engine push"),
    ("onboard.engine.engine", "Engine.admit", "engine push"),
    ("onboard.engine.engine", "Engine.tick", "engine tick"),
    ("onboard.engine.engine", "Engine.location_fixes", "zenoh"),
    ("onboard.service.intake", "Intake.tick", "intake tick"),
    ("onboard.service.publishers.zenoh_pub", "ZenohPublisher.publish_estimates", "zenoh"),
    ("onboard.service.publishers.zenoh_pub", "ZenohPublisher.publish_health", "zenoh"),
    ("onboard.service.publishers.mavlink_pub", "MavlinkPublisher.publish_estimates", "mavlink out"),
    ("onboard.service.publishers.mavlink_pub", "MavlinkPublisher.publish_health", "mavlink out"),
    ("onboard.service.daemon", "Service._health", "health"),
    ("onboard.service.daemon", "Service._poll_sessions", "sessions"),
    ("onboard.service.daemon", "Service._tick", "tick rest"),
)
"""(module, qualified name, component): the functions whose CPU time the profiled child
(:func:`profiled_run`) attributes to a component, exclusive of the profiled functions they
call; a name missing from the tree is skipped. The main thread's remaining CPU time is the
event loop's own (its steps, tasks, futures and timers) and the wait for the tick."""


def profiled_run(argv: list[str], out_path: str) -> int:
    """``onboard run ARGV`` with the functions of :data:`PROFILED` timed in thread CPU
    time (exclusive of nested profiled calls) and the event loop's iterations counted;
    every SIGUSR1 appends a JSON line of the totals so far (with the main thread's CPU
    time) to ``out_path``. The parent takes the difference of two lines (a window)."""
    import importlib

    totals: dict[str, float] = {}
    calls: dict[str, int] = {}
    stack: list[list[float]] = []
    tt = time.thread_time
    main_ident = threading.get_ident()

    def wrap(fn: Any, comp: str) -> Any:
        def timed(*a: Any, **kw: Any) -> Any:
            if threading.get_ident() != main_ident:
                return fn(*a, **kw)
            frame = [tt(), 0.0]
            stack.append(frame)
            try:
                return fn(*a, **kw)
            finally:
                stack.pop()
                spent = tt() - frame[0]
                totals[comp] = totals.get(comp, 0.0) + spent - frame[1]
                calls[comp] = calls.get(comp, 0) + 1
                if stack:
                    stack[-1][1] += spent
        return timed

    for mod_name, qual, comp in PROFILED:
        try:
            owner: Any = importlib.import_module(mod_name)
            *path, name = qual.split(".")
            for part in path:
                owner = getattr(owner, part)
            fn = getattr(owner, name)
        except (ImportError, AttributeError):
            continue
        setattr(owner, name, wrap(fn, comp))

    gc_start = [0.0]

    def on_gc(phase: str, info: dict[str, int]) -> None:
        if threading.get_ident() != main_ident:
            return
        if phase == "start":
            gc_start[0] = tt()
            return
        spent = tt() - gc_start[0]
        comp = f"gc (generation {info['generation']})"
        totals[comp] = totals.get(comp, 0.0) + spent
        calls[comp] = calls.get(comp, 0) + 1
        if stack:
            stack[-1][1] += spent

    gc.callbacks.append(on_gc)

    def snapshot(signum: int, frame: Any) -> None:
        with open(out_path, "a") as f:
            f.write(json.dumps({"main_cpu_s": tt(), "components_s": totals,
                                "calls": calls}) + "\n")

    signal.signal(signal.SIGUSR1, snapshot)
    from onboard.cli import main

    return main(argv)


def _profile_window(lines: list[dict[str, Any]], wall_s: float) -> dict[str, Any]:
    """Per component ms of main-thread CPU per wall second between two snapshots, and
    calls per second (``select`` calls are the event loop's wake-ups)."""
    a, b = lines[0], lines[-1]
    comps = {k: (v - a["components_s"].get(k, 0.0)) * 1000.0 / wall_s
             for k, v in b["components_s"].items()}
    main_ms = (b["main_cpu_s"] - a["main_cpu_s"]) * 1000.0 / wall_s
    comps["loop and the rest"] = main_ms - sum(comps.values())
    rates = {k: (v - a["calls"].get(k, 0)) / wall_s for k, v in b["calls"].items()}
    return {"main_thread_ms_per_s": round(main_ms, 2),
            "ms_per_s": {k: round(v, 2) for k, v in sorted(comps.items(), key=lambda kv: -kv[1])},
            "calls_per_s": {k: round(v, 1) for k, v in sorted(rates.items())}}


def measure(duration_s: float = 30.0, *, warmup_s: float = 3.0,
            pipelines: tuple[str, ...] | None = None, nice: int = -5,
            profile: bool = False, link: LinkDelay | None = None) -> dict[str, Any]:
    """Run the service under nominal load for ``duration_s`` wall seconds (after
    ``warmup_s``); return the figures of the module docstring (and a few more).

    ``pipelines`` overrides the registered pipeline modules (``onboard.pipelines.MODULES``)
    in the child, e.g. ``("nav", "aie", "kf", "current")``; None runs those registered.
    ``nice`` is applied to the child as systemd/onboard.service does (``Nice=-5``) when
    permitted (root or CAP_SYS_NICE), else ignored; ``nice_applied`` says which.
    ``profile``: the child is :func:`profiled_run` and ``profile`` in the result has its
    main thread's CPU per component over the window (the timing adds ~1 µs per profiled
    call to the figures). ``link``: the traffic reaches the service as over that link
    (:class:`LinkedTraffic`); None sends every frame on its grid time.
    """
    from onboard.service.publishers.zenoh_pub import open_router

    zport = free_tcp_port()
    endpoint = f"tcp/127.0.0.1:{zport}"
    mav_port, nmea_port, mav_out = free_udp_port(), free_udp_port(), free_udp_port()
    router = open_router(endpoint)
    tmp = tempfile.TemporaryDirectory(prefix="onboard-bench-")
    d = Path(tmp.name)
    (d / "bench.toml").write_text(bench_config_toml(mav_port, nmea_port, endpoint, mav_out))
    notify_path = str(d / "notify.sock")
    nsock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    nsock.bind(notify_path)
    nsock.settimeout(0.05)
    lat_sensor: list[float] = []
    lat_tick: list[float] = []
    measuring = threading.Event()
    import msgspec

    from onboard.core.messages import EstimateRecord

    dec = msgspec.json.Decoder(EstimateRecord)

    def on_sample(sample: Any) -> None:
        t_rx = time.monotonic()
        if not measuring.is_set():
            return
        try:
            rec = dec.decode(sample.payload.to_bytes())
        except msgspec.DecodeError:
            return
        lat_tick.append((t_rx - rec.t) * 1000.0)
        if rec.t_sensor is not None:
            lat_sensor.append((t_rx - rec.t_sensor) * 1000.0)

    sub = router.declare_subscriber(f"onboard/{BENCH_VEHICLE}/est/**", on_sample)
    env = dict(os.environ, NOTIFY_SOCKET=notify_path, ONBOARD_LOG_LEVEL="WARNING")
    env.pop("WATCHDOG_USEC", None)
    t_spawn = time.monotonic()
    argv = ["run", "--config", str(d / "bench.toml"), "--state-dir", str(d)]
    prof_path = str(d / "profile.jsonl")
    if profile:
        set_pipes = f"p.MODULES = {tuple(pipelines)!r}; " if pipelines is not None else ""
        cmd = [sys.executable, "-c", f"import sys, onboard.pipelines as p; {set_pipes}"
               "from onboard.apps.service_bench import profiled_run; "
               f"sys.exit(profiled_run({argv!r}, {prof_path!r}))"]
    elif pipelines is None:
        cmd = [sys.executable, "-m", "onboard", *argv]
    else:
        cmd = [sys.executable, "-c", "import sys, onboard.pipelines as p; "
               f"p.MODULES = {tuple(pipelines)!r}; from onboard.cli import main; "
               f"sys.exit(main({argv!r}))"]
    nice_ok = nice >= 0 or os.geteuid() == 0
    proc = subprocess.Popen(cmd, preexec_fn=(lambda: _renice(nice)) if nice else None,
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    ready_s = math.nan
    out: dict[str, Any] = {}
    try:
        deadline = t_spawn + 30.0
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                msg = nsock.recv(4096)
            except socket.timeout:
                continue
            if b"READY=1" in msg:
                ready_s = time.monotonic() - t_spawn
                break
        if proc.poll() is not None:
            raise RuntimeError("service exited: " + proc.stderr.read().decode()[-500:])  # type: ignore[union-attr]
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        cpu0 = wall0 = None
        threads0: dict[str, float] | None = None
        for t_send, port, f in paced(LinkedTraffic(mav_port, nmea_port, link),
                                     warmup_s + duration_s):
            if cpu0 is None and t_send >= warmup_s:
                cpu0, wall0 = _proc_cpu_s(proc.pid), time.monotonic()
                threads0 = _threads_cpu_s(proc.pid)
                switches0 = _switches(proc.pid)
                if profile:
                    proc.send_signal(signal.SIGUSR1)
                measuring.set()
            tx.sendto(f, ("127.0.0.1", port))
        measuring.clear()
        cpu1, wall1 = _proc_cpu_s(proc.pid), time.monotonic()
        threads1 = _threads_cpu_s(proc.pid)
        switches1 = _switches(proc.pid)
        if profile:
            proc.send_signal(signal.SIGUSR1)
        rss, hwm = _proc_rss_mb(proc.pid)
        tx.close()
        assert cpu0 is not None and wall0 is not None and threads0 is not None
        out = {
            "service_cpu_fraction": (cpu1 - cpu0) / (wall1 - wall0),
            "cpu_fraction_by_thread": {
                k: round((v - threads0.get(k, 0.0)) / (wall1 - wall0), 4)
                for k, v in sorted(threads1.items()) if v - threads0.get(k, 0.0) > 0},
            "service_wakeups_per_s": (switches1[0] - switches0[0]) / (wall1 - wall0),
            "main_thread_preemptions_per_s": (switches1[1] - switches0[1]) / (wall1 - wall0),
            "sensor_to_zenoh_p50_ms": _pct(lat_sensor, 50),
            "sensor_to_zenoh_p99_ms": _pct(lat_sensor, 99),
            "tick_to_zenoh_p50_ms": _pct(lat_tick, 50),
            "tick_to_zenoh_p99_ms": _pct(lat_tick, 99),
            "tick_to_zenoh_mean_ms": statistics.fmean(lat_tick) if lat_tick else math.nan,
            "service_rss_mb": rss,
            "service_peak_rss_mb": hwm,
            "startup_to_ready_s": ready_s,
            "estimates_received": len(lat_tick),
            "pipelines": list(pipelines) if pipelines is not None else "registered",
            "nice_applied": nice if nice_ok else 0,
            "loadavg_1min": os.getloadavg()[0],
            "duration_s": wall1 - wall0,
            "link": None if link is None else dataclasses.asdict(link),
                        "load": "IMU 50 Hz, servo 10 Hz, heartbeat 1 Hz (MAVLink/UDP); GNSS 5 Hz, "
                    "heading 10 Hz (NMEA/UDP)",
        }
        if profile:
            time.sleep(0.2)
            lines = [json.loads(x) for x in Path(prof_path).read_text().splitlines()]
            out["profile"] = _profile_window(lines, wall1 - wall0)
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if proc.stderr is not None:
            proc.stderr.close()
        sub.undeclare()
        router.close()
        nsock.close()
        tmp.cleanup()
    return out


def bare_receiver(mav_port: int, nmea_port: int, parse: bool, rate_hz: float = 10.0) -> None:
    """Receive the bench's traffic and do nothing else: wake on a ``rate_hz`` grid, as the
    service's ticks do, drain both UDP sockets, and with ``parse`` feed each datagram to
    the service's own parsers (:class:`drivers.mavlink.MavlinkParser`,
    :class:`drivers.nmea.NmeaParser`). On SIGTERM it prints the datagrams and samples it
    got (JSON) and exits. Its CPU is the floor under :func:`measure`'s:
    :func:`receiver_floor`."""
    import asyncio

    from onboard.drivers.mavlink import MavlinkParser
    from onboard.drivers.nmea import NmeaParser

    socks = []
    for port in (mav_port, nmea_port):
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", port))
        sock.setblocking(False)
        socks.append(sock)
    feeds = ([MavlinkParser().feed, NmeaParser().feed] if parse
             else [lambda data, t: (), lambda data, t: ()])
    got = {"datagrams": 0, "samples": 0}

    async def ticks() -> None:
        loop = asyncio.get_running_loop()
        stop = asyncio.Event()
        loop.add_signal_handler(signal.SIGTERM, stop.set)
        t0, k = loop.time(), 0
        while not stop.is_set():
            k += 1
            await asyncio.sleep(max(0.0, t0 + k / rate_hz - loop.time()))
            t = time.monotonic()
            for sock, feed in zip(socks, feeds):
                while True:
                    try:
                        data = sock.recv(65536)
                    except BlockingIOError:
                        break
                    got["datagrams"] += 1
                    got["samples"] += len(feed(data, t))

    asyncio.run(ticks())
    print(json.dumps(got), flush=True)


def receiver_floor(duration_s: float = 20.0, *, parse: bool, warmup_s: float = 3.0,
                   link: LinkDelay | None = None) -> dict[str, Any]:
    """:func:`bare_receiver` (a child process) fed :func:`measure`'s traffic: what
    receiving (and with ``parse``, parsing) that traffic costs a Python process on this
    machine before any of the service's own work. ``cpu_fraction``: its CPU seconds per
    wall second over the window; ``sent``: the datagrams sent in all; ``datagrams``,
    ``samples``: what it received and parsed (every datagram sent, or the floor is
    wrong)."""
    mav_port, nmea_port = free_udp_port(), free_udp_port()
    proc = subprocess.Popen(
        [sys.executable, "-c", "from onboard.apps.service_bench import bare_receiver; "
         f"bare_receiver({mav_port}, {nmea_port}, {parse})"],
        stdout=subprocess.PIPE, text=True)
    try:
        time.sleep(1.5)  # the interpreter up and the sockets bound
        if proc.poll() is not None:
            raise RuntimeError(f"the bare receiver exited ({proc.returncode})")
        cpu0 = wall0 = None
        sent = 0
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for t_send, port, frame in paced(LinkedTraffic(mav_port, nmea_port, link),
                                             warmup_s + duration_s):
                if cpu0 is None and t_send >= warmup_s:
                    cpu0, wall0 = _proc_cpu_s(proc.pid), time.monotonic()
                tx.sendto(frame, ("127.0.0.1", port))
                sent += 1
        assert cpu0 is not None and wall0 is not None
        fraction = (_proc_cpu_s(proc.pid) - cpu0) / (time.monotonic() - wall0)
        time.sleep(0.25)  # its last tick drains what is in flight
        proc.terminate()
        out, _ = proc.communicate(timeout=10)
        return {"cpu_fraction": fraction, "sent": sent, **json.loads(out)}
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


if __name__ == "__main__":  # pragma: no cover
    import json

    pipes = tuple(sys.argv[2].split(",")) if len(sys.argv) > 2 else None
    print(json.dumps(measure(float(sys.argv[1]) if len(sys.argv) > 1 else 10.0, pipelines=pipes),
                     indent=2))
