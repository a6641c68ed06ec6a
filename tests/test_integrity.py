"""The integrity monitor's checks on synthetic samples (onboard/monitor/integrity.py)."""

from __future__ import annotations

import math
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from onboard.monitor.alerts import Alerts
from onboard.core.geo import LocalFrame
from onboard.core.messages import DvlVelocity, GnssFix, Heading, Innovation
from onboard.monitor.integrity import (
    HEADING_BOUND_RAD,
    POSITION_SIGMA_BOUND,
    HeadingCourseCheck,
    IntegrityMonitor,
    NIS_BLOCK_UPDATES,
    NIS_SETTLE_S,
    NIS_SUSTAIN_BLOCKS,
    NisCheck,
    PositionCheck,
    SPEED_FLOOR_MPS,
    SpeedCheck,
    calibrated_nis,
    circular_mean,
    crab_bound,
    effective_count,
    nis_band,
)

LAT0, LON0 = 48.0, -4.0
FRAME = LocalFrame(LAT0, LON0)


def declared(name: str, *, position: tuple[str, ...] = (), speed: tuple[str, ...] = (),
             heading_dependent: tuple[str, ...] = (), frame: LocalFrame | None = None,
             frame_offset: tuple[float, float] | None = None) -> SimpleNamespace:
    """A pipeline as the monitor sees it: its name and its roles."""
    return SimpleNamespace(name=name, position=position, speed=speed,
                           heading_dependent=heading_dependent, frame=frame,
                           frame_offset=frame_offset)


CURRENT = declared("current", heading_dependent=("north", "east", "u_r", "v_r"))
"""A current pipeline as declared: its current and through-water velocity turn with the
heading."""
AIE = declared("aie", position=("north", "east"), speed=("speed",), frame=FRAME)
KF = declared("kf", position=("north", "east"), speed=("speed",), frame=FRAME)
ESESO = declared("eseso", position=("north", "east"), speed=("u", "v"), frame=FRAME,
                 frame_offset=(0.0, 0.0))


def monitor(alerts: Alerts, holonomic: bool = False, **kw: float) -> IntegrityMonitor:
    """A monitor watching :data:`CURRENT`, :data:`AIE`, :data:`KF` and :data:`ESESO`."""
    m = IntegrityMonitor(alerts, holonomic, **kw)
    m.watch([CURRENT, AIE, KF, ESESO])
    return m


def _boat(monitor: IntegrityMonitor, offset_deg: float, sog: float, seconds: int = 20,
          course_deg: float = 30.0) -> None:
    """A boat on a straight course at ``sog`` with its heading ``offset_deg`` off the
    course, one heading and one fix per second."""
    cog = math.radians(course_deg)
    for k in range(seconds):
        t = float(k)
        monitor.observe(Heading(t=t - 0.05, heading_rad=cog + math.radians(offset_deg)))
        n, e = sog * t * math.cos(cog), sog * t * math.sin(cog)
        lat, lon = FRAME.to_latlon(n, e)
        monitor.observe(GnssFix(t=t, lat_deg=lat, lon_deg=lon, sog_mps=sog, cog_rad=cog))


def test_a_heading_73_deg_off_the_course_is_a_mismatch_and_withholds_the_current() -> None:
    alerts = Alerts()
    m = monitor(alerts)
    _boat(m, 73.5, 1.8)
    assert m.heading is not None and abs(math.degrees(m.heading.offset_rad) - 73.5) < 0.1
    assert "heading_course_mismatch" in alerts.codes()
    assert "73.5 deg" in next(iter(alerts)).message
    assert "north" in m.withheld("current") and "east" in m.withheld("current")
    assert m.withheld("aie") == ()


def test_a_crab_of_a_few_degrees_is_no_mismatch() -> None:
    alerts = Alerts()
    m = monitor(alerts)
    _boat(m, 8.0, 1.8)
    assert m.heading is not None and m.heading.mismatch is False
    assert not alerts.codes() and m.withheld("current") == ()


def test_the_bound_widens_with_the_crab_a_current_makes_at_low_speed() -> None:
    assert crab_bound(2.0) == HEADING_BOUND_RAD  # asin(0.5/2) = 14.5 deg < 25 deg
    assert math.degrees(crab_bound(0.6)) > 56.0  # asin(0.5/0.6) = 56.4 deg
    alerts = Alerts()
    m = monitor(alerts)
    _boat(m, 40.0, 0.6)  # 40 deg at 0.6 m/s: a 0.4 m/s cross current does that
    assert not alerts.codes()


