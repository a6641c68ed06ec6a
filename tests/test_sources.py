"""One source per quantity (onboard/engine/sources.py): the selector alone and inside the engine.

Two GNSS receivers 3 m apart never average or alternate; the autopilot's ATTITUDE yaw is
used while fresh, VFR_HUD's whole-degree heading only when it is gone; a source dropping
out and returning gives a failover and a failback, each one event.
"""

from __future__ import annotations

import math
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as mav

from onboard.drivers.mavlink import MavlinkParser
from onboard.core.config import SourcePriorities, from_dict
from onboard.core.messages import Attitude, GnssFix, Heading, Sample
from onboard.engine import Engine
from onboard.engine.sources import SourceSelector, pattern_matches

LAT0, LON0 = 59.43, 10.47
"""Where the test boat sits (deg)."""


def _fix(t: float, source: str, east_m: float, quality: int = 1) -> GnssFix:
    lon = LON0 + math.degrees(east_m / (6378137.0 * math.cos(math.radians(LAT0))))
    return GnssFix(t=t, source=source, lat_deg=LAT0, lon_deg=lon, fix_quality=quality)


def _engine(**sources) -> Engine:
    cfg = from_dict({"vehicle": {"class": "rudder-boat"}, "sources": sources})
    return Engine(cfg, only={"nav"})


def _run(engine: Engine, samples: list[Sample], rate_hz: float = 10.0) -> list[tuple[float, dict]]:
    """Push ``samples`` (time-ordered) and tick at ``rate_hz``; the nav values per tick."""
    out = []
    samples = sorted(samples, key=lambda s: s.t)
    i = 0
    t_end = samples[-1].t
    k = 0
    while True:
        t = samples[0].t + k / rate_hz
        if t > t_end + 1.0 / rate_hz:
            break
        while i < len(samples) and samples[i].t <= t + 1e-9:
            engine.push(samples[i])
            i += 1
        recs = engine.tick(t)
        nav = next((r for r in recs if r.pipeline == "nav"), None)
        out.append((t, dict(nav.values) if nav else {}, dict(nav.sources) if nav else {}))
        k += 1
    return out


def test_patterns_match_sources_by_glob_and_mavlink_shorthand():
    assert pattern_matches("mavlink:ATTITUDE", "mavlink:1/ATTITUDE")
    assert pattern_matches("mavlink:ATTITUDE", "mavlink:2.191/ATTITUDE")
    assert not pattern_matches("mavlink:ATTITUDE", "mavlink:1/ATTITUDE_QUATERNION")
    assert pattern_matches("mavlink:1/GPS*", "mavlink:1/GPS2_RAW")
    assert not pattern_matches("mavlink:1/GPS*", "mavlink:2/GPS_RAW_INT")
    assert pattern_matches("gps*", "gps2") and not pattern_matches("gps", "gps2")


