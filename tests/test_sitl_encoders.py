"""The simulator's NMEA, Water Linked JSON and PD6 writers (sitl/nmea_out.py,
dvl_json_out.py, pd6_out.py) against the drivers that read them and against oracles that
are neither: the protocols' published examples (with their checksums), pynmeagps's
parser, Water Linked's documented field names and example output, scipy's rotations.

The writers share no code with the drivers (tests/test_layering.py), so a sentence the
driver reads back to the values written is one both ends understand the same way as the
documents, not one they misread alike."""

from __future__ import annotations

import calendar
import json
import math

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from pynmeagps import NMEAReader
from scipy.spatial.transform import Rotation

from onboard.core.messages import (
    Altitude,
    Attitude,
    Depth,
    DvlPosition,
    DvlVelocity,
    GnssFix,
    Heading,
    VehicleInfo,
    VelocityOverGround,
)
from onboard.drivers.dvl_json import DvlJsonParser, report_time
from onboard.drivers.nmea import KNOT_MPS, NmeaParser
from onboard.drivers.pd6 import Pd6Parser
from onboard.sitl import dvl_json_out, nmea_out, pd6_out
from onboard.sitl.sensors import GnssNoFix, HeadingInvalid
from onboard.sitl.emitters import (
    MAV_TYPE_SUBMARINE,
    MAV_TYPE_SURFACE_BOAT,
    DvlJsonEncoder,
    MavlinkEncoder,
    NmeaEncoder,
    Pd6Encoder,
    heartbeat_base_mode,
)

PUBLISHED_T = calendar.timegm((1994, 3, 23, 12, 35, 19))
"""12:35:19 UTC on 23 March 1994, the time of the published GGA and RMC examples."""
PUBLISHED = [b"$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n",
             b"$GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W*6A\r\n",
             b"$GPVTG,054.7,T,034.4,M,005.5,N,010.2,K*48\r\n"]
"""The GGA, RMC and VTG examples every NMEA primer gives, with their checksums (e.g. Dale
DePriest, "NMEA data"): 48 deg 07.038' N, 11 deg 31.000' E, fix 1, 8 satellites, HDOP
0.9, 545.4 m; 22.4 kn over ground at 84.4 deg true; VTG: 5.5 kn (10.2 km/h) at 54.7 deg."""
POSITION_TOL_DEG = 1e-7 / 60.0
"""Resolution of the simulator's latitude and longitude: 1e-7 minute (0.2 mm)."""
CASES = [  # (lat, lon): four hemispheres, 0, and a latitude a hair below a whole degree
    (48.1173, 11.516666666666667), (-33.8688, 151.2093), (64.1466, -21.9426),
    (-0.5, -179.99999), (0.0, 0.0), (42.99999999999, -71.0589)]


def _fixes(data: bytes) -> list:
    parser = NmeaParser(time_base="utc")
    out = parser.feed(data, 0.0) + parser.flush()
    assert not parser.stats.rejected, parser.stats.rejected
    return out


# --------------------------------------------------------------------------- NMEA


