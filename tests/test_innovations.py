"""The innovation summaries per channel and per source (onboard/monitor/innovations.py)."""

from __future__ import annotations

import msgspec

from onboard.core.messages import HEALTH_SCHEMA_VERSION, HealthRecord, Innovation
from onboard.monitor.innovations import InnovationMonitor


def _rec(t: float, source: str, nis: float, gate: float = 10.0) -> Innovation:
    return Innovation(channel="gnss_pos", t=t, z=(1.0,), S=(1.0,), nis=nis, dof=1,
                      gate=gate, accepted=nis < gate, reason="" if nis < gate else "gate",
                      source=source)


def test_one_source_gives_the_channel_summary_alone() -> None:
    m = InnovationMonitor()
    m.add("eseso", [_rec(k, "gps1", 1.0) for k in range(10)])
    ch = m.snapshot()["eseso"]["gnss_pos"]
    assert ch.n == 10 and ch.by_source == {}


def test_two_receivers_are_summarized_apart_and_together() -> None:
    """Two GNSS receivers: a good one (NIS 1) and a bad one (NIS 4, then a rejection);
    the channel's summary mixes them, ``by_source`` tells them apart."""
    m = InnovationMonitor()
    m.add("eseso", [_rec(k, "gps1", 1.0) for k in range(5)])  # before the second source
    m.add("eseso", [_rec(5 + k, "gps2" if k % 2 else "gps1", 4.0 if k % 2 else 1.0)
                    for k in range(10)])
    m.add("eseso", [_rec(20.0, "gps2", 30.0)])
    ch = m.snapshot()["eseso"]["gnss_pos"]
    assert ch.n == 16 and ch.rejected == 1
    one, two = ch.by_source["gps1"], ch.by_source["gps2"]
    assert (one.n, one.rejected, one.nis_mean) == (10, 0, 1.0)
    assert (two.n, two.rejected, two.nis_mean) == (6, 1, 4.0)
    assert two.test_ratio == 3.0 and two.reasons == {"gate": 1}
    assert one.test_ratio_max == 0.1 and two.test_ratio_max == 3.0
    # the largest test ratio starts afresh at each record, per source too
    again = m.snapshot()["eseso"]["gnss_pos"]
    assert again.by_source["gps2"].test_ratio_max == 0.0


def test_the_health_record_carries_the_sources_and_round_trips() -> None:
    m = InnovationMonitor()
    m.add("kf", [_rec(k, f"gps{k % 2}", 1.0) for k in range(4)])
    h = HealthRecord(vehicle="v", t=1.0, innovations=m.snapshot())
    assert h.schema == HEALTH_SCHEMA_VERSION == 3
    back = msgspec.json.decode(msgspec.json.encode(h), type=HealthRecord)
    assert back == h and set(back.innovations["kf"]["gnss_pos"].by_source) == {"gps0", "gps1"}