def test_two_receivers_3_m_apart_never_average_or_alternate_and_fail_over_on_staleness():
    """A at east 0 m and B at east 3 m, both at 5 Hz, A preferred. For 20 s nav.east is
    A's 0 m at every tick (no 1.5 m average, no jump to 3 m); A stops at 20 s: after
    stale_s (2 s) B is used, with one event; A is back at 30 s: after failback_s (3 s) of
    fresh A, A again, one event. Measured: exactly these three values and two switches."""
    a, b = "mavlink:1/GPS_RAW_INT", "gps-nmea"
    samples: list[Sample] = []
    for k in range(0, 250):  # 50 s at 5 Hz
        t = 0.2 * k
        if not 20.0 <= t < 30.0:
            samples.append(_fix(t + 0.01, a, 0.0))
        samples.append(_fix(t + 0.11, b, 3.0))
    eng = _engine(position=["mavlink:GPS_RAW_INT", "gps-nmea"], stale_s=2.0, failback_s=3.0)
    rows = _run(eng, samples)
    east = {round(t, 1): v.get("east") for t, v, _ in rows}
    used = {round(t, 1): s.get("position") for t, _, s in rows}
    for t, e in east.items():
        if e is None:
            continue
        assert abs(e) < 0.01 or abs(e - 3.0) < 0.01, f"t={t}: east {e} m is neither receiver"
    assert all(abs(east[t]) < 0.01 for t in east if 1.0 <= t <= 21.5)
    assert all(abs(east[t] - 3.0) < 0.01 for t in east if 22.5 <= t <= 32.5)
    assert all(abs(east[t]) < 0.01 for t in east if 33.5 <= t <= 49.0)
    assert used[10.0] == a and used[25.0] == b and used[45.0] == a
    switches = [e for e in eng.events if e.startswith("position:")]
    assert len(switches) == 3, switches  # the first choice, the failover, the failback
    assert "-> gps-nmea" in switches[1] and "silent" in switches[1]
    assert f"-> {a}" in switches[2]
    assert eng.selector.switches == 2
    # the switch happens on staleness only: not before A has been silent stale_s
    t_over = min(t for t, s in used.items() if s == b)
    assert 21.8 <= t_over <= 22.4, t_over  # A's last fix at 19.81 s
    t_back = min(t for t, s in used.items() if s == a and t > 30.0)
    assert 33.0 <= t_back <= 33.4, t_back


def test_a_receiver_without_fix_is_not_fresh():
    """Fix quality 0 does not keep a receiver active: B takes over after stale_s."""
    sel = SourceSelector(SourcePriorities(position=["a", "b"], stale_s=1.0))
    assert sel.admit(_fix(0.0, "a", 0.0)) is not None
    assert sel.admit(_fix(0.1, "b", 3.0)) is None
    for k in range(1, 20):
        sel.admit(_fix(0.1 * k, "a", 0.0, quality=0))  # the active source, no fix
    assert sel.admit(_fix(1.05, "b", 3.0)) is not None
    assert sel.active["position"] == "b"


def _mavlink_heading_stream(t_end: float, vfr_bias_deg: float, attitude_until: float | None,
                            attitude_from: float | None = None) -> list[Sample]:
    """From 1 s (a zero time stamp is refused) ATTITUDE at 10 Hz (yaw 0.5 rad + a slow
    turn) and VFR_HUD at 2 Hz (whole degrees,
    biased by ``vfr_bias_deg``), as real MAVLink 2 frames through the service's parser;
    ATTITUDE stops at ``attitude_until`` and resumes at ``attitude_from``."""
    m = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    parser = MavlinkParser()
    out: list[Sample] = []
    for k in range(int((t_end - 1.0) * 10) + 1):
        t = 1.0 + 0.1 * k
        yaw = 0.5 + 0.01 * t
        gap = attitude_until is not None and attitude_until <= t < (attitude_from or math.inf)
        if not gap:
            out += parser.feed(m.attitude_encode(int(t * 1000), 0.01, -0.02, yaw, 0.0, 0.0,
                                                 0.01).pack(m), t)
        if k % 5 == 0:
            hdg = int(round(math.degrees(yaw) + vfr_bias_deg))
            out += parser.feed(m.vfr_hud_encode(1.0, 1.0, hdg, 50, 0.0, 0.0).pack(m), t + 0.05)
    return out


def test_attitude_is_the_heading_while_fresh_and_vfr_hud_is_never_mixed_in():
    """ATTITUDE plus a VFR_HUD 10 degrees off: with the default priorities nav.heading is
    ATTITUDE's yaw at every tick (within 2e-3 rad: the newest ATTITUDE is up to one 0.1 s
    period of the 0.01 rad/s turn old), never VFR_HUD's (0.17 rad off, and its whole
    degrees alone up to 8.7e-3 rad). Measured: max difference 1.0e-3 rad over 20 s."""
    samples = _mavlink_heading_stream(20.0, vfr_bias_deg=10.0, attitude_until=None)
    assert {type(s) for s in samples} == {Attitude, Heading}
    eng = Engine(from_dict({"vehicle": {"class": "rudder-boat"}}), only={"nav"})
    rows = _run(eng, samples)
    worst = max(abs(v["heading"] - (0.5 + 0.01 * t)) for t, v, _ in rows if "heading" in v)
    assert worst < 2e-3, worst
    assert rows[-1][2]["heading"] == "mavlink:1/ATTITUDE"
    n_vfr = sum(1 for s in samples if s.source == "mavlink:1/VFR_HUD")
    assert eng.selector.standby[("heading", "mavlink:1/VFR_HUD")] == n_vfr


