"""NMEA 0183 parser, encoders and the text-capture readers (NMEA, mixed Arduino capture,
DDBoat), on synthetic input and on the real captures in shared/data."""

from __future__ import annotations

import calendar
import math
import statistics
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from onboard.drivers.base import UnreadableLog
from onboard.drivers.nmea import (
    KNOT_MPS,
    NmeaParser,
    checksum,
    encode_gga,
    encode_hdg,
    encode_hdm,
    encode_hdt,
    encode_rmc,
    encode_vtg,
    split_sentence,
)
from onboard.drivers.textlog import (
    DdboatLogReader,
    MixedCaptureReader,
    NmeaCaptureReader,
    open_text_log,
    sniff_text,
)
from onboard.core.messages import ActuatorCommand, GnssFix, Heading, Imu, RcChannels

GGA = "$GPGGA,094155.20,2234.33145313,N,11431.87220478,E,4,21,0.7,1.2097,M,-1.3523,M,02,0000*73"
RMC = "$GPRMC,094155.20,A,2234.33145313,N,11431.87220478,E,1.141,231.1,051224,3.4,W,D*2B"
VTG = "$GNVTG,231.097,T,234.530,M,1.14148,N,2.11403,K,D*39"
HDT = "$GNHDT,153.4475,T*1E"
DAY = float(calendar.timegm((2024, 12, 5, 0, 0, 0)))


def sentence(body: str) -> str:
    return f"${body}*{checksum(body):02X}"


def feed_lines(p: NmeaParser, lines, t0: float = 0.0, dt: float = 0.01):
    out = []
    for i, ln in enumerate(lines):
        out += p.feed_line(ln, None if p.time_base == "utc" else t0 + i * dt)
    return out + p.flush()


# ----------------------------------------------------------------------------- sentences


def test_checksum_of_a_real_sentence_verifies():
    talker, kind, fields, had = split_sentence(GGA)
    assert (talker, kind, had) == ("GP", "GGA", True)
    assert fields[0] == "094155.20"


def test_gga_and_rmc_of_one_epoch_merge_into_one_fix():
    p = NmeaParser(time_base="utc", date=DAY)
    out = feed_lines(p, [GGA, RMC])
    assert len(out) == 1
    fix = out[0]
    assert isinstance(fix, GnssFix)
    assert fix.lat_deg == pytest.approx(22 + 34.33145313 / 60, abs=1e-12)
    assert fix.lon_deg == pytest.approx(114 + 31.87220478 / 60, abs=1e-12)
    assert fix.alt_m == pytest.approx(1.2097)
    assert (fix.fix_quality, fix.num_sats, fix.hdop) == (4, 21, 0.7)
    assert fix.sog_mps == pytest.approx(1.141 * KNOT_MPS)
    assert fix.cog_rad == pytest.approx(math.radians(231.1))
    assert fix.t == pytest.approx(DAY + 9 * 3600 + 41 * 60 + 55.2)


@pytest.mark.parametrize("talker", ["GP", "GN", "GL", "GA", "GB", "HE", "II"])
def test_any_talker_id_is_accepted(talker):
    p = NmeaParser()
    out = p.feed_line(sentence(f"{talker}HDT,10.0,T"), 1.0)
    assert len(out) == 1 and out[0].heading_rad == pytest.approx(math.radians(10.0))


def test_empty_fields_become_none():
    p = NmeaParser(time_base="utc")
    out = feed_lines(p, [sentence("GPGGA,120000.00,4807.038,N,01131.000,E,1,,,,M,,M,,")])
    (fix,) = out
    assert fix.num_sats is None and fix.hdop is None and fix.alt_m is None
    assert fix.sog_mps is None and fix.cog_rad is None


def test_bad_checksum_is_rejected_and_counted():
    p = NmeaParser()
    bad = GGA[:-2] + "00"
    assert p.feed_line(bad, 0.0) == []
    assert p.stats.rejected["checksum"] == 1


def test_missing_checksum_is_rejected_by_default_and_accepted_on_request():
    body = "$GPHDT,45.0,T"
    strict = NmeaParser()
    assert strict.feed_line(body, 0.0) == []
    assert strict.stats.rejected["no_checksum"] == 1
    lax = NmeaParser(require_checksum=False)
    (h,) = lax.feed_line(body, 0.0)
    assert h.heading_rad == pytest.approx(math.pi / 4)
    assert lax.stats.by_type["no_checksum"] == 1