def test_a_stopped_boat_is_not_judged_and_an_rov_never() -> None:
    alerts = Alerts()
    m = monitor(alerts)
    _boat(m, 90.0, 0.3)
    assert m.heading is not None and m.heading.offset_rad is None
    rov = monitor(alerts, holonomic=True)
    _boat(rov, 90.0, 1.0)
    assert rov.heading is None and not alerts.codes()


def _first_mismatch(offset_deg: float, sog: float, period_s: float = 0.2,
                    first_offset_deg: float | None = None) -> float | None:
    """The time (s) of the first fix at which a boat whose heading is ``offset_deg`` off
    its course at ``sog`` (``first_offset_deg`` at its first fix), fixes and headings
    every ``period_s`` from t = 0, is judged a mismatch."""
    check = HeadingCourseCheck()
    cog = math.radians(30.0)
    for k in range(int(12.0 / period_s)):
        t = period_s * k
        off = math.radians(first_offset_deg if k == 0 and first_offset_deg is not None
                           else offset_deg)
        check.heading(t - 0.05, cog + off)
        if check.course(t, cog + off, sog, cog):
            return t
    return None


def test_a_heading_behind_the_course_at_speed_is_judged_before_the_window_fills() -> None:
    """Survey boat Test4: its compass 150 deg off the course at 2-3 m/s, and the aie
    speed -2.6 m/s (sigma 0.1) along that heading for 8 s before the 10-s window was
    judged. Fixes in a row beyond 90 deg at more than 1 m/s over ground: judged at the
    one 1 s after the first of them (Test4's 1 Hz receiver: at 20.7 s, where the window
    of 5 fixes over 3 s judged it at 23.7 s and 30 rows more gave the speed's wrong
    sign)."""
    assert _first_mismatch(150.0, 2.5) == pytest.approx(1.0)
    assert _first_mismatch(150.0, 2.5, period_s=1.0) == pytest.approx(1.0)
    # the first fix not behind: judged on the fixes after it, 1 s after the second
    assert _first_mismatch(150.0, 2.5, first_offset_deg=60.0) == pytest.approx(1.2)
    # below 90 deg, or drifting in a current at 0.8 m/s: judged when the window has
    # filled (8 s), as before
    assert _first_mismatch(60.0, 2.5) == pytest.approx(8.0)
    assert _first_mismatch(150.0, 0.8) == pytest.approx(8.0)


def test_a_heading_that_turns_behind_the_course_is_judged_on_its_newest_fixes() -> None:
    """A compass right for 6 s at 2.5 m/s, then 150 deg off (survey boat Test3, whose
    compass error follows the heading: its aie speed -0.4 to -1.0 m/s while it went
    ahead at 1.0-1.6 m/s). The window's mean would cross 90 deg only once the flipped
    fixes outweigh the right ones; its newest fixes, each behind at speed over 1 s, are
    judged at once, the offset theirs."""
    check = HeadingCourseCheck()
    cog = math.radians(30.0)
    verdicts = []
    for k in range(60):
        t = 0.2 * k
        off = math.radians(0.0 if t < 6.0 else 150.0)
        check.heading(t - 0.05, cog + off)
        verdicts.append((t, check.course(t, cog + off, 2.5, cog), check.behind))
    first = next(t for t, mismatch, behind in verdicts if mismatch)
    assert first == pytest.approx(7.0)
    assert check.behind and math.degrees(check.offset_rad) == pytest.approx(150.0)
    assert all(not mismatch for t, mismatch, behind in verdicts if t < 7.0)


def test_one_fix_behind_the_course_at_speed_withholds_the_speed_until_the_next() -> None:
    """A single fix whose course is beyond 90 deg off the heading at more than 1 m/s is
    no verdict, but the path speed's sign is then in doubt: withheld until a fix agrees
    (survey boat Test4: 19.7 s, a second before the window of two fixes flags it)."""
    aie = declared("aie", position=("north", "east"), speed=("speed",), frame=FRAME)
    aie.heading_estimate = ("heading",)
    m = IntegrityMonitor(Alerts())
    m.watch([aie])
    cog = math.radians(30.0)
    for k, off in enumerate((0.0, 0.0, 150.0, 0.0)):
        m.observe(Heading(t=k - 0.05, heading_rad=cog + math.radians(off)))
        m.observe(GnssFix(t=float(k), lat_deg=LAT0, lon_deg=LON0, sog_mps=2.0, cog_rad=cog))
        held = set(m.withheld("aie"))
        assert ({"speed", "std_speed"} <= held) is (off == 150.0), (k, held)
        assert "heading" not in held and not m.alerts.codes()