def test_aie_uses_attitude_not_the_one_degree_vfr_hud_heading():
    """The AIE and KF heading follow ATTITUDE (0.5 rad + 0.01 t) and not the VFR_HUD
    heading 10 degrees off: error < 2 degrees after 5 s. Measured: aie 0.03 deg, kf
    0.00 deg; with ``heading = ["mavlink:VFR_HUD"]`` (what surge_heading did before the
    selector: any Heading sample over ATTITUDE) 11.3 and 11.7 deg."""
    samples = _mavlink_heading_stream(30.0, vfr_bias_deg=10.0, attitude_until=None)
    for k in range(0, 151):  # a boat at rest, 5 Hz fixes
        samples.append(_fix(0.2 * k + 0.03, "mavlink:1/GPS_RAW_INT", 0.0))
    eng = Engine(from_dict({"vehicle": {"class": "rudder-boat"}}), only={"aie", "kf"})
    worst = 0.0
    samples.sort(key=lambda s: s.t)
    i = 0
    for k in range(301):
        t = 0.1 * k
        while i < len(samples) and samples[i].t <= t:
            eng.push(samples[i])
            i += 1
        for rec in eng.tick(t):
            if t >= 5.0 and "heading" in rec.values:
                err = abs(math.remainder(rec.values["heading"] - (0.5 + 0.01 * t), 2 * math.pi))
                worst = max(worst, err)
    assert math.degrees(worst) < 2.0, math.degrees(worst)


def test_attitude_drops_out_vfr_hud_takes_over_then_attitude_comes_back():
    """ATTITUDE stops at 10 s and returns at 20 s: VFR_HUD (here unbiased, whole degrees)
    is the heading from stale_s after the drop-out, ATTITUDE again failback_s after its
    return; one event each. Measured: switch at 12.05 s and back at 23.0 s."""
    samples = _mavlink_heading_stream(30.0, vfr_bias_deg=0.0, attitude_until=10.0,
                                      attitude_from=20.0)
    eng = Engine(from_dict({"vehicle": {"class": "rudder-boat"}}), only={"nav"})
    rows = _run(eng, samples)
    used = {round(t, 1): s.get("heading") for t, _, s in rows}
    assert used[9.0] == "mavlink:1/ATTITUDE"
    assert used[15.0] == "mavlink:1/VFR_HUD"
    assert used[25.0] == "mavlink:1/ATTITUDE"
    heading = {round(t, 1): v.get("heading") for t, v, _ in rows}
    assert abs(math.degrees(heading[15.0]) - round(math.degrees(0.5 + 0.01 * 14.55))) < 1e-6
    events = [e for e in eng.events if e.startswith("heading:")]
    assert len(events) == 3, events
    assert "VFR_HUD" in events[1] and "silent" in events[1]
    assert events[2].startswith("heading: mavlink:1/VFR_HUD -> mavlink:1/ATTITUDE")
    t_over = min(t for t, s in used.items() if s == "mavlink:1/VFR_HUD")
    t_back = min(t for t, s in used.items() if s == "mavlink:1/ATTITUDE" and t > 20.0)
    assert 12.0 <= t_over <= 12.6 and 23.0 <= t_back <= 23.2, (t_over, t_back)