def test_nan_and_non_numeric_fields_are_malformed():
    p = NmeaParser()
    p.feed_line(sentence("GPHDT,nan,T"), 0.0)
    p.feed_line(sentence("GPHDT,12a,T"), 0.0)
    assert p.stats.rejected["malformed"] == 2


def test_no_fix_sentences_are_counted_not_emitted():
    p = NmeaParser(time_base="utc")
    out = feed_lines(p, [
        sentence("GPGGA,235948.061,,,,,0,00,,,M,0.0,M,,0000"),
        sentence("GPRMC,235949.061,V,,,,,,,140209,,,N"),
    ])
    assert out == []
    assert p.stats.rejected["no_fix"] == 2


def test_rmc_alone_gives_a_fix_with_speed_and_course():
    p = NmeaParser(time_base="utc")
    (fix,) = feed_lines(p, [RMC])
    assert fix.fix_quality == 2  # mode D
    assert fix.sog_mps == pytest.approx(1.141 * KNOT_MPS)


def test_vtg_before_the_epoch_supplies_speed_when_there_is_no_rmc():
    p = NmeaParser(time_base="utc")
    (fix, hdg) = feed_lines(p, [VTG, HDT, GGA])
    assert fix.sog_mps == pytest.approx(1.14148 * KNOT_MPS)
    assert fix.cog_rad == pytest.approx(math.radians(231.097))
    assert isinstance(hdg, Heading) and hdg.t == fix.t  # heading joins the epoch


def test_hdg_deviation_and_variation():
    p = NmeaParser()
    (h,) = p.feed_line(sentence("HCHDG,100.0,2.0,W,3.5,E"), 0.0)
    assert h.reference == "magnetic"
    assert h.heading_rad == pytest.approx(math.radians(98.0))
    assert h.declination_rad == pytest.approx(math.radians(3.5))
    (m,) = p.feed_line(sentence("HCHDM,359.5,M"), 0.0)
    assert m.reference == "magnetic" and m.declination_rad is None


def test_empty_heading_is_counted():
    p = NmeaParser()
    assert p.feed_line("$GPHDT,,*4F", 0.0) == []  # as sent in ardusub nmea_log.txt
    assert p.stats.rejected["empty"] == 1


def test_utc_midnight_rollover_without_and_with_date():
    p = NmeaParser(time_base="utc", date=DAY)
    out = feed_lines(p, [
        sentence("GPGGA,235959.50,4807.0,N,01131.0,E,1,08,0.9,5.0,M,0.0,M,,"),
        sentence("GPGGA,000000.00,4807.0,N,01131.0,E,1,08,0.9,5.0,M,0.0,M,,"),
        sentence("GPRMC,000000.50,A,4807.0,N,01131.0,E,0.0,0.0,061224,,,A"),
    ])
    assert [round(s.t - DAY, 2) for s in out] == [86399.5, 86400.0, 86400.5]


def test_receive_time_stamps_and_hold_timeout():
    p = NmeaParser(time_base="rx", hold_s=0.25)
    assert p.feed_line(GGA, 10.0) == []  # first epoch: waits for the rest of its sentences
    assert p.feed_line(RMC, 10.01) == []
    (fix,) = p.feed(b"", 11.0)  # hold expired: emitted, stamped with the GGA's arrival
    assert fix.t == 10.0 and fix.sog_mps == pytest.approx(1.141 * KNOT_MPS)
    gga2 = GGA.replace("094155.20", "094155.40")
    gga2 = gga2[: gga2.rfind("*")]
    gga2 = sentence(gga2[1:])
    rmc2 = sentence(RMC[1 : RMC.rfind("*")].replace("094155.20", "094155.40"))
    assert p.feed_line(gga2, 11.2) == []
    (fix2,) = p.feed_line(rmc2, 11.21)  # GGA+RMC learned: complete at once
    assert fix2.t == 11.2
    gga3 = sentence(gga2[1 : gga2.rfind("*")].replace("094155.40", "094155.60"))
    assert p.feed_line(gga3, 11.4) == []  # waits for its RMC ...
    assert p.poll(11.5) == []
    (fix3,) = p.poll(11.7)  # ... until the hold expires on the transport's timer
    assert fix3.t == 11.4 and fix3.sog_mps is None


