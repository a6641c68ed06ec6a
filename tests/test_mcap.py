"""MCAP in and out: ``onboard replay`` of a BlueOS recording (mavlink-server's JSON MAVLink
channels, recorded by blueos-recorder) gives the estimates of the tlog it was made from;
``onboard replay --mcap`` writes the live Zenoh channels with their schemas; our own MCAP
is recognized as estimates, not sensor data.

The fixtures are written from the serialization the sources show (tests/helpers/
blueos_mcap.py), from the committed simulator tlog of the golden replay."""

from __future__ import annotations

import json
import math
from pathlib import Path

import msgspec
import pytest

pytest.importorskip("mcap", reason="needs the mcap package: pip install -e '.[mcap]'")

from pymavlink.dialects.v20 import ardupilotmega as dialect  # noqa: E402

from onboard.cli import main as cli_main  # noqa: E402
from onboard.core.geo import LocalFrame  # noqa: E402
from onboard.core.messages import EstimateRecord  # noqa: E402
from onboard.core.wire import LocationFix  # noqa: E402
from onboard.drivers.base import UnreadableLog  # noqa: E402
from onboard.drivers.logs import sniff  # noqa: E402
from onboard.drivers.mavlink_json import JsonFrameError, frame_from_json, parse  # noqa: E402
from onboard.drivers.mcap_log import McapReader  # noqa: E402
from onboard.drivers.tlog import TlogReader  # noqa: E402
from tests.helpers.blueos_mcap import BlueosRecorder, blueos_mcap_from_tlog, to_serde  # noqa: E402
from tests.helpers.foxglove_schema import foxglove_parses  # noqa: E402
from tests.helpers.nmea_times import rmc_times  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
TLOG = REPO / "tests" / "data" / "replay" / "jaiabot-turns.tlog"
LAYOUT = REPO / "docs" / "foxglove-layout.json"


@pytest.fixture(scope="module")
def blueos_mcap(tmp_path_factory) -> tuple[Path, dict[str, int]]:
    out = tmp_path_factory.mktemp("mcap") / "recorder_20260101_120000.mcap"
    return out, blueos_mcap_from_tlog(TLOG, out)


def _replay(log: Path, out: Path, *extra: str) -> dict:
    assert cli_main(["replay", str(log), "--out", str(out), "--no-plot", *extra]) == 0
    return json.loads((out / "summary.json").read_text())


# ------------------------------------------------------------------ reading BlueOS's MCAP


def test_a_blueos_recording_replays_to_the_estimates_of_its_tlog(blueos_mcap, tmp_path):
    mcap, written = blueos_mcap
    assert sniff(mcap) == "mcap"
    from_tlog = _replay(TLOG, tmp_path / "tlog")
    from_mcap = _replay(mcap, tmp_path / "mcap")
    # byte for byte: the same samples with the same stamps, the same detected config
    assert (tmp_path / "mcap" / "estimates.csv").read_bytes() == \
        (tmp_path / "tlog" / "estimates.csv").read_bytes()
    assert from_mcap["format"] == "mcap" and from_mcap["config"] == from_tlog["config"]
    read = from_mcap["read"]
    assert read["samples"] == from_tlog["read"]["samples"] == written["messages"]  # 3128
    # what was not read is counted: the unknown message and field the fixture added ...
    assert read["rejected"] == {"mcap:unknown_field": written["unknown_field"],
                                "mcap:unknown_message": written["unknown_message"]}
    # ... and the channels left out by design: mavlink/out and the per-field channels
    # (3495 here), the service's own estimates, another service's channel
    assert read["skipped"]["onboard_record"] == written["onboard"]
    assert read["skipped"]["other_channel"] == written["other"]
    assert read["skipped"]["duplicate"] > written["messages"]
    codes = [w["code"] for w in from_mcap["warnings"]]
    assert "mcap_unread" in codes and "mcap_unread" not in [w["code"] for w in from_tlog["warnings"]]


