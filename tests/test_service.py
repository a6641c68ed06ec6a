"""The service end to end with hand-made protocol bytes: UDP, pty and TCP in; Zenoh and
MAVLink out; bad input counted; replay of the recording reproduces the live estimates
exactly; adaptive state across restarts; SIGTERM and READY in a real child process."""

from __future__ import annotations

import asyncio
import json
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import tty
from pathlib import Path

import msgspec
import pytest
from pymavlink.dialects.v20 import common as mavlink2

import onboard.pipelines as pipelines_pkg
from onboard.drivers.dvl_json import encode_velocity_report
from onboard.drivers.recording import read_records
from onboard.core.messages import HEALTH_SCHEMA_VERSION, EstimateRecord, HealthRecord
from onboard.engine import Engine
from onboard.service.daemon import Service
from onboard.service.publishers.zenoh_pub import open_router
from onboard.service.recorder import replay_recording
from onboard.sitl.link import ARDUSUB_TETHER
from onboard.apps.service_bench import (
    LinkedTraffic, TrafficGenerator, free_tcp_port, free_udp_port, paced, receiver_floor)
from tests.helpers.service_config import service_config

REPO = Path(__file__).resolve().parent.parent
TIMEOUT = 60.0


def _all_pipelines(monkeypatch) -> None:
    """Run every pipeline module that exists (the integrator registers them in MODULES)."""
    mods = [m for m in ("nav", "aie", "kf", "current", "eseso")
            if (REPO / "onboard" / "pipelines" / f"{m}.py").exists()]
    monkeypatch.setattr(pipelines_pkg, "MODULES", tuple(mods))


def _new_pty() -> tuple[int, str]:
    master, slave = os.openpty()
    tty.setraw(slave)
    return master, os.ttyname(slave)


class Traffic:
    """Sends the generator's frames: MAVLink over UDP, NMEA on a pty (split mid-line),
    DVL JSON to a TCP client, plus garbage on every link."""

    def __init__(self, mav_port: int, nmea_master: int) -> None:
        self.gen = TrafficGenerator(system_id=1)
        self.udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.mav_port = mav_port
        self.master = nmea_master
        self.dvl_clients: list[socket.socket] = []

    def send(self, t: float, k: int) -> None:
        for f in self.gen.mavlink(t):
            self.udp.sendto(f, ("127.0.0.1", self.mav_port))
        for f in self.gen.nmea(t):
            half = len(f) // 2  # a serial line delivers sentences in arbitrary pieces
            os.write(self.master, f[:half])
            os.write(self.master, f[half:])
        if k % 10 == 0:
            line = encode_velocity_report(1.5, 0.0, 0.0, altitude_m=3.0)
            for c in list(self.dvl_clients):
                try:
                    c.sendall(line)
                except OSError:
                    self.dvl_clients.remove(c)
        if k % 25 == 7:  # bad input on every link
            self.udp.sendto(b"\xfd\x09garbage-not-mavlink", ("127.0.0.1", self.mav_port))
            os.write(self.master, b"$GPHDT,123.4,T*00\r\n")  # wrong checksum
            os.write(self.master, b"$GPGGA," + b"9" * 400 + b"\r\n")  # oversize line
            for c in list(self.dvl_clients):
                c.sendall(b'{"type": "velocity", "vx": NaN}\n')

    def close(self) -> None:
        self.udp.close()
        for c in self.dvl_clients:
            c.close()


async def _drive(svc: Service, traffic: Traffic, seconds: float) -> None:
    t0 = time.monotonic()
    k = 0
    while k / 50.0 < seconds:
        delay = t0 + k / 50.0 - time.monotonic()
        if delay > 0:
            await asyncio.sleep(delay)
        traffic.send(k / 50.0, k)
        k += 1


