"""Teledyne PD6: parser, capture reader and encoders (no real PD6 capture is available;
the tests use the encoders and hand-written lines in the RDI manual's layout)."""

from __future__ import annotations

import calendar
import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from onboard.drivers.base import UnreadableLog
from onboard.drivers.pd6 import (
    Pd6LogReader,
    Pd6Parser,
    encode_bd,
    encode_be,
    encode_bi,
    encode_bs,
    encode_ensemble,
    encode_sa,
    encode_ts,
    parse_ts_time,
)
from onboard.drivers.textlog import open_text_log
from onboard.core.messages import Altitude, Attitude, Depth, DvlVelocity, VelocityOverGround

T0 = float(calendar.timegm((2024, 6, 1, 12, 30, 15))) + 0.25


def test_bi_example_from_the_brief():
    p = Pd6Parser(velocity_frame="instrument")
    (v,) = p.feed_line(":BI,+00012,-00034,+00005,+00000,A", 3.0)
    assert isinstance(v, DvlVelocity) and v.valid and v.track == "bottom"
    assert (v.vx, v.vy, v.vz) == (0.012, 0.034, -0.005)  # Z up -> down, Y flipped
    assert v.fom_mps == 0.0 and v.t == 3.0


def test_ship_frame_is_the_default_and_maps_to_frd():
    p = Pd6Parser()
    (v,) = p.feed_line(":BS,-00200,+01000,-00050,A", 1.0)
    assert (v.vx, v.vy, v.vz) == (1.0, -0.2, 0.05)
    assert p.feed_line(":BI,+00012,-00034,+00005,+00000,A", 1.0) == []
    assert p.stats.by_type["ignored"] == 1  # the other frame is not fused twice


def test_bad_status_and_missing_components_give_invalid_zero_velocity():
    p = Pd6Parser()
    (a,) = p.feed_line(":BS,+00100,+00200,+00000,V", 0.0)
    (b,) = p.feed_line(":BS,-32768,-32768,-32768,A", 0.0)
    for v in (a, b):
        assert not v.valid and (v.vx, v.vy, v.vz) == (0.0, 0.0, 0.0)
    assert p.feed_line(":BE,-32768,+00001,+00000,A", 0.0) == []
    assert p.stats.rejected["invalid"] == 1


def test_water_track():
    p = Pd6Parser()
    (w,) = p.feed(encode_bs(0.3, 0.1, 0.0, water=True), 0.0)
    assert w.track == "water" and w.vx == pytest.approx(0.3)


def test_ensemble_round_trip_with_instrument_time():
    data = encode_ensemble(T0, 1.2, -0.3, 0.05, depth_m=42.5, altitude_m=7.25, roll_rad=0.05,
                           pitch_rad=-0.02, heading_rad=2.0, temperature_c=8.5)
    p = Pd6Parser(time_base="instrument")
    out = p.feed(data, 0.0)
    kinds = [type(s).__name__ for s in out]
    assert kinds == ["Attitude", "Depth", "DvlVelocity", "VelocityOverGround", "Altitude"]
    assert all(s.t == pytest.approx(T0) for s in out)
    att, dep, vel, vog, alt = out
    assert isinstance(att, Attitude) and att.yaw_rad == pytest.approx(2.0, abs=1e-3)
    assert att.roll_rad == pytest.approx(0.05, abs=1e-3)
    assert isinstance(dep, Depth) and dep.depth_m == 42.5 and dep.temperature_c == 8.5
    assert (vel.vx, vel.vy, vel.vz) == (1.2, -0.3, 0.05)
    c, s = math.cos(2.0), math.sin(2.0)
    assert isinstance(vog, VelocityOverGround)
    assert vog.v_north_mps == pytest.approx(1.2 * c + 0.3 * s, abs=1e-3)
    assert vog.v_east_mps == pytest.approx(1.2 * s - 0.3 * c, abs=1e-3)
    assert isinstance(alt, Altitude) and alt.altitude_m == 7.25