def test_the_published_sentences_and_ours_of_the_same_values_read_alike():
    published = _fixes(PUBLISHED[0] + PUBLISHED[1])
    ours = _fixes(nmea_out.gga(PUBLISHED_T, 48.1173, 11.0 + 31.0 / 60.0, 545.4, 1, 8, 0.9)
                  + nmea_out.rmc(PUBLISHED_T, 48.1173, 11.0 + 31.0 / 60.0, 22.4 * KNOT_MPS,
                                 math.radians(84.4)))
    (p,), (o,) = published, ours
    assert p.t == o.t == PUBLISHED_T
    assert p.lat_deg == pytest.approx(48.1173, abs=1e-12)
    assert (o.lat_deg, o.lon_deg) == pytest.approx((p.lat_deg, p.lon_deg), abs=POSITION_TOL_DEG)
    assert (o.fix_quality, o.num_sats, o.hdop, o.alt_m) == (1, 8, 0.9, 545.4)
    assert (p.fix_quality, p.num_sats, p.hdop, p.alt_m) == (1, 8, 0.9, 545.4)
    assert o.sog_mps == pytest.approx(p.sog_mps, abs=1e-12)
    assert o.cog_rad == pytest.approx(p.cog_rad, abs=1e-12)
    (p_vtg,) = _fixes(PUBLISHED[0] + PUBLISHED[2])  # speed and course from VTG alone
    (o_vtg,) = _fixes(PUBLISHED[0] + nmea_out.vtg(5.5 * KNOT_MPS, math.radians(54.7)))
    assert p_vtg.sog_mps == pytest.approx(5.5 * KNOT_MPS, abs=1e-12)
    assert o_vtg.sog_mps == pytest.approx(p_vtg.sog_mps, abs=1e-12)
    assert o_vtg.cog_rad == pytest.approx(p_vtg.cog_rad, abs=1e-12)


@pytest.mark.parametrize("lat, lon", CASES)
def test_gga_and_rmc_read_back_to_the_values_written(lat, lon):
    t = PUBLISHED_T + 3600.0 * 11 + 0.37
    gga = nmea_out.gga(t, lat, lon, -3.25, 4, 14, 0.6)
    rmc = nmea_out.rmc(t, lat, lon, 2.5, math.radians(359.999), 4)
    (fix,) = _fixes(gga + rmc)
    assert fix.t == pytest.approx(t, abs=1e-6)
    assert (fix.lat_deg, fix.lon_deg) == pytest.approx((lat, lon), abs=POSITION_TOL_DEG)
    assert (fix.alt_m, fix.fix_quality, fix.num_sats, fix.hdop) == (-3.25, 4, 14, 0.6)
    assert fix.sog_mps == pytest.approx(2.5, abs=0.0005 * KNOT_MPS)
    assert fix.cog_rad == pytest.approx(0.0, abs=1e-12)  # 359.999 deg is sent as 0.00
    for sentence in (gga, rmc):  # pynmeagps reads the same fields in the same places
        msg = NMEAReader.parse(sentence)
        assert (msg.lat, msg.lon) == pytest.approx((lat, lon), abs=POSITION_TOL_DEG)
    assert NMEAReader.parse(gga).quality == 4 and NMEAReader.parse(rmc).posMode == "R"


def test_the_time_and_the_date_come_from_one_rounded_instant():
    """Five thousandths before midnight rounds to midnight: 000000.00 of the next day."""
    midnight = calendar.timegm((2026, 1, 1, 0, 0, 0))
    rmc = nmea_out.rmc(midnight - 0.004, 10.0, 10.0, 0.0, None)
    assert rmc.split(b",")[1] == b"000000.00" and rmc.split(b",")[9] == b"010126"
    (fix,) = _fixes(rmc)
    assert fix.t == midnight and fix.cog_rad is None


def test_vtg_and_hdt_read_back_to_the_values_written():
    parser = NmeaParser(time_base="utc")
    out = parser.feed(nmea_out.gga(PUBLISHED_T, 1.0, 2.0, 0.0, 1, 9, 1.0)
                      + nmea_out.vtg(1.75, math.radians(123.456)) + nmea_out.hdt(-0.25), 0.0)
    out += parser.flush()
    fix = next(s for s in out if isinstance(s, GnssFix))
    head = next(s for s in out if isinstance(s, Heading))
    assert fix.sog_mps == pytest.approx(1.75, abs=0.0005 * KNOT_MPS)
    assert fix.cog_rad == pytest.approx(math.radians(123.46), abs=1e-12)
    assert head.heading_rad == pytest.approx(2 * math.pi - 0.25, abs=math.radians(0.005))
    assert head.reference == "true"
    vtg = NMEAReader.parse(nmea_out.vtg(1.75, None))
    assert vtg.cogt == "" and vtg.sogk == pytest.approx(1.75 * 3.6, abs=0.0005)