def _epoch_lines(tod: str) -> list[str]:
    gga = sentence(GGA[1:GGA.rfind("*")].replace("094155.20", tod))
    rmc = sentence(RMC[1:RMC.rfind("*")].replace("094155.20", tod))
    return [gga, rmc]


def test_live_stamps_keep_the_receivers_spacing_when_fixes_arrive_bunched():
    """The live time base maps each fix's UTC through the least-delayed epoch: five 5 Hz
    epochs that reach a stalled computer together 1.5 s late keep their 0.2 s spacing
    and the times they were received at without the stall; stamped with their receive
    time (``rx``, the negative control) they would all share one instant."""
    tods = [f"0941{55.2 + 0.2 * k:05.2f}" for k in range(8)]
    arrivals = [10.0, 10.2, 10.4] + [12.1] * 5  # the last five after a 1.5 s stall

    def stamps(time_base: str) -> list[float]:
        p = NmeaParser(time_base=time_base)
        out = []
        for tod, t_rx in zip(tods, arrivals):
            for k, line in enumerate(_epoch_lines(tod)):
                out += p.feed_line(line, t_rx + 0.001 * k)
        return [s.t for s in out + p.flush() if isinstance(s, GnssFix)]

    synced = stamps("synced")
    assert synced == pytest.approx([10.0 + 0.2 * k for k in range(8)], abs=1e-3)
    assert NmeaParser().time_base == "synced"  # the live default
    rx = stamps("rx")
    assert rx[3:] == pytest.approx([12.1] * 5, abs=0.01)


# ----------------------------------------------------------------------------- the stream


def _stream() -> bytes:
    return (VTG + "\r\n" + HDT + "\r\n" + GGA + "\r\n" + RMC + "\r\n").encode() * 3


@pytest.mark.parametrize("chunk", [1, 7, 64, 10_000])
def test_lines_are_assembled_across_chunks(chunk):
    data = _stream()
    p = NmeaParser()
    out = []
    for i in range(0, len(data), chunk):
        out += p.feed(data[i : i + chunk], i * 1e-4)
    kinds = [type(s).__name__ for s in out]
    assert kinds.count("Heading") == 3
    assert p.stats.rejected.get("checksum", 0) == 0


def test_garbage_bytes_truncated_and_merged_sentences_are_counted():
    p = NmeaParser()
    data = (b"\x00\xff\xfe junk\r\n" + GGA[:40].encode() + b"\r\n"
            + b"xx" + HDT.encode() + b"$GPRMC,12" + b"\r\n" + b"A" * 1000 + b"\r\n"
            + HDT.encode() + b"\r\n")
    out = p.feed(data, 1.0)
    assert [type(s).__name__ for s in out] == ["Heading", "Heading"]
    r = p.stats.rejected
    assert r["garbage"] == 2 and r["no_checksum"] == 2 and r["too_long"] == 1


# ----------------------------------------------------------------------------- encoders


@pytest.mark.parametrize("lat,lon", [(22.5720901, 114.5311), (-33.9, -151.2), (0.0, 0.0),
                                     (63.4015810, 10.3149769), (-0.00001, 179.99999)])
def test_encode_gga_rmc_round_trip(lat, lon):
    t = DAY + 3600 * 23 + 59 * 60 + 59.25
    data = encode_gga(t, lat, lon, alt_m=12.345, fix_quality=4, num_sats=17, hdop=0.6) \
        + encode_rmc(t, lat, lon, sog_mps=2.5, cog_rad=4.0, variation_rad=-0.05)
    p = NmeaParser(time_base="utc", date=DAY)
    out = p.feed(data, 0.0) + p.flush()
    (fix,) = out
    assert fix.lat_deg == pytest.approx(lat, abs=1e-9)  # 8 decimals of minutes ~ 2 mm
    assert fix.lon_deg == pytest.approx(lon, abs=1e-9)
    assert fix.alt_m == pytest.approx(12.345) and fix.fix_quality == 4 and fix.num_sats == 17
    assert fix.sog_mps == pytest.approx(2.5, abs=1e-3)
    assert fix.cog_rad == pytest.approx(4.0, abs=1e-4)
    assert fix.t == pytest.approx(t, abs=1e-6)