def test_raw_frames_are_read_where_present_and_mavlink_out_alone_suffices(tmp_path):
    want = list(TlogReader(TLOG))
    raw = tmp_path / "raw.mcap"
    blueos_mcap_from_tlog(TLOG, raw, raw=True, extras=False)
    reader = McapReader(raw)
    assert reader.source == "raw"
    assert list(reader) == want
    assert reader.stats.rejected == {} and reader.stats.skipped["duplicate"] > 0
    # a recording with only mavlink/out (every message on one channel)
    only_out = tmp_path / "out.mcap"
    rec = BlueosRecorder(only_out)
    from tests.helpers.blueos_mcap import tlog_messages

    for t_us, msg in tlog_messages(TLOG):
        rec.put("mavlink/out", to_serde(msg), t_us * 1000)
    rec.close()
    reader = McapReader(only_out)
    assert reader.source == "all" and list(reader) == want


def test_rust_mavlink_serde_forms_become_the_frames_they_came_from():
    mav = dialect.MAVLink(None, srcSystem=1, srcComponent=1)
    hb = dialect.MAVLink_heartbeat_message(dialect.MAV_TYPE_SURFACE_BOAT,
                                           dialect.MAV_AUTOPILOT_ARDUPILOTMEGA, 209, 10, 4, 3)
    mav.seq = 7
    want = bytes(hb.pack(mav))
    obj = {"header": {"system_id": 1, "component_id": 1, "sequence": 7},
           "message": {"type": "HEARTBEAT", "custom_mode": 10,
                       "mavtype": {"type": "MAV_TYPE_SURFACE_BOAT"},
                       "autopilot": {"type": "MAV_AUTOPILOT_ARDUPILOTMEGA"},
                       "base_mode": {"bits": 209}, "system_status": {"type": "MAV_STATE_ACTIVE"},
                       "mavlink_version": 3}}
    assert frame_from_json(obj).frame == want
    # char arrays as arrays of bytes (rust-mavlink before CharArray) or as strings
    pv = {"header": {"system_id": 1, "component_id": 1, "sequence": 0},
          "message": {"type": "PARAM_VALUE", "param_value": 26.0, "param_count": 900,
                      "param_index": 3, "param_type": {"type": "MAV_PARAM_TYPE_REAL32"},
                      "param_id": list(b"SERVO1_FUNCTION") + [0]}}
    as_list = frame_from_json(pv).frame
    pv["message"]["param_id"] = "SERVO1_FUNCTION"
    assert frame_from_json(pv).frame == as_list
    # json5's NaN, an unknown enum, an unknown message
    att = parse(b'{"header": {"system_id": 1, "component_id": 1, "sequence": 0}, "message": '
                b'{"type": "ATTITUDE", "time_boot_ms": 5, "roll": NaN, "pitch": 0.0, "yaw": 1.0,'
                b' "rollspeed": 0, "pitchspeed": 0, "yawspeed": 0}}')
    decoded = dialect.MAVLink(None).parse_buffer(frame_from_json(att).frame)[0]
    assert math.isnan(decoded.roll) and decoded.yaw == 1.0
    pv["message"]["param_type"] = {"type": "MAV_PARAM_TYPE_FUTURE"}
    with pytest.raises(JsonFrameError) as err:
        frame_from_json(pv)
    assert err.value.reason == "unknown_enum"
    with pytest.raises(JsonFrameError) as err:
        frame_from_json({"header": pv["header"], "message": {"type": "NOT_A_MESSAGE"}})
    assert err.value.reason == "unknown_message"


# ------------------------------------------------------------------ writing MCAP


def _messages(path: Path) -> list[tuple[str, str, str, str, bytes]]:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [(c.topic, c.message_encoding, s.name, s.encoding, m.data)
                for s, c, m in make_reader(f).iter_messages()]


