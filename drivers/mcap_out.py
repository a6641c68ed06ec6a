"""A replay's estimates as MCAP, with the channels and schemas of the live Zenoh records.

``onboard replay LOG --mcap OUT.mcap`` writes, per tick, what the service would publish
on Zenoh (architecture.md §4.4; :mod:`onboard.core.wire`), as BlueOS's recorder would
record it:

=================================  ==============================  =================
channel (topic)                    schema name (``jsonschema``)    message
=================================  ==============================  =================
``<prefix>/<id>/est/<pipeline>``   ``onboard.Estimate.v1``         EstimateRecord
``<prefix>/<id>/fix/<pipeline>``   ``foxglove.LocationFix``        its position
=================================  ==============================  =================

Messages are JSON (message encoding ``json``), log and publish time the tick time ``t``
in ns (the log's clock: seconds since the epoch for a tlog, a DataFlash log with GPS time
or a BlueOS recording). The health record is the live service's (1 Hz, with its rates);
a replay's counterpart is summary.json.

Needs the ``mcap`` package (the ``mcap`` extra).
"""

from __future__ import annotations

import json
import os
from typing import Sequence

import msgspec

from onboard.core import wire
from onboard.core.messages import EstimateRecord

LIBRARY = "onboard replay"
"""The MCAP header's library field."""


class McapRecordWriter:
    """Writes ticks of records into an MCAP file (see the module docstring).

    Parameters:
        path: the file to write.
        prefix: the first key segment (``[service.zenoh] key_prefix``).
        vehicle: the vehicle id (the second).
    """

    def __init__(self, path: str | os.PathLike, prefix: str, vehicle: str) -> None:
        from onboard.drivers.mcap_log import mcap_module

        mcap_module()
        from mcap.writer import Writer

        self.prefix, self.vehicle = prefix, vehicle
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

    def _add(self, topic: str, schema: str, t: float, payload: bytes) -> None:
        t_ns = max(0, round(t * wire.NS_PER_S))
        self.writer.add_message(self._channel(topic, schema), log_time=t_ns, data=payload,
                                publish_time=t_ns)
        self.messages += 1

    def write(self, t: float, records: Sequence[EstimateRecord],
              fixes: Sequence[wire.LocationFix] = ()) -> None:
        """One tick at ``t`` (s): each record on its ``est/`` channel, each fix on its
        ``fix/`` channel."""
        enc = self._enc.encode
        for rec in records:
            self._add(wire.estimate_key(self.prefix, self.vehicle, rec.pipeline),
                      wire.ESTIMATE_SCHEMA, t, enc(rec))
        for fix in fixes:
            self._add(wire.fix_key(self.prefix, self.vehicle, fix.frame_id),
                      wire.LOCATION_FIX_SCHEMA, t, enc(fix))

    def close(self) -> None:
        """Finish the file (summary, index) and close it."""
        try:
            self.writer.finish()
        finally:
            self._f.close()