@pytest.mark.integration
def test_service_end_to_end_over_udp_pty_tcp_to_zenoh_and_mavlink_and_exact_replay(
        tmp_path, monkeypatch):
    _all_pipelines(monkeypatch)
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_router(endpoint)
    import zenoh

    from onboard.service.publishers.zenoh_pub import session_config

    shore = zenoh.open(session_config("client", connect=[endpoint]))
    got: dict[str, list[bytes]] = {}
    lock = threading.Lock()

    def on(sample):
        with lock:
            got.setdefault(str(sample.key_expr), []).append(sample.payload.to_bytes())

    sub = shore.declare_subscriber("onboard/testboat/**", on)
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", 0))
    gcs.setblocking(False)
    master, pty_path = _new_pty()
    dvl_server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    dvl_server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    dvl_server.bind(("127.0.0.1", 0))
    dvl_server.listen(1)
    mav_port = free_udp_port()
    cfg = service_config(
        sources=[{"kind": "mavlink", "url": f"udp:127.0.0.1:{mav_port}", "name": "autopilot"},
                 {"kind": "nmea", "url": f"pty:{pty_path}", "name": "gps"},
                 {"kind": "dvl-json", "url": f"tcp:127.0.0.1:{dvl_server.getsockname()[1]}",
                  "name": "dvl"}],
        zenoh={"mode": "client", "connect": [endpoint]},
        mavlink={"url": f"udpout:127.0.0.1:{gcs.getsockname()[1]}"},
        recorder={"flush_interval_s": 0.2})
    live: list[tuple[float, list[bytes]]] = []
    enc = msgspec.json.Encoder()
    traffic = Traffic(mav_port, master)

    async def main() -> Service:
        svc = Service(cfg, state_dir=tmp_path,
                      on_tick=lambda t, recs: live.append((t, [enc.encode(r) for r in recs])))
        accept = asyncio.get_running_loop().run_in_executor(None, dvl_server.accept)
        await svc.start()
        conn, _ = await asyncio.wait_for(accept, TIMEOUT)
        traffic.dvl_clients.append(conn)
        await _drive(svc, traffic, 3.0)
        await asyncio.sleep(0.5)
        svc._health(svc.clock.now())
        svc.request_stop()
        await svc.shutdown()
        return svc

    try:
        svc = asyncio.run(asyncio.wait_for(main(), TIMEOUT))
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            with lock:
                if "onboard/testboat/health" in got and "onboard/testboat/est/nav" in got:
                    break
            time.sleep(0.05)
    finally:
        traffic.close()
        sub.undeclare()
        shore.close()
        router.close()
        os.close(master)
        dvl_server.close()

    # inputs: every link connected and delivered samples; bad input counted, not fatal
    assert {s: st.samples > 0 for s, st in svc.intake.sources.items()} == {
        "autopilot": True, "gps": True, "dvl": True}
    h = svc.health(svc.clock.now())
    assert h.rejected.get("parse:gps:checksum", 0) >= 1
    assert h.rejected.get("parse:gps:too_long", 0) >= 1
    assert any(k.startswith("parse:autopilot:") for k in h.rejected)  # "incompat" here
    assert any(k.startswith("parse:dvl:") for k in h.rejected)
    # Zenoh: estimates and health on the contract keys, JSON with schema
    with lock:
        keys = set(got)
        nav = [msgspec.json.decode(p, type=EstimateRecord) for p in got["onboard/testboat/est/nav"]]
        healths = [msgspec.json.decode(p, type=HealthRecord) for p in got["onboard/testboat/health"]]
    assert "onboard/testboat/est/nav" in keys and nav[-1].vehicle == "testboat"
    assert {"north", "east", "heading"} <= set(nav[-1].values)
    assert max(x.rates_hz.get("autopilot", 0) for x in healths) > 10  # ~60 samples/s
    assert max(x.rates_hz.get("gps", 0) for x in healths) > 3  # 5 fixes + 10 headings/s
    assert healths[-1].schema == HEALTH_SCHEMA_VERSION and healths[-1].mode == "surface"
    # MAVLink out: heartbeat from (3, 191) and ESTIMATOR_STATUS reached the "GCS"
    mav = mavlink2.MAVLink(None)
    types = set()
    while True:
        try:
            data = gcs.recv(65536)
        except BlockingIOError:
            break
        for m in mav.parse_buffer(data) or []:
            assert (m.get_srcSystem(), m.get_srcComponent()) == (3, 191)
            types.add(m.get_type())
    gcs.close()
    assert {"HEARTBEAT", "ESTIMATOR_STATUS"} <= types

    # replay of the recording reproduces every live tick exactly, record for record
    files = svc.recorder.files
    kinds = {r.kind for f in files for r in read_records(f)}
    assert {"meta", "tick", "mavlink", "nmea", "dvl-json"} <= kinds
    replayed: list[tuple[float, list[bytes]]] = []
    res = replay_recording(files, Engine(cfg),
                           lambda t, recs: replayed.append((t, [enc.encode(r) for r in recs])))
    assert res.ticks == len(live) > 20
    assert replayed == live
    assert res.rejected == svc.intake.parse_rejections()  # same bad input, same counts
    n_values = sum(len(msgspec.json.decode(b)["values"]) for _, recs in live for b in recs)
    assert n_values > 100


