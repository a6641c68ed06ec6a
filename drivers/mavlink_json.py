"""MAVLink messages in rust-mavlink's serde JSON, as BlueOS's mavlink-server publishes them.

mavlink-server (bluerobotics/mavlink-server ``src/lib/drivers/zenoh/json.rs``,
``src/lib/mavlink_json.rs``) publishes every message it routes on ``mavlink/out`` and on
``mavlink/<sys>/<comp>/<MSG>`` as::

    {"header": {"system_id": 1, "component_id": 1, "sequence": 42, "message_id": 30},
     "message": {"type": "ATTITUDE", "time_boot_ms": 1234, "roll": 0.01, ...}}

rust-mavlink's serde form (mavlink-bindgen ``parser.rs``): the message enum is tagged by
``type``; a field named ``type`` in the XML is ``mavtype`` (HEARTBEAT's and every other);
an enum field is ``{"type": "<ENTRY NAME>"}``; a bitmask field ``{"bits": N}``; arrays are
JSON arrays, char arrays arrays of byte values or (newer versions, ``CharArray``) strings.
mavlink-server writes it with json5, whose non-finite floats are ``NaN`` / ``Infinity``
(Python's :mod:`json` reads them).

:func:`frame_from_json` turns one such object back into the MAVLink 2 frame it came from
(same system, component and sequence; pymavlink's ``ardupilotmega`` dialect), so that a
recording of it reads exactly as a tlog of the frames. What cannot be converted is not
guessed: an unknown message, a value of the wrong kind or an unknown enum name raise
:class:`JsonFrameError` with the reason; fields the dialect does not have are ignored and
counted, fields it has that are missing are zero (as MAVLink 2 does for truncated
extensions) and counted.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as _dialect

RENAMED = {"type": "mavtype"}
"""XML field name -> rust-mavlink's serde name (``type`` is a Rust keyword)."""

ENUM_VALUES: dict[str, int] = {entry.name: value for enum in _dialect.enums.values()
                               for value, entry in enum.items() if not entry.name.endswith("_ENUM_END")}
"""Every enum entry name of the dialect -> its value (the names are unique across enums)."""

MESSAGES: dict[str, type] = {cls.msgname: cls for cls in _dialect.mavlink_map.values()}
"""Message name -> pymavlink message class."""


class JsonFrameError(ValueError):
    """A JSON message that cannot be turned into a frame; ``reason`` is a short code
    (``bad_json``, ``no_header``, ``unknown_message``, ``bad_value``, ``unknown_enum``)."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason


@dataclass
class JsonFrame:
    """A frame rebuilt from JSON, with what the conversion tolerated."""

    frame: bytes
    name: str
    unknown_fields: int = 0
    """Fields in the JSON that the dialect's message does not have (ignored)."""
    missing_fields: int = 0
    """Fields of the dialect's message absent from the JSON (zero)."""


def parse(payload: bytes | str) -> dict[str, Any]:
    """The JSON object of one sample (json5's ``NaN``/``Infinity`` accepted)."""
    try:
        obj = json.loads(payload)
    except (ValueError, UnicodeDecodeError) as err:
        raise JsonFrameError("bad_json", str(err)[:80]) from None
    if not isinstance(obj, dict):
        raise JsonFrameError("bad_json", "not a JSON object")
    return obj


def _scalar(value: Any, field: str) -> int | float:
    """A number from its serde form: a number, ``{"type": NAME}`` (an enum entry, or
    ``{"bits": N}``, bit flags)."""
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, (int, float)):
        return value
    if isinstance(value, dict):
        if "bits" in value and isinstance(value["bits"], int):
            return value["bits"]
        name = value.get("type")
        if isinstance(name, str):
            if name in ENUM_VALUES:
                return ENUM_VALUES[name]
            raise JsonFrameError("unknown_enum", f"{field}: {name}")
    if isinstance(value, str) and value in ENUM_VALUES:
        return ENUM_VALUES[value]
    raise JsonFrameError("bad_value", f"{field}: {str(value)[:40]}")


def _field(value: Any, ftype: str, length: int, field: str) -> Any:
    """The pymavlink argument of one field from its serde value."""
    if ftype == "char":
        if isinstance(value, str):
            return value.encode("utf-8", "replace")
        if isinstance(value, list) and all(isinstance(b, int) and 0 <= b < 256 for b in value):
            return bytes(value).split(b"\0", 1)[0]
        raise JsonFrameError("bad_value", f"{field}: not a string")
    if length:
        if not isinstance(value, list):
            raise JsonFrameError("bad_value", f"{field}: not an array")
        out = [_scalar(v, field) for v in value[:length]]
        return out + [0] * (length - len(out))
    v = _scalar(value, field)
    if ftype in ("float", "double"):
        return float(v)
    if isinstance(v, float):
        if not v.is_integer():
            raise JsonFrameError("bad_value", f"{field}: {v} is not an integer")
        v = int(v)
    return v


def frame_from_json(obj: dict[str, Any]) -> JsonFrame:
    """The MAVLink 2 frame of one mavlink-server JSON object (see the module docstring);
    raises :class:`JsonFrameError`."""
    header, message = obj.get("header"), obj.get("message")
    if not isinstance(header, dict) or not isinstance(message, dict):
        raise JsonFrameError("no_header", "expected {header, message}")
    name = message.get("type")
    cls = MESSAGES.get(name) if isinstance(name, str) else None
    if cls is None:
        raise JsonFrameError("unknown_message", str(name)[:40])
    try:
        sysid, compid = int(header["system_id"]), int(header["component_id"])
        seq = int(header.get("sequence", 0))
    except (KeyError, TypeError, ValueError):
        raise JsonFrameError("no_header", "system_id/component_id") from None
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths))
    types = dict(zip(cls.fieldnames, cls.fieldtypes))
    known = {RENAMED.get(f, f) for f in cls.fieldnames} | {"type"}
    args: dict[str, Any] = {}
    missing = 0
    for f in cls.fieldnames:
        key = RENAMED.get(f, f)
        if key not in message and f not in message:
            missing += 1
            length = lengths.get(f, 0)
            args[f] = b"" if types[f] == "char" else [0] * length if length else 0
            continue
        args[f] = _field(message.get(key, message.get(f)), types[f], lengths.get(f, 0), f)
    mav = _dialect.MAVLink(None, srcSystem=sysid & 0xFF, srcComponent=compid & 0xFF)
    mav.seq = seq & 0xFF
    try:
        frame = bytes(cls(**args).pack(mav))
    except Exception as err:  # noqa: BLE001 - struct.error and friends: a value out of range
        raise JsonFrameError("bad_value", f"{name}: {err}"[:80]) from None
    unknown = sum(1 for k in message if k not in known)
    return JsonFrame(frame, name, unknown_fields=unknown, missing_fields=missing)

