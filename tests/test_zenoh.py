"""Zenoh publisher: keys, JSON payloads with schema, liveliness, queryable (in-process router)."""

from __future__ import annotations

import threading
import time

import msgspec
import pytest

from onboard.core.config import ZenohOut
from onboard.core.messages import (
    HEALTH_SCHEMA_VERSION,
    SCHEMA_VERSION,
    ChannelHealth,
    EstimateRecord,
    HealthRecord,
)
from onboard.service.publishers.zenoh_pub import ZenohPublisher, open_router, session_config
from onboard.apps.service_bench import free_tcp_port

pytestmark = pytest.mark.integration

TIMEOUT = 20.0


def wait_for(cond, timeout=TIMEOUT):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.02)
    return False


@pytest.fixture
def router():
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    r = open_router(endpoint)
    yield endpoint, r
    r.close()


def _client(endpoint):
    import zenoh

    return zenoh.open(session_config("client", connect=[endpoint]))


def test_estimates_and_health_arrive_as_json_with_schema_on_the_contract_keys(router):
    endpoint, _ = router
    shore = _client(endpoint)
    got: list[tuple[str, bytes, str]] = []
    lock = threading.Lock()

    def on(sample):
        with lock:
            got.append((str(sample.key_expr), sample.payload.to_bytes(), str(sample.encoding)))

    sub = shore.declare_subscriber("onboard/**", on)
    pub = ZenohPublisher(ZenohOut(mode="peer", connect=[endpoint]), "boat7")
    pub.start()
    try:
        rec = EstimateRecord(vehicle="boat7", pipeline="current", t=12.5,
                             values={"north": 0.2, "east": -0.1}, std={"north": 0.05}, t_sensor=12.49)
        health = HealthRecord(vehicle="boat7", t=12.5, rates_hz={"gps": 5.0},
                              rejected={"gnss:nan": 2},
                              innovations={"current": {"velocity": ChannelHealth(
                                  n=3, dof=2, nis_mean=1.2, z=[0.1, -0.2],
                                  S=[0.04, 0.0, 0.0, 0.04])}},
                              counters={"current": {"updates": 3.0}},
                              events=["gps: connected"], mode="surface")
        assert wait_for(lambda: (pub.publish_estimates([rec]), pub.publish_health(health),
                                 len(got) >= 2)[-1])
        with lock:
            keys = {k for k, _, _ in got}
            by_key = {k: (p, e) for k, p, e in got}
        assert {"onboard/boat7/est/current", "onboard/boat7/health"} <= keys
        payload, enc = by_key["onboard/boat7/est/current"]
        assert enc == "application/json;onboard.Estimate.v2"  # the schema named, versioned
        assert by_key["onboard/boat7/health"][1] == f"application/json;onboard.Health.v{HEALTH_SCHEMA_VERSION}"
        back = msgspec.json.decode(payload, type=EstimateRecord)
        assert back == rec and back.schema == SCHEMA_VERSION
        h = msgspec.json.decode(by_key["onboard/boat7/health"][0], type=HealthRecord)
        assert h == health and h.schema == HEALTH_SCHEMA_VERSION

        # the queryable answers the latest value of every key under onboard/boat7/**
        replies = {str(r.ok.key_expr): r.ok.payload.to_bytes()
                   for r in shore.get("onboard/boat7/**", timeout=TIMEOUT) if r.ok is not None}
        assert set(replies) == {"onboard/boat7/est/current", "onboard/boat7/health"}
        only = [str(r.ok.key_expr) for r in shore.get("onboard/boat7/est/*", timeout=TIMEOUT)
                if r.ok is not None]
        assert only == ["onboard/boat7/est/current"]

        # liveliness: present while running, gone after close
        alive = [str(r.ok.key_expr) for r in shore.liveliness().get("onboard/*/alive", timeout=TIMEOUT)
                 if r.ok is not None]
        assert alive == ["onboard/boat7/alive"]
    finally:
        pub.close()
        sub.undeclare()
    assert wait_for(lambda: not [r for r in shore.liveliness().get("onboard/*/alive", timeout=5)
                                 if r.ok is not None])
    shore.close()


def test_client_mode_without_a_router_fails_at_start_with_a_reason():
    pub = ZenohPublisher(ZenohOut(mode="client", connect=[f"tcp/127.0.0.1:{free_tcp_port()}"]), "x")
    with pytest.raises(Exception, match="(?i)connect"):
        pub.start()
    pub.close()