@pytest.mark.integration
def test_adaptive_state_is_saved_on_stop_and_restored_on_start_corrupt_is_ignored(tmp_path):
    cfg = service_config(sources=[{"kind": "nmea", "url": f"udp:127.0.0.1:{free_udp_port()}"}],
                  zenoh={"enabled": False}, mavlink={"enabled": False},
                  recorder={"enabled": False}, state_file="st/adaptive.json")

    async def once() -> Service:
        svc = Service(cfg, state_dir=tmp_path)
        await svc.start()
        await asyncio.sleep(0.3)
        svc.request_stop()
        await svc.shutdown()
        return svc

    first = asyncio.run(asyncio.wait_for(once(), TIMEOUT))
    doc = json.loads((tmp_path / "st" / "adaptive.json").read_text())
    assert doc["format"] == "onboard-state" and doc["vehicle"] == "testboat"
    assert first.stats.state_saves >= 1
    second = asyncio.run(asyncio.wait_for(once(), TIMEOUT))
    assert any("restored adaptive state" in e for e in second.events)
    (tmp_path / "st" / "adaptive.json").write_text("{ not json")
    third = asyncio.run(asyncio.wait_for(once(), TIMEOUT))
    assert any("corrupt" in e for e in third.events)
    assert third.stats.ticks > 0  # and it ran anyway
    # a file that parses with one malformed entry: the service starts and says which
    doc["pipelines"]["current"]["thetas"] = "junk"
    (tmp_path / "st" / "adaptive.json").write_text(json.dumps(doc))
    fourth = asyncio.run(asyncio.wait_for(once(), TIMEOUT))
    said = [e for e in fourth.events if "not restored: current (AttributeError" in e]
    assert len(said) == 1 and fourth.stats.ticks > 0
    kept = [p.name for p in (tmp_path / "st").iterdir() if ".corrupt-" in p.name]
    assert len(kept) == 2 and any(k in said[0] for k in kept)


@pytest.mark.integration
@pytest.mark.parametrize("wait_s", [0.0, 0.05])
def test_ticks_fire_on_the_grid_or_on_the_first_sample_after_it(tmp_path, wait_s):
    """``service.tick_wait_s = 0``: every tick on the grid ``k / rate_hz``, its newest
    sample older than the grid time. ``> 0``: a tick waits for the first sample after its
    grid time and carries it (this is what makes sensor-to-shore latency the step, not the
    wait for the grid); a tick with no such sample in time fires at the deadline."""
    port, nmea_port = free_udp_port(), free_udp_port()
    cfg = service_config(sources=[{"kind": "mavlink", "url": f"udp:127.0.0.1:{port}"},
                           {"kind": "nmea", "url": f"udp:127.0.0.1:{nmea_port}"}],
                  zenoh={"enabled": False}, mavlink={"enabled": False},
                  recorder={"enabled": False}, tick_wait_s=wait_s)
    ticks: list[tuple[float, float | None]] = []
    gen = TrafficGenerator(system_id=1)
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    async def main() -> Service:
        svc = Service(cfg, state_dir=tmp_path, on_tick=lambda t, recs: ticks.append(
            (t, recs[0].t_sensor if recs else None)))
        await svc.start()
        t0 = time.monotonic()
        for k in range(100):  # 2 s of 50 Hz MAVLink and 5-10 Hz NMEA
            await asyncio.sleep(max(0.0, t0 + k / 50.0 - time.monotonic()))
            for f in gen.mavlink(k / 50.0):
                udp.sendto(f, ("127.0.0.1", port))
            for f in gen.nmea(k / 50.0):
                udp.sendto(f, ("127.0.0.1", nmea_port))
        svc.request_stop()
        await svc.shutdown()
        return svc

    try:
        asyncio.run(asyncio.wait_for(main(), TIMEOUT))
    finally:
        udp.close()
    fed = [(t, ts) for t, ts in ticks if ts is not None]
    assert len(fed) > 10
    grid = [math.floor(t * 10.0 + 1e-9) / 10.0 for t, _ in fed]
    assert all(0.0 <= t - g <= 0.05 + 1e-9 for (t, _), g in zip(fed, grid))
    assert all(ts <= t for t, ts in fed)  # never a sample from the tick's future
    after_grid = sum(ts > g for (_, ts), g in zip(fed, grid)) / len(fed)
    if wait_s == 0.0:
        assert all(t == g or abs(t - g) < 1e-9 for (t, _), g in zip(fed, grid))
        assert after_grid == 0.0
    else:
        # the 50 Hz IMU is sent within 20 ms of every grid time: most ticks carry a sample
        # stamped after it (measured 0.9-1.0 alone; 0.42 in a CI run whose load stalled the
        # sender, which shares the service's event loop). A tick is triggered by a chunk
        # that arrives after its grid time, and a MAVLink sample is stamped by its own
        # boot time, which may lie before it: the share, not every tick, is asserted
        assert after_grid > 0.2, after_grid


