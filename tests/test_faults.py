"""Fault injection through the real service (issue 9).

Each test drives the service over the real protocols and asserts against the simulator's
hidden truth or the service's own counters:

* SITL faults (``sitl.scenarios`` ``fault-*``, declared sensor faults of
  :mod:`sitl.effects`): the SITL child emits MAVLink over UDP, NMEA on a pty and DVL JSON
  over TCP; the in-process service runs on a clock shared with the simulator, scaled
  ``SPEED`` times faster than the wall clock (``onboard.demo.run_demo``); estimates are
  taken from an independent Zenoh subscriber behind an in-process router;
* the Zenoh router restarted under a running service (wall clock: Zenoh's reconnection
  runs on it);
* ``onboard run`` killed with SIGKILL mid-traffic: the recording and the adaptive state.

The pty unplug/replug case is ``tests/test_service.py::
test_an_unplugged_input_is_reported_and_picked_up_again_while_the_service_runs``.

Every bound is set from a measured figure, written beside it (measured on the 2-core
development VM with other jobs running; SITL seed 1). Timing is never asserted: the
deadlines below only stop a hung test.
"""

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
from pathlib import Path

import msgspec
import pytest

from drivers.recording import read_records
from onboard.messages import EstimateRecord, HealthRecord
from onboard.service_bench import TrafficGenerator, free_tcp_port, free_udp_port

REPO = Path(__file__).resolve().parent.parent
SPEED = 10.0
"""Simulated seconds per wall second in the SITL fault tests."""
TIMEOUT = 180.0


# --------------------------------------------------------------------------- helpers


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _fly(scenario: str, duration_s: float, tmp_path: Path, speed: float = SPEED):
    """Fly ``scenario`` through the service; (DemoResult, truth by round(10 t))."""
    from onboard.demo import run_demo
    from sitl.runner import read_truth

    res = asyncio.run(asyncio.wait_for(run_demo(
        scenario, duration_s, speed=speed, out_dir=tmp_path, out=None, keep_state=False,
        router_endpoint=f"tcp/127.0.0.1:{free_tcp_port()}",
        mavlink_out=f"udpout:127.0.0.1:{free_udp_port()}"), TIMEOUT))
    truth = {round(tr.t * 10): tr for tr in read_truth(tmp_path / "truth.jsonl")}
    return res, truth


def _series(res, truth, pipeline: str):
    """[(t, record values, truth)] of one pipeline's estimates received over Zenoh."""
    out = []
    for r in res.estimates:
        if r.pipeline == pipeline:
            tr = truth.get(round(r.t * 10))
            if tr is not None:
                out.append((r.t, r.values, tr))
    return out


def _events(res) -> list[str]:
    return [e for h in res.healths for e in h.events]


def _max(xs) -> float:
    xs = list(xs)
    return max(xs) if xs else math.nan