def test_onboard_shore_once_prints_a_snapshot_from_the_queryables(router, capsys):
    import argparse

    from onboard.apps import shore

    endpoint, _ = router
    pub = ZenohPublisher(ZenohOut(mode="client", connect=[endpoint]), "boat9")
    pub.start()
    try:
        pub.publish_estimates([EstimateRecord(vehicle="boat9", pipeline="aie", t=5.0,
                                              values={"heading": 1.5708, "speed": 1.25})])
        pub.publish_health(HealthRecord(
            vehicle="boat9", t=5.0, rates_hz={"gps": 5.0}, rejected={"gnss:nan": 1},
            mode="surface", innovations={"aie": {"surge.rate": ChannelHealth(
                n=40, rejected=2, dof=1, nis_recent=0.85)}}))
        # the snapshot says what the router knows when it asks: wait until the vehicle's
        # liveliness token has reached it (a loaded machine took longer than the query)
        probe = _client(endpoint)
        try:
            assert wait_for(lambda: [r for r in probe.liveliness().get(
                "onboard/boat9/alive", timeout=5) if r.ok is not None])
        finally:
            probe.close()
        args = argparse.Namespace(connect=[endpoint], listen=None, mode=None, vehicle="boat9",
                                  once=True)
        rc = shore.main(args)
        out = capsys.readouterr().out
    finally:
        pub.close()
    assert rc == 0
    assert "== boat9 (alive), mode surface" in out
    assert "heading=90.0°" in out and "speed=+1.25" in out
    assert "gnss:nan=1" in out and "gps=5.0" in out
    assert "aie.surge.rate=0.85/1 (2 rejected)" in out
    args = argparse.Namespace(connect=[endpoint], listen=None, mode=None, vehicle="nobody",
                              once=True)
    assert shore.main(args) == 1  # nothing answered


def test_positions_also_go_out_as_foxglove_location_fixes_with_their_schema_name(router):
    from onboard.core.geo import LocalFrame
    from onboard.core.wire import LocationFix, location_fix

    endpoint, _ = router
    shore = _client(endpoint)
    got: dict[str, tuple[bytes, str]] = {}
    sub = shore.declare_subscriber(
        "onboard/boat7/fix/*", lambda s: got.update({str(s.key_expr): (s.payload.to_bytes(),
                                                                       str(s.encoding))}))
    pub = ZenohPublisher(ZenohOut(mode="peer", connect=[endpoint]), "boat7")
    pub.start()
    frame = LocalFrame(63.44, 10.40)
    rec = EstimateRecord(vehicle="boat7", pipeline="kf", t=1700000000.25,
                         values={"north": 111.0, "east": -50.0, "heading": 0.5},
                         std={"north": 2.0, "east": 3.0})
    fix = location_fix(rec, frame)
    try:
        assert wait_for(lambda: (pub.publish_estimates([rec], [fix]), bool(got))[-1])
    finally:
        pub.close()
        sub.undeclare()
        shore.close()
    payload, enc = got["onboard/boat7/fix/kf"]
    assert enc == "application/json;foxglove.LocationFix"
    back = msgspec.json.decode(payload, type=LocationFix)
    assert back.timestamp.sec == 1700000000 and back.timestamp.nsec == 250_000_000
    assert back.frame_id == "kf" and back.heading == 0.5
    n, e = frame.to_ne(back.latitude, back.longitude)
    assert abs(n - 111.0) < 1e-6 and abs(e + 50.0) < 1e-6  # the same point, round trip
    # Foxglove's covariance is East-North-Up, row-major: east's variance first
    assert back.position_covariance == [9.0, 0, 0, 0, 4.0, 0, 0, 0, 0]
    assert back.position_covariance_type == 2