def test_encode_vtg_and_headings_round_trip():
    p = NmeaParser()
    (h,) = p.feed(encode_hdt(6.0), 0.0)
    assert h.heading_rad == pytest.approx(6.0, abs=1e-3) and h.reference == "true"
    (m,) = p.feed(encode_hdm(0.5), 0.0)
    assert m.heading_rad == pytest.approx(0.5, abs=1e-3) and m.reference == "magnetic"
    (g,) = p.feed(encode_hdg(1.0, deviation_rad=0.02, variation_rad=-0.1), 0.0)
    assert g.heading_rad == pytest.approx(1.02, abs=2e-3)
    assert g.declination_rad == pytest.approx(-0.1, abs=2e-3)
    q = NmeaParser(time_base="utc")
    out = q.feed(encode_vtg(3.0, 1.5) + encode_gga(DAY, 1.0, 2.0), 0.0) + q.flush()
    assert out[0].sog_mps == pytest.approx(3.0, abs=1e-3)
    assert out[0].cog_rad == pytest.approx(1.5, abs=1e-3)


# ----------------------------------------------------------------------------- properties

_lines = st.one_of(
    st.binary(max_size=120),
    st.sampled_from([GGA, RMC, VTG, HDT, "$GPHDT,,*4F"]).map(str.encode),
    st.builds(lambda s, i, c: (s[:i] + c + s[i + 1 :]).encode("latin-1"),
              st.sampled_from([GGA, RMC, VTG, HDT]), st.integers(0, 80),
              st.sampled_from([",", "*", "$", "9", "\x00", "", "N"])),
)


@settings(max_examples=200, deadline=None)
@given(st.lists(_lines, max_size=8))
def test_property_every_line_is_parsed_or_rejected(lines):
    p = NmeaParser(time_base="utc")
    for ln in lines:
        if not ln.strip(b" \r\n\t\x0b\x0c\x1c\x1d\x1e\x1f\x85"):
            continue
        before = sum(p.stats.rejected.values()) + sum(p.stats.by_type.values())
        p.feed_line(ln)
        assert sum(p.stats.rejected.values()) + sum(p.stats.by_type.values()) > before
    for s in p.flush():
        assert math.isfinite(s.t)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=600), st.integers(1, 50))
def test_property_random_bytes_never_raise(data, chunk):
    p = NmeaParser()
    for i in range(0, len(data), chunk):
        for s in p.feed(data[i : i + chunk], float(i)):
            assert isinstance(s, (GnssFix, Heading))


# ----------------------------------------------------------------------------- sniffing


def test_sniff_and_unreadable(tmp_path: Path):
    assert sniff_text((GGA + "\n" + RMC + "\n").encode()) == "nmea"
    assert sniff_text(b'{"vx":0.1,"velocity_valid":true}\n') == "dvl-json"
    assert sniff_text(b":BS,+00001,+00002,+00003,A\n") == "pd6"
    empty = tmp_path / "empty.txt"
    empty.write_bytes(b"")
    with pytest.raises(UnreadableLog):
        open_text_log(empty)
    prose = tmp_path / "notes.txt"
    prose.write_text("Test 1 clockwise circles\nStart Time: 10:24:13\n")
    with pytest.raises(UnreadableLog):
        open_text_log(prose)
    with pytest.raises(UnreadableLog):
        open_text_log(tmp_path / "missing.txt")
    # a pretty-printed JSON document (onboard sitl --tlog's X.scenario.json beside its
    # log) is no DVL capture: its lines are not objects, one per line
    document = b'{\n  "scenario": "effect-waves",\n  "sensors": {\n    "gnss": {}\n  }\n}\n'
    assert sniff_text(document) == ""
    # nor are other JSON lines (onboard sitl --fleet's truth, t/north/east/u/v per line)
    assert sniff_text(b'{"t":0.0,"north":-50.0,"u":1.43,"v":0.18}\n') == ""
    assert sniff_text(b'{"type":"position_local","ts":1.0,"x":0,"y":0,"z":0}\n') == "dvl-json"