def test_a_path_speed_along_a_heading_behind_the_course_is_withheld() -> None:
    """The aie/kf path speed is signed along the heading: with the heading more than
    90 deg off the course at speed its sign is wrong (Test4: -2.6 m/s while the boat
    went ahead at 2.6), so it is withheld with the heading; at 73.5 deg (Shenzhen 1751)
    the heading is withheld and the speed, right, is kept."""
    aie = declared("aie", position=("north", "east"), speed=("speed",), frame=FRAME)
    aie.heading_estimate = ("heading",)
    for offset, speed_withheld in ((150.0, True), (73.5, False)):
        m = IntegrityMonitor(Alerts())
        m.watch([aie])
        _boat(m, offset, 1.8)
        assert {"heading", "std_heading", "north"} <= set(m.withheld("aie"))
        assert ({"speed", "std_speed"} <= set(m.withheld("aie"))) is speed_withheld


def test_the_mismatch_clears_when_the_heading_agrees_again() -> None:
    m = monitor(Alerts())
    _boat(m, 73.5, 1.8)
    assert m.withheld("current")
    cog = math.radians(30.0)
    for k in range(20, 40):
        m.observe(Heading(t=k - 0.05, heading_rad=cog))
        m.observe(GnssFix(t=float(k), lat_deg=LAT0, lon_deg=LON0, sog_mps=1.8, cog_rad=cog))
    assert m.withheld("current") == ()


def test_a_mismatch_withholds_until_they_agree_again_and_its_warning_says_so() -> None:
    """Shenzhen 202412051751's case: the boat stops after the mismatch (no verdict below
    the speed floor), so the current stays withheld to the end of the log; the warning
    says 'until they agree again' (before: 'while it lasts', its span ending at the stop)
    and names the command and the key that fix a constant offset."""
    alerts = Alerts()
    m = monitor(alerts)
    _boat(m, 73.5, 1.8)
    cog = math.radians(30.0)
    for k in range(20, 80):  # stopped: below the speed floor, not judged
        m.observe(Heading(t=k - 0.05, heading_rad=cog + math.radians(73.5)))
        m.observe(GnssFix(t=float(k), lat_deg=LAT0, lon_deg=LON0, sog_mps=0.05,
                          cog_rad=cog))
    assert m.withheld("current")
    (w,) = list(alerts)
    assert "current withheld until they agree again" in w.message
    assert "onboard diagnose LOG --write-config FILE" in w.message
    assert "[corrections] heading_offset_rad" in w.message
    assert "\n" not in w.message and "misaligned compass" in w.details


def test_withheld_rows_count_each_record_with_a_value_withheld() -> None:
    m = monitor(Alerts())
    for n in (4, 0, 2):
        m.count_withheld("current", n)
    assert m.flagged == {"current": 6} and m.withheld_rows == {"current": 2}


def _positions(error_m: float, std_m: float) -> tuple[Alerts, IntegrityMonitor]:
    alerts = Alerts()
    m = monitor(alerts, fix_std_m=1.0)
    for k in range(40):
        t = float(k)
        lat, lon = FRAME.to_latlon(0.0, 0.0)
        m.observe(GnssFix(t=t, lat_deg=lat, lon_deg=lon, sog_mps=0.0, cog_rad=0.0))
        m.positions_at(t + 0.05, [("aie", {"north": error_m, "east": 0.0,
                                           "std_north": std_m, "std_east": std_m})])
    return alerts, m


def test_a_track_14_m_off_gnss_with_a_2_m_sigma_is_a_position_residual() -> None:
    alerts, m = _positions(14.0, 1.9)  # DDBoat: 14 m (median) with a stated 1.9 m
    assert "position_residual" in alerts.codes()
    assert m.active() == {"aie": ["position_residual"]}