def test_shore_decodes_its_schema_versions_and_counts_another_as_bad():
    from onboard.apps.shore import ShoreView

    view = ShoreView()
    rec = EstimateRecord(vehicle="b", pipeline="kf", t=1.0, values={"speed": 1.0},
                         utc=1.7e9, lat_deg=43.0, lon_deg=5.0)
    payload = msgspec.json.encode(rec)
    view.feed("onboard/b/est/kf", payload, "application/json;onboard.Estimate.v2")
    view.feed("onboard/b/est/kf", payload, "application/json")  # before schema names
    assert view.received["est"] == 2 and view.bad == 0
    assert view.estimates[("b", "kf")].utc == 1.7e9
    # a schema-1 record (no utc, lat_deg, lon_deg) is read and counted apart
    v1 = b'{"schema":1,"vehicle":"b","pipeline":"kf","t":2.0,"values":{"speed":1.5}}'
    view.feed("onboard/b/est/kf", v1, "application/json;onboard.Estimate.v1")
    assert view.received["est"] == 3 and view.received["est.v1"] == 1 and view.bad == 0
    old = view.estimates[("b", "kf")]
    assert old.utc is None and old.lat_deg is None and old.values == {"speed": 1.5}
    view.feed("onboard/b/est/kf", payload, "application/json;onboard.Estimate.v3")
    assert view.received["est"] == 3 and view.bad == 1
    view.feed("onboard/b/fix/kf", b"{}", "application/json;foxglove.LocationFix")
    assert view.bad == 1  # a fix is not decoded by the table, and not bad


SCHEMA_NAME = r"onboard\.(Estimate|Health)\.v(\d+)"
HISTORY = {("docs/architecture.md", "onboard.Health.v2")}
"""(page, schema name) of a past name a page cites as such (a dated correction)."""


def test_the_docs_name_the_schemas_the_wire_carries():
    """Every ``onboard.Estimate.vN`` / ``onboard.Health.vN`` in the README, the docs and the
    package's docstrings is the encoding the service sends (onboard/core/wire.py), but for
    the past names :data:`HISTORY` lists."""
    import re
    from pathlib import Path

    from onboard.core.wire import ESTIMATE_SCHEMA, HEALTH_SCHEMA

    root = Path(__file__).resolve().parent.parent
    current = {"Estimate": ESTIMATE_SCHEMA, "Health": HEALTH_SCHEMA}
    pages = [root / "README.md", *sorted((root / "docs").glob("*.md")),
             *sorted((root / "onboard").rglob("*.py")), *sorted((root / "drivers").glob("*.py"))]
    wrong = []
    for page in pages:
        rel = page.relative_to(root).as_posix()
        for m in re.finditer(SCHEMA_NAME, page.read_text(encoding="utf-8")):
            if m.group(0) != current[m.group(1)] and (rel, m.group(0)) not in HISTORY:
                wrong.append(f"{rel}: {m.group(0)}")
    assert wrong == []


def test_the_shore_table_shows_a_records_control_characters_not_acts_on_them():
    """A vehicle id or an event with an escape sequence (clear the screen, retitle the
    terminal) is printed as \\xNN, each line still one line."""
    import msgspec

    from onboard.apps.shore import ShoreView
    from onboard.core.messages import HealthRecord

    view = ShoreView()
    evil = "b\x1b[2J\x1b]0;pwned\x07"
    view.feed(f"onboard/{evil}/health",
              msgspec.json.encode(HealthRecord(vehicle=evil, t=1.0,
                                               events=["gnss lost\x1b[31m\r\nfake line"])))
    table = view.table()
    assert "\x1b" not in table and "\x07" not in table and "\r" not in table
    assert "b\\x1b[2J\\x1b]0;pwned\\x07" in table and "gnss lost\\x1b[31m\\x0d\\x0afake" in table


@pytest.mark.integration
@pytest.mark.parametrize("opener", ["onboard.apps.shore", "onboard.fleet.service"])
def test_a_zenoh_config_file_gives_the_endpoints_and_mode_when_the_flags_do_not(
        router, tmp_path, opener):
    """``--zenoh-config FILE`` without ``--connect``/``--mode`` connects where FILE says
    (docs/security.md: ``onboard shore --once --zenoh-config shore.json5``), not to the
    default tcp/127.0.0.1:7447; ``--connect`` still wins over the file."""
    import importlib

    from onboard.core.errors import UsageError

    open_session = importlib.import_module(opener).open_session
    endpoint, _ = router
    good = tmp_path / "good.json5"
    good.write_text(f'{{ mode: "client", connect: {{ endpoints: ["{endpoint}"] }} }}\n')
    open_session(None, None, None, str(good)).close()
    nowhere = f"tcp/127.0.0.1:{free_tcp_port()}"
    bad = tmp_path / "bad.json5"
    bad.write_text(f'{{ mode: "client", connect: {{ endpoints: ["{nowhere}"] }} }}\n')
    with pytest.raises(UsageError, match=f"cannot reach Zenoh at {nowhere}:"):
        open_session(None, None, None, str(bad))
    open_session([endpoint], None, None, str(bad)).close()