def test_mixed_capture_rows_are_timed_between_gps_epochs(tmp_path: Path):
    row = "-0.71,0.16,9.69,6.36,-32.27,-41.53,1.74,-1.91,-4.56,0.93,-4.17,281.15,1396,1516"
    t0 = DAY + 17 * 3600
    lines = ["START OF TEST", "ax, ay, az, mx, my, mz, rx, ry, rz, roll, pitch, yaw, throttle, rudder"]
    for k in range(4):
        lines.append(encode_gga(t0 + k, 32.88, -117.23).decode().strip())
        lines.append(encode_rmc(t0 + k, 32.88, -117.23, 1.0, 0.5).decode().strip())
        lines += [row] * 10
    lines.append(row[:30] + "START OF TEST")  # merged/truncated
    lines.append("\x93\xc4garbage\x86")
    path = tmp_path / "capture.txt"
    path.write_bytes("\r\n\r\n".join(lines).encode("latin-1"))
    r = open_text_log(path)
    assert isinstance(r, MixedCaptureReader)
    out = list(r)
    imu = [s for s in out if isinstance(s, Imu)]
    assert len(imu) == 40 and len([s for s in out if isinstance(s, GnssFix)]) == 4
    assert [round(s.t - t0, 3) for s in imu[:11]] == [round(0.1 * i, 3) for i in range(11)]
    assert imu[0].accel_z == pytest.approx(-9.69)  # z up -> FRD z down
    assert imu[0].gyro_z == pytest.approx(math.radians(4.56))
    rc = [s for s in out if isinstance(s, RcChannels)]
    assert rc[0].pwm_us == (1396.0, 1516.0)
    assert r.stats.rejected["truncated"] == 1 and r.stats.rejected["garbage"] == 1
    assert all(a.t <= b.t for a, b in zip(out, out[1:]))


# ----------------------------------------------------------------------------- real data

SHENZHEN = {  # file: (duration s from SOURCE.md, SOG median kn from SOURCE.md)
    "202412051037.txt": (646, 0.06),
    "202412071110.txt": (604, 0.45),
    "202412051751.txt": (579, 3.5),
    "202412071021.txt": (553, 2.9),
}


@pytest.mark.data
@pytest.mark.parametrize("name", sorted(SHENZHEN))
def test_shenzhen_rtk_captures(shared_data, name):
    dur, sog_kn = SHENZHEN[name]
    r = open_text_log(shared_data / "usv_rtk_gnss_heading_nmea_shenzhen" / name)
    assert isinstance(r, NmeaCaptureReader) and not r.receive_times
    out = list(r)
    fixes = [s for s in out if isinstance(s, GnssFix)]
    heads = [s for s in out if isinstance(s, Heading)]
    # measured: 2765-3230 fixes and 2764-3225 headings per file, 5 Hz, <= 6 rejections
    assert len(fixes) >= 2700 and len(heads) >= 2700
    assert sum(r.stats.rejected.values()) <= 6
    assert set(r.stats.rejected) <= {"garbage", "empty", "duplicate"}
    assert abs((out[-1].t - out[0].t) - dur) < 1.0
    assert all(a.t <= b.t for a, b in zip(out, out[1:]))
    dts = [b.t - a.t for a, b in zip(fixes, fixes[1:])]
    assert statistics.median(dts) == pytest.approx(0.2, abs=1e-4) and max(dts) < 0.21
    assert min(f.fix_quality for f in fixes) >= 2  # RTK / DGPS throughout
    assert statistics.median(f.lat_deg for f in fixes) == pytest.approx(22.57, abs=0.01)
    assert statistics.median(f.lon_deg for f in fixes) == pytest.approx(114.53, abs=0.01)
    sog = statistics.median(f.sog_mps for f in fixes if f.sog_mps is not None) / KNOT_MPS
    assert sog == pytest.approx(sog_kn, abs=0.05)
    assert all(h.reference == "true" for h in heads)