def test_replay_writes_the_live_zenoh_channels_and_schemas_as_mcap(tmp_path):
    out = tmp_path / "estimates.mcap"
    summary = _replay(TLOG, tmp_path / "r", "--mcap", str(out))
    msgs = _messages(out)
    assert summary["mcap"]["messages"] == len(msgs) > 0
    topics = {t for t, *_ in msgs}
    vid = summary["vehicle_id"]  # rudder-boat, as the layout names it
    assert {f"onboard/{vid}/est/{p}" for p in ("nav", "aie", "kf", "current")} <= topics
    assert {f"onboard/{vid}/fix/{p}" for p in ("nav", "aie", "kf")} <= topics
    assert f"onboard/{vid}/fix/current" not in topics  # a velocity, not a position
    by_schema = {}
    for topic, enc, schema, schema_enc, data in msgs:
        assert enc == "json" and schema_enc == "jsonschema"
        by_schema.setdefault(schema, []).append((topic, data))
    # each channel's schema is one Foxglove's MCAP reader parses (msgspec's own, a map with
    # no properties and nullable fields as anyOf [number, null], is not: the control)
    for name, schema in _schemas(out).items():
        foxglove_parses(schema, name)
    with pytest.raises(ValueError, match="an object without properties"):
        foxglove_parses(msgspec.json.schema(EstimateRecord)["$defs"]["EstimateRecord"],
                        "raw")
    assert set(by_schema) == {"onboard.Estimate.v2", "foxglove.LocationFix"}
    recs = [msgspec.json.decode(d, type=EstimateRecord) for _, d in by_schema["onboard.Estimate.v2"]]
    assert {r.vehicle for r in recs} == {vid}
    fixes = [msgspec.json.decode(d, type=LocationFix) for _, d in by_schema["foxglove.LocationFix"]]
    # the fixes lie where the estimates say: back to metres about the first nav fix
    first_nav = next(f for f in fixes if f.frame_id == "nav")
    kf = [r for r in recs if r.pipeline == "kf" and "north" in r.values][-1]
    kf_fix = [f for f in fixes if f.frame_id == "kf"][-1]
    frame = LocalFrame(first_nav.latitude, first_nav.longitude)
    n, e = frame.to_ne(kf_fix.latitude, kf_fix.longitude)
    assert abs(n - kf.values["north"]) < 0.01 and abs(e - kf.values["east"]) < 0.01
    assert kf_fix.position_covariance_type == 2
    # reading it back: estimates, not sensor data, and said so (exit status 2)
    with pytest.raises(UnreadableLog, match="estimates, not sensor data"):
        McapReader(out)
    assert cli_main(["replay", str(out), "--out", str(tmp_path / "again")]) == 2


def test_every_schema_the_vehicle_publishes_is_one_foxglove_reads():
    """The Estimate, Health and LocationFix schemas (replay --mcap, the live Foxglove
    bridge, the fleet's grid) pass the checks of Foxglove's MCAP reader: one type per
    field (the health's declination source, an enumeration, typed ``string``; every
    nullable number a ``number``), every object with its properties (a map's empty)."""
    from onboard.core import wire

    for name, kind in wire.SCHEMAS.items():
        foxglove_parses(wire.json_schema(kind), name)


def _schemas(path: Path) -> dict[str, dict]:
    """Each schema of an MCAP file, by name, as JSON."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return {s.name: json.loads(s.data) for s in make_reader(f).get_summary().schemas.values()}


def _read(path: Path) -> tuple[list, dict[str, dict[str, str]]]:
    """(schema name, topic, log time, publish time, payload) of every message, and the
    metadata records, as the mcap library reads them."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        msgs = [(s.name, c.topic, m.log_time, m.publish_time, json.loads(m.data))
                for s, c, m in reader.iter_messages()]
        f.seek(0)
        meta = {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}
    return msgs, meta


