"""Fault injection through the real service.

Each test drives the service over the real protocols and asserts against the simulator's
hidden truth or the service's own counters:

* SITL faults (``sitl.scenarios`` ``fault-*``, declared sensor faults of
  :mod:`sitl.effects`): the SITL child emits MAVLink over UDP, NMEA on a pty and DVL JSON
  over TCP; the in-process service runs on a clock shared with the simulator, scaled
  ``SPEED`` times faster than the wall clock (``onboard.apps.demo.run_demo``); estimates are
  taken from an independent Zenoh subscriber behind an in-process router;
* the Zenoh router restarted under a running service (wall clock: Zenoh's reconnection
  runs on it);
* ``onboard run`` killed with SIGKILL mid-traffic: the recording and the adaptive state.

The pty unplug/replug case is ``tests/test_service.py::
test_an_unplugged_input_is_reported_and_picked_up_again_while_the_service_runs``.

Every bound is set from a measured figure, written beside it (measured on the 2-core
development VM with other jobs running; SITL seed 1). Timing is never asserted: the
deadlines below only stop a hung test. A SITL run on a machine too busy for its speed
(the simulator or the service more than ``MAX_LATE_S`` of :mod:`tests.helpers.live_demo`
behind the shared clock, as the demo reports it) is flown again slower: at load 18-19 on 2 cores the runs needed 2.5-5x
instead of 10-20x, and passed.
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import msgspec
import pytest

from onboard.drivers.recording import read_records
from onboard.core.geo import wrap_pi
from onboard.core.messages import EstimateRecord, HealthRecord
from onboard.apps.service_bench import TrafficGenerator, free_tcp_port, free_udp_port
from tests.helpers.live_demo import demo_that_kept_up
from tests.helpers.service_config import service_config

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parent.parent
SPEED = 10.0
"""Simulated seconds per wall second in the SITL fault tests."""
TIMEOUT = 180.0


# --------------------------------------------------------------------------- helpers


def _fly(scenario: str, duration_s: float, tmp_path: Path, speed: float = SPEED):
    """Fly ``scenario`` through the service; (DemoResult, truth by round(10 t)), flown
    again slower while the machine could not keep up (:mod:`tests.helpers.live_demo`)."""
    from onboard.sitl.runner import read_truth

    res, _ = demo_that_kept_up(scenario, duration_s, speed=speed, out_dir=tmp_path,
                               keep_state=False,
                               mavlink_out=f"udpout:127.0.0.1:{free_udp_port()}")
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


def test_zenoh_router_restarted_the_service_keeps_ticking_and_delivers_again(tmp_path):
    """Close the router under a running service, reopen it on the same port: no tick is
    missed, the shore subscriber gets estimates again, the loss and the return are
    events (the return one reaches the shore in a health record)."""
    import zenoh

    from onboard.service.daemon import Service
    from onboard.service.publishers.zenoh_pub import open_router, session_config

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_router(endpoint)
    shore = zenoh.open(session_config("client", connect=[endpoint]))
    got: list[tuple[float, str, bytes]] = []
    lock = threading.Lock()

    def on(sample) -> None:
        with lock:
            got.append((time.monotonic(), str(sample.key_expr), sample.payload.to_bytes()))

    sub = shore.declare_subscriber("onboard/testboat/**", on)
    port, nmea_port = free_udp_port(), free_udp_port()
    cfg = service_config(sources=[{"kind": "mavlink", "url": f"udp:127.0.0.1:{port}",
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

        await feed(time.monotonic() + 1.5)
        ticks["closed"], marks["closed"] = svc.stats.ticks, time.monotonic()
        router.close()
        await feed(time.monotonic() + 2.5)
        ticks["reopened"], marks["reopened"] = svc.stats.ticks, time.monotonic()
        router = open_router(endpoint)
        deadline = time.monotonic() + 30.0  # a hung test, not a performance bound
        while time.monotonic() < deadline:
            await feed(time.monotonic() + 0.2)
            with lock:
                back = [k_ for t, k_, _ in got if t > marks["reopened"]]
            if "onboard/testboat/est/nav" in back and any(
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


# --------------------------------------------------------------------------- SITL faults


def _position_errors(series):
    """[(t, horizontal position error m)]: positions compared as displacements from the
    pipeline's first estimate (they are reported from the first fix)."""
    out = []
    base = None
    for t, v, tr in series:
        if "north" not in v:
            continue
        if base is None:
            base = (v["north"] - tr.north, v["east"] - tr.east)
        out.append((t, math.hypot(v["north"] - tr.north - base[0],
                                  v["east"] - tr.east - base[1])))
    return out