def test_a_track_within_its_sigma_passes() -> None:
    alerts, m = _positions(2.0, 1.9)  # 2 m against sqrt(1.9^2 + 1^2) = 2.1 m
    assert not alerts.codes() and not m.active()


def test_the_nis_band_is_the_chi_square_band_of_the_block_mean_or_the_coverage_target() -> None:
    # 20 effective updates: chi2(20) 0.5 % and 99.5 % quantiles / 20: 7.43 / 20 = 0.372,
    # 40.00 / 20 = 2.000 (wider than the coverage target's NIS)
    lo, hi = nis_band(1, 20.0)
    assert abs(lo - 0.372) < 0.02 and abs(hi - 2.000) < 0.03
    # 1-sigma coverage 0.6-0.8 is a sigma 0.84-1.28 times the true one: NIS 1.41-0.61
    c_lo, c_hi = calibrated_nis()
    assert abs(c_lo - 0.609) < 0.002 and abs(c_hi - 1.412) < 0.002
    # 100 white updates: chi2(100) gives [0.673, 1.402], narrower: the target is the band
    assert nis_band(1) == (c_lo, c_hi)
    assert nis_band(3) == (3 * c_lo, 3 * c_hi)


def test_the_effective_count_follows_the_lag_1_autocorrelation() -> None:
    assert effective_count(100, 0.0) == 100
    assert effective_count(100, -0.3) == 100               # never narrower than white
    assert abs(effective_count(100, 0.5) - 100 / 3) < 1e-9
    assert abs(effective_count(100, 0.99) - 100 * 0.1 / 1.9) < 1e-9   # clipped at 0.9


def test_a_consistent_channel_stays_in_band_and_an_overconfident_one_does_not() -> None:
    rng = np.random.default_rng(1)
    ok = NisCheck(2)
    assert not any(ok.add(float(x)) for x in rng.chisquare(2, 2000))
    bad = NisCheck(2)
    assert any(bad.add(float(x)) for x in 4.0 * rng.chisquare(2, NIS_SUSTAIN_BLOCKS * NIS_BLOCK_UPDATES))


def test_a_timid_channel_at_half_its_nis_is_flagged_below() -> None:
    # the simulator's GNSS increments before [sensors.gnss] drift_share: NIS 0.48-0.57
    rng = np.random.default_rng(2)
    check = NisCheck(1)
    assert any(check.add(float(x)) for x in 0.5 * rng.chisquare(1, 400))
    assert check.outside <= -2 and check.mean < check.band[0]


def test_a_consistent_channel_rarely_fires_in_an_hour() -> None:
    # 36000 white dof-1 updates (1 h at 10 Hz), 10 runs: none fires (measured 0 of 20
    # runs per dof 1-3; the old 20-update running mean fired in 20-25 % of them)
    rng = np.random.default_rng(3)
    fired = 0
    for _ in range(10):
        check = NisCheck(1)
        fired += any(check.add(x) for x in rng.chisquare(1, 36000).tolist())
    assert fired == 0


def test_correlated_but_consistent_innovations_widen_the_band_and_pass() -> None:
    # normalized innovations AR(1) with lag-1 correlation 0.95 (NIS correlation 0.9):
    # blocks of 100 vary like ~5 independent updates; white bands would fire
    rng = np.random.default_rng(4)
    z = np.empty(20000)
    z[0] = rng.standard_normal()
    for k in range(1, len(z)):
        z[k] = 0.95 * z[k - 1] + math.sqrt(1 - 0.95 ** 2) * rng.standard_normal()
    check = NisCheck(1)
    assert not any(check.add(x) for x in (z * z).tolist())
    assert check.rho > 0.7            # measured 0.87


def test_nis_out_of_band_flags_the_pipeline_and_names_the_channel() -> None:
    alerts = Alerts()
    m = IntegrityMonitor(alerts)
    recs = [Innovation(channel="velocity", t=0.1 * k, z=(1.0, 1.0), S=(0.1, 0, 0, 0.1),
                       nis=20.0, dof=2) for k in range(NIS_SUSTAIN_BLOCKS * NIS_BLOCK_UPDATES)]
    m.innovations("current", recs)
    assert m.active() == {"current": ["nis_out_of_band"]}
    assert "velocity" in next(iter(alerts)).message


