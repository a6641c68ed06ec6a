"""A replay's estimates as MCAP, with the channels and schemas of the live Zenoh records.

``onboard replay LOG --mcap OUT.mcap`` writes, per tick, what the service would publish
on Zenoh (architecture.md §4.4; :mod:`onboard.core.wire`), as BlueOS's recorder would
record it:

=================================  ==============================  =================
channel (topic)                    schema name (``jsonschema``)    message
=================================  ==============================  =================
``<prefix>/<id>/est/<pipeline>``   ``onboard.Estimate.v2``         EstimateRecord
``<prefix>/<id>/fix/<pipeline>``   ``foxglove.LocationFix``        its position
=================================  ==============================  =================

Messages are JSON (message encoding ``json``). Log and publish time are the tick time in
UTC, ns since the epoch, wherever the log knows UTC (:mod:`drivers.logclock`: a tlog's
record stamps, a DataFlash log's GPS time, a CSV's POSIX time column, ...), and so is each
LocationFix's ``timestamp``; the records keep ``t`` and ``t_sensor`` on the log's clock, as
the live service's keep its own. A log without UTC (time since boot and no GPS time) is
written on its own clock, seconds since boot or since its start: Foxglove shows them as
1970-01-01. Either way the file's metadata record ``onboard-clock`` says which
(``utc``: ``"true"`` or ``"false"``; ``source``: the log's clock in words; ``start``: the
first tick in ISO 8601 UTC, or empty). The health record is the live service's (1 Hz,
with its rates); a replay's counterpart is summary.json.

Needs the ``mcap`` package (the ``mcap`` extra).
"""

from __future__ import annotations

import json
import os
from typing import Sequence

import msgspec

from onboard.core import wire
from onboard.core.messages import EstimateRecord
from onboard.drivers.logclock import LogClock, iso8601

LIBRARY = "onboard replay"
"""The MCAP header's library field."""
CLOCK_METADATA = "onboard-clock"
"""The name of the metadata record that says how the file is stamped."""
NO_CLOCK = "no UTC: the log's own clock (none was given to the writer)"
"""The clock's words when the writer is given none."""


class McapRecordWriter:
    """Writes ticks of records into an MCAP file (see the module docstring).

    Parameters:
        path: the file to write.
        prefix: the first key segment (``[service.zenoh] key_prefix``).
        vehicle: the vehicle id (the second).
        clock: the log's clock (:func:`drivers.logclock.log_clock`); None: a log without
            UTC, written on its own clock.
    """

    def __init__(self, path: str | os.PathLike, prefix: str, vehicle: str,
                 clock: LogClock | None = None) -> None:
        from onboard.drivers.mcap_log import mcap_module

        mcap_module()
        from mcap.writer import Writer

        self.prefix, self.vehicle = prefix, vehicle
        self.clock = clock if clock is not None else LogClock(NO_CLOCK)
        self._start: float | None = None
        self._f = open(path, "wb")
        self.writer = Writer(self._f)
        self.writer.start(profile="", library=LIBRARY)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._enc = msgspec.json.Encoder()
        self.messages = 0

    def _channel(self, topic: str, schema: str) -> int:
        cid = self._channels.get(topic)
        if cid is None:
            sid = self._schemas.get(schema)
            if sid is None:
                data = json.dumps(wire.json_schema(wire.SCHEMAS[schema])).encode()
                sid = self._schemas[schema] = self.writer.register_schema(
                    schema, "jsonschema", data)
            cid = self._channels[topic] = self.writer.register_channel(topic, "json", sid)
        return cid

    def _add(self, topic: str, schema: str, t_ns: int, payload: bytes) -> None:
        self.writer.add_message(self._channel(topic, schema), log_time=t_ns, data=payload,
                                publish_time=t_ns)
        self.messages += 1

    def write(self, t: float, records: Sequence[EstimateRecord],
              fixes: Sequence[wire.LocationFix] = ()) -> None:
        """One tick at ``t`` (s, the log's clock): each record on its ``est/`` channel,
        each fix on its ``fix/`` channel, stamped in UTC where the log knows it."""
        if self._start is None:
            self._start = t
        t_out = self.clock.to_utc(t)
        t_ns = max(0, round((t if t_out is None else t_out) * wire.NS_PER_S))
        if t_out is not None and t_out != t:
            stamp = wire.Time(*divmod(t_ns, wire.NS_PER_S))
            fixes = [msgspec.structs.replace(f, timestamp=stamp) for f in fixes]
        enc = self._enc.encode
        for rec in records:
            self._add(wire.estimate_key(self.prefix, self.vehicle, rec.pipeline),
                      wire.ESTIMATE_SCHEMA, t_ns, enc(rec))
        for fix in fixes:
            self._add(wire.fix_key(self.prefix, self.vehicle, fix.frame_id),
                      wire.LOCATION_FIX_SCHEMA, t_ns, enc(fix))

    def close(self) -> None:
        """Write the ``onboard-clock`` metadata, finish the file (summary, index) and close
        it."""
        try:
            start = self.clock.to_utc(self._start) if self._start is not None else None
            self.writer.add_metadata(CLOCK_METADATA, {
                "utc": "true" if self.clock.utc else "false", "source": self.clock.source,
                "start": iso8601(start) if start is not None else ""})
            self.writer.finish()
        finally:
            self._f.close()