def test_every_checksum_is_right_and_one_changed_character_is_caught():
    """A negative control: the driver rejects a sentence with one digit changed."""
    sentences = [nmea_out.gga(PUBLISHED_T, *CASES[1], 1.0, 1, 8, 0.9),
                 nmea_out.rmc(PUBLISHED_T, *CASES[1], 1.0, 0.2),
                 nmea_out.vtg(1.0, 0.2), nmea_out.hdt(0.2)]
    for s in sentences:
        body, _, given = s.strip().partition(b"*")
        want = 0
        for c in body[1:]:
            want ^= c
        assert int(given, 16) == want
        bad = NmeaParser()
        bad.feed(s.replace(b"1", b"2", 1), 0.0)
        assert bad.stats.rejected == {"checksum": 1}


def test_the_nmea_encoder_sends_gga_rmc_vtg_per_fix_and_hdt_per_heading():
    enc = NmeaEncoder(epoch_s=PUBLISHED_T)
    frames = enc.encode([GnssFix(t=0.2, source="gnss", lat_deg=-12.5, lon_deg=130.8, alt_m=4.0,
                                 fix_quality=1, num_sats=10, hdop=0.8, sog_mps=1.0,
                                 cog_rad=1.0),
                         Heading(t=0.2, source="compass", heading_rad=1.1)])
    assert [f[:6] for f in frames] == [b"$GPGGA", b"$GPRMC", b"$GPVTG", b"$HEHDT"]
    fix, head = _fixes(b"".join(frames))
    assert fix.t == head.t == pytest.approx(PUBLISHED_T + 0.2)
    assert (fix.lat_deg, fix.lon_deg) == pytest.approx((-12.5, 130.8), abs=POSITION_TOL_DEG)
    assert head.heading_rad == pytest.approx(1.1, abs=math.radians(0.005))


def test_an_epoch_without_a_fix_is_sent_as_the_survey_boats_receiver_sends_it():
    """GGA quality 0, RMC ``V`` and VTG ``N`` with the position, speed and course empty
    (the field layout of ../shared/data/survey_boat_arduino_rc's receiver); pynmeagps
    reads them; the driver rejects each as ``no_fix``, counted, and takes no fix from
    them, but its UTC clock goes on."""
    t = PUBLISHED_T + 0.2
    gga, rmc, vtg = nmea_out.gga_no_fix(t), nmea_out.rmc_no_fix(t), nmea_out.vtg_no_fix()
    assert gga.split(b"*")[0] == b"$GPGGA,123519.20,,,,,0,00,,,M,0.000,M,,"
    assert rmc.split(b"*")[0] == b"$GPRMC,123519.20,V,,,,,,,230394,,,N,V"
    assert vtg.split(b"*")[0] == b"$GPVTG,,T,,M,,N,,K,N"
    g, r, v = (NMEAReader.parse(x) for x in (gga, rmc, vtg))
    assert (g.quality, g.lat, g.lon) == (0, "", "")
    assert (r.status, r.posMode, r.lat, r.spd) == ("V", "N", "", "")
    assert (v.posMode, v.cogt, v.sogn) == ("N", "", "")
    parser = NmeaParser(time_base="utc")
    out = parser.feed(gga + rmc + vtg, 0.0) + parser.flush()
    assert out == [] and parser.stats.rejected == {"no_fix": 2}
    assert parser.utc_time == pytest.approx(t)


def test_the_nmea_encoder_sends_an_epoch_without_a_fix():
    frames = NmeaEncoder(epoch_s=PUBLISHED_T).encode([GnssNoFix(t=0.4, source="gnss")])
    assert [f[:6] for f in frames] == [b"$GPGGA", b"$GPRMC", b"$GPVTG"]
    assert frames == [nmea_out.gga_no_fix(PUBLISHED_T + 0.4),
                      nmea_out.rmc_no_fix(PUBLISHED_T + 0.4), nmea_out.vtg_no_fix()]