def _speeds(pipeline: str, published: dict[str, float], sog: float | None = None,
            dvl_vx: float | None = None, std: float = 0.05) -> tuple[Alerts, IntegrityMonitor]:
    """40 s of one fix (speed over ground ``sog``) and/or one DVL report (forward
    ``dvl_vx``) a second, and ``pipeline`` publishing ``published`` with sigma ``std``."""
    alerts = Alerts()
    m = monitor(alerts)
    for k in range(40):
        t = float(k)
        if sog is not None:
            m.observe(GnssFix(t=t, lat_deg=LAT0, lon_deg=LON0, sog_mps=sog, cog_rad=0.0))
        if dvl_vx is not None:
            m.observe(DvlVelocity(t=t, vx=dvl_vx, vy=0.0, vz=0.0, fom_mps=0.01))
        values = {**published, **{"std_" + q: std for q in published}}
        m.speeds_at(t + 0.05, [(pipeline, values)])
    return alerts, m


def test_a_speed_of_2_m_s_against_a_doppler_1_2_m_s_is_a_speed_mismatch() -> None:
    # 0.8 m/s against sqrt(0.05^2 + 0.1^2) = 0.11 m/s: 7.2 sigma on every comparison
    alerts, m = _speeds("aie", {"speed": 2.0}, sog=1.2)
    assert "speed_mismatch" in alerts.codes()
    assert m.active() == {"aie": ["speed_mismatch"]}
    assert "0.80 m/s from the GNSS Doppler speed" in next(iter(alerts)).message
    # published as unknown while flagged, its sigma too (a frozen speed with a confident
    # sigma: a submerged AUV's aie at 0.11 +- 0.28 m/s while it cruises at 1.5)
    assert set(m.withheld("aie")) == {"speed", "std_speed"}
    assert m.withheld("kf") == ()
    # judged on the speed as computed, not as published: withheld, it still clears once
    # it agrees again (the published record no longer carries it)
    for k in range(40, 100):
        t = float(k)
        m.observe(GnssFix(t=t, lat_deg=LAT0, lon_deg=LON0, sog_mps=1.2, cog_rad=0.0))
        m.speeds_at(t + 0.05, [("aie", {"speed": 1.22, "std_speed": 0.05})])
    assert m.withheld("aie") == () and not m.active()
    _, ok = _speeds("aie", {"speed": 1.3}, sog=1.2)
    assert ok.withheld("aie") == ()


def test_a_speed_within_its_sigma_of_the_doppler_speed_passes() -> None:
    # 0.1 m/s against 0.11 m/s; astern (negative path speed) compares its magnitude
    for speed in (1.3, -1.3):
        alerts, m = _speeds("kf", {"speed": speed}, sog=1.2)
        assert not alerts.codes() and not m.active()


def test_a_doppler_speed_at_rest_is_not_judged_below_the_floor() -> None:
    # a boat at rest: the speed over ground of its noise against a 0.01 m/s sigma
    alerts, m = _speeds("aie", {"speed": 0.0}, sog=SPEED_FLOOR_MPS - 0.05, std=0.01)
    assert not alerts.codes()


def test_fixes_stamped_back_by_the_gnss_latency_are_still_compared() -> None:
    """With ``[corrections] gnss_latency_s`` a fix is stamped the latency before its
    arrival, so at the tick after it arrives it is older than :data:`FIX_MAX_AGE_S`: its
    age is counted from its arrival (Shenzhen 1751 with its diagnosed 1.25 s latency had
    no speed or position compared on any of its 2,897 fixes)."""
    def run(latency: float) -> IntegrityMonitor:
        m = IntegrityMonitor(Alerts(), gnss_latency_s=latency)
        m.watch([AIE])
        for k in range(40):
            t = float(k)   # arrived at t + 1.25, the tick at t + 1.3
            m.observe(GnssFix(t=t, lat_deg=LAT0, lon_deg=LON0, sog_mps=1.2, cog_rad=0.0))
            m.speeds_at(t + 1.3, [("aie", {"speed": 2.0, "std_speed": 0.05})])
        return m
    assert run(1.25).active() == {"aie": ["speed_mismatch"]}
    assert run(0.0).active() == {}   # the fixes taken as 1.3 s old: never compared


