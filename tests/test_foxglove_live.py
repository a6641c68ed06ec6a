"""``onboard shore --foxglove``: the Zenoh records relayed to Foxglove channels with their
schema names and JSON schemas (checked through the SDK's MCAP sink, which records what a
WebSocket client would be sent)."""

from __future__ import annotations

import json
import threading
import time

import pytest

pytest.importorskip("foxglove", reason="needs foxglove-sdk: pip install -e '.[foxglove]'")
pytest.importorskip("mcap", reason="needs the mcap package: pip install -e '.[mcap]'")

from onboard.core.config import ZenohOut  # noqa: E402
from onboard.core.errors import UsageError  # noqa: E402
from onboard.core.geo import LocalFrame  # noqa: E402
from onboard.core.messages import HEALTH_SCHEMA_VERSION, EstimateRecord, HealthRecord  # noqa: E402,E501
from onboard.core.wire import location_fix  # noqa: E402
from onboard.service.publishers.zenoh_pub import ZenohPublisher, open_router, session_config  # noqa: E402
from onboard.apps.foxglove_live import FoxgloveRelay, parse_listen  # noqa: E402
from onboard.apps.service_bench import free_tcp_port  # noqa: E402


def test_listen_address_parses():
    assert parse_listen("8765") == ("127.0.0.1", 8765)
    assert parse_listen("0.0.0.0:9000") == ("0.0.0.0", 9000)
    with pytest.raises(UsageError):
        parse_listen("host:")


@pytest.mark.integration
def test_records_reach_foxglove_channels_named_as_their_keys_with_their_schemas(tmp_path):
    import foxglove
    import zenoh
    from mcap.reader import make_reader

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_router(endpoint)
    shore = zenoh.open(session_config("client", connect=[endpoint]))
    ctx = foxglove.Context()
    out = tmp_path / "live.mcap"
    writer = foxglove.open_mcap(out, context=ctx)
    relay = FoxgloveRelay(context=ctx)
    sub = shore.declare_subscriber("onboard/**", relay.on_sample)
    pub = ZenohPublisher(ZenohOut(mode="client", connect=[endpoint]), "boat1")
    pub.start()
    rec = EstimateRecord(vehicle="boat1", pipeline="kf", t=10.0,
                         values={"north": 5.0, "east": 1.0, "speed": 1.2},
                         std={"north": 1.0, "east": 1.0})
    fix = location_fix(rec, LocalFrame(63.4, 10.4))
    try:
        deadline = time.monotonic() + 20
        while relay.relayed < 3 and time.monotonic() < deadline:
            pub.publish_estimates([rec], [fix])
            pub.publish_health(HealthRecord(vehicle="boat1", t=10.0))
            time.sleep(0.1)
    finally:
        pub.close()
        sub.undeclare()
        shore.close()
        router.close()
    writer.close()
    with open(out, "rb") as f:
        seen = {c.topic: (s.name, s.encoding, c.message_encoding, json.loads(s.data))
                for s, c, _ in make_reader(f).iter_messages()}
    assert {k: v[:3] for k, v in seen.items()} == {
        "onboard/boat1/est/kf": ("onboard.Estimate.v2", "jsonschema", "json"),
        "onboard/boat1/fix/kf": ("foxglove.LocationFix", "jsonschema", "json"),
        "onboard/boat1/health": (f"onboard.Health.v{HEALTH_SCHEMA_VERSION}", "jsonschema", "json")}
    assert "values" in seen["onboard/boat1/est/kf"][3]["properties"]
    assert relay.skipped == 0


@pytest.mark.integration
def test_a_busy_foxglove_port_is_one_line_and_exit_2_as_a_busy_web_port():
    import socket
    import subprocess
    import sys

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_router(endpoint)
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    port = busy.getsockname()[1]
    try:
        run = subprocess.run([sys.executable, "-m", "onboard", "shore", "--connect", endpoint,
                              "--foxglove", f"127.0.0.1:{port}"],
                             capture_output=True, text=True, timeout=60)
    finally:
        busy.close()
        router.close()
    assert run.returncode == 2, run.stderr
    assert run.stderr.strip().splitlines() == [
        f"onboard shore: --foxglove 127.0.0.1:{port}: Address already in use"], run.stderr


@pytest.mark.integration
def test_with_web_and_foxglove_the_page_and_the_foxglove_server_both_run():
    import socket
    import subprocess
    import sys
    import urllib.request

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_router(endpoint)
    web, fox = free_tcp_port(), free_tcp_port()
    shore = subprocess.Popen([sys.executable, "-m", "onboard", "shore", "--connect", endpoint,
                              "--web", f"127.0.0.1:{web}", "--foxglove", f"127.0.0.1:{fox}"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(shore.stdout), daemon=True)
    reader.start()
    try:
        deadline = time.monotonic() + 30
        while len(lines) < 2 and shore.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert any(f"ws://127.0.0.1:{fox}" in line for line in lines), lines
        assert any("the page is on" in line for line in lines), lines
        with urllib.request.urlopen(f"http://127.0.0.1:{web}/api/state", timeout=10) as r:
            assert r.status == 200
        with socket.create_connection(("127.0.0.1", fox), timeout=10):
            pass
    finally:
        shore.terminate()
        shore.wait(10)
        router.close()


def websocket_handshake(port: int, protocols: str | None) -> str:
    """The status line a WebSocket upgrade offering ``protocols`` gets on ``port``."""
    import base64
    import os
    import socket

    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        head = (f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
                "Connection: Upgrade\r\nSec-WebSocket-Version: 13\r\n"
                f"Sec-WebSocket-Key: {base64.b64encode(os.urandom(16)).decode()}\r\n"
                + (f"Sec-WebSocket-Protocol: {protocols}\r\n" if protocols else "") + "\r\n")
        s.sendall(head.encode())
        return s.recv(4096).decode("latin-1").split("\r\n")[0]


@pytest.mark.integration
def test_the_server_speaks_foxglove_sdk_v1_as_docs_foxglove_md_says():
    import foxglove

    from onboard.apps.foxglove_live import start_server

    port = free_tcp_port()
    server = start_server(foxglove, "127.0.0.1", port, str(port))
    try:
        assert " 101 " in websocket_handshake(port, "foxglove.sdk.v1")
        assert " 101 " in websocket_handshake(port, "foxglove.websocket.v1, foxglove.sdk.v1")
        assert " 400 " in websocket_handshake(port, "foxglove.websocket.v1")
    finally:
        server.stop()
