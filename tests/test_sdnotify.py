"""The systemd notify protocol against a real AF_UNIX datagram socket."""

from __future__ import annotations

import asyncio
import os
import socket

import pytest

from onboard.service.sdnotify import Notifier


@pytest.fixture
def notify_socket(tmp_path):
    path = str(tmp_path / "notify")
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind(path)
    s.settimeout(10.0)
    yield path, s
    s.close()


@pytest.mark.integration
def test_ready_status_and_stopping_are_sent_as_datagrams(notify_socket):
    path, sock = notify_socket
    n = Notifier({"NOTIFY_SOCKET": path})
    assert n.enabled
    assert n.ready("2/2 inputs up")
    assert sock.recv(4096) == b"READY=1\nSTATUS=2/2 inputs up"
    n.status("line one\nline two")
    assert sock.recv(4096) == b"STATUS=line one line two"
    n.stopping()
    assert sock.recv(4096) == b"STOPPING=1"
    n.close()


@pytest.mark.integration
def test_watchdog_pings_at_half_the_interval(notify_socket):
    path, sock = notify_socket
    t = [0.0]
    n = Notifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "2000000",
                  "WATCHDOG_PID": str(os.getpid())}, clock=lambda: t[0])
    assert n.watchdog_interval_s == 1.0
    sent = []
    for i in range(31):  # 3 s of 10 Hz ticks
        t[0] = i * 0.1
        sent.append(n.watchdog())
    assert sum(sent) == 4  # at 0, 1, 2, 3 s
    assert sock.recv(4096) == b"WATCHDOG=1"


@pytest.mark.integration
def test_watchdog_for_another_pid_is_ignored(notify_socket):
    path, _ = notify_socket
    n = Notifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "1000000", "WATCHDOG_PID": "1"})
    assert n.watchdog_interval_s is None and not n.watchdog()


@pytest.mark.integration
def test_abstract_socket_names_are_supported():
    name = f"onboard-test-{os.getpid()}"
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind("\0" + name)
    s.settimeout(10.0)
    try:
        Notifier({"NOTIFY_SOCKET": "@" + name}).ready()
        assert s.recv(100) == b"READY=1"
    finally:
        s.close()


def test_without_systemd_every_call_is_a_no_op():
    n = Notifier({})
    assert not n.enabled and not n.ready() and not n.watchdog() and not n.status("x")


@pytest.mark.integration
def test_a_vanished_socket_is_counted_not_raised(tmp_path):
    n = Notifier({"NOTIFY_SOCKET": str(tmp_path / "gone")})
    assert not n.ready() and n.errors == 1


@pytest.mark.integration
def test_the_service_sends_ready_then_watchdog_from_its_tick_loop(notify_socket, tmp_path):
    """READY=1 after start-up; WATCHDOG=1 keeps coming while the loop ticks."""
    from onboard.core.config import from_dict
    from onboard.service.daemon import Service
    from onboard.apps.service_bench import free_udp_port

    path, sock = notify_socket
    cfg = from_dict({"vehicle": {"id": "wd"}, "engine": {"rate_hz": 20.0}, "service": {
        "sources": [{"kind": "nmea", "url": f"udp:127.0.0.1:{free_udp_port()}"}],
        "zenoh": {"enabled": False}, "mavlink": {"enabled": False},
        "recorder": {"enabled": False}}})
    notifier = Notifier({"NOTIFY_SOCKET": path, "WATCHDOG_USEC": "200000"})

    async def main():
        svc = Service(cfg, state_dir=tmp_path, notifier=notifier)
        await svc.start()
        await asyncio.sleep(0.6)
        svc.request_stop()
        await svc.shutdown()

    asyncio.run(asyncio.wait_for(main(), 30))
    msgs = []
    sock.settimeout(0.5)
    while True:
        try:
            msgs.append(sock.recv(4096))
        except socket.timeout:
            break
    assert msgs[0].startswith(b"READY=1\nSTATUS=ready: 1/1 inputs up")
    assert msgs.count(b"WATCHDOG=1") >= 2
    assert msgs[-1].startswith(b"STOPPING=1")


def test_the_unit_file_is_type_notify_with_a_watchdog_and_hardening():
    from pathlib import Path

    unit = (Path(__file__).resolve().parent.parent / "systemd" / "onboard.service").read_text()
    keys = {}
    for line in unit.splitlines():
        if "=" in line and not line.lstrip().startswith("#"):
            k, v = line.split("=", 1)
            keys.setdefault(k.strip(), []).append(v.strip())
    assert keys["Type"] == ["notify"] and keys["WatchdogSec"][0].rstrip("s").isdigit()
    assert "onboard run --config" in keys["ExecStart"][0]
    for k, v in {"DynamicUser": "yes", "SupplementaryGroups": "dialout",
                 "ProtectSystem": "strict", "NoNewPrivileges": "yes", "ProtectHome": "yes",
                 "PrivateTmp": "yes", "StateDirectory": "onboard", "LogsDirectory": "onboard"}.items():
        assert keys[k] == [v], k
    assert "AF_INET" in keys["RestrictAddressFamilies"][0]
    assert keys["SystemCallFilter"][0] == "@system-service"
    env = (Path(__file__).resolve().parent.parent / "systemd" / "onboard.env.example").read_text()
    assert "ONBOARD_CONFIG=" in env