def _oscillating(amplitude: float, std: float, t_end: float = 60.0
                 ) -> tuple[Alerts, IntegrityMonitor, list[float]]:
    """A boat at rest (Doppler 0.02 m/s, 5 Hz) whose published speed swings
    ``amplitude * sin(2 pi t / 5 s)`` from t = 20 to 35 s, with sigma ``std``; the times
    at which the speed was flagged."""
    alerts = Alerts()
    m = monitor(alerts)
    flagged = []
    for k in range(int(t_end * 5)):
        t = 0.2 * k
        m.observe(GnssFix(t=t, lat_deg=LAT0, lon_deg=LON0, sog_mps=0.02, cog_rad=0.0))
        speed = amplitude * math.sin(2.0 * math.pi * t / 5.0) if 20.0 <= t < 35.0 else 0.0
        m.speeds_at(t + 0.05, [("aie", {"speed": speed, "std_speed": std})])
        if m.active().get("aie"):
            flagged.append(t)
    return alerts, m, flagged


def test_a_speed_swinging_through_many_sigmas_is_flagged_within_seconds() -> None:
    """An input estimator oscillating at rest (Shenzhen 1751 with the overlay diagnose
    wrote: 4.5 m/s swings with sigma 0.2-0.7 for 10 s) passes near zero twice a period,
    so half the 30-s window never fails; the gross rule flags it within the 10-s window,
    names the RMS, and clears once it is over."""
    alerts, m, flagged = _oscillating(3.0, 0.3)
    assert flagged and 20.0 < flagged[0] < 27.0
    assert 35.0 < flagged[-1] < 45.0   # cleared within the 10-s window after the swings
    warning = next(a for a in alerts if a.code == "speed_mismatch")
    assert "m/s RMS from the GNSS Doppler speed" in warning.message
    assert "sigma RMS" in warning.details
    # within its sigma (0.5 m/s swings, sigma 0.3) nothing is flagged; a swing the
    # fraction rule alone judges (3 m/s against sigma 2.5: 1.2 sigma RMS) neither
    assert not _oscillating(0.5, 0.3)[2] and not _oscillating(3.0, 2.5)[2]


def test_one_wild_doppler_speed_does_not_flag_a_good_estimate() -> None:
    alerts = Alerts()
    m = monitor(alerts)
    for k in range(200):
        t = 0.2 * k
        sog = 30.0 if k == 100 else 1.0   # one glitch: 29 m/s, hundreds of sigmas
        m.observe(GnssFix(t=t, lat_deg=LAT0, lon_deg=LON0, sog_mps=sog, cog_rad=0.0))
        m.speeds_at(t + 0.05, [("aie", {"speed": 1.0, "std_speed": 0.05})])
        assert not m.active()


def test_an_eseso_running_away_from_the_dvl_bottom_track_is_flagged() -> None:
    # small.BIN before the zero-velocity update: u 6.2 m/s on a bench (DVL 0 m/s)
    alerts, m = _speeds("eseso", {"u": 6.2, "v": 0.0}, dvl_vx=0.0, std=1.25)
    assert m.active() == {"eseso": ["speed_mismatch"]}
    assert "DVL" in next(iter(alerts)).message
    assert set(m.withheld("eseso")) == {"u", "v", "std_u", "std_v"}


def test_an_eseso_following_the_dvl_passes() -> None:
    alerts, m = _speeds("eseso", {"u": 0.52, "v": 0.1}, dvl_vx=0.5, std=0.03)
    assert not alerts.codes() and not m.active()


# ------------------------------------------------------------------ window bookkeeping
# The windows keep what each judgement needs as the comparisons come and go (counts, the
# sines and cosines); these tests hold them to a recomputation over the whole window.


def test_the_circular_mean_is_the_loop_over_sines_and_cosines() -> None:
    angles = np.random.default_rng(5).uniform(-4.0, 4.0, 200).tolist()
    s = c = 0.0
    for a in angles:  # the plain loop the mean was first written as
        s += math.sin(a)
        c += math.cos(a)
    # bit for bit where sum adds left to right (Python 3.11); from 3.12 on sum compensates
    # the rounding, for the kept columns as for circular_mean alike
    if sys.version_info < (3, 12):
        assert circular_mean(angles) == math.atan2(s, c)
    assert circular_mean(angles) == pytest.approx(math.atan2(s, c), abs=1e-12)
    assert circular_mean(iter(angles)) == circular_mean(angles)