def test_mcap_log_times_are_utc_ns_from_a_dataflash_logs_gps_time(tmp_path):
    """A DataFlash log stamped in time since boot, whose GPS records carry GPS week 2262:
    the MCAP's log and publish times and the fixes' timestamps are the UTC of each tick
    (as pymavlink's DataFlash clock gives it), the records keep the log's clock."""
    from pymavlink import mavutil

    from tests.helpers.dataflash_log import gps_timed_log

    log = tmp_path / "boat.bin"
    log.write_bytes(gps_timed_log(2262, 345_600_000, seconds=6.0))
    summary = _replay(log, tmp_path / "r", "--mcap", str(tmp_path / "e.mcap"))
    msgs, meta = _read(tmp_path / "e.mcap")
    first_gps = mavutil.mavlink_connection(str(log)).recv_match(type="GPS",
                                                                condition="GPS.GWk > 0")
    offset = first_gps._timestamp - first_gps.TimeUS / 1e6  # UTC minus time since boot
    assert summary["utc"]["utc"] and summary["utc"]["start"].startswith("2023-05-")
    assert meta["onboard-clock"]["utc"] == "true"
    assert meta["onboard-clock"]["start"] == summary["utc"]["start"]
    assert msgs
    for schema, topic, log_time, publish_time, payload in msgs:
        assert publish_time == log_time
        if schema == "onboard.Estimate.v2":
            assert payload["t"] < 100.0  # the record's own t: seconds since boot
            assert log_time == pytest.approx((payload["t"] + offset) * 1e9, abs=2e3)
        else:
            stamp = payload["timestamp"]["sec"] * 10**9 + payload["timestamp"]["nsec"]
            assert abs(stamp - log_time) <= 1


def test_mcap_of_a_log_without_utc_keeps_its_clock_and_says_so(tmp_path):
    """The BlueBoat CSV in ms since boot: log times are the ticks on the log's clock
    (seconds since boot, shown by Foxglove as 1970-01-01), and the metadata says why."""
    from onboard.drivers.logclock import UTC_MIN_S

    csv_log = REPO / "tests/data/csv/blueboat-run.csv"
    summary = _replay(csv_log, tmp_path / "r", "--config",
                      str(REPO / "config/blueboat-ntnu-csv.toml"), "--mcap",
                      str(tmp_path / "e.mcap"))
    msgs, meta = _read(tmp_path / "e.mcap")
    assert meta["onboard-clock"] == {"utc": "false", "start": "",
                                     "source": summary["utc"]["source"]}
    est = [(lt, p["t"]) for s, _, lt, _, p in msgs if s == "onboard.Estimate.v2"]
    assert est and all(lt == round(t * 1e9) for lt, t in est)
    assert max(lt for lt, _ in est) < UTC_MIN_S * 1e9


# ------------------------------------------------------------------ the Foxglove layout


def _camel(name: str) -> str:
    head, *rest = name.split("_")
    return head + "".join(w.title() for w in rest)


def _literals(hint) -> tuple:
    """The values a (possibly optional) Literal type allows; () for any other type."""
    import typing

    if typing.get_origin(hint) is typing.Literal:
        return typing.get_args(hint)
    return tuple(v for a in typing.get_args(hint) for v in _literals(a))


def _as_sdk(cls, cfg: dict):
    """``cfg`` (a panel config as the layout has it) built as the foxglove-sdk's typed
    config ``cls``: every key must be one the SDK's schema of Foxglove's panels knows,
    every value of an enumerated setting one it allows."""
    import dataclasses
    import typing

    import foxglove.layouts as fl

    fields = {_camel(f.name): f.name for f in dataclasses.fields(cls)}
    hints = typing.get_type_hints(cls)
    kwargs = {}
    for key, value in cfg.items():
        assert key in fields, f"{cls.__name__} has no {key!r}"
        allowed = _literals(hints[fields[key]])
        assert not allowed or value in allowed, f"{key} = {value!r} not in {allowed}"
        kwargs[fields[key]] = ([_as_sdk(fl.PlotSeries, p) for p in value] if key == "paths"
                               else value)
    return cls(**kwargs)


