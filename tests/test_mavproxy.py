"""A real peer in the loop: MAVProxy (PyPI ``MAVProxy``, the ``test`` extra) routes the
simulator's MAVLink to the service and to a ground station, and the service's estimates
to that ground station, as on a companion computer (docs/service.md "MAVLink out")::

    onboard sitl --link udp:...A --realtime
         -> mavproxy.py --master=udpin:A --master=udpin:B --out=udp:C --out=udp:D
    service: input udp:C (the autopilot's stream), MAVLink out udpout:B
    ground station (this test, pymavlink): udp:D -> the autopilot's messages and the
    service's HEARTBEAT, NAMED_VALUE_FLOAT (CUR_N ...) and WIND_COV

The service's link is MAVProxy's second master because MAVProxy forwards what arrives on
an ``--out`` link to the master only, and what arrives on any master to every output.
"""

from __future__ import annotations

import asyncio
import os
import shutil
import signal
import socket
import subprocess
import sys
from pathlib import Path

import msgspec
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from onboard.core.config import from_dict
from onboard.apps.service_bench import free_udp_port
from tests.helpers.service_config import service_config

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parent.parent
INSTALL = "pip install 'MAVProxy==1.8.74' future  (the test extra: pip install -e '.[test]')"
NAMED = {"CUR_N", "CUR_E", "THR_EST", "TRQ_EST"}
"""The service's NAMED_VALUE_FLOATs the ground station must get (the wait lasts until all
have come: one estimate can reach a later message than another)."""


def _mavproxy() -> str:
    exe = Path(sys.executable).with_name("mavproxy.py")
    found = str(exe) if exe.exists() else shutil.which("mavproxy.py")
    if found is None:
        pytest.skip(f"MAVProxy is not installed: {INSTALL}")
    return found


def test_mavproxy_routes_the_simulator_to_the_service_and_the_estimates_to_a_ground_station(tmp_path):
    exe = _mavproxy()
    a, b, c, d = (free_udp_port() for _ in range(4))
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", d))
    gcs.setblocking(False)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proxy = subprocess.Popen(
        [sys.executable, exe, f"--master=udpin:127.0.0.1:{a}", f"--master=udpin:127.0.0.1:{b}",
         f"--out=udp:127.0.0.1:{c}", f"--out=udp:127.0.0.1:{d}", "--daemon", "--non-interactive",
         "--no-state", "--default-modules=link"],
        cwd=tmp_path, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, start_new_session=True)
    sim = subprocess.Popen(
        [sys.executable, "-m", "onboard", "sitl", "--scenario", "jaiabot-turns", "--realtime",
         "--duration", "120", "--link", f"udp:127.0.0.1:{a}"],
        cwd=tmp_path, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        start_new_session=True)
    from onboard.service.daemon import Service

    cfg = service_config(sources=[{"name": "autopilot", "kind": "mavlink", "url": f"udp:127.0.0.1:{c}"}],
                         zenoh={"enabled": False}, recorder={"enabled": False},
                         mavlink={"url": f"udpout:127.0.0.1:{b}", "rate_hz": 5.0})
    # routing is under test, not observability: the current is published from the start
    # (by default it is published once its sigma is below 0.3 m/s, after the first turn)
    data = msgspec.to_builtins(cfg)
    data["pipelines"] = {"current": {"unknown_above_std_mps": 100.0}}
    cfg = from_dict(data)
    svc = Service(cfg, state_dir=tmp_path)
    mav = mavlink2.MAVLink(None)
    mav.robust_parsing = True
    got: list = []

    def drain() -> None:
        while True:
            try:
                data = gcs.recv(65536)
            except BlockingIOError:
                return
            got.extend(m for m in (mav.parse_buffer(data) or []) if m.get_type() != "BAD_DATA")

    def ours(kind: str) -> list:
        return [m for m in got if m.get_type() == kind and m.get_srcComponent() == 191
                and m.get_srcSystem() == 3]

    async def main() -> None:
        await svc.start()
        try:
            for _ in range(600):  # at most 60 s; done as soon as everything arrived
                await asyncio.sleep(0.1)
                drain()
                if (ours("WIND_COV") and ours("HEARTBEAT")
                        and NAMED <= {m.name for m in ours("NAMED_VALUE_FLOAT")}):
                    break
                if proxy.poll() is not None or sim.poll() is not None:
                    break
        finally:
            svc.request_stop()
            await svc.run()

    try:
        asyncio.run(main())
    finally:
        for p in (sim, proxy):
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()
        gcs.close()
    log = proxy.stdout.read().decode(errors="replace")[-2000:] if proxy.stdout else ""
    log += "\nsim: " + (sim.stderr.read().decode(errors="replace")[-2000:] if sim.stderr else "")
    autopilot = {m.get_type() for m in got if m.get_srcSystem() == 1}
    assert {"HEARTBEAT", "ATTITUDE", "SERVO_OUTPUT_RAW"} <= autopilot, (sorted(autopilot), log)
    assert svc.intake.sources["autopilot"].samples > 0  # the service got the stream via MAVProxy
    assert ours("HEARTBEAT") and ours("HEARTBEAT")[0].type == mavlink2.MAV_TYPE_ONBOARD_CONTROLLER, log
    names = {m.name for m in ours("NAMED_VALUE_FLOAT")}
    assert NAMED <= names, (sorted(names), log)
    wind = ours("WIND_COV")
    assert wind, log
    est = svc.engine.latest["current"].values
    assert all(abs(w.wind_x) < 3.0 and abs(w.wind_y) < 3.0 for w in wind)
    assert abs(wind[-1].wind_x - est["north"]) < 1.0  # what went out is the estimate