def test_the_heading_window_mean_equals_the_circular_mean_of_its_differences() -> None:
    """Every judged window's offset, from the sines and cosines kept as fixes arrive, is
    bit for bit the circular mean of the window's differences, and its speed the mean."""
    rng = np.random.default_rng(3)
    check = HeadingCourseCheck()
    judged = 0
    diff: dict[float, float] = {}  # heading - course of each fix, by its time
    for k in range(600):  # 5 Hz for 120 s, with stops that empty the window
        t = 0.2 * k
        sog = 0.0 if 300 <= k < 400 else float(rng.uniform(0.6, 2.0))
        heading = float(rng.uniform(-math.pi, math.pi))
        check.heading(t - 0.05, heading)
        fix = GnssFix(t=t, lat_deg=LAT0, lon_deg=LON0, sog_mps=sog,
                      cog_rad=float(rng.uniform(-math.pi, math.pi)))
        diff[t] = heading - fix.cog_rad
        if check.fix(fix) is not None:
            judged += 1
            # the window's fixes are those at the times it keeps
            assert check.offset_rad == circular_mean(diff[x] for x in check._t)
            assert check.speed() == sum(check._sog) / len(check._sog)
        assert all(x >= t - 10.0 for x in check._t)
    assert judged > 300  # 420 of the 600 fixes judged


