"""MCAP fixtures written as BlueOS writes them, from a tlog's MAVLink messages.

The serialization follows the sources, not our reader: rust-mavlink's serde form as
mavlink-bindgen generates it (``parser.rs``: the message enum tagged ``type``, a field
named ``type`` renamed ``mavtype``, enum fields ``{"type": NAME}``, bitmask fields
``{"bits": N}``, arrays as arrays), wrapped by mavlink-server as ``{"header":
{"system_id", "component_id", "sequence", "message_id"}, "message": ...}``
(``src/lib/mavlink_json.rs``) and published on ``mavlink/out``, on
``mavlink/<sys>/<comp>/<MSG>`` and, per field, on ``mavlink/<sys>/<comp>/<MSG>/<field>``
(``src/lib/drivers/zenoh/json.rs``); blueos-recorder keeps the samples whose payload is a
JSON object, one channel per key with the key's dots as schema name and a JSON schema
inferred from the first payload (``src/channel_descriptor.rs``), log time in ns.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path
from typing import Any, Iterator

from pymavlink.dialects.v20 import ardupilotmega as dialect

_TS = struct.Struct(">Q")


def tlog_messages(path: Path) -> Iterator[tuple[int, Any]]:
    """(receive time in us, pymavlink message) of every frame of a tlog that pymavlink
    decodes (a frame it refuses, e.g. a bad CRC, is not one mavlink-server would route)."""
    data = Path(path).read_bytes()
    mav = dialect.MAVLink(None)
    mav.robust_parsing = True
    pos = 0
    while pos + 9 < len(data):
        t_us = _TS.unpack_from(data, pos)[0]
        f = pos + 8
        if data[f] == 0xFD:
            end = f + 12 + data[f + 1] + (13 if data[f + 2] & 1 else 0)
        else:
            end = f + 8 + data[f + 1]
        try:
            msgs = mav.parse_buffer(data[f:end]) or []
        except dialect.MAVError:
            msgs = []
        for msg in msgs:
            if msg.get_type() != "BAD_DATA":
                yield t_us, msg
        pos = end


def to_serde(msg: Any, char_arrays_as_strings: bool = True) -> dict[str, Any] | None:
    """mavlink-server's JSON of one message (None where rust-mavlink could not decode it:
    an enum value with no entry)."""
    fields: dict[str, Any] = {"type": msg.get_type()}
    enums = getattr(msg, "fieldenums_by_name", {})
    displays = getattr(msg, "fielddisplays_by_name", {})
    for name, ftype in zip(msg.fieldnames, msg.fieldtypes):
        value = getattr(msg, name)
        key = "mavtype" if name == "type" else name
        enum = enums.get(name)
        if isinstance(value, (bytes, str)) and ftype == "char":
            raw = value.encode() if isinstance(value, str) else value
            value = raw.decode("utf-8", "replace") if char_arrays_as_strings else list(raw)
        elif enum is not None and not isinstance(value, list):
            if displays.get(name) == "bitmask":
                value = {"bits": value}
            else:
                entry = dialect.enums.get(enum, {}).get(value)
                if entry is None:
                    return None
                value = {"type": entry.name}
        fields[key] = value
    return {"header": {"system_id": msg.get_srcSystem(), "component_id": msg.get_srcComponent(),
                       "sequence": msg.get_seq(), "message_id": msg.get_msgId()},
            "message": fields}


def _schema(value: Any) -> dict[str, Any]:
    """blueos-recorder's create_schema: the JSON schema of one value."""
    if value is None:
        return {"type": "null"}
    if isinstance(value, bool):
        return {"type": "boolean"}
    if isinstance(value, int):
        return {"type": "integer"}
    if isinstance(value, float):
        return {"type": "number"}
    if isinstance(value, str):
        return {"type": "string"}
    if isinstance(value, list):
        return {"type": "array", "items": _schema(value[0]) if value else {}}
    return {"type": "object", "properties": {k: _schema(v) for k, v in sorted(value.items())}}


