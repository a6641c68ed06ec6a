"""``onboard fleet`` end to end through a real Zenoh router (in process): vehicles publish
schema-2 records on ``<prefix>/<id>/est/current``, the service fuses them, answers
``<prefix>/fleet/current`` queries and publishes ``<prefix>/fleet/current/grid``
(architecture.md §4.4)."""

from __future__ import annotations

import json
import threading
import time

import msgspec
import numpy as np
import pytest

from onboard.apps.service_bench import free_tcp_port
from onboard.fleet.messages import FleetCurrent, FleetGrid
from onboard.fleet.service import FleetService
from onboard.service.publishers.zenoh_pub import open_router, session_config
from tests.helpers.fleet_scenarios import UTC0, eddy, fleet

pytestmark = pytest.mark.integration
TIMEOUT = 30.0


def wait_for(cond, timeout=TIMEOUT):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.05)
    return False


def test_records_from_several_vehicles_become_a_field_that_answers_queries(tmp_path):
    import zenoh

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_router(endpoint)
    sessions = [zenoh.open(session_config("client", connect=[endpoint])) for _ in range(3)]
    fleet_session, vehicles, shore = sessions
    service = FleetService(fleet_session, "onboard", mcap=tmp_path / "field.mcap")
    grids: list[tuple[bytes, str]] = []
    lock = threading.Lock()

    def on_grid(sample):
        with lock:
            grids.append((sample.payload.to_bytes(), str(sample.encoding)))

    sub = shore.declare_subscriber("onboard/fleet/current/grid", on_grid)
    try:
        f = fleet("eddy", seed=21, vehicles=4, duration_s=900.0, rate_hz=1.0)
        enc = msgspec.json.Encoder()
        order = np.random.default_rng(0).permutation(len(f.t))   # late, out of order
        pubs = {}
        for i in order:
            rec = f.record(int(i))
            key = f"onboard/{rec.vehicle}/est/current"
            if key not in pubs:
                pubs[key] = vehicles.declare_publisher(   # every record arrives
                    key, encoding="application/json;onboard.Estimate.v2",
                    congestion_control=zenoh.CongestionControl.BLOCK)
            pubs[key].put(enc.encode(rec))
        assert wait_for(lambda: service.field.added == len(f.t)), service.received
        assert service.step(refit=True) is not None
        lat, lon = f.plane.to_latlon(100.0, -200.0)
        utc = UTC0 + 600.0
        replies = list(shore.get(f"onboard/fleet/current?lat={lat};lon={lon};utc={utc}",
                                 timeout=10.0))
        assert len(replies) == 1 and replies[0].ok is not None
        ok = replies[0].ok
        assert str(ok.encoding) == "application/json;onboard.FleetCurrent.v1"
        doc = json.loads(ok.payload.to_bytes())
        assert list(doc) == ["lat", "lon", "utc", "north", "east", "std_north", "std_east",
                             "n_obs"]   # exactly issue 33's fields (the grid adds the down)
        got = msgspec.json.decode(ok.payload.to_bytes(), type=FleetCurrent)
        truth = eddy(np.array(100.0), np.array(-200.0), 600.0)
        assert got.n_obs > 0 and got.utc == utc
        assert abs(got.north - float(truth[0])) < 3 * got.std_north + 0.01
        assert abs(got.east - float(truth[1])) < 3 * got.std_east + 0.01
        amp = list(shore.get(f"onboard/fleet/current?utc={utc}&lat={lat}&lon={lon}",
                             timeout=10.0))   # '&' as a URL's query writes it
        assert len(amp) == 1 and amp[0].ok is not None
        assert amp[0].ok.payload.to_bytes() == ok.payload.to_bytes()
        bad = list(shore.get("onboard/fleet/current?lat=43;utc=1", timeout=10.0))
        assert len(bad) == 1 and bad[0].err is not None
        assert "lon is missing" in json.loads(bad[0].err.payload.to_bytes())["error"]
        assert wait_for(lambda: len(grids) >= 1)
        payload, encoding = grids[0]
        assert encoding == "application/json;onboard.FleetGrid.v1"
        grid = msgspec.json.decode(payload, type=FleetGrid)
        assert len(grid.vehicles) == 4 and any(c.north is not None for c in grid.cells)
    finally:
        sub.undeclare()
        service.close()
        for s in sessions:
            s.close()
        router.close()
    from mcap.reader import make_reader

    with open(tmp_path / "field.mcap", "rb") as fh:
        topics = [ch.topic for _, ch, _ in make_reader(fh).iter_messages()]
    assert topics == ["onboard/fleet/current/grid", "onboard/fleet/current/geojson"]


def test_onboard_fleet_serves_its_field_on_the_web_page_and_to_a_chart_plotter():
    """``onboard fleet --web``: the page's ``/api/fleet`` holds the grid the service made
    from the vehicles' records, known cells with their sigmas; with ``--at`` (a vehicle's
    last place) and ``--vdr``, VDR sentences of the field there reach a UDP listener and
    each grid's line counts them."""
    import socket
    import subprocess
    import sys
    import urllib.request

    import zenoh

    f = fleet("eddy", seed=22, vehicles=3, duration_s=600.0, rate_hz=1.0)
    shift = time.time() - (UTC0 + 600.0)   # the records end now: the field is asked now
    lat, lon = f.plane.to_latlon(f.north_m[-1], f.east_m[-1])
    plotter = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    plotter.bind(("127.0.0.1", 0))
    plotter.settimeout(60.0)
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_router(endpoint)
    vehicles = zenoh.open(session_config("client", connect=[endpoint]))
    proc = subprocess.Popen([sys.executable, "-m", "onboard", "fleet", "--connect", endpoint,
                             "--period", "1", "--web", "127.0.0.1:0",
                             "--at", f"{lat:.7f},{lon:.7f}",
                             "--vdr", f"udp:127.0.0.1:{plotter.getsockname()[1]}"],
                            stdout=subprocess.PIPE, text=True)
    try:
        url = ""
        while not url:
            line = proc.stdout.readline()
            assert line, "onboard fleet ended before serving its page"
            if "the page is on " in line:
                url = line.split("the page is on ")[1].strip()
        enc = msgspec.json.Encoder()
        pubs = {}
        for i in range(len(f.t)):
            rec = msgspec.structs.replace(f.record(i), utc=f.record(i).utc + shift)
            key = f"onboard/{rec.vehicle}/est/current"
            if key not in pubs:
                pubs[key] = vehicles.declare_publisher(
                    key, encoding="application/json;onboard.Estimate.v2",
                    congestion_control=zenoh.CongestionControl.BLOCK)
            pubs[key].put(enc.encode(rec))

        def grid():
            with urllib.request.urlopen(url + "api/fleet", timeout=5.0) as r:
                return json.loads(r.read()).get("grid")

        assert wait_for(lambda: (grid() or {}).get("cells"), timeout=60.0)
        known = [c for c in grid()["cells"] if c["north"] is not None]
        assert known and all(c["std_north"] > 0 for c in known)
        sentence = plotter.recv(200).decode("ascii")
        assert sentence.startswith("$IIVDR,") and sentence.endswith("*" + sentence[-4:-2]
                                                                     + "\r\n")
        counted = []   # the lines' counts, the first before the field was known
        while not counted or counted[-1] == "0":
            line = proc.stdout.readline()
            assert line and len(counted) < 60, f"no set and drift counted: {line!r}"
            if "set and drift: " in line:
                counted.append(line.split("set and drift: ")[1].split()[0])
    finally:
        proc.terminate()
        proc.wait(20.0)
        plotter.close()
        vehicles.close()
        router.close()
