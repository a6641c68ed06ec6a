"""MCAP recordings: BlueOS's (blueos-recorder) MAVLink channels, read as a tlog.

BlueOS 1.5 records every Zenoh sample whose encoding is ``application/json[;<schema>]``
and whose payload is a JSON object into MCAP (bluerobotics/blueos-recorder
``src/service.rs``, ``src/channel_descriptor.rs``): a channel per Zenoh key, message
encoding ``json``, log time the recorder's wall clock (ns since the epoch). mavlink-server
publishes every MAVLink message there as rust-mavlink's serde JSON
(:mod:`drivers.mavlink_json`) on ``mavlink/<sys>/<comp>/<MSG>`` and ``mavlink/out``, and
each object-valued field on ``mavlink/<sys>/<comp>/<MSG>/<field>`` too.

:class:`McapReader` turns the MAVLink messages back into frames, in log-time order, each
stamped with its log time, and decodes them exactly as :class:`drivers.tlog.TlogReader`
decodes a tlog (same samples, same rejections). Which channels carry the MAVLink:

1. raw frames where present: a channel whose topic ends in ``mavlink_raw/out`` and whose
   message encoding is not JSON (one or more whole frames per message);
2. else the per-message channels ``mavlink/<sys>/<comp>/<MSG>``;
3. else ``mavlink/out`` (every message on one channel).

Each message is taken from one of them only. The other channels' messages are counted in
``stats.skipped`` by reason: ``duplicate`` (``mavlink/out`` or field channels beside the
per-message ones), ``onboard_record`` (the service's own estimates and health,
``onboard/...``), ``other_channel`` (video, other services). Messages of the chosen
channels that cannot be read are counted in ``stats.rejected``: ``mcap:bad_json``,
``mcap:unknown_message``, ``mcap:unknown_enum``, ``mcap:bad_value``, ``mcap:no_header``,
``mcap:raw_garbage``; fields ignored or missing in otherwise good messages as
``mcap:unknown_field`` and ``mcap:missing_field`` (the message is used).

An MCAP with no MAVLink but the service's records (``onboard replay --mcap`` output, or a
recording of the service alone) has no sensor data to replay: :class:`UnreadableLog` says
so and lists its channels.
"""

from __future__ import annotations

import os
import re
import struct
from collections import Counter
from pathlib import Path
from typing import Iterator

from onboard.drivers.base import MappedLog, ReadStats, UnreadableLog
from onboard.drivers.mavlink import select, wanted_types
from onboard.drivers.mavlink_frame import header_at
from onboard.drivers.mavlink_json import JsonFrameError, frame_from_json, parse
from onboard.drivers.tlog import TlogReader
from onboard.core.messages import Sample

MISSING_MCAP = "reading or writing MCAP needs the mcap package: pip install 'onboard[mcap]'"
PER_MESSAGE = re.compile(r"^mavlink/(\d+)/(\d+)/([A-Z0-9_]+)$")
"""mavlink-server's per-message topic ``mavlink/<sys>/<comp>/<MSG>``."""
FIELD_TOPIC = re.compile(r"^mavlink/\d+/\d+/[A-Z0-9_]+/.+$")
"""mavlink-server's per-field topic ``mavlink/<sys>/<comp>/<MSG>/<field>``."""
ALL_MESSAGES = "mavlink/out"
RAW_SUFFIX = "mavlink_raw/out"
ONBOARD_SCHEMA_PREFIXES = ("onboard.", "foxglove.LocationFix")
_TS = struct.Struct(">Q")


def mcap_module():
    """The ``mcap`` package, or :class:`UnreadableLog` naming the extra to install."""
    try:
        import mcap.reader  # noqa: F401
        import mcap.writer  # noqa: F401
    except ImportError:
        raise UnreadableLog(MISSING_MCAP) from None
    import mcap

    return mcap


def _is_json(encoding: str) -> bool:
    return encoding.lower() in ("json", "application/json")