def test_a_heading_epoch_without_a_heading_is_the_shenzhen_receivers_empty_hdt(shared_data):
    """An empty HDT is byte for byte the dual-antenna receiver's ``$GPHDT,,T*1B`` of the
    Shenzhen USV capture; the encoder sends one per HeadingInvalid; the driver rejects it
    as ``empty``, counted, and pynmeagps reads an empty heading."""
    ours = nmea_out.hdt(None, talker="GP")
    assert ours == b"$GPHDT,,T*1B\r\n"
    capture = shared_data / "usv_rtk_gnss_heading_nmea_shenzhen" / "202412051037.txt"
    assert capture.read_bytes().count(ours) == 4
    frames = NmeaEncoder(epoch_s=PUBLISHED_T).encode([HeadingInvalid(t=0.1, source="compass")])
    assert frames == [b"$HEHDT,,T*01\r\n"]
    assert NMEAReader.parse(frames[0]).headingT == ""
    parser = NmeaParser()
    assert parser.feed(frames[0], 0.0) == [] and parser.stats.rejected == {"empty": 1}


# --------------------------------------------------------------------------- Water Linked JSON

VELOCITY_FIELDS = {"time", "vx", "vy", "vz", "fom", "covariance", "altitude", "transducers",
                   "velocity_valid", "status", "tracking_mode", "format", "type",
                   "time_of_validity", "time_of_transmission"}
"""The velocity-and-transducer report's fields in Water Linked's json_v3.2 document."""
TRANSDUCER_FIELDS = {"id", "velocity", "distance", "rssi", "nsd", "beam_valid"}
POSITION_FIELDS = {"ts", "x", "y", "z", "std", "roll", "pitch", "yaw", "type", "status",
                   "format"}
"""The dead reckoning report's fields in the same document."""


def test_the_reports_carry_exactly_the_documented_fields():
    vel = json.loads(dvl_json_out.velocity_report(
        0.5, -0.2, 0.05, valid=True, fom_mps=0.002, altitude_m=3.0, dt_s=0.2,
        t_validity_s=PUBLISHED_T))
    assert set(vel) == VELOCITY_FIELDS
    assert len(vel["transducers"]) == 4
    assert all(set(b) == TRANSDUCER_FIELDS for b in vel["transducers"])
    assert [b["id"] for b in vel["transducers"]] == [0, 1, 2, 3]
    pos = json.loads(dvl_json_out.dead_reckoning_report(
        1.0, 2.0, 3.0, t_s=PUBLISHED_T, std_m=0.1, roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0))
    assert set(pos) == POSITION_FIELDS and pos["type"] == "position_local"


@pytest.mark.parametrize("track", ["bottom", "water"])
def test_a_velocity_report_reads_back_to_the_values_written(track):
    cov = (4e-6, 1e-7, 0.0, 1e-7, 5e-6, 0.0, 0.0, 0.0, 9e-6)
    line = dvl_json_out.velocity_report(0.61, -0.17, 0.033, valid=True, fom_mps=0.0024,
                                        altitude_m=7.5, dt_s=0.2, t_validity_s=PUBLISHED_T + 0.4,
                                        covariance=cov, track=track)
    parser = DvlJsonParser()
    (s,) = parser.feed(line, 100.0)
    assert isinstance(s, DvlVelocity) and not parser.stats.rejected
    assert (s.vx, s.vy, s.vz, s.fom_mps, s.covariance) == (0.61, -0.17, 0.033, 0.0024, cov)
    assert (s.track, s.valid, s.altitude_m) == (track, True, 7.5)
    assert report_time(json.loads(line)) == pytest.approx(PUBLISHED_T + 0.4, abs=1e-6)
    assert json.loads(line)["time"] == pytest.approx(200.0)