def test_an_attitude_not_chosen_for_heading_keeps_roll_and_pitch_without_yaw():
    """heading = [compass, ATTITUDE]: while the compass is fresh ATTITUDE passes with
    yaw_selected False (its roll and pitch still used); the compass gone, its yaw is the
    heading."""
    sel = SourceSelector(SourcePriorities(heading=["compass", "mavlink:ATTITUDE"],
                                          stale_s=1.0))
    att = Attitude(t=0.0, source="mavlink:1/ATTITUDE", roll_rad=0.1, pitch_rad=0.0, yaw_rad=1.0)
    sel.admit(Heading(t=0.0, source="compass", heading_rad=1.1))
    a0 = sel.admit(att)
    assert isinstance(a0, Attitude) and a0.yaw_selected is False and a0.roll_rad == 0.1
    a1 = sel.admit(Attitude(t=1.5, source="mavlink:1/ATTITUDE", roll_rad=0.1, pitch_rad=0.0,
                            yaw_rad=1.0))
    assert isinstance(a1, Attitude) and a1.yaw_selected is True
    assert sel.active["heading"] == "mavlink:1/ATTITUDE"


def test_an_excluded_source_is_never_used():
    """``!mavlink:SCALED_PRESSURE`` (ArduSub's enclosure barometer) is not a depth even
    when it is the only pressure."""
    from onboard.core.messages import Depth

    sel = SourceSelector(SourcePriorities())
    assert sel.admit(Depth(t=0.0, source="mavlink:1/SCALED_PRESSURE", depth_m=0.0)) is None
    assert sel.admit(Depth(t=0.1, source="mavlink:1/SCALED_PRESSURE2", depth_m=5.0)) is not None
    assert "depth" in sel.active and sel.active["depth"] == "mavlink:1/SCALED_PRESSURE2"


def test_health_and_estimates_name_the_active_sources():
    eng = _engine()
    eng.push(_fix(1.0, "mavlink:1/GPS_RAW_INT", 0.0))
    recs = eng.tick(1.0)
    assert recs[0].sources == {"position": "mavlink:1/GPS_RAW_INT"}
    h = eng.health(1.5)
    assert h.sources == {"position": "mavlink:1/GPS_RAW_INT"}
    assert any(e.startswith("position: using mavlink:1/GPS_RAW_INT") for e in h.events)