def _median(xs) -> float:
    xs = sorted(xs)
    return xs[len(xs) // 2] if xs else math.nan


# --------------------------------------------------------------------------- Zenoh router


def _boat_config(**service):
    from onboard.config import from_dict

    data = {"vehicle": {"id": "faultboat", "class": "rudder-boat", "system_id": 3},
            "engine": {"rate_hz": 10.0},
            "inputs": {"rudder": {"source": "servo", "channel": 1, "half_range_us": 500,
                                  "full_scale": 0.5236},
                       "throttle": {"source": "servo", "channel": 3, "half_range_us": 500}},
            "service": service}
    return from_dict(data)


def test_zenoh_router_restarted_the_service_keeps_ticking_and_delivers_again(tmp_path):
    """Close the router under a running service, reopen it on the same port: no tick is
    missed, the shore subscriber gets estimates again, the loss and the return are
    events (the return one reaches the shore in a health record)."""
    import zenoh

    from onboard.publishers.zenoh_pub import open_router, session_config
    from onboard.service import Service

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_router(endpoint)
    shore = zenoh.open(session_config("client", connect=[endpoint]))
    got: list[tuple[float, str, bytes]] = []
    lock = threading.Lock()

    def on(sample) -> None:
        with lock:
            got.append((time.monotonic(), str(sample.key_expr), sample.payload.to_bytes()))

    sub = shore.declare_subscriber("onboard/faultboat/**", on)
    port, nmea_port = free_udp_port(), free_udp_port()
    cfg = _boat_config(sources=[{"kind": "mavlink", "url": f"udp:127.0.0.1:{port}",
                                 "name": "autopilot"},
                                {"kind": "nmea", "url": f"udp:127.0.0.1:{nmea_port}",
                                 "name": "gps"}],
                       zenoh={"mode": "client", "connect": [endpoint]},
                       mavlink={"enabled": False}, recorder={"enabled": False})
    gen = TrafficGenerator()
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    marks: dict[str, float] = {}
    ticks: dict[str, int] = {}

    async def main() -> Service:
        nonlocal router
        svc = Service(cfg, state_dir=tmp_path)
        await svc.start()
        t0 = time.monotonic()
        k = 0

        async def feed(until: float) -> None:
            nonlocal k
            while time.monotonic() < until:
                for f in gen.mavlink(k / 50.0):
                    tx.sendto(f, ("127.0.0.1", port))
                for f in gen.nmea(k / 50.0):
                    tx.sendto(f, ("127.0.0.1", nmea_port))
                k += 1
                await asyncio.sleep(max(0.0, t0 + k / 50.0 - time.monotonic()))

        await feed(time.monotonic() + 2.0)
        ticks["closed"], marks["closed"] = svc.stats.ticks, time.monotonic()
        router.close()
        await feed(time.monotonic() + 3.0)
        ticks["reopened"], marks["reopened"] = svc.stats.ticks, time.monotonic()
        router = open_router(endpoint)
        deadline = time.monotonic() + 30.0  # a hung test, not a performance bound
        while time.monotonic() < deadline:
            await feed(time.monotonic() + 0.2)
            with lock:
                back = [k_ for t, k_, _ in got if t > marks["reopened"]]
            if "onboard/faultboat/est/nav" in back and any(
                    "connected again" in e for t, key, p in got if t > marks["reopened"]
                    and key.endswith("/health")
                    for e in msgspec.json.decode(p, type=HealthRecord).events):
                break
        marks["back"] = time.monotonic()
        await feed(time.monotonic() + 0.5)
        svc.request_stop()
        await svc.shutdown()
        return svc

    try:
        svc = asyncio.run(asyncio.wait_for(main(), TIMEOUT))
    finally:
        tx.close()
        sub.undeclare()
        shore.close()
        router.close()
    # the loop never stopped: ticks while the router was away, none skipped
    away = marks["reopened"] - marks["closed"]
    assert (ticks["reopened"] - ticks["closed"]) / (away * 10.0) > 0.8  # measured 1.0
    assert svc.stats.tick_skips == 0 and svc.stats.tick_errors == 0
    # events: lost, then connected again (at most one health period after each)
    evs = list(svc.events)
    lost = [i for i, e in enumerate(evs) if e.startswith("zenoh: lost")]
    again = [i for i, e in enumerate(evs) if e.startswith("zenoh: connected again")]
    assert lost and again and lost[0] < again[-1], evs
    assert svc.zenoh.disconnects == 1
    # the shore got estimates after the router came back, with new tick times
    with lock:
        before = [msgspec.json.decode(p, type=EstimateRecord) for t, k_, p in got
                  if t < marks["closed"] and "/est/" in k_]
        after = [msgspec.json.decode(p, type=EstimateRecord) for t, k_, p in got
                 if t > marks["reopened"] and "/est/" in k_]
    assert before and after, (len(before), len(after))
    assert min(r.t for r in after) > max(r.t for r in before)
    # first estimate at the shore 0.6-1.1 s (wall) after the router was back (measured);
    # not asserted: Zenoh's own retry (1 s doubling to 4 s) sets it