class BlueosRecorder:
    """An MCAP written as blueos-recorder writes one: :meth:`put` a Zenoh sample (key,
    JSON object) at a log time; non-object payloads are not recorded."""

    def __init__(self, path: Path) -> None:
        from mcap.writer import Writer

        self._f = open(path, "wb")
        self.writer = Writer(self._f)
        self.writer.start(profile="", library="blueos-recorder fixture")
        self.channels: dict[str, int] = {}

    def put(self, key: str, obj: Any, t_ns: int, schema_name: str | None = None) -> None:
        """Record ``obj`` on ``key`` (a JSON object, else skipped as the recorder does)."""
        if not isinstance(obj, dict):
            return
        cid = self.channels.get(key)
        if cid is None:
            sid = self.writer.register_schema(schema_name or key.replace("/", "."), "jsonschema",
                                              json.dumps(_schema(obj)).encode())
            cid = self.channels[key] = self.writer.register_channel(key, "json", sid)
        self.writer.add_message(cid, log_time=t_ns, data=json.dumps(obj).encode(),
                                publish_time=t_ns)

    def put_raw(self, key: str, data: bytes, t_ns: int) -> None:
        """Record raw bytes (a channel as a recorder of ``mavlink_raw/out`` would keep it)."""
        cid = self.channels.get(key)
        if cid is None:
            sid = self.writer.register_schema("mavlink", "", b"")
            cid = self.channels[key] = self.writer.register_channel(key, "application/octet-stream",
                                                                    sid)
        self.writer.add_message(cid, log_time=t_ns, data=data, publish_time=t_ns)

    def close(self) -> None:
        """Finish the file."""
        self.writer.finish()
        self._f.close()


def mavlink_server_samples(obj: dict[str, Any]) -> Iterator[tuple[str, Any]]:
    """The Zenoh samples mavlink-server publishes for one message: ``mavlink/out``, the
    per-message key and one key per field."""
    h, m = obj["header"], obj["message"]
    topic = f"mavlink/{h['system_id']}/{h['component_id']}/{m['type']}"
    yield "mavlink/out", obj
    yield topic, obj
    for name, value in m.items():
        yield f"{topic}/{name}", value


def blueos_mcap_from_tlog(tlog: Path, out: Path, *, raw: bool = False,
                          extras: bool = True) -> dict[str, int]:
    """Write ``out`` as BlueOS would record the MAVLink of ``tlog`` (``raw``: the frames on
    ``mavlink_raw/out`` too); ``extras`` adds what a real recording has beside it: an
    unknown message, an unknown field, another service's channel and the service's own
    estimates. Returns counts of what was written (``messages``, ``dropped``: messages
    rust-mavlink would not decode, and the extras)."""
    rec = BlueosRecorder(out)
    counts = {"messages": 0, "dropped": 0, "unknown_message": 0, "unknown_field": 0,
              "other": 0, "onboard": 0}
    first = True
    for t_us, msg in tlog_messages(tlog):
        t_ns = t_us * 1000
        if raw:
            rec.put_raw("mavlink_raw/out", msg.get_msgbuf(), t_ns)
        obj = to_serde(msg)
        if obj is None:
            counts["dropped"] += 1
            continue
        if extras and msg.get_type() == "ATTITUDE" and first:
            obj["message"]["future_field"] = 1.5  # a newer dialect's field
            counts["unknown_field"] += 1
            first = False
        for key, value in mavlink_server_samples(obj):
            rec.put(key, value, t_ns)
        counts["messages"] += 1
        if extras and counts["messages"] % 500 == 1:
            future = {"header": dict(obj["header"], message_id=65000),
                      "message": {"type": "FUTURE_MESSAGE", "x": 1}}
            rec.put("mavlink/1/1/FUTURE_MESSAGE", future, t_ns)
            rec.put("cockpit/widgets/state", {"visible": True}, t_ns)
            rec.put("onboard/boat1/est/kf", {"schema": 1, "vehicle": "boat1", "pipeline": "kf",
                                             "t": t_us / 1e6, "values": {"speed": 1.0}},
                    t_ns, schema_name="onboard.Estimate.v1")
            counts["unknown_message"] += 1
            counts["other"] += 1
            counts["onboard"] += 1
    rec.close()
    return counts