class McapReader:
    """Samples of an MCAP recording's MAVLink, in time order (see the module docstring).

    Raises :class:`UnreadableLog` at construction when the file cannot be read, is not
    MCAP, or has no MAVLink (saying what it has instead). ``stats`` is reset at each
    iteration, like the tlog reader's, with the MCAP's own skips added.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self.stats = ReadStats()
        mcap_module()
        self.channels = self._channels()
        self.source = self._choose()

    def _open(self):
        from mcap.reader import make_reader

        try:
            f = open(self.path, "rb")
        except OSError as e:
            raise UnreadableLog(f"{self.path}: {e.strerror or e}") from e
        return f, make_reader(f)

    def _channels(self) -> dict[int, tuple[str, str, str, int]]:
        """Channel id -> (topic, message encoding, schema name, message count)."""
        f, reader = self._open()
        try:
            summary = reader.get_summary()
            counts: Counter[int] = Counter()
            if summary is not None and summary.statistics is not None:
                counts.update(summary.statistics.channel_message_counts)
                chans, schemas = summary.channels, summary.schemas
            else:  # no summary section (a recording cut short): one pass
                chans, schemas = {}, {}
                for schema, channel, _ in reader.iter_messages(log_time_order=False):
                    chans[channel.id] = channel
                    if schema is not None:
                        schemas[schema.id] = schema
                    counts[channel.id] += 1
        except Exception as err:  # noqa: BLE001 - mcap raises its own errors on bad files
            raise UnreadableLog(f"{self.path}: not a readable MCAP file ({err})") from None
        finally:
            f.close()
        return {cid: (c.topic, c.message_encoding,
                      schemas[c.schema_id].name if c.schema_id in schemas else "", counts[cid])
                for cid, c in chans.items()}

    def _choose(self) -> str:
        """Which MAVLink the file has: ``raw``, ``per_message`` or ``all`` (see the
        module docstring); UnreadableLog when none."""
        topics = [(t, enc, n) for t, enc, _, n in self.channels.values()]
        if any(t.endswith(RAW_SUFFIX) and not _is_json(enc) and n for t, enc, n in topics):
            return "raw"
        if any(PER_MESSAGE.match(t) and n for t, _, n in topics):
            return "per_message"
        if any(t == ALL_MESSAGES and n for t, _, n in topics):
            return "all"
        ours = sorted(t for t, _, schema, _ in self.channels.values()
                      if schema.startswith(ONBOARD_SCHEMA_PREFIXES))
        listing = ", ".join(sorted(t for t, _, _, _ in self.channels.values())[:12]) or "none"
        if ours:
            raise UnreadableLog(
                f"{self.path}: an MCAP of onboard estimates ({len(ours)} channel(s): "
                f"{', '.join(ours[:6])}{', ...' if len(ours) > 6 else ''}), written by "
                "`onboard replay --mcap` or recorded from the service: it holds estimates, "
                "not sensor data, so there is nothing to replay; open it in Foxglove "
                "(docs/foxglove.md)")
        raise UnreadableLog(f"{self.path}: an MCAP with no MAVLink channel (mavlink/<sys>/"
                            f"<comp>/<MSG>, mavlink/out or mavlink_raw/out); channels: {listing}")

    def _skip_reason(self, topic: str, encoding: str, schema: str) -> str | None:
        """Why a channel's messages are not read (None: they are)."""
        src = self.source
        if src == "raw" and topic.endswith(RAW_SUFFIX) and not _is_json(encoding):
            return None
        if src == "per_message" and PER_MESSAGE.match(topic) and _is_json(encoding):
            return None
        if src == "all" and topic == ALL_MESSAGES and _is_json(encoding):
            return None
        if topic.startswith("mavlink") or FIELD_TOPIC.match(topic):
            return "duplicate"
        if schema.startswith(ONBOARD_SCHEMA_PREFIXES):
            return "onboard_record"
        return "other_channel"

    def _frames(self, skipped: Counter[str], bad: Counter[str]) -> Iterator[tuple[int, bytes]]:
        """(log time in us, frame) of the chosen MAVLink, in log-time order."""
        f, reader = self._open()
        skip = {cid: self._skip_reason(t, enc, schema)
                for cid, (t, enc, schema, _) in self.channels.items()}
        raw = self.source == "raw"
        try:
            for _, channel, msg in reader.iter_messages(log_time_order=True):
                why = skip.get(channel.id, "other_channel")
                if why is not None:
                    skipped[why] += 1
                    continue
                t_us = msg.log_time // 1000
                if raw:
                    yield from ((t_us, fr) for fr in _split_frames(msg.data, bad))
                    continue
                try:
                    jf = frame_from_json(parse(msg.data))
                except JsonFrameError as err:
                    bad[err.reason] += 1
                    continue
                if jf.unknown_fields:
                    bad["unknown_field"] += jf.unknown_fields
                if jf.missing_fields:
                    bad["missing_field"] += jf.missing_fields
                yield t_us, jf.frame
        finally:
            f.close()

    def __iter__(self) -> Iterator[Sample]:
        skipped: Counter[str] = Counter()
        bad: Counter[str] = Counter()
        data = b"".join(_TS.pack(t) + fr for t, fr in self._frames(skipped, bad))
        inner = _TlogBytes(self.path, data)
        try:
            yield from inner
        finally:
            stats = self.stats = inner.stats
            stats.skipped.update(skipped)
            for why, n in bad.items():
                stats.rejected[f"mcap:{why}"] += n


def _split_frames(data: bytes, bad: Counter[str]) -> Iterator[bytes]:
    """The whole MAVLink frames of one raw message (bytes after the last one counted as
    ``raw_garbage``)."""
    pos, n = 0, len(data)
    while pos < n:
        h = header_at(data, pos, n)
        if h is None or h[-1] > n:
            bad["raw_garbage"] += 1
            return
        yield bytes(data[pos:h[-1]])
        pos = h[-1]


class _TlogBytes(TlogReader):
    """A :class:`TlogReader` over tlog records held in memory."""

    def __init__(self, path: Path, data: bytes) -> None:
        self.path = path
        self.stats = ReadStats()
        self._specs = select(None)
        self._want = wanted_types(None)
        self._verify_all = True
        self._include_gcs = False
        self._data = data
        self._first = 0

    def _open(self) -> MappedLog:
        return MappedLog.of_bytes(self._data, self.path)