def _ticks_fed(tmp_path: Path, link, seconds: float) -> tuple[Service, list]:
    """A service reading the bench's traffic (:class:`LinkedTraffic`, over ``link`` or on
    its grid) sent from a thread of its own for ``seconds``: the service and its ticks
    ``(t, t_sensor)``."""
    port, nmea_port = free_udp_port(), free_udp_port()
    cfg = service_config(sources=[{"kind": "mavlink", "url": f"udp:127.0.0.1:{port}"},
                                  {"kind": "nmea", "url": f"udp:127.0.0.1:{nmea_port}"}],
                         zenoh={"enabled": False}, mavlink={"enabled": False},
                         recorder={"enabled": False})
    ticks: list[tuple[float, float | None]] = []
    traffic = LinkedTraffic(port, nmea_port, link)
    stop = threading.Event()

    def send() -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
            for _, to, f in paced(traffic, seconds + 1.0):
                if stop.is_set():
                    return
                udp.sendto(f, ("127.0.0.1", to))

    async def main() -> Service:
        svc = Service(cfg, state_dir=tmp_path, on_tick=lambda t, recs: ticks.append(
            (t, recs[0].t_sensor if recs else None)))
        await svc.start()
        sender = threading.Thread(target=send, daemon=True)
        sender.start()
        await asyncio.sleep(seconds)
        stop.set()
        sender.join()
        svc.request_stop()
        await svc.shutdown()
        return svc

    svc = asyncio.run(asyncio.wait_for(main(), TIMEOUT))
    return svc, [(t, ts) for t, ts in ticks if ts is not None]


def test_ticks_fed_at_a_steady_phase_wake_once_at_the_predicted_arrival(tmp_path):
    """A 50 Hz input sent from its own thread keeps its phase against the tick grid: after
    the first tick, a tick's timer is set at the predicted arrival of its fresh sample and
    finds it there, so few ticks watch the inputs for it (a second wake-up); the ticks
    still carry a sample received after their grid time."""
    for attempt in range(3):
        # a machine too busy for the sender's thread to keep its phase gives ticks that
        # watch (17 of 30 once, in a fresh-clone suite at load 2): measured again, twice
        work = tmp_path / str(attempt)
        work.mkdir()
        svc, fed = _ticks_fed(work, None, 3.0)
        if svc.stats.tick_watches < svc.stats.ticks / 2:
            break
    assert len(fed) > 20 and svc.stats.ticks >= len(fed)
    # measured 1-6 watches in 30 ticks (load 1-2; without the prediction every tick
    # watches); the bound leaves room for a loaded machine
    assert svc.stats.tick_watches < svc.stats.ticks / 2, (svc.stats.tick_watches, svc.stats.ticks)
    after_grid = sum(ts > math.floor(t * 10.0 + 1e-9) / 10.0 for t, ts in fed) / len(fed)
    assert after_grid > 0.5, after_grid


