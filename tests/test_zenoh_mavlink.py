"""MAVLink over Zenoh: ``onboard run`` with a ``zenoh:mavlink_raw`` source against the
ArduPilot-like simulator bridged onto a Zenoh router as BlueOS's mavlink-server bridges
the autopilot (tests/helpers/zenoh_bridge.py), and the transport's URL and its pieces."""

from __future__ import annotations

import asyncio
import subprocess
import sys
import threading
import time
from pathlib import Path

import msgspec
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from onboard.core.config import ConfigError, from_dict
from onboard.core.messages import EstimateRecord, HealthRecord
from onboard.drivers.transports import (
    TransportUrlError,
    ZenohTransport,
    open_transport,
    parse_url,
)
from onboard.service.config_check import check_zenoh_url
from onboard.service.publishers.zenoh_pub import open_router, session_config
from onboard.apps.service_bench import free_tcp_port
from tests.helpers.zenoh_bridge import UdpZenohBridge

REPO = Path(__file__).resolve().parent.parent
SIM_SECONDS = 30.0
"""Simulated (= wall, --realtime) seconds the simulator flies."""
WAIT_S = 45.0
PIPELINES = {"nav", "aie", "kf", "current"}
"""The pipelines of config/sitl-jaiabot.toml (a rudder boat)."""
SENT = {"COMMAND_LONG", "PARAM_REQUEST_READ", "TIMESYNC", "HEARTBEAT", "NAMED_VALUE_FLOAT",
        "ESTIMATOR_STATUS", "STATUSTEXT"}
"""What the service writes on ``mavlink_raw/in``: its stream requests, parameter reads and
TIMESYNC to the autopilot, and its estimates and events as component 191 (WIND_COV too
once the current has both horizontal components: in this scenario after about 40 s, as
over UDP, so the test checks it only when they came)."""


def test_zenoh_url_parses_to_its_key_prefix():
    spec = parse_url("zenoh:mavlink_raw")
    assert spec.scheme == "zenoh" and spec.path == "mavlink_raw" and str(spec) == "zenoh:mavlink_raw"
    assert parse_url("zenoh:/blueos/mavlink_raw/").path == "blueos/mavlink_raw"
    for bad in ("zenoh:", "zenoh:mavlink/*", "zenoh:a//b", "zenoh:$x"):
        with pytest.raises(TransportUrlError):
            parse_url(bad)


def test_a_zenoh_url_needs_a_session_and_the_zenoh_table():
    with pytest.raises(TransportUrlError, match="session"):
        open_transport("zenoh:mavlink_raw")
    tr = open_transport("zenoh:mavlink_raw", zenoh_session=lambda: None)
    assert isinstance(tr, ZenohTransport)
    assert (tr.rx_key, tr.tx_key) == ("mavlink_raw/out", "mavlink_raw/in")
    assert not tr.send(b"\xfd")  # no session yet: refused and counted
    assert tr.stats.tx_dropped == 1
    off = from_dict({"service": {"zenoh": {"enabled": False}}})
    with pytest.raises(ConfigError, match="service.zenoh.enabled"):
        check_zenoh_url(off, "zenoh:mavlink_raw", "service.sources[0].url", "mavlink")
    with pytest.raises(ConfigError, match="MAVLink"):
        check_zenoh_url(from_dict({}), "zenoh:mavlink_raw", "service.sources[0].url", "nmea")
    check_zenoh_url(from_dict({}), "zenoh:mavlink_raw", "service.sources[0].url", "mavlink")


@pytest.mark.integration
def test_zenoh_transport_delivers_samples_in_order_and_sends_on_in():
    import zenoh

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_router(endpoint)
    svc = zenoh.open(session_config("client", connect=[endpoint]))
    peer = zenoh.open(session_config("client", connect=[endpoint]))
    got_in: list[bytes] = []
    sub = peer.declare_subscriber("mavlink_raw/in", lambda s: got_in.append(s.payload.to_bytes()))
    tr = open_transport("zenoh:mavlink_raw", zenoh_session=lambda: svc)

    async def main() -> list[bytes]:
        chunks: list[bytes] = []
        task = asyncio.create_task(tr.pump(lambda data, t: chunks.append(data)))
        while not tr.stats.connected:
            await asyncio.sleep(0.01)
        await asyncio.sleep(0.3)  # the subscription reaches the router
        for i in range(50):
            peer.put("mavlink_raw/out", bytes([i]) * 3)
        deadline = time.monotonic() + 10
        while len(chunks) < 50 and time.monotonic() < deadline:
            await asyncio.sleep(0.02)
        assert tr.send(b"hello")
        await asyncio.sleep(0.3)
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
        return chunks

    try:
        chunks = asyncio.run(main())
    finally:
        sub.undeclare()
        peer.close()
        svc.close()
        router.close()
    assert chunks == [bytes([i]) * 3 for i in range(50)]  # one chunk per sample, in order
    assert got_in == [b"hello"] and tr.stats.chunks == 50


def _overlay(path: Path, endpoint: str) -> Path:
    path.write_text(f"""
[service]
sources = [{{ kind = "mavlink", url = "zenoh:mavlink_raw", name = "autopilot" }}]

[service.zenoh]
mode = "client"
connect = ["{endpoint}"]

[service.mavlink]
url = "zenoh:mavlink_raw"

[service.recorder]
enabled = false
""")
    return path


