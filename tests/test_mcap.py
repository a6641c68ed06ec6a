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
    assert set(by_schema) == {"onboard.Estimate.v1", "foxglove.LocationFix"}
    recs = [msgspec.json.decode(d, type=EstimateRecord) for _, d in by_schema["onboard.Estimate.v1"]]
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


def test_the_foxglove_layout_names_channels_and_fields_the_replay_writes(tmp_path):
    out = tmp_path / "estimates.mcap"
    _replay(TLOG, tmp_path / "r", "--mcap", str(out))
    payloads: dict[str, dict] = {}  # per topic, every field any of its records had
    for topic, _, _, _, data in _messages(out):
        merged = payloads.setdefault(topic, {})
        for k, v in json.loads(data).items():
            if isinstance(v, dict):
                merged.setdefault(k, {}).update(v)
            else:
                merged[k] = v
    layout = json.loads(LAYOUT.read_text())
    panels = layout["configById"]
    assert {k.split("!")[0] for k in panels} == {"Map", "Plot"}
    for cfg in panels.values():
        for path in cfg.get("paths", []):
            topic, _, fields = path["value"][1:].partition('".')
            node = payloads[topic]
            for f in fields.split("."):
                node = node[f]  # every plotted field exists in the records
            assert isinstance(node, float)
        for topic in [cfg.get("followTopic"), *cfg.get("disabledTopics", [])]:
            assert topic is None or topic in payloads


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