def test_ticks_over_a_link_whose_delay_wanders_still_fire_once_per_grid_time(tmp_path):
    """The autopilot's frames and the NMEA late by a delay that wanders as the ArduSub
    tlog's did (``sitl.link.ARDUSUB_TETHER``: 8 ms, spread 7 ms, 0.25 s of memory; the
    receiver on a phase of its own): the predictions miss more often, and still every grid
    time gets one tick within the wait, none carries a sample measured after it fired, and
    most carry one measured after their grid time."""
    svc, fed = _ticks_fed(tmp_path, ARDUSUB_TETHER, 3.5)
    assert len(fed) > 20 and svc.stats.tick_skips == 0
    grid = [math.floor(t * 10.0 + 1e-9) / 10.0 for t, _ in fed]
    assert len(set(grid)) == len(grid)  # one tick per grid time
    assert all(0.0 <= t - g <= 0.05 + 1e-9 for (t, _), g in zip(fed, grid))
    assert all(ts <= t for t, ts in fed)
    after_grid = sum(ts > g for (_, ts), g in zip(fed, grid)) / len(fed)
    assert after_grid > 0.5, after_grid


def _write_config(path: Path, udp_port: int) -> None:
    path.write_text(f"""
[vehicle]
id = "proc"
class = "rudder-boat"

[[service.sources]]
kind = "mavlink"
url = "udp:127.0.0.1:{udp_port}"

[service.zenoh]
enabled = false

[service.mavlink]
url = "udpout:127.0.0.1:{free_udp_port()}"
""")


@pytest.mark.integration
@pytest.mark.parametrize("sig, status", [(signal.SIGTERM, 0), (signal.SIGINT, 130)],
                         ids=["sigterm", "sigint"])