def test_a_report_without_lock_is_invalid_never_a_zero_velocity():
    line = dvl_json_out.velocity_report(0.61, -0.17, 0.033, valid=False, fom_mps=0.5,
                                        altitude_m=7.5, dt_s=0.2, t_validity_s=PUBLISHED_T)
    (s,) = DvlJsonParser().feed(line, 0.0)
    assert (s.valid, s.altitude_m) == (False, None)
    beams = json.loads(line)["transducers"]
    assert all(b["distance"] == -1.0 and not b["beam_valid"] for b in beams)


def test_a_report_flagged_while_locked_keeps_its_velocity_as_the_a50_s():
    """The A50 flags some reports invalid while its four beams see the bottom: they carry
    their velocity and altitude (../shared/data/waterlinked_dvl_a50_json_tank); the
    driver reads them as invalid with those values."""
    enc = DvlJsonEncoder(epoch_s=PUBLISHED_T)
    (line,) = enc.encode([DvlVelocity(t=0.2, source="dvl", vx=0.61, vy=-0.17, vz=0.033,
                                      valid=False, fom_mps=0.004, altitude_m=7.5)])
    obj = json.loads(line)
    assert (obj["velocity_valid"], obj["vx"], obj["altitude"]) == (False, 0.61, 7.5)
    assert all(b["beam_valid"] and b["distance"] > 7.5 for b in obj["transducers"])
    (s,) = DvlJsonParser().feed(line, 0.0)
    assert (s.valid, s.vx, s.altitude_m) == (False, 0.61, 7.5)


def test_the_four_beam_velocities_give_back_the_velocity():
    """The beams' velocities are the projections of one velocity: least squares over the
    four beam directions recovers it (and the distances the altitude)."""
    v = np.array([0.8, -0.3, 0.1])
    report = json.loads(dvl_json_out.velocity_report(
        *v, valid=True, fom_mps=0.002, altitude_m=4.0, dt_s=0.2, t_validity_s=PUBLISHED_T))
    b = np.array([dvl_json_out.beam_direction(a) for a in dvl_json_out.BEAM_AZIMUTHS_RAD])
    along = np.array([t["velocity"] for t in report["transducers"]])
    assert np.linalg.lstsq(b, along, rcond=None)[0] == pytest.approx(v, abs=1e-12)
    assert [t["distance"] * bz for t, bz in zip(report["transducers"], b[:, 2])] == \
        pytest.approx([4.0] * 4)


def test_a_dead_reckoning_report_reads_back_to_the_values_written():
    line = dvl_json_out.dead_reckoning_report(12.5, -3.25, 1.75, t_s=PUBLISHED_T + 1.5,
                                              std_m=0.04, roll_rad=0.01, pitch_rad=-0.02,
                                              yaw_rad=2.5)
    (s,) = DvlJsonParser().feed(line, 0.0)
    assert isinstance(s, DvlPosition)
    assert (s.north_m, s.east_m, s.down_m, s.std_m) == (12.5, -3.25, 1.75, 0.04)
    assert (s.roll_rad, s.pitch_rad, s.yaw_rad) == pytest.approx((0.01, -0.02, 2.5), abs=1e-12)
    assert report_time(json.loads(line)) == PUBLISHED_T + 1.5


def test_the_dvl_json_encoder_times_each_track_from_its_previous_report():
    enc = DvlJsonEncoder(epoch_s=PUBLISHED_T, period_s=0.25)
    lines = [json.loads(f) for t in (1.0, 1.2) for f in enc.encode([
        DvlVelocity(t=t, source="dvl", vx=0.5, vy=0.0, vz=0.0, fom_mps=0.002, altitude_m=3.0),
        DvlVelocity(t=t, source="dvl", vx=0.4, vy=0.0, vz=0.0, track="water")])]
    assert [r["type"] for r in lines] == ["velocity", "velocity_water"] * 2
    assert [r["time"] for r in lines] == pytest.approx([250.0, 250.0, 200.0, 200.0])


# --------------------------------------------------------------------------- PD6