@pytest.mark.data
def test_shenzhen_heading_and_course_differ_by_a_constant_mounting_offset(shared_data):
    out = list(open_text_log(shared_data / "usv_rtk_gnss_heading_nmea_shenzhen" / "202412051751.txt"))
    hdg = {s.t: s.heading_rad for s in out if isinstance(s, Heading)}
    d = [math.degrees((f.cog_rad - hdg[f.t] + math.pi) % (2 * math.pi) - math.pi)
         for f in out if isinstance(f, GnssFix) and f.sog_mps and f.sog_mps > 1.0 and f.t in hdg]
    q10, q50, q90 = (statistics.quantiles(d, n=10)[i] for i in (0, 4, 8))
    # measured: COG - HDT deciles 71 / 74 / 77 deg underway: the dual-antenna baseline is
    # not along the bow (plus crab). Kept as a fact for the heading-bias diagnosis.
    assert 65 < q50 < 80 and q90 - q10 < 10


@pytest.mark.data
def test_ardusub_loguru_capture_uses_receive_times(shared_data):
    r = open_text_log(shared_data / "ardusub_small_logs" / "nmea_log.txt")
    assert isinstance(r, NmeaCaptureReader) and r.receive_times
    out = list(r)
    # measured: 129 RMC (8 Hz) + 16 GGA -> 129 fixes; 129 empty HDT; 5 log-only lines
    assert len(out) == 129 and all(isinstance(s, GnssFix) for s in out)
    assert r.stats.rejected["empty"] == 129 and r.stats.rejected["unrecognized"] == 5
    assert out[0].t == calendar.timegm((2023, 9, 1, 15, 56, 44)) + 0.626
    assert abs(out[-1].t - out[0].t - 16.0) < 0.1
    assert statistics.median(s.lat_deg for s in out) == pytest.approx(47.6075, abs=1e-3)
    assert statistics.median(s.lon_deg for s in out) == pytest.approx(-122.3412, abs=1e-3)


SURVEY = {  # file: (IMU rows, GPS duration s) measured; SOURCE.md: 2.3k-3.9k rows, 78-566 s
    "Test1_counterclockwise.TXT": (2786, 92),
    "Test2_clockwise.txt": (3956, 131),
    "Test3_slow.txt": (3932, 130),
    "Test4_fast.txt": (2329, 77),
    "Test5_acceleration.txt": (3125, 103),
    "Test6_slow.txt": (3539, 117),
    "Rest_of_tests.TXT": (16881, 558),
}


@pytest.mark.data
@pytest.mark.parametrize("name", sorted(SURVEY))
def test_survey_boat_mixed_captures(shared_data, name):
    rows, dur = SURVEY[name]
    r = open_text_log(shared_data / "survey_boat_arduino_rc" / name)
    assert isinstance(r, MixedCaptureReader)
    out = list(r)
    imu = [s for s in out if isinstance(s, Imu)]
    assert len(imu) == rows
    assert len([s for s in out if isinstance(s, RcChannels)]) == rows
    assert abs((out[-1].t - out[0].t) - dur) < 2.0
    assert all(a.t <= b.t for a, b in zip(out, out[1:]))
    assert r.row_rate_hz == pytest.approx(30.0, abs=1.0)  # SOURCE.md: ~30 lines/s
    # corrupt and merged lines are counted, never turned into samples (<= 6 per file)
    bad = {k: v for k, v in r.stats.rejected.items() if k != "no_fix"}
    assert r.stats.by_type["ignored"] > 0  # GSA and GSV are counted, not rejected
    assert sum(bad.values()) <= 12
    assert statistics.median(s.accel_z for s in imu) == pytest.approx(-9.8, abs=0.3)
    pwm = [p for s in out if isinstance(s, RcChannels) for p in s.pwm_us]
    assert 1000 < min(pwm) and max(pwm) < 2000
    fixes = [s for s in out if isinstance(s, GnssFix)]
    if name != "Test1_counterclockwise.TXT":  # Test1: the GPS never got a fix
        assert len(fixes) >= dur - 3
        assert statistics.median(f.lat_deg for f in fixes) == pytest.approx(32.881, abs=0.001)


