"""Issue 32: fixes that carry no course over ground (the DDBoat's) still have their heading
checked, against the course of their track (``onboard.monitor.track_course``;
docs/integrity.md, "A course from the track").

Each drive has a negative control: the heading along the track, and a vehicle at rest
whose fixes only scatter, stay silent.
"""

from __future__ import annotations

import math
import random

import pytest

from onboard.core.messages import ActuatorCommand, GnssFix, Heading
from onboard.monitor.alerts import Alerts
from onboard.monitor.integrity import IntegrityMonitor
from onboard.monitor.track_course import COURSE_MAX_STD_RAD, TrackCourse
from tests.helpers.watched import Boat

LAT0, LON0 = 48.2, -4.47
"""Near Brest, where the DDBoat log was taken."""


def _fix(t: float, n: float, e: float) -> GnssFix:
    """A fix at north/east ``n``/``e`` (m) from (LAT0, LON0), no course, no accuracy."""
    return GnssFix(t=t, source="g", lat_deg=LAT0 + n / 111_320.0,
                   lon_deg=LON0 + e / (111_320.0 * math.cos(math.radians(LAT0))))


def _drive(monitor: IntegrityMonitor, offset_deg: float, speed: float = 0.85,
           seconds: float = 240.0, fix_noise_m: float = 0.15, seed: int = 4,
           throttle: float | None = None) -> None:
    """The DDBoat's pattern: 1 Hz fixes of ``fix_noise_m`` of noise and no course, a
    compass at 10 Hz reading ``offset_deg`` off the track; straight legs of 40 s joined
    by 90 deg turns at 9 deg/s; a ``throttle`` command with each fix when given."""
    rng = random.Random(seed)
    n = e = chi = 0.0
    t = 0.0
    while t < seconds:
        t = round(t + 0.1, 6)
        if (t % 50.0) > 40.0:
            chi += math.radians(9.0) * 0.1
        n += speed * 0.1 * math.cos(chi)
        e += speed * 0.1 * math.sin(chi)
        monitor.observe(Heading(t=t, source="c", heading_rad=chi + math.radians(offset_deg)
                                + rng.gauss(0.0, 0.02)))
        if abs(t - round(t)) < 1e-6:
            if throttle is not None:
                monitor.observe(ActuatorCommand(t=t, source="m", throttle=throttle))
            monitor.observe(_fix(t, n + rng.gauss(0.0, fix_noise_m),
                                 e + rng.gauss(0.0, fix_noise_m)))


def test_a_heading_79_deg_off_the_track_is_flagged_without_a_receiver_course() -> None:
    monitor = IntegrityMonitor(Alerts())  # fixes taken at the default 2.0 m
    monitor.watch([Boat()])
    _drive(monitor, 79.0)
    assert monitor.heading is not None and monitor.heading.mismatch
    # measured: 213 windows judged, their mean heading - course 78.3-79.3 deg
    assert math.degrees(monitor.heading.offset_rad or 0.0) == pytest.approx(79.0, abs=3.0)
    assert {"heading", "north", "east", "std_heading"} <= set(monitor.withheld("aie"))
    assert "heading_course_mismatch" in {a.code for a in monitor.alerts}


def test_a_heading_along_the_track_stays_silent() -> None:
    """Negative control: the same drive, the compass true (turns included)."""
    monitor = IntegrityMonitor(Alerts())
    monitor.watch([Boat()])
    _drive(monitor, 0.0)
    assert monitor.heading is not None and monitor.heading.offset_rad is not None
    # measured: 213 windows judged, |mean heading - course| at most 0.7 deg (bound 25;
    # the mean heading over each chord follows the turns)
    assert abs(math.degrees(monitor.heading.offset_rad)) < 10.0
    assert monitor.active() == {} and list(monitor.alerts) == []


def test_a_vehicle_at_rest_gives_no_course() -> None:
    """Negative control: fixes scattering by 2 m about one point (the default accuracy)
    never lie far enough apart for a course, whatever the compass reads."""
    monitor = IntegrityMonitor(Alerts())
    monitor.watch([Boat()])
    _drive(monitor, 79.0, speed=0.0, fix_noise_m=2.0)
    assert monitor.heading is not None and monitor.heading.offset_rad is None
    assert monitor.active() == {}


@pytest.mark.parametrize("throttle", [-0.3, 0.3])
def test_a_vehicle_going_astern_is_not_taken_for_a_reversed_compass(throttle: float
                                                                    ) -> None:
    """Going astern the heading is opposite the track (the BlueBoat's reverse steps): no
    course is derived for 60 s after a command astern. Control: the same track and
    compass with the thrusters ahead is a compass 180 deg off, flagged."""
    monitor = IntegrityMonitor(Alerts())
    monitor.watch([Boat()])
    _drive(monitor, 180.0, throttle=throttle)
    assert monitor.heading is not None
    assert monitor.heading.mismatch is (throttle > 0)
    assert ("heading_course_mismatch" in {a.code for a in monitor.alerts}) is (throttle > 0)


def test_the_chord_is_long_enough_for_the_fixes_noise() -> None:
    """The course is taken from the latest earlier fix at least hypot(s0, s1) /
    COURSE_MAX_STD_RAD away (16.2 m for two 2 m fixes), with the mean heading over it."""
    track = TrackCourse()
    need = math.sqrt(2.0 * 4.0) / COURSE_MAX_STD_RAD
    assert need == pytest.approx(16.2, abs=0.1)
    out = []
    for k in range(30):
        track.heading(float(k), 0.3)
        out.append(track.fix(float(k), float(k), 0.0, 4.0))
    first = next(i for i, o in enumerate(out) if o is not None)
    assert first == math.ceil(need)
    sog, cog, heading = out[first]  # type: ignore[misc]
    assert sog == pytest.approx(1.0) and cog == pytest.approx(0.0, abs=1e-9)
    assert heading == pytest.approx(0.3)