ENSEMBLE_EPOCH = calendar.timegm((2026, 1, 1, 0, 0, 0))
"""Simulation time 0 of the PD6 tests (TS carries a two-digit year, read as 20yy)."""


def test_our_lines_have_the_widths_of_water_linkeds_example_output():
    """Water Linked's PD6 example (docs "PD formats", a DVL's output): the same values
    written here give the same lines, padding included."""
    when = calendar.timegm((2022, 2, 8, 12, 6, 18))
    assert pd6_out.sa(0.0, 0.0, 0.0) == b":SA, +0.00, +0.00,  0.00\r\n"
    assert pd6_out.ts(when, 0.0, 0.0, 0.0, 1475.0) == \
        b":TS,22020812061800, 0.0, +0.0,   0.0,1475.0,  0\r\n"
    assert pd6_out.ship_velocity(0.123, -0.420, -2.0, True) == b":BS,  -420,  +123, +2000,A\r\n"
    assert pd6_out.instrument_velocity(0.123, 0.420, -2.0, 0.0, True) == \
        b":BI,  +123,  -420, +2000,    +0,A\r\n"
    assert pd6_out.bottom_distance(0.0, 0.0, 0.0, 5.32, 0.0) == \
        b":BD,       +0.00,       +0.00,       +0.00,   5.32,  0.00\r\n"


def _ensemble(frame_kind: str, samples) -> list:
    parser = Pd6Parser(time_base="instrument", velocity_frame=frame_kind)
    out = parser.feed(b"".join(Pd6Encoder(epoch_s=ENSEMBLE_EPOCH).encode(samples)), 0.0)
    assert not parser.stats.rejected, parser.stats.rejected
    return out


ATT = Attitude(t=2.0, source="ahrs", roll_rad=0.05, pitch_rad=-0.08, yaw_rad=2.2)
BOTTOM = DvlVelocity(t=2.0, source="dvl", vx=0.734, vy=-0.121, vz=0.045, fom_mps=0.003,
                     altitude_m=6.25)
WATER = DvlVelocity(t=2.0, source="dvl", vx=0.412, vy=0.087, vz=-0.02, track="water",
                    fom_mps=0.01)
DEPTH = Depth(t=2.0, source="depth", depth_m=12.34, temperature_c=11.5)


@pytest.mark.parametrize("frame_kind", ["ship", "instrument"])
def test_an_ensemble_reads_back_to_the_values_written(frame_kind):
    out = _ensemble(frame_kind, [ATT, DEPTH, BOTTOM, WATER])
    t = ENSEMBLE_EPOCH + 2.0
    assert all(s.t == pytest.approx(t) for s in out)
    att = next(s for s in out if isinstance(s, Attitude))
    assert (att.roll_rad, att.pitch_rad, att.yaw_rad) == pytest.approx(
        (0.05, -0.08, 2.2), abs=math.radians(0.005))
    depth = next(s for s in out if isinstance(s, Depth))
    assert (depth.depth_m, depth.temperature_c) == pytest.approx((12.3, 11.5))
    dvl = {s.track: s for s in out if isinstance(s, DvlVelocity)}
    for track, want in (("bottom", BOTTOM), ("water", WATER)):
        got = dvl[track]
        assert got.valid
        assert (got.vx, got.vy, got.vz) == pytest.approx((want.vx, want.vy, want.vz), abs=5e-4)
        if frame_kind == "instrument":  # the error velocity: the figure of merit here
            assert got.fom_mps == pytest.approx(want.fom_mps, abs=5e-4)
    (alt,) = [s for s in out if isinstance(s, Altitude)]
    assert alt.altitude_m == 6.25