@pytest.mark.data
def test_survey_boat_gps_clock_jumps_are_removed(shared_data):
    # Test1: the GPS clock starts in 2009 and is set twice; Test3 steps back 2 s at 17:56:08
    r1 = MixedCaptureReader(shared_data / "survey_boat_arduino_rc" / "Test1_counterclockwise.TXT")
    out = list(r1)
    assert r1.stats.by_type["clock_jump"] == 3 and out[-1].t - out[0].t < 95
    r3 = MixedCaptureReader(shared_data / "survey_boat_arduino_rc" / "Test3_slow.txt")
    list(r3)
    assert r3.stats.by_type["clock_jump"] == 1
    assert "time_backwards" not in r3.stats.rejected


DDBOAT_LINE = ("2022-09-02 11:41:14,483 - INFO - Temperature l,r are 24 26 deg.C /cmd motors "
               "l,r are b'dirl: 1, motl: 0, dirr: 1, motr: 0\\r' /GPS timeout /IMU: MAG "
               "[225, -3715, 1858] /CONTROL: ACCD -0.42 WD 0.41 CMDL 10.0 CMDR 23.6 THETA {} "
               "/KAL: STATE [[-3.4], [3.1]]\n")


@pytest.mark.parametrize("theta, heading_deg", [(0.0, 90.0), (math.pi / 2, 0.0),
                                                (-2.81148625373, 251.08)])
def test_ddboat_theta_is_a_magnetic_heading_from_east_counterclockwise(tmp_path, theta,
                                                                       heading_deg):
    # THETA is 0 facing east and grows counterclockwise (ENSTA's DdboatFilter.cap)
    log = tmp_path / "ddboat.log"
    log.write_text(DDBOAT_LINE.format(theta))
    heading = [s for s in DdboatLogReader(log) if isinstance(s, Heading)]
    assert len(heading) == 1 and heading[0].reference == "magnetic"
    assert heading[0].source == "ddboat/THETA"
    assert math.degrees(heading[0].heading_rad) == pytest.approx(heading_deg, abs=0.01)


def test_ddboat_line_without_a_number_for_theta_gives_no_heading(tmp_path):
    log = tmp_path / "ddboat.log"
    log.write_text(DDBOAT_LINE.format("nan") + DDBOAT_LINE.format("x")
                   + DDBOAT_LINE.replace(" THETA {}", ""))
    r = DdboatLogReader(log)
    out = list(r)
    assert not [s for s in out if isinstance(s, Heading)]
    assert len(out) == 3 and r.stats.rejected["bad_heading"] == 2


@pytest.mark.data
def test_ddboat_log(shared_data):
    r = open_text_log(shared_data / "ddboat_ensta_log" / "DDBOAT8_t_2022_9_2_0_0.log")
    assert isinstance(r, DdboatLogReader)
    out = list(r)
    fixes = [s for s in out if isinstance(s, GnssFix)]
    cmds = [s for s in out if isinstance(s, ActuatorCommand)]
    headings = [s for s in out if isinstance(s, Heading)]
    # SOURCE.md: 2,439 lines, 245 s, 245 GPS fixes, motor commands 0-200 (of 255); a
    # CONTROL record with THETA on 2,436 lines
    assert len(fixes) == 245 and len(cmds) == 2436 and len(headings) == 2436
    assert abs(out[-1].t - out[0].t - 245) < 1
    assert statistics.median(f.lat_deg for f in fixes) == pytest.approx(48.418, abs=1e-3)
    assert statistics.median(f.lon_deg for f in fixes) == pytest.approx(-4.4736, abs=1e-3)
    assert max(c.left for c in cmds) == pytest.approx(200 / 255)
    assert not r.stats.rejected
    ex = list(open_text_log(shared_data / "ddboat_ensta_log" / "logexample.txt"))
    assert len(ex) == 24 + 13   # 24 motor commands, 13 THETA headings


STATUS_LINE = b"2024-12-05 10:37:%02d INFO status: waiting for the GNSS receiver, battery 12.%d V\n"
"""A logger's status line, prefixed, without a sentence (about 80 bytes)."""
SAMPLE_NMEA = Path(__file__).resolve().parent / "data" / "nmea" / "gnss-compass.nmea"


def _status_lines(n: int) -> bytes:
    return b"".join(STATUS_LINE % (i % 60, i % 10) for i in range(n))


