"""Water Linked DVL JSON: parser, capture reader and encoders, on synthetic input and on
the real A50 tank captures."""

from __future__ import annotations

import json
import math
import statistics
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from onboard.drivers.base import UnreadableLog
from onboard.drivers.dvl_json import (
    DvlJsonLogReader,
    DvlJsonParser,
    encode_position_local,
    encode_velocity_report,
)
from onboard.drivers.textlog import open_text_log
from onboard.core.messages import DvlPosition, DvlVelocity

V1 = ('{"time":120.7,"vx":0.0027,"vy":0.0137,"vz":-0.0097,"fom":0.0002,"altitude":1.5167,'
      '"transducers":[],"velocity_valid":true,"status":0,"format":"json_v1"}')
V1_LOST = ('{"time":109.9,"vx":0,"vy":0,"vz":0,"fom":2.37,"altitude":-1,"transducers":[],'
           '"velocity_valid":false,"status":0,"format":"json_v1"}')


def test_json_v1_report():
    p = DvlJsonParser()
    (v,) = p.feed((V1 + "\n").encode(), 5.0)
    assert isinstance(v, DvlVelocity)
    assert (v.vx, v.vy, v.vz) == (0.0027, 0.0137, -0.0097)
    assert v.valid and v.track == "bottom" and v.fom_mps == 0.0002
    assert v.altitude_m == 1.5167 and v.t == 5.0 and v.covariance is None


def test_lock_loss_zeros_are_never_a_valid_sample():
    p = DvlJsonParser()
    (v,) = p.feed((V1_LOST + "\n").encode(), 1.0)
    assert not v.valid and v.altitude_m is None  # altitude -1 = unknown


def test_current_protocol_velocity_is_corrected_for_processing_delay():
    line = encode_velocity_report(0.5, -0.1, 0.02, t_validity_s=1.7e9, t_transmission_s=1.7e9 + 0.12,
                                  covariance=(1e-4, 0, 0, 0, 2e-4, 0, 0, 0, 3e-4))
    obj = json.loads(line)
    assert obj["type"] == "velocity" and len(obj["transducers"]) == 4
    (v,) = DvlJsonParser().feed(line, 100.0)
    assert v.t == pytest.approx(100.0 - 0.12)
    assert (v.vx, v.vy, v.vz) == (0.5, -0.1, 0.02)
    assert v.covariance == (1e-4, 0, 0, 0, 2e-4, 0, 0, 0, 3e-4)


def test_water_track_and_position_local_round_trip():
    p = DvlJsonParser()
    out = p.feed(encode_velocity_report(0.3, 0.0, 0.0, track="water", t_validity_s=1.0)
                 + encode_position_local(12.4, 64.3, 1.26, t_s=49056.8, std_m=0.31,
                                         roll_rad=0.036, pitch_rad=-0.02, yaw_rad=3.0), 7.0)
    w, pos = out
    assert isinstance(w, DvlVelocity) and w.track == "water" and w.valid
    assert isinstance(pos, DvlPosition)
    assert (pos.north_m, pos.east_m, pos.down_m, pos.std_m) == (12.4, 64.3, 1.26, 0.31)
    assert pos.yaw_rad == pytest.approx(3.0) and pos.roll_rad == pytest.approx(0.036)


def test_encoder_lock_loss_and_v1_format():
    line = encode_velocity_report(0.4, 0.1, 0.0, valid=False, fmt="json_v1")
    obj = json.loads(line)
    assert obj["format"] == "json_v1" and "type" not in obj and obj["altitude"] == -1
    (v,) = DvlJsonParser().feed(line, 0.0)
    assert not v.valid and (v.vx, v.vy, v.vz) == (0.0, 0.0, 0.0)


def test_corrupt_lines_are_counted():
    p = DvlJsonParser(max_line=4096)
    data = b"".join([
        V1.encode() + b"\n",
        V1.encode() + b"\n",                       # repeated reading
        V1.encode()[:60] + b"\n",                  # truncated
        b"\x00\xff garbage\n",
        b'{"vx": NaN, "vy": 0, "vz": 0, "velocity_valid": true, "format": "json_v1"}\n',
        b"[1, 2, 3]\n",
        b'{"vx": "fast", "vy": 0, "vz": 0, "velocity_valid": true}\n',
        b'{"vx": 0.1, "vy": 0, "vz": 0, "velocity_valid": "yes"}\n',
        b'{"response_to": "get_config", "success": true, "type": "response"}\n',
        b"x" * 5000 + b"\n",
        b"\n",
    ])
    out = p.feed(data, 0.0)
    assert len(out) == 1
    r = p.stats.rejected
    assert r == {"duplicate": 1, "json": 4, "malformed": 2, "too_long": 1}
    assert p.stats.by_type["ignored"] == 1  # the command response
    assert p.stats.records == 10


@pytest.mark.parametrize("chunk", [1, 13, 500])
def test_stream_assembles_lines_across_chunks(chunk):
    data = b"".join(encode_velocity_report(0.01 * i, 0, 0, t_validity_s=float(i)) for i in range(5))
    p = DvlJsonParser()
    out = []
    for i in range(0, len(data), chunk):
        out += p.feed(data[i : i + chunk], 1.0)
    assert [s.vx for s in out] == [0.01 * i for i in range(5)]