def test_the_position_and_speed_windows_count_their_failures_exactly() -> None:
    """The counts kept as comparisons come and go equal a recount of the window, and the
    verdicts follow them, through windows that fill with failures and empty again."""
    rng = np.random.default_rng(4)
    pos, speed = PositionCheck(), SpeedCheck()
    flips = speed_flips = 0
    for k in range(1000):  # 5 Hz; the error comes and goes every 40 s
        t = 0.2 * k
        err = 10.0 if (k // 200) % 2 else 1.0
        was, speed_was = pos.failing, speed.failing
        pos.add(t, (float(rng.normal(0.0, err)), float(rng.normal(0.0, err))), (4.0, 4.0))
        speed.add(t, float(rng.normal(0.0, 0.1 * err)), 0.01)
        flips += pos.failing != was
        speed_flips += speed.failing != speed_was
        assert pos.beyond == sum(1 for _, d, _ in pos._window if d > POSITION_SIGMA_BOUND)
        assert speed.failed == sum(1 for w in speed._window if w[2])
        assert pos.failing == (pos.beyond > 0.5 * len(pos._window))
    assert flips >= 4 and speed_flips >= 4  # each verdict changed 4 times


def test_a_failing_window_composes_its_warning_at_most_once_a_second(monkeypatch) -> None:
    """At 5 Hz a failing check fails at every fix; its message (two sorted medians) is
    composed only when the warning is raised, every WARN_EVERY_S."""
    composed = []
    median = PositionCheck.median_m
    monkeypatch.setattr(PositionCheck, "median_m",
                        lambda self: composed.append(1) or median(self))
    alerts = Alerts()
    m = monitor(alerts, fix_std_m=1.0)
    lat, lon = FRAME.to_latlon(0.0, 0.0)
    for k in range(200):  # 40 s at 5 Hz, 14 m off with a stated 1.9 m
        t = 0.2 * k
        m.observe(GnssFix(t=t, lat_deg=lat, lon_deg=lon, sog_mps=0.0, cog_rad=0.0))
        m.positions_at(t + 0.05, [("aie", {"north": 14.0, "east": 0.0,
                                           "std_north": 1.9, "std_east": 1.9})])
    warning = next(iter(alerts))
    assert warning.code == "position_residual" and warning.n == len(composed)
    assert len(composed) <= 40  # 40 of the 196 failing comparisons


def test_a_heading_mismatch_withholds_what_is_declared_heading_dependent_whatever_its_name(
        ) -> None:
    """The withheld outputs follow the declaration: a pipeline called ``flow`` that turns
    its ``v_x`` with the heading loses it; a ``current`` that declares nothing keeps all."""
    alerts = Alerts()
    m = IntegrityMonitor(alerts)
    m.watch([declared("flow", heading_dependent=("v_x",)), declared("current")])
    _boat(m, 73.5, 1.8)
    assert "heading_course_mismatch" in alerts.codes()
    assert m.withheld("flow") == ("v_x",) and m.withheld("current") == ()
    assert m.active() == {"flow": ["heading_course_mismatch"]}


def _positions_of(p: SimpleNamespace, error_m: float) -> IntegrityMonitor:
    """40 fixes at the frame's origin and ``p`` publishing its declared position
    ``error_m`` north of it (in its frame) with a 1.9 m sigma."""
    m = IntegrityMonitor(Alerts(), fix_std_m=1.0)
    m.watch([p])
    qn, qe = p.position or ("north", "east")
    off_n, off_e = p.frame_offset or (0.0, 0.0)
    lat, lon = FRAME.to_latlon(0.0, 0.0)
    for k in range(40):
        t = float(k)
        m.observe(GnssFix(t=t, lat_deg=lat, lon_deg=lon, sog_mps=0.0, cog_rad=0.0))
        m.positions_at(t + 0.05, [(p.name, {qn: off_n + error_m, qe: off_e,
                                            f"std_{qn}": 1.9, f"std_{qe}": 1.9})])
    return m


def test_the_position_check_reads_the_declared_columns_and_frame() -> None:
    """14 m off with a stated 1.9 m fails wherever the position is declared: under any
    name and column names, and in a frame whose origin sits at ``frame_offset`` in the
    published position; an ``aie`` that declares no position is not checked."""
    named = declared("x", position=("p_n", "p_e"), frame=FRAME)
    offset = declared("y", position=("north", "east"), frame=FRAME,
                      frame_offset=(100.0, -50.0))
    undeclared = declared("aie", frame=FRAME)
    assert _positions_of(named, 14.0).active() == {"x": ["position_residual"]}
    assert _positions_of(offset, 14.0).active() == {"y": ["position_residual"]}
    assert not _positions_of(offset, 2.0).active()  # the offset is taken off
    assert not _positions_of(undeclared, 14.0).active()


def test_the_doppler_comparison_takes_the_magnitude_of_the_declared_speed() -> None:
    """A forward and a sideways speed are compared as their horizontal magnitude: (1.0,
    1.2) m/s is 1.56 m/s, within the sigma of a 1.56 m/s Doppler speed; declared as the
    forward speed alone, 1.0 m/s is 0.56 m/s off at 0.11 m/s and fails."""
    for speed, failing in ((("u", "v"), False), (("u",), True)):
        alerts = Alerts()
        m = IntegrityMonitor(alerts)
        m.watch([declared("z", speed=speed)])
        for k in range(40):
            t = float(k)
            m.observe(GnssFix(t=t, lat_deg=LAT0, lon_deg=LON0, sog_mps=1.56, cog_rad=0.0))
            m.speeds_at(t + 0.05, [("z", {"u": 1.0, "v": 1.2, "std_u": 0.05, "std_v": 0.05})])
        assert ("speed_mismatch" in alerts.codes()) is failing


def test_a_channel_is_judged_against_the_sigma_its_pipeline_publishes() -> None:
    # the current's velocity rows at a quarter of their S (NIS 0.5 for 2): a filter too
    # timid by 4; its published sigma scaled by the factor 0.25 (algorithms.md §9.1) makes
    # them consistent with what is published, so no warning. Negative control: the same
    # innovations from a pipeline that publishes its filter's sigma (factor 1) are flagged.
    from onboard.estimators.noise_learning import ChannelNoise

    rng = np.random.default_rng(5)
    # 2 Hz: the settling (below the band is judged after it), then NIS_SUSTAIN_BLOCKS
    blocks = math.ceil(NIS_SETTLE_S / (0.5 * NIS_BLOCK_UPDATES)) + NIS_SUSTAIN_BLOCKS
    nis = (0.25 * rng.chisquare(2, blocks * NIS_BLOCK_UPDATES)).tolist()
    recs = [Innovation(channel="velocity", t=0.5 * k, z=(0.1, 0.1), S=(0.1, 0, 0, 0.1),
                       nis=x, dof=2) for k, x in enumerate(nis)]
    for published, flagged in (({"velocity": lambda: 0.25}, False), ({}, True)):
        alerts = Alerts()
        m = IntegrityMonitor(alerts)
        m.watch([SimpleNamespace(name="current", noise=ChannelNoise([], published))])
        m.innovations("current", recs)
        assert ("nis_out_of_band" in alerts.codes()) is flagged, published