def test_onboard_run_notifies_ready_and_stops_cleanly_on_sigterm(tmp_path, sig, status):
    """READY=1, watchdog pings, then a graceful stop (STOPPING=1, recording and state
    written) on SIGTERM, exit 0 (systemd's stop), and on SIGINT, exit 130 (Ctrl-C, as
    every command, architecture.md §4.1)."""
    cfg_path = tmp_path / "boat.toml"
    port = free_udp_port()
    _write_config(cfg_path, port)
    notify = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    notify.bind(str(tmp_path / "notify"))
    notify.settimeout(TIMEOUT)
    env = dict(os.environ, NOTIFY_SOCKET=str(tmp_path / "notify"), WATCHDOG_USEC="1000000")
    proc = subprocess.Popen([sys.executable, "-m", "onboard", "run", "--config", str(cfg_path),
                             "--state-dir", str(tmp_path / "state")], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        msgs = [notify.recv(4096)]
        while not msgs[-1].startswith(b"READY=1"):
            msgs.append(notify.recv(4096))
        gen = TrafficGenerator()
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for k in range(50):
            for f in gen.mavlink(k / 50.0):
                tx.sendto(f, ("127.0.0.1", port))
            time.sleep(0.01)
        tx.close()
        while b"WATCHDOG=1" not in msgs:
            msgs.append(notify.recv(4096))
        proc.send_signal(sig)
        rc = proc.wait(TIMEOUT)
        while not msgs[-1].startswith(b"STOPPING=1"):
            msgs.append(notify.recv(4096))
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        err = proc.stderr.read().decode()
        proc.stdout.close()
        proc.stderr.close()
        notify.close()
    assert rc == status, err
    assert "Traceback" not in err, err
    recs = list((tmp_path / "state" / "recordings").glob("*.onbrec"))
    assert len(recs) == 1
    kinds = [r.kind for r in read_records(recs[0])]
    assert kinds[0] == "meta" and "mavlink" in kinds and "tick" in kinds
    assert (tmp_path / "state" / "state" / "adaptive.json").exists()


@pytest.mark.integration
@pytest.mark.parametrize("text, reason", [
    ("[vehicle]\nid = 3\n", "vehicle.id"),
    ("[vehicle]\nid = \"x\"\n", "sources is empty"),
    ("[[service.sources]]\nkind = \"nmea\"\nurl = \"udp:nowhere\"\n", "sources[0].url"),
    ("[[service.sources]]\nkind = \"nmea\"\nurl = \"udp:127.0.0.1:1\"\n"
     "[service.mavlink]\nrequire_signing = true\n", "require_signing"),
])
def test_onboard_run_with_a_bad_config_exits_2_with_a_one_line_reason(tmp_path, text, reason):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    r = subprocess.run([sys.executable, "-m", "onboard", "run", "--config", str(p),
                        "--state-dir", str(tmp_path)], capture_output=True, text=True,
                       timeout=TIMEOUT)
    assert r.returncode == 2 and reason in r.stderr and len(r.stderr.strip().splitlines()) == 1


@pytest.mark.integration
def test_an_unplugged_input_is_reported_and_picked_up_again_while_the_service_runs(tmp_path):
    link = tmp_path / "gps"

    def plug() -> int:
        master, slave = os.openpty()
        tty.setraw(slave)
        name = os.ttyname(slave)
        os.close(slave)
        os.symlink(name, str(link) + ".new")
        os.replace(str(link) + ".new", link)
        return master

    cfg = service_config(sources=[{"kind": "nmea", "url": f"pty:{link}", "name": "gps"}],
                  zenoh={"enabled": False}, mavlink={"enabled": False},
                  recorder={"enabled": False})
    from onboard.drivers.nmea import encode_hdt

    async def main() -> Service:
        master = plug()
        svc = Service(cfg, state_dir=tmp_path)
        await svc.start()
        os.write(master, encode_hdt(1.0))
        await asyncio.sleep(0.3)
        os.close(master)  # unplugged
        await asyncio.sleep(0.5)
        master = plug()  # back
        deadline = time.monotonic() + 20
        while svc.inputs[0].transport.stats.connects < 2 and time.monotonic() < deadline:
            await asyncio.sleep(0.05)
        os.write(master, encode_hdt(2.0))
        await asyncio.sleep(0.3)
        svc.request_stop()
        await svc.shutdown()
        os.close(master)
        return svc

    svc = asyncio.run(asyncio.wait_for(main(), TIMEOUT))
    assert any("gps: lost" in e for e in svc.events), list(svc.events)
    assert svc.intake.sources["gps"].samples == 2  # one heading before, one after
    assert svc.stats.ticks > 5


def test_the_bench_traffic_is_real_protocol_at_the_nominal_rates():
    """50 Hz IMU, 5 Hz GNSS, 10 Hz heading, 10 Hz servo outputs, 1 Hz heartbeat."""
    from collections import Counter

    from onboard.drivers.protocols import parser_for

    gen = TrafficGenerator()
    mav, nmea = parser_for("mavlink"), parser_for("nmea", "gps")
    kinds: Counter[str] = Counter()
    for k in range(500):  # 10 s
        t = k / 50.0
        for f in gen.mavlink(t):
            kinds.update(type(s).__name__ for s in mav.feed(f, t))
        for f in gen.nmea(t):
            kinds.update(type(s).__name__ for s in nmea.feed(f, t))
    assert not mav.stats.rejected and not nmea.stats.rejected
    assert kinds["Imu"] == 500 and kinds["ActuatorOutputs"] == 100
    assert kinds["Heading"] == 100 and 49 <= kinds["GnssFix"] <= 50
    assert kinds["VehicleInfo"] == 10


@pytest.mark.integration
def test_random_and_mutated_bytes_on_every_protocol_never_stop_the_service(tmp_path):
    """Fuzz the live path: valid frames with flipped bytes, truncations and pure noise."""
    import random

    rng = random.Random(7)
    ports = {k: free_udp_port() for k in ("mavlink", "nmea", "dvl-json", "pd6")}
    cfg = service_config(sources=[{"kind": k, "url": f"udp:127.0.0.1:{p}", "name": k}
                           for k, p in ports.items()],
                  zenoh={"enabled": False}, mavlink={"enabled": False},
                  recorder={"enabled": False})
    gen = TrafficGenerator()
    valid = {"mavlink": [f for k in range(50) for f in gen.mavlink(k / 50)],
             "nmea": [f for k in range(50) for f in gen.nmea(k / 50)],
             "dvl-json": [encode_velocity_report(0.5, 0.1, 0.0)],
             "pd6": [b":BS,+01500,+00100,+00000,A\r\n:BD,+0000000.00,+0000000.00,+0000000.00,"
                     b"+003.00,000.00\r\n"]}

    def mutate(frame: bytes) -> bytes:
        b = bytearray(frame)
        op = rng.randrange(4)
        if op == 0 and b:
            for _ in range(rng.randint(1, 4)):
                b[rng.randrange(len(b))] = rng.randrange(256)
        elif op == 1 and b:
            b = b[: rng.randrange(len(b))]
        elif op == 2:
            b = bytearray(rng.randbytes(rng.randint(1, 600)))
        else:
            b += rng.randbytes(rng.randint(0, 50))
        return bytes(b)

    async def main() -> Service:
        svc = Service(cfg, state_dir=tmp_path)
        await svc.start()
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for i in range(2000):
            kind = rng.choice(list(ports))
            frame = rng.choice(valid[kind])
            tx.sendto(mutate(frame) if rng.random() < 0.7 else frame, ("127.0.0.1", ports[kind]))
            if i % 50 == 0:
                await asyncio.sleep(0.02)
        tx.close()
        await asyncio.sleep(0.3)
        svc.request_stop()
        await svc.shutdown()
        return svc

    svc = asyncio.run(asyncio.wait_for(main(), TIMEOUT))
    assert svc.stats.ticks > 5 and svc.stats.tick_errors == 0
    rej = svc.health(svc.clock.now()).rejected
    assert sum(v for k, v in rej.items() if k.startswith("parse:")) > 100
    assert all(st.parser_errors == 0 for st in svc.intake.sources.values()), {
        k: v for k, v in rej.items() if "parser_error" in k}


@pytest.mark.integration
def test_a_killed_service_leaves_a_readable_recording_missing_at_most_the_flush_interval(
        tmp_path):
    """SIGKILL (no chance to flush): everything received up to ~flush_interval_s before the
    kill is on disk and reads back; at most one torn frame at the end."""
    from onboard.drivers.base import ReadStats

    cfg_path = tmp_path / "boat.toml"
    port = free_udp_port()
    _write_config(cfg_path, port)
    notify = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    notify.bind(str(tmp_path / "notify"))
    notify.settimeout(TIMEOUT)
    proc = subprocess.Popen([sys.executable, "-m", "onboard", "run", "--config", str(cfg_path),
                             "--state-dir", str(tmp_path / "state")],
                            env=dict(os.environ, NOTIFY_SOCKET=str(tmp_path / "notify")),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        while not notify.recv(4096).startswith(b"READY=1"):
            pass
        gen = TrafficGenerator()
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sent = 0
        for k in range(100):  # 2 s of traffic
            for f in gen.mavlink(k / 50.0):
                tx.sendto(f, ("127.0.0.1", port))
                sent += 1
            time.sleep(0.02)
        time.sleep(1.5)  # > flush_interval_s (0.5 s) + the fsync
        proc.kill()
        proc.wait(TIMEOUT)
        tx.close()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        notify.close()
    (rec,) = (tmp_path / "state" / "recordings").glob("*.onbrec")
    stats = ReadStats()
    frames = [r for r in read_records(rec, stats) if r.kind == "mavlink"]
    assert len(frames) == sent  # all of it: the last datagram came 1.5 s before the kill
    assert sum(stats.rejected.values()) <= 1


@pytest.mark.integration
@pytest.mark.parametrize("level, ok", [("warning", True), ("VERBOSE", False)])
def test_onboard_log_level_is_read_in_any_case_and_a_bad_one_is_one_line(tmp_path, level, ok):
    p = tmp_path / "bad.toml"
    p.write_text("[vehicle]\nid = 3\n")  # refused after the log level is read
    r = subprocess.run([sys.executable, "-m", "onboard", "run", "--config", str(p),
                        "--state-dir", str(tmp_path)], capture_output=True, text=True,
                       timeout=TIMEOUT, env={**os.environ, "ONBOARD_LOG_LEVEL": level})
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert ("vehicle.id" in r.stderr) == ok and ("ONBOARD_LOG_LEVEL" in r.stderr) != ok


def test_the_bare_receiver_under_the_service_floor_gets_and_parses_every_datagram():
    """``service_bench.receiver_floor`` (docs/performance.md, "The floor"): the CPU of a
    process that only receives and parses the bench's traffic is a floor only if it got
    all of it; every SCALED_IMU frame (50 of the 76 datagrams a second) is a sample."""
    got = receiver_floor(2.0, parse=True, warmup_s=0.5)
    assert got["datagrams"] == got["sent"] > 100
    assert got["samples"] >= 0.6 * got["sent"]
    assert 0.0 <= got["cpu_fraction"] < 1.0