def test_the_same_samples_give_the_same_choices():
    """The selector is a pure function of the samples and their times (replay = live)."""
    a = _engine(position=["x", "y"])
    b = _engine(position=["x", "y"])
    samples = [_fix(1.0 + 0.3 * k, "x" if (k // 7) % 3 else "y", 3.0 * (k % 2)) for k in range(60)]
    ra, rb = _run(a, list(samples)), _run(b, list(samples))
    assert ra == rb and a.events == b.events


def test_unlisted_heading_sources_prefer_the_ahrs_yaw_over_a_bare_compass():
    """A compass (Heading) and an AHRS (Attitude) that no pattern names: the AHRS is the
    heading, also when the compass came first (the start-up choice is corrected)."""
    sel = SourceSelector(SourcePriorities())
    assert sel.admit(Heading(t=1.0, source="compass", heading_rad=1.0)) is not None
    a = sel.admit(Attitude(t=1.0, source="ahrs", roll_rad=0.0, pitch_rad=0.0, yaw_rad=1.0))
    assert isinstance(a, Attitude) and a.yaw_selected
    assert sel.admit(Heading(t=1.1, source="compass", heading_rad=1.0)) is None
    assert sel.active["heading"] == "ahrs" and sel.switches == 0


def test_a_recording_replays_the_live_choices_exactly(tmp_path):
    """Two receivers as real NMEA bytes (one drops out for 8 s) and a gpsd input through
    the intake with a recorder, as the service runs them; the replay of the recording
    gives the same estimates, the same active sources and the same switch events."""
    from onboard.drivers.nmea import encode_gga, encode_rmc
    from onboard.service.intake import Intake
    from onboard.service.recorder import Recorder, replay_recording

    cfg = from_dict({"vehicle": {"class": "rudder-boat"},
                     "sources": {"position": ["gps-a", "gps-b"]}})
    gpsd_lines = [ln for ln in (Path(__file__).parent / "data" / "gpsd" / "boat.jsonl")
                  .read_bytes().split(b"\n") if ln.strip()]
    rec = Recorder(tmp_path / "rec", fsync=False, clock=lambda: 0.0)
    live = Engine(cfg, only={"nav"})
    intake = Intake(live, recorder=rec)
    out_live = []
    for k in range(300):  # 30 s at 10 Hz ticks, fixes at 1 Hz on each receiver
        t = 100.0 + 0.1 * k
        if k % 10 == 0:
            tod = 43200.0 + k / 10
            for name, east in (("gps-a", 0.0), ("gps-b", 3.0)):
                if name == "gps-a" and 10 <= k / 10 < 18:  # gps-a silent 8 s
                    continue
                lon = LON0 + math.degrees(east / (6378137.0 * math.cos(math.radians(LAT0))))
                data = encode_gga(tod, LAT0, lon, 5.0, 1, 9, 0.9) + encode_rmc(tod, LAT0, lon,
                                                                               0.0, 0.0)
                intake.chunk(name, "nmea", data, t + (0.01 if name == "gps-a" else 0.02))
        if k < len(gpsd_lines):
            intake.chunk("gnss", "gpsd", gpsd_lines[k] + b"\n", t + 0.03)
        out_live.append([(r.pipeline, r.values, r.sources) for r in intake.tick(t + 0.05)])
    rec.close()
    events_live = [e for e in live.events if e.startswith("position:")]
    assert len(events_live) == 3, events_live  # gps-a, -> gps-b (silent), -> gps-a
    out_replay = []
    again = Engine(cfg, only={"nav"})
    replay_recording(rec.files, again, lambda t, recs: out_replay.append(
        [(r.pipeline, r.values, r.sources) for r in recs]))
    assert out_replay == out_live
    assert [e for e in again.events if e.startswith("position:")] == events_live
    assert again.selector.standby == live.selector.standby
    assert live.selector.standby[("position", "gnss")] > 10  # the gpsd fixes, held back


def test_receiver_speed_and_ekf_velocity_are_one_quantity():
    """GPS_RAW_INT's speed and course and GLOBAL_POSITION_INT's velocity are two sources
    of the velocity: with the defaults the fix keeps its position but loses its speed and
    course while the EKF velocity is fresh; when that stops, the receiver's speed and
    course are the velocity again (a failover with its event)."""
    from onboard.core.messages import VelocityOverGround

    sel = SourceSelector(SourcePriorities(stale_s=1.0))
    gps, ekf = "mavlink:1/GPS_RAW_INT", "mavlink:1/GLOBAL_POSITION_INT"

    def fix(t):
        return GnssFix(t=t, source=gps, lat_deg=LAT0, lon_deg=LON0, sog_mps=1.0, cog_rad=0.5)

    assert sel.admit(VelocityOverGround(t=1.0, source=ekf, v_north_mps=1.0,
                                        v_east_mps=0.0)) is not None
    f = sel.admit(fix(1.1))
    assert isinstance(f, GnssFix) and f.sog_mps is None and f.cog_rad is None
    assert f.lat_deg == LAT0  # the position still passes
    f = sel.admit(fix(2.5))  # the EKF velocity silent for 1.5 s
    assert isinstance(f, GnssFix) and f.sog_mps == 1.0 and f.cog_rad == 0.5
    assert sel.active == {"velocity": gps, "position": gps}
    assert any(e.startswith(f"velocity: {ekf} -> {gps}") for e in sel.events)
    # a second receiver that is the velocity but not the position gives a velocity sample
    sel2 = SourceSelector(SourcePriorities(position=["a"], velocity=["b"]))
    sel2.admit(GnssFix(t=1.0, source="a", lat_deg=LAT0, lon_deg=LON0))
    v = sel2.admit(GnssFix(t=1.0, source="b", lat_deg=LAT0, lon_deg=LON0, sog_mps=2.0,
                           cog_rad=math.pi / 2))
    assert isinstance(v, VelocityOverGround) and abs(v.v_east_mps - 2.0) < 1e-12