def test_individual_encoders_round_trip():
    p = Pd6Parser(velocity_frame="instrument")
    (v,) = p.feed(encode_bi(0.5, 0.25, -0.125, error_mps=0.004), 0.0)
    assert (v.vx, v.vy, v.vz, v.fom_mps) == (0.5, 0.25, -0.125, 0.004)
    (g,) = p.feed(encode_be(0.1, 0.2, 0.0), 0.0)
    assert (g.v_north_mps, g.v_east_mps) == (0.1, 0.2)
    (a,) = p.feed(encode_bd(3.5), 0.0)
    assert a.altitude_m == 3.5
    (d,) = p.feed(encode_ts(T0, 12.0), 0.0)
    assert d.depth_m == 12.0 and p.instrument_time == pytest.approx(T0)
    (s,) = p.feed(encode_sa(0.0, 0.0, 6.2), 0.0)
    assert s.yaw_rad == pytest.approx(6.2, abs=1e-3)
    assert parse_ts_time("24060112301525") == pytest.approx(T0)


def test_untimed_garbage_and_malformed_lines_are_counted():
    p = Pd6Parser(time_base="instrument")
    out = p.feed(b":BS,+00100,+00200,+00000,A\r\n"   # before any TS: untimed
                 b"\x00\xffnoise\r\n"
                 b"xx:BD,+0.00,+0.00,+0.00,0004.50,000.00\r\n"  # garbage prefix, then untimed
                 b":BS,+001a0,+00200,+00000,A\r\n"
                 b":BS,+00100,+00200,A\r\n"
                 b":BS,+00100,+00200,+00000,X\r\n"
                 b":TS,2406011230152,35.0,+10.0,12.0,1500.0,000\r\n"
                 b":ZZ,1,2\r\n" + b"9" * 500 + b"\r\n", 0.0)
    assert out == []
    r = p.stats.rejected
    assert r == {"untimed": 2, "garbage": 2, "malformed": 4, "unsupported": 1, "too_long": 1}


def test_capture_reader_and_sniffing(tmp_path: Path):
    path = tmp_path / "pd6.txt"
    path.write_bytes(b"".join(encode_ensemble(T0 + 0.2 * k, 1.0, 0.0, 0.0, depth_m=5.0)
                              for k in range(10)))
    r = open_text_log(path)
    assert isinstance(r, Pd6LogReader)
    out = list(r)
    assert len(out) == 50 and out[-1].t - out[0].t == pytest.approx(1.8)
    assert all(a.t <= b.t for a, b in zip(out, out[1:]))
    with pytest.raises(UnreadableLog):
        Pd6LogReader(tmp_path / "missing.txt")


@settings(max_examples=200, deadline=None)
@given(st.lists(st.one_of(
    st.binary(max_size=60),
    st.builds(lambda k, vals, s: f":{k},{','.join(vals)},{s}".encode(),
              st.sampled_from(["BI", "BS", "BE", "BD", "TS", "SA", "WI", "WS", "WE", "WD"]),
              st.lists(st.sampled_from(["+00012", "-32768", "+1.5", "", "abc", "24060112301525",
                                        "0004.50"]), max_size=6),
              st.sampled_from(["A", "V", "", "x"])),
), max_size=8))
def test_property_every_line_is_a_sample_or_a_rejection(lines):
    p = Pd6Parser()
    for ln in lines:
        if b"\n" in ln or b"\r" in ln or not ln.decode("ascii", "replace").strip():
            continue  # blank lines (any Unicode whitespace) are skipped, not records
        rej, typ = sum(p.stats.rejected.values()), sum(p.stats.by_type.values())
        ign = p.stats.by_type["ignored"]
        out = p.feed_line(ln, 1.0)
        assert out or sum(p.stats.rejected.values()) > rej or p.stats.by_type["ignored"] > ign
        assert sum(p.stats.rejected.values()) > rej or sum(p.stats.by_type.values()) > typ
