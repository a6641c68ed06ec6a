"""Service events: one severity for the log and STATUSTEXT (onboard.service.events)."""

from __future__ import annotations

import logging
import socket

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from onboard.core.config import MavlinkOut, from_dict
from onboard.service import events
from onboard.service.publishers.mavlink_pub import MavlinkPublisher
from tests.helpers.mavlink_listener import receive_mavlink

WARNINGS = [
    "autopilot: cannot open (ENOENT: No such file or directory); retrying",
    "autopilot: cannot open (EADDRINUSE: Address already in use: another process listens "
    "on UDP port 14551); retrying",
    "zenoh: cannot open session: Can not create a new TCP listener bound to "
    "tcp/127.0.0.1:7448: Address already in use",
    "autopilot: autopilot link lost (no HEARTBEAT for 3 s)",
    "autopilot: lost (EIO: Input/output error)",
    "gps: silent for 5 s",
    "state file /var/lib/onboard/state/adaptive.json is corrupt (DecodeError: x): ignored, "
    "kept as /var/lib/onboard/state/adaptive.json.corrupt-1",
    "state file /s/adaptive.json belongs to vehicle 'b', not 'a': ignored, kept as /s/x",
    "estimator loop stalled 2.5 s: skipped 24 ticks",
    "tick failed (ValueError; 1 so far)",
    "state save failed: [Errno 28] No space left on device",
    "recorder disabled: cannot write /rec: Permission denied",
    "web: cannot listen on 0.0.0.0:8080: Address already in use",
    "mavlink out: cannot open udpout:nowhere:1: bad address",
    "recorder: disk full (10 MB free, minimum 200 MB): recording paused",
    "autopilot: ATTITUDE not sent by the autopilot (asked 4 times); no longer asked",
]
INFOS = [
    "autopilot: connected",
    "autopilot: autopilot found: system 1 component 1, type 10, autopilot 3",
    "restored adaptive state (aie, current) saved 0.1 h ago",
    "zenoh: session open",
    "mavlink out: open",
    "gps: data again",
]


def test_the_severities_are_mavlinks():
    for name in ("EMERGENCY", "ALERT", "CRITICAL", "ERROR", "WARNING", "NOTICE", "INFO",
                 "DEBUG"):
        assert getattr(events, f"MAV_SEVERITY_{name}") == getattr(mavlink2,
                                                                  f"MAV_SEVERITY_{name}")


@pytest.mark.parametrize("text", WARNINGS)
def test_failures_are_warnings(text):
    assert events.severity(text) == mavlink2.MAV_SEVERITY_WARNING
    assert events.log_level(events.severity(text)) == logging.WARNING


@pytest.mark.parametrize("text", INFOS)
def test_the_rest_is_information(text):
    assert events.severity(text) == mavlink2.MAV_SEVERITY_INFO
    assert events.log_level(events.severity(text)) == logging.INFO


@pytest.mark.integration
def test_the_service_logs_each_event_at_the_level_of_its_statustext(tmp_path, caplog):
    """``Service.event``: a failure is logged at WARNING (kept by ONBOARD_LOG_LEVEL=WARNING
    and ``journalctl -p warning``), the rest at INFO; the STATUSTEXT of the same event has
    the severity of that level."""
    from onboard.service.daemon import Service

    cfg = from_dict({"vehicle": {"id": "b", "class": "rudder-boat"},
                     "service": {"zenoh": {"enabled": False}, "mavlink": {"enabled": False},
                                 "recorder": {"enabled": False}}})
    svc = Service(cfg, state_dir=tmp_path)
    caplog.set_level(logging.INFO, logger="onboard.service")
    for text in WARNINGS + INFOS:
        svc.event(text)
    logged = {r.getMessage(): r.levelno for r in caplog.records if r.name == "onboard.service"}
    assert logged == {**{t: logging.WARNING for t in WARNINGS},
                      **{t: logging.INFO for t in INFOS}}

    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    listener.bind(("127.0.0.1", 0))
    listener.settimeout(5.0)
    try:
        pub = MavlinkPublisher(MavlinkOut(url=f"udpout:127.0.0.1:{listener.getsockname()[1]}"),
                               1)
        pub.start()
        for i, text in enumerate(WARNINGS + INFOS):
            assert pub.event(text, now=10.0 * i)  # spaced out: none rate-limited
        pub.close()
        msgs = [m for m in receive_mavlink(listener) if m.get_type() == "STATUSTEXT"]
    finally:
        listener.close()
    by_id: dict[int, list] = {}
    for m in msgs:
        key = m.id or -len(by_id) - 1  # a short one is one message of id 0
        by_id.setdefault(key, []).append(m)
    sent = {"".join(m.text for m in sorted(ms, key=lambda m: m.chunk_seq)): ms[0].severity
            for ms in by_id.values()}
    assert {t: events.log_level(s) for t, s in sent.items()} == logged


@pytest.mark.integration
def test_the_engines_own_events_reach_the_log_too(tmp_path, caplog):
    """The engine's events (a source switch, a stale stream, a time jump, an integrity
    warning) went to the health record and STATUSTEXT but never to the log: now each is
    logged once, when its health record is made, at its STATUSTEXT severity's level."""
    from onboard.service.daemon import Service

    cfg = from_dict({"vehicle": {"id": "b", "class": "rudder-boat"},
                     "service": {"zenoh": {"enabled": False}, "mavlink": {"enabled": False},
                                 "recorder": {"enabled": False}}})
    svc = Service(cfg, state_dir=tmp_path)
    caplog.set_level(logging.INFO, logger="onboard.service")
    svc.event("autopilot found")
    svc.engine.events.append("gnss stream stale: no sample for 3 s")
    svc.engine.events.append("heading source: compass -> autopilot")
    h = svc.health(1.0)
    assert h.events == ["autopilot found", "gnss stream stale: no sample for 3 s",
                        "heading source: compass -> autopilot"]
    logged = [(r.getMessage(), r.levelno) for r in caplog.records
              if r.name == "onboard.service"]
    assert logged == [("autopilot found", logging.INFO),
                      ("gnss stream stale: no sample for 3 s", logging.WARNING),
                      ("heading source: compass -> autopilot", logging.INFO)]
    svc.health(2.0)  # nothing new: nothing logged again
    assert len([r for r in caplog.records if r.name == "onboard.service"]) == 3