def test_the_earth_velocity_is_the_velocity_rotated_by_the_attitude():
    """BE against scipy's rotation (ZYX Euler angles: yaw, pitch, roll)."""
    (vog,) = [s for s in _ensemble("ship", [ATT, DEPTH, BOTTOM])
              if isinstance(s, VelocityOverGround)]
    r = Rotation.from_euler("ZYX", [ATT.yaw_rad, ATT.pitch_rad, ATT.roll_rad])
    want = r.apply([BOTTOM.vx, BOTTOM.vy, BOTTOM.vz])
    assert (vog.v_north_mps, vog.v_east_mps, vog.v_down_mps) == pytest.approx(want, abs=5e-4)


def test_a_bottom_report_without_lock_is_invalid_with_missing_components():
    lost = DvlVelocity(t=2.0, source="dvl", vx=0.0, vy=0.0, vz=0.0, valid=False)
    frame = b"".join(Pd6Encoder(epoch_s=ENSEMBLE_EPOCH).encode([ATT, lost]))
    assert b":BS,-32768,-32768,-32768,V\r\n" in frame
    parser = Pd6Parser()
    out = parser.feed(frame, 0.0)
    (dvl,) = [s for s in out if isinstance(s, DvlVelocity)]
    assert not dvl.valid
    assert not any(isinstance(s, (VelocityOverGround, Altitude)) for s in out)


def test_the_distance_made_good_sums_the_earth_velocity():
    enc = Pd6Encoder(epoch_s=ENSEMBLE_EPOCH)
    level = Attitude(t=0.0, source="ahrs", roll_rad=0.0, pitch_rad=0.0, yaw_rad=math.pi / 2)
    frames = [enc.encode([level, DvlVelocity(t=0.2 * k, source="dvl", vx=1.0, vy=0.0,
                                             vz=0.0, altitude_m=5.0)])[0] for k in range(11)]
    last_bd = frames[-1].split(b"\r\n")[-2].split(b",")
    assert last_bd[0] == b":BD"
    east, north, up = (float(x) for x in last_bd[1:4])
    assert (east, north, up) == pytest.approx((2.0, 0.0, 0.0), abs=0.005)  # 1 m/s east, 2 s


def test_the_heartbeat_base_mode_is_the_firmware_s(shared_data) -> None:
    """HEARTBEAT's base_mode as ArduPilot sets it (GCS_MAVLINK_Sub::base_mode,
    GCS_MAVLINK_Rover::base_mode), checked against the ArduSub tlog of ../shared/data,
    whose autopilot sends 81 disarmed and 209 armed in MANUAL (19); the simulator sent
    129 (armed, custom mode) for every vehicle and mode."""
    log = shared_data / "ardusub_small_logs" / "small.tlog"
    if not log.exists():
        pytest.skip(f"{log} not present")
    conn = mavutil.mavlink_connection(str(log))
    seen = set()
    while (hb := conn.recv_match(type="HEARTBEAT")) is not None:
        if hb.get_srcComponent() == 1:
            seen.add((hb.type, hb.custom_mode, hb.base_mode))
    assert seen == {(MAV_TYPE_SUBMARINE, 19, heartbeat_base_mode(MAV_TYPE_SUBMARINE, 19, a))
                    for a in (False, True)}
    assert heartbeat_base_mode(MAV_TYPE_SUBMARINE, 4) == 217  # GUIDED: guided flag too
    assert heartbeat_base_mode(MAV_TYPE_SURFACE_BOAT, 10) == 137  # Rover AUTO
    assert heartbeat_base_mode(MAV_TYPE_SURFACE_BOAT, 0) == 193  # Rover MANUAL
    enc = MavlinkEncoder(mav_type=MAV_TYPE_SURFACE_BOAT, custom_mode=10)
    frames = enc.encode([VehicleInfo(t=0.0, system_id=1, component_id=1,
                                     mav_type=MAV_TYPE_SURFACE_BOAT, autopilot=3)])
    parser = mavlink2.MAVLink(None)
    msgs = [m for f in frames for m in (parser.parse_buffer(f) or [])]
    assert [(m.get_type(), m.base_mode) for m in msgs] == [("HEARTBEAT", 137)]