def _fix_frame(nav, t0: float, t1: float) -> tuple[float, float]:
    """Where the first fix puts the truth's origin: the median over ``[t0, t1)`` s of the
    measured fix position (``nav.north/east``, metres from the first fix, the frame the
    AIE and KF report in too) minus the truth (m; the fixes' noise averages out, unlike
    one estimate's)."""
    dn = sorted(v["north"] - tr.north for t, v, tr in nav if t0 <= t < t1 and "north" in v)
    de = sorted(v["east"] - tr.east for t, v, tr in nav if t0 <= t < t1 and "east" in v)
    assert dn and de, "no fix in the window"
    return dn[len(dn) // 2], de[len(de) // 2]


def _frame_errors(series, frame: tuple[float, float]):
    """[(t, horizontal position error m)] in the frame of the fixes (:func:`_fix_frame`)."""
    return [(t, math.hypot(v["north"] - tr.north - frame[0], v["east"] - tr.east - frame[1]))
            for t, v, tr in series if "north" in v]


def _heading_errors_deg(series):
    return [(t, abs(math.degrees(wrap_pi(v["heading"] - tr.yaw)))) for t, v, tr in series
            if "heading" in v]


def _in(pairs, a, b):
    return [x for t, x in pairs if a <= t < b]


@pytest.fixture(scope="module")
def gnss_outage(tmp_path_factory):
    """fault-gnss-outage (no fix from 30 s to 150 s) flown once for the tests below, from
    10x (at 20x the service fell 1.2-1.8 s behind on a quiet machine: a flight wasted)."""
    return _fly("fault-gnss-outage", 170.0, tmp_path_factory.mktemp("outage"), speed=10.0)


def test_gnss_lost_for_120_s_estimates_continue_reported_stale_and_recover(gnss_outage):
    """fault-gnss-outage: no fix from 30 s to 150 s. The AIE and KF keep estimating from
    the model and the compass (the position dead reckoned); health shows the GNSS stream
    at 0 Hz and a stale event; after the return the position follows the fixes again."""
    res, truth = gnss_outage
    aie = _series(res, truth, "aie")
    # every estimate reached the shore whole, and no pipeline was restarted (a restart
    # starts a new frame at its next fix: every later position offset by the distance run)
    bad = {k: n for k, n in res.health.rejected.items() if k.startswith("pipeline:")}
    assert not bad, (bad, [e for e in res.events if "restarted" in e])
    # estimates kept coming through the outage, one per tick
    n_out = sum(1 for t, _, _ in aie if 32.0 <= t < 148.0)
    print("aie records in the outage per tick:", n_out / 1160)
    assert n_out / 1160 > 0.9  # measured 1.00
    # health: the GNSS stream at 0 Hz during the outage, stale then back as events
    during = [h for h in res.healths if 35.0 <= h.t < 149.0]
    assert during and all(h.rates_hz.get("gnss:gps", 0.0) == 0.0 for h in during)
    evs = [(h.t, e) for h in res.healths for e in h.events]
    assert any(30.0 < t < 36.0 and e.startswith("gnss:gps: stale") for t, e in evs), evs
    assert any(t > 150.0 and e.startswith("gnss:gps: samples again") for t, e in evs), evs
    alive = sum(h.rates_hz.get("heading:gps", 0.0) > 0 for h in during) / len(during)
    assert alive > 0.8  # the compass on the same pty carries on (measured 1.00)
    # position: drifts during the outage, bounded; recovers after
    pe = _position_errors(aie)
    before, late_out = _max(_in(pe, 20.0, 30.0)), _max(_in(pe, 130.0, 150.0))
    after = _median(_in(pe, 160.0, 170.0))
    he_after = _median(_in(_heading_errors_deg(aie), 152.0, 170.0))
    print(f"aie position error: before {before:.1f} m, end of outage {late_out:.1f} m, "
          f"10-20 s after {after:.1f} m; heading error after {he_after:.2f} deg")
    # The same in the frame of the fixes, and where the fixes put the truth's origin:
    # an offset of metres along the track means fixes stamped late (a fix reaching the
    # service seconds after it was measured, stamped at its arrival), not the estimator
    first = next((t, v["north"], v["east"]) for t, v, _ in aie if "north" in v)
    frame = _fix_frame(_series(res, truth, "nav"), 5.0, 30.0)
    pf = _frame_errors(aie, frame)
    print(f"  first estimate at {first[0]:.2f} s: {first[1]:.2f}, {first[2]:.2f} m; fixes minus "
          f"truth (median, 5-30 s) {frame[0]:.2f}, {frame[1]:.2f} m; in their frame: before "
          f"{_max(_in(pf, 20.0, 30.0)):.1f}, end of outage {_max(_in(pf, 130.0, 150.0)):.1f}, "
          f"after {_median(_in(pf, 160.0, 170.0)):.1f} m")
    # dead reckoned with the speed and heading estimates: it stays within a few metres
    # (measured 4.8 m at the end of the outage; held, it drifted to 37-39 m)
    assert late_out < 15.0
    assert after < 10.0  # measured 0.4-0.9 m (held: 10-13 m, then a slow pull); margin for
    # the live timing under load
    assert he_after < 5.0  # measured 1-3 deg


def test_gnss_outage_uncertainty_grows(gnss_outage):
    """fault-gnss-outage: the aie position's published one sigma (``std_north``, through
    the service and Zenoh into ``EstimateRecord.std``) grows once the fixes stop at 30 s
    (docs/aie.md, "Published uncertainty")."""
    res, _ = gnss_outage
    aie = [r for r in res.estimates if r.pipeline == "aie"]
    early = [r.std.get("north") for r in aie if 20.0 <= r.t < 30.0]
    late = [r.std.get("north") for r in aie if 37.0 <= r.t < 42.0]
    assert early and late and None not in early + late
    print(f"aie std_north median: 20-30 s {_median(early):.2f} m, 37-42 s {_median(late):.2f} m")
    # 7-12 s without a fix: dead reckoned with a well-known speed and heading, the sigma
    # grows a little and stays small (measured 1.91 -> 1.92 m; held, it reached 7 m)
    assert _median(early) < _median(late) < 10.0


DIVE_RATE_MPS = 0.25
"""The fastest descent of fault-gnss-submerged's AUV after 15 s (truth: 0.245 m/s at 15-17 s)."""


def test_gnss_under_water_is_rejected_and_counted_estimates_continue(tmp_path):
    """fault-gnss-submerged: a torpedo AUV dives from the surface; its receiver keeps
    reporting (wrong) fixes at 1 Hz. Every fix below the surface depth is rejected as
    ``gnss:submerged``; the current and nav pipelines carry on on DVL/INS/depth."""
    res, truth = _fly("fault-gnss-submerged", 40.0, tmp_path)
    from onboard.core.config import load

    surface = load("torpedo-auv").sensors.depth.surface_depth_m
    deep = sum(1 for k, tr in truth.items() if k % 10 == 0 and 1.0 <= tr.t < 40.0
               and tr.down > surface + 0.1)
    shallow = sum(1 for k, tr in truth.items() if k % 10 == 0 and 1.0 <= tr.t < 40.0
                  and tr.down < surface - 0.1)
    rejected = res.health.rejected.get("gnss:submerged", 0)
    print(f"fixes under water {deep}, rejected {rejected}; at the surface {shallow}")
    assert deep > 20 and shallow >= 3
    assert deep * 0.9 <= rejected <= deep + (40 - deep - shallow) + 1  # measured = deep
    assert res.health.mode == "submerged"
    assert any(h.rates_hz.get("gnss:gps", 0.0) > 0 for h in res.healths if h.t < 8.0)
    cur = _series(res, truth, "current")
    n = sum(1 for t, _, _ in cur if 15.0 <= t < 38.0)
    # per tick the service made (a busy machine merges late ticks: 193-202 of the 230
    # nominal ones at 5x with a second test process running, the estimate at every one)
    ticks = len({round(r.t * 10) for r in res.estimates if 15.0 <= r.t < 38.0})
    print(f"current estimates {n} at {ticks} ticks of 230")
    assert ticks > 0.5 * 230 and n / ticks > 0.9  # measured 1.00-1.01 (202 at 200 ticks)
    nav = _series(res, truth, "nav")
    depth_err = _max(abs(v["depth"] - tr.down) for t, v, tr in nav if t > 15.0 and "depth" in v)
    # a tick takes the depth samples the service has read before it: a simulator running
    # behind the shared clock sends them late, a service running behind reads them late,
    # and the vehicle, diving at up to DIVE_RATE_MPS, is deeper by then (measured 0.06-0.07
    # m when on time; 0.24 m with the two 0.73 s and 0.50 s behind on a loaded 2-core
    # runner, 0.33 m with 0.88 s and 0.72 s)
    allowed = 0.1 + DIVE_RATE_MPS * (res.sim_late_s + res.service_late_s)
    print(f"nav depth error under water {depth_err:.3f} m (allowed {allowed:.3f} m)")
    assert depth_err < allowed


@pytest.fixture(scope="module")
def rov_dvl_lock_loss(tmp_path_factory):
    """fault-dvl-lock-loss-rov flown once for the tests below."""
    return _fly("fault-dvl-lock-loss-rov", 80.0, tmp_path_factory.mktemp("rov"))


def _v_ned(tr) -> tuple[float, float]:
    c, s = math.cos(tr.yaw), math.sin(tr.yaw)
    return c * tr.u - s * tr.v, s * tr.u + c * tr.v


def test_dvl_lock_loss_is_rejected_never_fused_as_zero_velocity(rov_dvl_lock_loss):
    """fault-dvl-lock-loss-rov: the BlueROV2's DVL reports no bottom lock (valid=False,
    zeros) from 40 s to 70 s while the vehicle circles at 0.5 m/s. Every such report is
    counted ``dvl:invalid`` and none reaches a pipeline (the stream's accepted rate is 0,
    reported stale and back); the current estimate stays near the truth."""
    res, truth = rov_dvl_lock_loss
    invalid = res.health.rejected.get("dvl:invalid", 0)
    print("dvl:invalid", invalid)
    assert invalid >= 0.95 * 150  # 30 s at 5 Hz; measured 150
    during = [h for h in res.healths if 43.0 <= h.t < 69.0]
    assert during and all(h.rates_hz.get("dvl:dvl", 0.0) == 0.0 for h in during)
    evs = [(h.t, e) for h in res.healths for e in h.events]
    assert any(40.0 < t < 48.0 and e.startswith("dvl:dvl: stale") for t, e in evs), evs
    assert any(70.0 < t and e.startswith("dvl:dvl: samples again") for t, e in evs), evs
    # the engine handed no DVL velocity to any pipeline during the loss (the rates above);
    # the current stays near the truth (zero here). A negative control (the parser turning
    # lock-loss reports into valid zeros) fails the count and rate checks above; the
    # current's error alone would not tell (0.38-0.86 m/s max with the zeros passed on,
    # 0.08-0.40 without)
    cur = _series(res, truth, "current")
    window = [(v, tr) for t, v, tr in cur if 42.0 <= t < 75.0]
    # a component is published only while known (one-sigma <= 0.3 m/s), else absent
    assert window and all(("north" in v) == (v["std_north"] <= 0.3)
                          and ("east" in v) == (v["std_east"] <= 0.3) for v, _ in window)
    err = [math.hypot(v["north"] - tr.current_north, v["east"] - tr.current_east)
           for v, tr in window if "north" in v and "east" in v] or [0.0]
    speed = _median(math.hypot(tr.u, tr.v) for t, v, tr in cur if 40.0 <= t < 70.0)
    print(f"current error in the lock loss: median {_median(err):.3f}, max {_max(err):.3f} m/s "
          f"(vehicle speed {speed:.2f} m/s)")
    assert speed > 0.3
    # measured 0.08-0.20 m/s over 19 live runs, every component within one sigma; with
    # three busy loops on a 2-core machine (stalls beyond the 0.5 s hold, the 5x retry)
    # 0.11-0.35, within 2 sigma. Before the current pipeline held late samples and
    # restarted on an inconsistent start (docs/current.md, "Late measurements"):
    # 0.04-0.73 (0.63 in a CI run), beyond 3 sigma in 7 of 16
    assert _max(err) < 0.5
    # (|error| / sigma, t, axis, error, sigma) of every published component
    scored = [(abs(e) / v[f"std_{ax}"], t, ax, e, v[f"std_{ax}"])
              for t, v, tr in cur if 42.0 <= t < 75.0 for ax in ("north", "east")
              if ax in v for e in (v[ax] - getattr(tr, f"current_{ax}"),)]
    worst = max(scored, default=(0.0,))
    print("largest error over its sigma (z, t, axis, error, sigma):", worst)
    assert worst[0] < 3.0


def test_eseso_velocity_bounded_through_a_dvl_lock_loss_and_recovers(rov_dvl_lock_loss):
    """The ESESO carries its velocity on the IMU, the INS and the thrust model while the
    DVL is out, and takes the DVL back when the lock returns (it is not gated out)."""
    res, truth = rov_dvl_lock_loss
    es = _series(res, truth, "eseso")
    verr = [(t, math.hypot(v["u"] - tr.u, v["v"] - tr.v)) for t, v, tr in es if "u" in v]
    z = [abs(v[q] - getattr(tr, q)) / v[f"std_{q}"] for t, v, tr in es
         if 40.0 <= t < 70.0 and "u" in v for q in ("u", "v")]
    before, during = _median(_in(verr, 30.0, 40.0)), _max(_in(verr, 40.0, 70.0))
    after = _median(_in(verr, 75.0, 80.0))
    print(f"eseso velocity error: before {before:.3f}, max in the lock loss {during:.3f}, "
          f"5-10 s after it {after:.3f} m/s; within 3 sigma in the loss "
          f"{sum(x <= 3.0 for x in z) / max(1, len(z)):.2f}")
    assert during < 0.4  # measured 0.03-0.19 (0.63 with the ESESO of 2026-11-22 09:40)
    assert after < 0.05  # measured 0.008 (0.15-0.9 then: DVL and INS gated out)


def test_compass_step_30_deg_for_5_s_is_followed_then_recovered_nis_reported(tmp_path):
    """fault-compass-step: the compass reads 30 deg too much from 40 s to 45 s. A
    heading-only filter cannot tell that from a turn (the outlier gate is 20 sigma =
    34 deg at 0.03 rad noise): the AIE/KF follow it, the heading NIS shows it in health,
    and within seconds of the step's end the heading is back within a few degrees."""
    res, truth = _fly("fault-compass-step", 62.0, tmp_path)
    # recovered 3 s after the step's end, plus what the machine made the samples late by
    # (the simulator sending, the service reading behind the shared clock: under the
    # suite's load the recovery came 1-2 s later, 9.2 deg at 48 s)
    late_s = res.sim_late_s + res.service_late_s
    recovered_from = 48.0 + late_s
    # The gyro compass's HDT carries no time and is stamped on receipt: a sentence the
    # loaded simulator sent late_s late is that old, which in the boat's turns (up to
    # 16 deg/s) is a heading error the service cannot see. The test allows it on top of
    # the filter's own error: 3 s of each run flown live showed 11-22 deg of it, under
    # published sigmas of 1.4-2.6 deg, where ATTITUDE had fallen silent under the load
    # and the heading had switched to the receipt-stamped compass (docs/formats-text.md,
    # "Time").
    stale_deg = late_s * max(abs(math.degrees(tr.r)) for tr in truth.values()
                             if recovered_from <= tr.t < 60.0)
    for name in ("aie", "kf"):
        he = _heading_errors_deg(_series(res, truth, name))
        before = _median(_in(he, 25.0, 40.0))
        in_step = _max(_in(he, 40.0, 45.5))
        # up to 60 s: the simulator's last samples are sent at 62 s
        after = _median(_in(he, recovered_from, 60.0))
        after_max = _max(_in(he, recovered_from, 60.0))
        print(f"{name} heading error: before {before:.2f}, max in the step {in_step:.1f}, "
              f"from {recovered_from:.1f} s median {after:.2f}, max {after_max:.2f} deg "
              f"(a heading {late_s:.2f} s stale: up to {stale_deg:.1f} deg)")
        assert in_step < 50.0  # measured 31-42 deg: follows the 30 deg step
        # replayed, the error is back in its noise within 0.5 s of the step's end
        assert after < 3.0  # measured 1.0-1.6 deg
        # a third of the step left would be 10 deg; the largest of ~110 samples measured
        # 3.8-4.7 deg (published sigma 1.5-1.6 deg) where no heading came late
        assert after_max < 6.0 + stale_deg
        assert before < 3.0
    # the heading channel's largest test ratio (NIS over its gate) since the previous
    # health record (1 Hz), as ESTIMATOR_STATUS reports it
    ratio = {h.t: ch.test_ratio_max for h in res.healths
             if (ch := h.innovations.get("aie", {}).get("heading.increment")) is not None
             and ch.test_ratio_max is not None}
    quiet = _median(v for t, v in ratio.items() if 25.0 <= t < 40.0)
    peak = _max(v for t, v in ratio.items() if 40.0 <= t < 47.0)
    print(f"aie heading.increment test ratio: quiet median {quiet:.4f}, peak in the step "
          f"{peak:.3f}")
    assert peak > 10 * quiet  # measured: quiet median 0.007, peak 0.53 (NIS 210, gate 400)


# --------------------------------------------------------------------------- SIGKILL


def test_sigkill_mid_traffic_loses_under_1_s_of_recording_and_restart_restores_state(tmp_path):
    """``onboard run`` killed with SIGKILL while the sensors stream: the recording reads
    back up to less than 1 s before the kill (flush_interval_s 0.5 + the fsync), at most
    one torn frame; a restart restores exactly the adaptive state saved last (every
    1 s here), which is not the cold-start state."""
    from onboard.drivers.base import ReadStats
    from onboard.core.config import load
    from onboard.engine import Engine
    from onboard.service.daemon import Service
    from onboard.service.persistence import plain

    mav_port, nmea_port = free_udp_port(), free_udp_port()
    cfg_path = tmp_path / "boat.toml"
    cfg_path.write_text(f"""
[vehicle]
id = "killed"
class = "rudder-boat"

[inputs.rudder]
source = "servo"
channel = 1
half_range_us = 500
full_scale = 0.5236

[inputs.throttle]
source = "servo"
channel = 3
half_range_us = 500

[service]
state_save_interval_s = 1.0

[[service.sources]]
name = "autopilot"
kind = "mavlink"
url = "udp:127.0.0.1:{mav_port}"

[[service.sources]]
name = "gps"
kind = "nmea"
url = "udp:127.0.0.1:{nmea_port}"

[service.zenoh]
enabled = false

[service.mavlink]
url = "udpout:127.0.0.1:{free_udp_port()}"
""")
    state_dir = tmp_path / "state"
    notify = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    notify.bind(str(tmp_path / "notify"))
    notify.settimeout(60.0)
    proc = subprocess.Popen([sys.executable, "-m", "onboard", "run", "--config", str(cfg_path),
                             "--state-dir", str(state_dir)],
                            env=dict(os.environ, NOTIFY_SOCKET=str(tmp_path / "notify")),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    gen = TrafficGenerator()
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sent: list[float] = []  # send time of each MAVLink datagram
    try:
        while not notify.recv(4096).startswith(b"READY=1"):
            pass
        t0 = time.monotonic()
        k = 0
        while k < 200:  # 4 s at 50 Hz, killed mid-stream
            for f in gen.mavlink(k / 50.0):
                tx.sendto(f, ("127.0.0.1", mav_port))
                sent.append(time.monotonic())
            for f in gen.nmea(k / 50.0):
                tx.sendto(f, ("127.0.0.1", nmea_port))
            k += 1
            time.sleep(max(0.0, t0 + k / 50.0 - time.monotonic()))
        t_kill = time.monotonic()
        proc.kill()  # SIGKILL: no chance to flush or save
        proc.wait(60)
    finally:
        tx.close()
        notify.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    (rec,) = (state_dir / "recordings").glob("*.onbrec")
    stats = ReadStats()
    records = list(read_records(rec, stats))
    last = max(r.t for r in records if r.kind != "meta")
    frames = [r for r in records if r.kind == "mavlink"]
    print(f"last record {t_kill - last:.3f} s before the kill; {len(frames)} of {len(sent)} "
          "MAVLink datagrams on disk")
    assert t_kill - last < 1.0  # measured 0.3-0.6 s
    assert len(frames) >= sum(1 for t in sent if t < t_kill - 1.0)  # nothing older lost
    assert sum(stats.rejected.values()) <= 1  # at most one torn frame
    # the state file is the last periodic save (the kill left no newer one)
    saved = json.loads((state_dir / "state" / "adaptive.json").read_text())["pipelines"]
    cfg = load(str(cfg_path))
    cold = plain(Engine(cfg).get_state())
    assert saved.get("aie") and saved["aie"] != cold["aie"], "nothing learned in 4 s"

    async def restart() -> tuple[dict | None, dict, list[str]]:
        svc = Service(cfg, state_dir=state_dir)
        await svc.start()
        state = plain(svc.engine.get_state())  # before the first tick
        svc.request_stop()
        await svc.shutdown()
        return svc.restored, state, list(svc.events)

    restored, state, events = asyncio.run(asyncio.wait_for(restart(), 60))
    assert any("restored adaptive state" in e for e in events), events
    assert plain(restored) == saved
    # AIE and current coefficients exactly as saved; the current itself too, with its
    # sigma floored at 0.2 m/s on restore by design (the water may have changed since)
    expected = json.loads(json.dumps(saved))
    if "current_std" in expected.get("current", {}):
        expected["current"]["current_std"] = [max(x, 0.2) for x in
                                              expected["current"]["current_std"]]
    assert state == expected, _diff(state, expected)


def _diff(a, b, path: str = "") -> list[str]:
    """Where two plain (JSON) structures differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [d for k in sorted(set(a) | set(b))
                for d in (_diff(a[k], b[k], f"{path}/{k}") if k in a and k in b
                          else [f"{path}/{k}: only in {'first' if k in a else 'second'}"])]
    return [] if a == b else [f"{path}: {str(a)[:80]} != {str(b)[:80]}"]