def test_capture_reader_times(tmp_path: Path):
    path = tmp_path / "dvl.txt"
    lines = [encode_velocity_report(0.1, 0, 0, dt_ms=100.0 + i, fmt="json_v1") for i in range(3)]
    path.write_bytes(b"".join(lines))
    out = list(DvlJsonLogReader(path))
    assert [round(s.t, 3) for s in out] == [0.0, 0.101, 0.203]  # sum of "time" after the first
    path2 = tmp_path / "dvl2.txt"
    path2.write_bytes(encode_velocity_report(0.1, 0, 0, t_validity_s=1.7e9 + 0.5)
                      + encode_position_local(1, 2, 3, t_s=1.7e9 + 0.6)
                      + encode_velocity_report(0.1, 0, 0, t_validity_s=1.7e9 + 0.4))
    r = DvlJsonLogReader(path2)
    out = list(r)
    assert [s.t for s in out] == [1.7e9 + 0.5, 1.7e9 + 0.6]
    assert r.stats.rejected["time_backwards"] == 1
    with pytest.raises(UnreadableLog):
        DvlJsonLogReader(tmp_path / "missing.txt")


@settings(max_examples=200, deadline=None)
@given(st.lists(st.one_of(
    st.binary(max_size=80),
    st.dictionaries(st.sampled_from(["vx", "vy", "vz", "velocity_valid", "type", "fom",
                                     "altitude", "covariance", "x", "y", "z", "ts"]),
                    st.one_of(st.none(), st.booleans(), st.floats(allow_nan=False),
                              st.text(max_size=5), st.lists(st.integers(), max_size=3)))
    .map(lambda d: json.dumps(d).encode()),
), max_size=6))
def test_property_every_line_is_a_sample_or_a_rejection(lines):
    p = DvlJsonParser()
    for ln in lines:
        if b"\n" in ln or not ln.strip():
            continue
        before = (p.stats.samples, sum(p.stats.rejected.values()), p.stats.by_type["ignored"])
        p.feed(ln + b"\n", 0.0)
        after = (p.stats.samples, sum(p.stats.rejected.values()), p.stats.by_type["ignored"])
        assert sum(after) == sum(before) + 1


TANK = {  # file: (lines, distinct reports, valid fraction, duration s) -- SOURCE.md figures
    "out20210528.txt": (250, 234, 1.00, 35),
    "out20210528_circle.txt": (662, 602, 0.92, 92),
    "out20210528_straight+turn360.txt": (342, 320, 0.97, 48),
    "out.txt": (1973, 1749, 0.0, 400),
}


@pytest.mark.data
@pytest.mark.parametrize("name", sorted(TANK))
def test_waterlinked_tank_captures(shared_data, name):
    lines, distinct, valid_frac, dur = TANK[name]
    r = open_text_log(shared_data / "waterlinked_dvl_a50_json_tank" / name)
    assert isinstance(r, DvlJsonLogReader)
    out = list(r)
    assert r.stats.records == lines and len(out) == distinct
    assert r.stats.rejected == {"duplicate": lines - distinct}
    valid = [s for s in out if s.valid]
    assert len(valid) / len(out) == pytest.approx(valid_frac, abs=0.01)
    assert abs(out[-1].t - out[0].t - dur) < 1.0
    assert all(a.t < b.t for a, b in zip(out, out[1:]))
    for s in out:
        if not s.valid:
            assert s.altitude_m is None or s.altitude_m > 0
    if valid:
        alt = statistics.median(s.altitude_m for s in valid)
        assert 1.4 < alt < 1.9  # tank: SOURCE.md ~1.79 m; measured medians 1.68-1.79 m
        assert max(abs(s.vx) for s in valid) < 1.0
        assert all(math.isfinite(s.fom_mps) for s in valid)


@pytest.mark.data
@pytest.mark.parametrize("name,distinct", [("out_circle.txt", 31), ("out_straight.txt", 11),
                                           ("out_still_60s.txt", 53)])
def test_waterlinked_repeated_capture_lines_are_duplicates(shared_data, name, distinct):
    r = DvlJsonLogReader(shared_data / "waterlinked_dvl_a50_json_tank" / name)
    assert len(list(r)) == distinct
    assert r.stats.rejected["duplicate"] == r.stats.records - distinct


def test_live_reports_are_stamped_at_their_time_of_validity_on_our_clock():
    """The DVL's clock (Unix time, not ours) is mapped through the least-delayed report:
    a report that waited in a socket buffer is stamped when it was measured."""
    p = DvlJsonParser()
    tov = 1.7e9
    lines = [encode_velocity_report(0.5, 0.0, 0.0, t_validity_s=tov + k * 0.2,
                                     t_transmission_s=tov + k * 0.2 + 0.05) for k in range(3)]
    # received 0.30 s, 0.02 s and 0.15 s after transmission (our clock: 100 + ...)
    (a,) = p.feed(lines[0], 100.0 + 0.05 + 0.30)
    (b,) = p.feed(lines[1], 100.2 + 0.05 + 0.02)
    (c,) = p.feed(lines[2], 100.4 + 0.05 + 0.15)
    assert a.t == pytest.approx(100.30)  # the first: its own delay is all there is to go by
    assert b.t == pytest.approx(100.22)  # the least-delayed one sets the offset
    assert c.t == pytest.approx(100.42)  # the buffered one: stamped when it was measured