def _check_layout(layout: dict, mcap: Path, prefix: str, vehicle: str) -> set[str]:
    """A layout of onboard replay against what Foxglove expects and what the MCAP holds;
    the topics it names."""
    fl = pytest.importorskip("foxglove.layouts", reason="needs foxglove-sdk")
    msgs, _ = _read(mcap)
    fields: dict[str, dict] = {}  # per topic, every numeric field any of its records had
    schemas = {}
    for schema, topic, _, _, payload in msgs:
        schemas[topic] = schema
        merged = fields.setdefault(topic, {})
        for k, v in payload.items():
            if isinstance(v, dict):
                merged.setdefault(k, {}).update({f: x for f, x in v.items() if x is not None})
    # Foxglove's exported-layout format: panels by id (type!name), the mosaic of their ids
    assert set(layout) >= {"configById", "layout", "globalVariables", "userNodes",
                           "playbackConfig"}
    panels = layout["configById"]

    def ids(node):
        return [node] if isinstance(node, str) else ids(node["first"]) + ids(node["second"])
    assert sorted(ids(layout["layout"])) == sorted(panels)
    named = set()
    for pid, cfg in panels.items():
        kind = pid.split("!")[0]
        panel, config = {"Map": (fl.MapPanel, fl.MapConfig),
                         "Plot": (fl.PlotPanel, fl.PlotConfig)}[kind]
        # a panel's title is its config's foxglovePanelTitle in an exported layout
        own = {k: v for k, v in cfg.items() if k != "foxglovePanelTitle"}
        sdk = panel(config=_as_sdk(config, own), title=cfg.get("foxglovePanelTitle"))
        as_sdk = json.loads(sdk.to_json())
        assert as_sdk["panelType"] == kind and as_sdk.get("title") == cfg.get(
            "foxglovePanelTitle")
        assert as_sdk["config"] == own  # nothing lost, nothing Foxglove does not know
        for path in cfg.get("paths", []):
            topic, _, field = path["value"][1:].partition('".')
            node = fields[topic]
            for f in field.split("."):
                node = node[f]  # every plotted field is in the records
            assert isinstance(node, float)
            named.add(topic)
        for topic in [cfg.get("followTopic"), *cfg.get("disabledTopics", []),
                      *cfg.get("topicColors", {})]:
            if topic is not None:
                assert schemas[topic] == "foxglove.LocationFix"
                named.add(topic)
    assert named and all(t.startswith(f"{prefix}/{vehicle}/") for t in named)
    return named


def test_the_foxglove_layout_is_written_for_the_replay_and_names_what_the_mcap_holds(tmp_path):
    summary = _replay(TLOG, tmp_path / "r", "--mcap", str(tmp_path / "e.mcap"),
                      "--foxglove-layout", str(tmp_path / "layout.json"))
    layout = json.loads((tmp_path / "layout.json").read_text())
    named = _check_layout(layout, tmp_path / "e.mcap", "onboard", summary["vehicle_id"])
    assert summary["foxglove_layout"]["vehicle_id"] == summary["vehicle_id"] == "rudder-boat"
    assert set(summary["foxglove_layout"]["topics"]) == named
    assert {t.rsplit("/", 2)[1] for t in named} == {"est", "fix"}
    # the layout of docs/foxglove.md is this replay's (the simulator's rudder-boat)
    assert LAYOUT.read_text() == (tmp_path / "layout.json").read_text()


def test_a_layout_for_another_vehicle_and_prefix_names_its_own_topics(tmp_path):
    """A config overlay naming the vehicle boat7 under the prefix fleet: no topic of the
    layout names rudder-boat or onboard (the negative control of the id check)."""
    overlay = tmp_path / "boat7.toml"
    overlay.write_text('[vehicle]\nid = "boat7"\n[service.zenoh]\nkey_prefix = "fleet"\n')
    base = REPO / "config" / "rudder-boat.toml"
    _replay(TLOG, tmp_path / "r", "--config", str(base), "--config", str(overlay),
            "--mcap", str(tmp_path / "e.mcap"), "--foxglove-layout", str(tmp_path / "l.json"))
    layout = json.loads((tmp_path / "l.json").read_text())
    _check_layout(layout, tmp_path / "e.mcap", "fleet", "boat7")
    with pytest.raises(AssertionError):
        _check_layout(layout, tmp_path / "e.mcap", "onboard", "rudder-boat")