def test_status_lines_past_the_first_window_do_not_hide_the_sentences(tmp_path):
    """1,500 status lines (117 kB) before the first sentence: read as the capture alone
    is, the status lines counted as garbage."""
    log = tmp_path / "late.txt"
    log.write_bytes(_status_lines(1500) + SAMPLE_NMEA.read_bytes())
    assert log.stat().st_size > 64 * 1024
    r = open_text_log(log)
    assert isinstance(r, NmeaCaptureReader) and not r.receive_times
    alone = [(type(s), s.t) for s in open_text_log(SAMPLE_NMEA)]
    assert [(type(s), s.t) for s in r] == alone and alone
    assert r.stats.rejected["garbage"] == 1500


def test_late_sentences_with_receive_times_are_read_with_them(tmp_path):
    """Sentences after 1,500 prefixed status lines carry their receive times too."""
    sentences = [ln for ln in SAMPLE_NMEA.read_bytes().splitlines() if ln]
    log = tmp_path / "late.txt"
    log.write_bytes(_status_lines(1500) + b"".join(
        b"2024-05-01 12:00:%02d.000 | DEBUG | gps - %s\n" % (i // 4, ln)
        for i, ln in enumerate(sentences)))
    r = open_text_log(log)
    assert isinstance(r, NmeaCaptureReader) and r.receive_times


def test_a_text_file_without_records_says_how_far_it_looked(tmp_path, monkeypatch):
    from onboard.drivers import textlog

    monkeypatch.setattr(textlog, "SNIFF_MAX_BYTES", 256 * 1024)
    log = tmp_path / "status.txt"
    log.write_bytes(_status_lines(4000) + SAMPLE_NMEA.read_bytes())   # 312 kB, then NMEA
    with pytest.raises(UnreadableLog, match=r"in the first 256 kB \(it looks no further\)"):
        open_text_log(log)
    short = tmp_path / "short.txt"
    short.write_bytes(_status_lines(100))
    with pytest.raises(UnreadableLog, match=r"no NMEA.* in the whole file \(8 kB\)"):
        open_text_log(short)


@pytest.mark.data
def test_notes_file_is_unreadable(shared_data):
    with pytest.raises(UnreadableLog):
        open_text_log(shared_data / "survey_boat_arduino_rc" / "Notes_Test.txt")


@pytest.mark.data
def test_survey_boat_config_maps_rc_channels(shared_data):
    from onboard.core.config import CONFIG_DIR, load
    from onboard.engine.inputs import InputMapper

    cfg = load(CONFIG_DIR / "survey-boat-csv.toml")
    mapper = InputMapper(cfg.inputs)
    out = list(open_text_log(shared_data / "survey_boat_arduino_rc" / "Test2_clockwise.txt"))
    cmds = [mapper.map(s) for s in out if isinstance(s, RcChannels)]
    # clockwise circles: the rudder sits at 1877-1900 us for the turning part (>= 30 %)
    right = sum(1 for c in cmds if c.rudder_rad > 0.4) / len(cmds)
    assert right > 0.3 and all(-1.0 <= c.throttle <= 1.0 for c in cmds)


def test_capture_starting_just_before_midnight_gets_the_right_day(tmp_path: Path):
    day2 = DAY + 86400.0
    lines = [encode_gga(day2 - 0.5, 48.0, 11.0), encode_gga(day2 + 0.5, 48.0, 11.0),
             encode_rmc(day2 + 0.5, 48.0, 11.0, 1.0, 0.2)]
    path = tmp_path / "midnight.nmea"
    path.write_bytes(b"".join(lines))
    out = list(open_text_log(path))
    assert [s.t - DAY for s in out] == pytest.approx([86399.5, 86400.5])


def test_degrees_and_decimal_minutes_one_conversion_for_every_driver():
    """drivers.base.ddmm_degrees: NMEA's, the text loggers' and a Slocum's DDMM.MMMM."""
    from onboard.drivers.base import ddmm_degrees

    assert ddmm_degrees(5415.5979) == pytest.approx(54.259965)
    assert ddmm_degrees(-726.7404) == pytest.approx(-7.44567333)
    assert ddmm_degrees(12000.0) == 120.0 and ddmm_degrees(0.0) == 0.0
    assert ddmm_degrees(4960.0) is None            # 60 minutes
    assert ddmm_degrees(math.nan) is None and ddmm_degrees(math.inf) is None
