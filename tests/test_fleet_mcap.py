"""``onboard fleet --mcap``: the file opens in Foxglove (docs/fleet.md, "The contract"):
every channel's ``jsonschema`` is one Foxglove's MCAP reader parses, and the messages are
stamped with the grid's UTC in nanoseconds since the epoch."""

from __future__ import annotations

import json

import msgspec
import pytest

from onboard.fleet.service import FleetService
from tests.helpers.fleet_scenarios import UTC0, fleet
from tests.helpers.foxglove_schema import foxglove_parses


def test_the_mcaps_schemas_are_ones_foxglove_reads_and_its_times_are_the_grids(tmp_path):
    reader = pytest.importorskip("mcap.reader")
    f = fleet("eddy", seed=21, vehicles=3, duration_s=120.0, rate_hz=1.0)
    service = FleetService(mcap=tmp_path / "field.mcap")
    enc = msgspec.json.Encoder()
    for i in range(len(f.t)):
        service.feed(enc.encode(f.record(i)), "application/json;onboard.Estimate.v2")
    grid = service.step(refit=True)
    service.close()
    with open(tmp_path / "field.mcap", "rb") as fh:
        r = reader.make_reader(fh)
        summary = r.get_summary()
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            assert schema.encoding == "jsonschema" and channel.message_encoding == "json"
            foxglove_parses(json.loads(schema.data), schema.name)
        times = [(ch.topic, m.log_time, m.publish_time) for _, ch, m in r.iter_messages()]
    t_ns = round(grid.utc * 1e9)
    assert grid.utc == pytest.approx(UTC0 + 119.0)
    assert times == [("onboard/fleet/current/grid", t_ns, t_ns),
                     ("onboard/fleet/current/geojson", t_ns, t_ns)]