def test_the_blueboat_csv_gets_a_layout_of_blueboat_ntnu(tmp_path):
    summary = _replay(REPO / "tests/data/csv/blueboat-run.csv", tmp_path / "r", "--config",
                      str(REPO / "config/blueboat-ntnu-csv.toml"), "--mcap",
                      str(tmp_path / "e.mcap"), "--foxglove-layout", str(tmp_path / "l.json"))
    assert summary["vehicle_id"] == "blueboat-ntnu"
    _check_layout(json.loads((tmp_path / "l.json").read_text()), tmp_path / "e.mcap",
                  "onboard", "blueboat-ntnu")


@pytest.mark.data
@pytest.mark.parametrize("name, vehicle", [("ardusub_small_logs/small.tlog", "bluerov2"),
                                           ("ardusub_small_logs/nmea_log.txt", "vehicle")])
def test_real_logs_get_a_layout_of_their_vehicle_and_utc_log_times(shared_data, tmp_path,
                                                                     name, vehicle):
    """bluerov2 (the ESESO's position and surge) and vehicle (an NMEA capture whose
    wall-clock prefixes are local time, 7 h behind its RMC sentences' UTC): each layout's
    every topic is in the MCAP of the same replay, whose log times lie within the log's own
    UTC as read here without our readers (pymavlink's record stamps for the tlog, the RMC
    date and time for the capture)."""
    log = shared_data / name
    summary = _replay(log, tmp_path / "r", "--mcap", str(tmp_path / "e.mcap"),
                      "--foxglove-layout", str(tmp_path / "l.json"))
    assert summary["vehicle_id"] == vehicle and summary["utc"]["utc"]
    _check_layout(json.loads((tmp_path / "l.json").read_text()), tmp_path / "e.mcap",
                  "onboard", vehicle)
    if log.suffix == ".tlog":
        from pymavlink import mavutil

        mlog = mavutil.mavlink_connection(str(log))
        stamps = [m._timestamp for m in iter(mlog.recv_msg, None)]
    else:
        stamps = rmc_times(log)
    times = [lt / 1e9 for *_, lt, _, _ in _read(tmp_path / "e.mcap")[0]]
    assert min(stamps) - 1.0 <= min(times) <= max(times) <= max(stamps) + 1.0


def test_without_the_mcap_package_the_error_names_the_extra(monkeypatch):
    import sys

    from onboard.drivers.mcap_log import mcap_module

    monkeypatch.setitem(sys.modules, "mcap", None)
    monkeypatch.setitem(sys.modules, "mcap.reader", None)
    with pytest.raises(UnreadableLog, match=r"onboard\[mcap\]"):
        mcap_module()


@pytest.mark.data
def test_a_real_ardusub_log_recorded_as_blueos_would_reads_as_its_tlog(shared_data, tmp_path):
    """35912 messages of 60-odd types from a real ArduSub (every enum value known to the
    dialect, so rust-mavlink would have routed them all): the same 14802 samples as the
    tlog, and the same rejections but the 4 frames with a bad CRC, which mavlink-server
    never routes (measured: 8 s to write, 2 s to read)."""
    tlog = shared_data / "ardusub_small_logs" / "small.tlog"
    out = tmp_path / "ardusub.mcap"
    written = blueos_mcap_from_tlog(tlog, out, extras=False)
    assert written["dropped"] == 0
    want = TlogReader(tlog)
    reader = McapReader(out)
    assert list(reader) == list(want)
    assert dict(reader.stats.rejected) == {k: n for k, n in want.stats.rejected.items()
                                           if k != "crc"}