@pytest.mark.integration
def test_onboard_run_on_zenoh_mavlink_raw_gives_every_pipeline_from_the_bridged_simulator(tmp_path):
    import zenoh

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_router(endpoint)
    shore = zenoh.open(session_config("client", connect=[endpoint]))
    bridge = UdpZenohBridge(zenoh.open(session_config("client", connect=[endpoint])))
    lock = threading.Lock()
    records: dict[str, EstimateRecord] = {}
    sent_in: list[bytes] = []

    encodings: dict[str, str] = {}

    def on_est(sample) -> None:
        encodings[str(sample.key_expr).split("/")[2]] = str(sample.encoding)
        if "/fix/" in str(sample.key_expr):
            return
        rec = msgspec.json.decode(sample.payload.to_bytes(), type=EstimateRecord)
        if rec.values:
            with lock:
                records[rec.pipeline] = rec

    def on_in(sample) -> None:
        with lock:
            sent_in.append(sample.payload.to_bytes())

    from_autopilot: list[bytes] = []
    healths: list[HealthRecord] = []

    def on_out(sample) -> None:
        with lock:
            from_autopilot.append(sample.payload.to_bytes())

    def on_health(sample) -> None:
        with lock:
            healths.append(msgspec.json.decode(sample.payload.to_bytes(), type=HealthRecord))

    subs = [shore.declare_subscriber("onboard/*/est/*", on_est),
            shore.declare_subscriber("onboard/*/fix/*", on_est),
            shore.declare_subscriber("mavlink_raw/in", on_in),
            shore.declare_subscriber("mavlink_raw/out", on_out),
            shore.declare_subscriber("onboard/*/health", on_health)]
    overlay = _overlay(tmp_path / "zenoh.toml", endpoint)
    service = subprocess.Popen(
        [sys.executable, "-m", "onboard", "run", "--config", str(REPO / "config" / "sitl-jaiabot.toml"),
         "--config", str(overlay), "--state-dir", str(tmp_path / "state")],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    sim = subprocess.Popen(
        [sys.executable, "-m", "onboard", "sitl", "--scenario", "jaiabot-turns", "--realtime",
         "--duration", str(SIM_SECONDS), "--link", f"udp:127.0.0.1:{bridge.port}"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def estimating() -> set[str]:
        with lock:
            return set(records)

    def received() -> dict[str, float]:
        """The streams the service's health says arrive (Hz, over its 2 s window)."""
        with lock:
            return {k: v for h in healths for k, v in h.rates_hz.items()
                    if k.startswith("autopilot/") and k.endswith(":received") and v > 0}

    def sent() -> list:
        mav = mavlink2.MAVLink(None)
        with lock:
            chunks = list(sent_in)
        return [m for chunk in chunks for m in (mav.parse_buffer(chunk) or [])]

    def answered() -> list:
        """The autopilot's side, as it came back on mavlink_raw/out."""
        mav = mavlink2.MAVLink(None)
        with lock:
            chunks = list(from_autopilot)
        return [m for chunk in chunks for m in (mav.parse_buffer(chunk) or [])]

    def all_answered() -> bool:
        back = answered()
        return ({m.param_id for m in back if m.get_type() == "PARAM_VALUE"}
                >= {"SERVO1_FUNCTION", "SERVO3_FUNCTION"}
                and any(m.get_type() == "TIMESYNC" and m.tc1 != 0 for m in back))

    try:
        # every check below waited for (the parameter answers come one by one after the
        # requests, and may trail the first estimates)
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline and (estimating() != PIPELINES or not SENT <= {
                m.get_type() for m in sent()} or not received() or not all_answered()):
            assert service.poll() is None, service.stderr.read() if service.stderr else ""
            time.sleep(0.5)
    finally:
        sim.terminate()
        service.terminate()
        sim.wait(10)
        _, err = service.communicate(timeout=20)
        for s in subs:
            s.undeclare()
        bridge.close()
        shore.close()
        router.close()
    assert estimating() == PIPELINES, (sorted(records), err[-2000:])
    assert service.returncode == 0, err[-2000:]
    assert encodings == {"est": "application/json;onboard.Estimate.v2",
                         "fix": "application/json;foxglove.LocationFix"}
    # what the service wrote on mavlink_raw/in: its stream requests, parameter reads and
    # TIMESYNC to the autopilot, and its estimates as component 191
    msgs = sent()
    names = {m.get_type() for m in msgs}
    assert SENT <= names, sorted(names)
    assert any(m.get_type() == "COMMAND_LONG" and m.command == 511 for m in msgs)
    assert {m.get_srcComponent() for m in msgs} == {191}
    # the autopilot's side, as it came back on mavlink_raw/out: the requests were answered
    back = answered()
    assert any(m.get_type() == "COMMAND_ACK" and m.command == 511 and m.result == 0 for m in back)
    assert {m.param_id for m in back if m.get_type() == "PARAM_VALUE"} >= {"SERVO1_FUNCTION",
                                                                           "SERVO3_FUNCTION"}
    assert any(m.get_type() == "TIMESYNC" and m.tc1 != 0 for m in back)  # autopilot time
    assert "autopilot/SCALED_IMU:received" in received(), sorted(received())
    cur = records["current"].values
    if "north" in cur and "east" in cur:
        assert "WIND_COV" in names
    assert bridge.to_udp > 0 and bridge.to_zenoh > 0
