"""The simulator's link delay (sitl/link.py) against what it says it reproduces."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from onboard.sitl.link import ARDUSUB_TETHER, DelayedClock, LinkDelay


def test_the_tether_delay_has_the_tlogs_percentiles_memory_and_keeps_the_frames_in_order():
    """20 Hz frames for an hour: the delay's 50th / 95th percentiles near the ArduSub
    tlog's ATTITUDE (7 / 20 ms; the clipped normal gives 8 / 19.5), consecutive delays
    correlated 0.82 (the tlog's), never negative, and no frame overtaking another."""
    clock = DelayedClock(ARDUSUB_TETHER, np.random.default_rng(7))
    t = np.arange(0.0, 3600.0, 0.05)
    arrival = np.array([clock.arrival(x) for x in t])
    d = (arrival - t) * 1000.0
    assert np.all(d >= 0.0) and np.all(np.diff(arrival) >= 0.0)
    p50, p95 = np.percentile(d, [50, 95])
    assert 6.5 < p50 < 9.5 and 17.0 < p95 < 23.0, (p50, p95)
    assert 0.75 < np.corrcoef(d[:-1], d[1:])[0, 1] < 0.88


def test_a_link_without_spread_delays_every_frame_by_its_mean():
    """The control: no wandering part, every frame exactly ``mean`` late."""
    clock = DelayedClock(LinkDelay(mean_s=0.004, std_s=0.0, tau_s=1.0),
                         np.random.default_rng(0))
    assert [round(clock.arrival(x) - x, 12) for x in (0.0, 0.02, 0.04, 1.0)] == [0.004] * 4


def _imu_delays_ms(extra: list[str]) -> np.ndarray:
    """``onboard sitl --realtime`` streaming to a UDP socket of ours for 4 s: each
    SCALED_IMU's receive time less its boot time, less the least of them (ms)."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink2

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as rx:
        rx.bind(("127.0.0.1", 0))
        rx.settimeout(0.5)
        port = rx.getsockname()[1]
        proc = subprocess.Popen(
            [sys.executable, "-m", "onboard", "sitl", "--scenario", "jaiabot-turns",
             "--realtime", "--duration", "4", "--link", f"udp:127.0.0.1:{port}",
             "--stream-unasked", *extra],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        mav = mavlink2.MAVLink(None)
        mav.robust_parsing = True
        got: list[float] = []
        deadline = time.monotonic() + 30.0
        while proc.poll() is None and time.monotonic() < deadline:
            try:
                data = rx.recv(65536)
            except socket.timeout:
                continue
            t_rx = time.monotonic()
            for msg in mav.parse_buffer(data) or []:
                if msg.get_type() == "SCALED_IMU":
                    got.append(t_rx - msg.time_boot_ms / 1000.0)
        _, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
    d = np.array(got[50:]) * 1000.0  # after the first second
    return d - d.min()


@pytest.mark.integration
def test_onboard_sitl_link_delay_sends_the_live_frames_late_as_the_tether_did():
    """``--link-delay tether``: the IMU frames' delay spreads as the ArduSub tlog's (5th
    to 95th percentile about 19 ms); without it they leave on their simulation times."""
    steady, tether = _imu_delays_ms([]), _imu_delays_ms(["--link-delay", "tether"])
    assert len(steady) > 100 and len(tether) > 100
    spread = [float(np.percentile(d, 95) - np.percentile(d, 5)) for d in (steady, tether)]
    assert spread[1] > 10.0 and spread[1] > spread[0] + 5.0, spread


def test_link_delay_needs_realtime():
    proc = subprocess.run([sys.executable, "-m", "onboard", "sitl", "--scenario",
                           "jaiabot-turns", "--duration", "1", "--link-delay", "tether",
                           "--tlog", os.devnull, "--force"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "--link-delay goes with --realtime" in proc.stderr
