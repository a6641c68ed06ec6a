"""The integrity monitor's checks on synthetic samples (onboard/integrity.py)."""

from __future__ import annotations

import math

import numpy as np

from onboard.alerts import Alerts
from onboard.core.geo import LocalFrame
from onboard.core.messages import EstimateRecord, GnssFix, Heading, Innovation
from onboard.integrity import (
    HEADING_BOUND_RAD,
    IntegrityMonitor,
    NisCheck,
    crab_bound,
    nis_band,
)

LAT0, LON0 = 48.0, -4.0
FRAME = LocalFrame(LAT0, LON0)


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
    m = IntegrityMonitor(alerts, "rudder-boat")
    _boat(m, 73.5, 1.8)
    assert m.heading is not None and abs(math.degrees(m.heading.offset_rad) - 73.5) < 0.1
    assert "heading_course_mismatch" in alerts.codes()
    assert "73.5 deg" in next(iter(alerts)).message
    assert "north" in m.withheld("current") and "east" in m.withheld("current")
    assert m.withheld("aie") == ()


def test_a_crab_of_a_few_degrees_is_no_mismatch() -> None:
    alerts = Alerts()
    m = IntegrityMonitor(alerts, "rudder-boat")
    _boat(m, 8.0, 1.8)
    assert m.heading is not None and m.heading.mismatch is False
    assert not alerts.codes() and m.withheld("current") == ()


def test_the_bound_widens_with_the_crab_a_current_makes_at_low_speed() -> None:
    assert crab_bound(2.0) == HEADING_BOUND_RAD  # asin(0.5/2) = 14.5 deg < 25 deg
    assert math.degrees(crab_bound(0.6)) > 56.0  # asin(0.5/0.6) = 56.4 deg
    alerts = Alerts()
    m = IntegrityMonitor(alerts, "rudder-boat")
    _boat(m, 40.0, 0.6)  # 40 deg at 0.6 m/s: a 0.4 m/s cross current does that
    assert not alerts.codes()


def test_a_stopped_boat_is_not_judged_and_an_rov_never() -> None:
    alerts = Alerts()
    m = IntegrityMonitor(alerts, "rudder-boat")
    _boat(m, 90.0, 0.3)
    assert m.heading is not None and m.heading.offset_rad is None
    rov = IntegrityMonitor(alerts, "bluerov2")
    _boat(rov, 90.0, 1.0)
    assert rov.heading is None and not alerts.codes()


def test_the_mismatch_clears_when_the_heading_agrees_again() -> None:
    m = IntegrityMonitor(Alerts(), "rudder-boat")
    _boat(m, 73.5, 1.8)
    assert m.withheld("current")
    cog = math.radians(30.0)
    for k in range(20, 40):
        m.observe(Heading(t=k - 0.05, heading_rad=cog))
        m.observe(GnssFix(t=float(k), lat_deg=LAT0, lon_deg=LON0, sog_mps=1.8, cog_rad=cog))
    assert m.withheld("current") == ()


class _Pipe:
    """A pipeline as the position check sees it: its local frame."""

    frame = FRAME


def _positions(error_m: float, std_m: float) -> tuple[Alerts, IntegrityMonitor]:
    alerts = Alerts()
    m = IntegrityMonitor(alerts, "rudder-boat", fix_std_m=1.0)
    for k in range(40):
        t = float(k)
        lat, lon = FRAME.to_latlon(0.0, 0.0)
        m.observe(GnssFix(t=t, lat_deg=lat, lon_deg=lon, sog_mps=0.0, cog_rad=0.0))
        rec = EstimateRecord(vehicle="v", pipeline="aie", t=t + 0.05,
                             values={"north": error_m, "east": 0.0},
                             std={"north": std_m, "east": std_m})
        m.positions_at(t + 0.05, [rec], {"aie": _Pipe()})
    return alerts, m


def test_a_track_14_m_off_gnss_with_a_2_m_sigma_is_a_position_residual() -> None:
    alerts, m = _positions(14.0, 1.9)  # DDBoat: 14 m (median) with a stated 1.9 m
    assert "position_residual" in alerts.codes()
    assert m.active() == {"aie": ["position_residual"]}


def test_a_track_within_its_sigma_passes() -> None:
    alerts, m = _positions(2.0, 1.9)  # 2 m against sqrt(1.9^2 + 1^2) = 2.1 m
    assert not alerts.codes() and not m.active()


def test_the_nis_band_is_the_chi_square_band_of_the_running_mean() -> None:
    lo, hi = nis_band(1)
    # chi2(39) 2.5 % and 97.5 % quantiles / 39: 23.65 / 39 = 0.606, 58.12 / 39 = 1.490
    assert abs(lo - 0.606) < 0.01 and abs(hi - 1.490) < 0.01


def test_a_consistent_channel_stays_in_band_and_an_overconfident_one_does_not() -> None:
    rng = np.random.default_rng(1)
    ok = NisCheck(2)
    assert not any(ok.add(float(x)) for x in rng.chisquare(2, 2000))
    bad = NisCheck(2)
    assert any(bad.add(float(x)) for x in 4.0 * rng.chisquare(2, 200))


def test_nis_out_of_band_flags_the_pipeline_and_names_the_channel() -> None:
    alerts = Alerts()
    m = IntegrityMonitor(alerts)
    recs = [Innovation(channel="velocity", t=0.1 * k, z=(1.0, 1.0), S=(0.1, 0, 0, 0.1),
                       nis=20.0, dof=2) for k in range(100)]
    m.innovations("current", recs)
    assert m.active() == {"current": ["nis_out_of_band"]}
    assert "velocity" in next(iter(alerts)).message
