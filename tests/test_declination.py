"""Magnetic headings made true (onboard/engine/declination.py): the World Magnetic Model's value
against its published test values, the engine's rule for each heading, and the end
result: an NMEA log with magnetic headings (HDM) at a place with 12 degrees of
declination shows no false cross-track current.
"""

from __future__ import annotations

import calendar
import json
import math
import time
from pathlib import Path

import numpy as np
import pytest

from onboard.cli import main as cli_main
from onboard.core.config import Config, ConfigError, Corrections, from_dict
from onboard.core.messages import GnssFix, Heading
from onboard.engine.declination import (
    WAIT_FOR_FIX_S,
    DeclinationCorrector,
    decimal_year,
    wmm_declination,
)
from onboard.drivers.nmea import encode_gga, encode_hdm, encode_hdt, encode_rmc
from onboard.engine import Engine

# The published WMM-2025 test values (NOAA/NCEI and BGS, WMM2025 report; the file
# WMM2025_FINAL_TEST_VALUES.txt of NOAA's wmm package): decimal year, altitude (km above
# the ellipsoid), geodetic latitude and longitude (deg), declination (deg, 2 decimals).
WMM2025_TEST_VALUES = [
    (2025.0, 65, 43, 93, 0.50),
    (2025.0, 51, -33, 109, -5.49),
    (2025.5, 69, 38, -144, 12.93),
    (2026.0, 69, 23, 63, 1.17),
    (2026.5, 12, 33, -145, 11.96),
    (2027.0, 54, 54, 178, 0.63),
    (2028.5, 28, 54, -120, 15.43),
    (2029.0, 57, 34, -13, -1.89),
]

AKHIOK = (56.94, -154.17)
"""Akhiok, Kodiak Island, Alaska: WMM-2025 gives 12.4 deg east on 2026-07-01."""
JULY_2026 = float(calendar.timegm((2026, 7, 1, 18, 0, 0)))


@pytest.mark.parametrize("year,alt_km,lat,lon,dec", WMM2025_TEST_VALUES)
def test_wmm_declination_matches_the_published_test_values(year, alt_km, lat, lon, dec):
    got, model, _ = wmm_declination(lat, lon, year, alt_km)
    assert model == "WMM-2025"
    assert got == pytest.approx(dec, abs=0.006)  # the table's rounding


def test_the_model_is_chosen_by_date_and_the_nearest_extrapolated_outside_them():
    assert wmm_declination(48.4, -4.5, 2022.7)[1] == "WMM-2020"
    assert wmm_declination(48.4, -4.5, 2031.0)[1] == "WMM-2025 (extrapolated)"
    assert wmm_declination(48.4, -4.5, 2009.1)[1] == "WMM-2010 (extrapolated)"
    assert decimal_year(JULY_2026) == pytest.approx(2026.0 + (181 + 0.75) / 365, abs=1e-9)


def _hdm(t: float, deg: float, dec: float | None = None) -> Heading:
    return Heading(t=t, heading_rad=math.radians(deg), reference="magnetic",
                   declination_rad=None if dec is None else math.radians(dec))


def test_auto_uses_the_wmm_at_the_first_fix_and_leaves_true_headings_alone():
    c = DeclinationCorrector("auto")
    assert c.heading(_hdm(JULY_2026 - 1.0, 10.0))[1] == "wait"
    c.observe_fix(GnssFix(t=JULY_2026, lat_deg=AKHIOK[0], lon_deg=AKHIOK[1]))
    rep = c.report
    assert (rep.source, rep.model, rep.date_from) == ("wmm", "WMM-2025", "log")
    assert rep.deg == pytest.approx(12.4, abs=0.05)  # measured 12.39
    h, outcome = c.heading(_hdm(JULY_2026 + 1.0, 10.0))
    assert outcome == "corrected" and h.reference == "true" and h.declination_rad is None
    assert math.degrees(h.heading_rad) == pytest.approx(10.0 + rep.deg, abs=1e-9)
    true = Heading(t=JULY_2026 + 1.0, heading_rad=1.0)
    assert c.heading(true) == (true, "true")


def test_the_date_is_today_when_the_fixes_are_not_stamped_in_utc():
    c = DeclinationCorrector("auto", today=lambda: JULY_2026)
    c.observe_fix(GnssFix(t=123.4, lat_deg=AKHIOK[0], lon_deg=AKHIOK[1]))  # boot time
    assert c.report.date_from == "today" and c.report.year == pytest.approx(2026.497, abs=1e-3)


def test_the_override_and_the_sensor_s_own_declination_come_before_the_model():
    c = DeclinationCorrector(-3.5)
    h, _ = c.heading(_hdm(0.0, 100.0, dec=7.0))
    assert math.degrees(h.heading_rad) == pytest.approx(96.5)
    assert (c.report.deg, c.report.source) == (-3.5, "config")
    s = DeclinationCorrector("auto")
    h, _ = s.heading(_hdm(0.0, 100.0, dec=7.0))  # NMEA HDG's variation
    assert math.degrees(h.heading_rad) == pytest.approx(107.0)
    assert (s.report.deg, s.report.source) == (pytest.approx(7.0), "sensor")


def test_without_a_position_magnetic_headings_wait_then_pass_uncorrected_with_a_warning():
    cfg = Config()
    eng = Engine(cfg, pipelines=[])
    n = int(2 * WAIT_FOR_FIX_S)
    for i in range(n):
        eng.push(_hdm(100.0 + i, 45.0))
    # rejected while waiting for a fix, then used as they are and warned of
    assert eng.rejected["heading:no_declination"] == WAIT_FOR_FIX_S
    assert eng.accepted[("heading", "")] == n - WAIT_FOR_FIX_S
    assert "no_declination" in eng.alerts.codes()
    assert eng.health(100.0 + n).declination.source == "none"


def test_a_fix_after_the_wait_makes_the_warning_say_what_was_done_to_which_headings():
    """The survey boat's case: magnetic headings wait 30 s, are used as true until the
    first fix, corrected by the WMM's declination after it. The warning says both (before:
    'no GNSS position' while summary.json held the declination applied after the fix)."""
    eng = Engine(Config(), pipelines=[])
    for i in range(60):
        eng.push(_hdm(JULY_2026 + i, 45.0))
    eng.push(GnssFix(t=JULY_2026 + 60.0, lat_deg=AKHIOK[0], lon_deg=AKHIOK[1]))
    eng.push(_hdm(JULY_2026 + 61.0, 45.0))
    (w,) = [a for a in eng.alerts if a.code == "no_declination"]
    deg = eng.declination.report.deg
    assert w.message.startswith("magnetic headings used as true until the first GNSS fix, "
                                f"then corrected by {deg:+.1f} deg (wmm)")
    assert "[corrections] declination_deg" in w.message
    assert "30 magnetic heading(s) rejected" in w.details and "30 used as true" in w.details
    assert f"on {time.strftime('%Y-%m-%d', time.gmtime(JULY_2026 + 60.0))}" in w.details
    assert (w.t_start, w.t_end) == (JULY_2026 + 30.0, JULY_2026 + 59.0)  # the magnetic span
    assert eng.declination.uncorrected == 30   # the heading after the fix was corrected


def test_without_any_fix_the_warning_says_so_and_names_the_key():
    eng = Engine(Config(), pipelines=[])
    for i in range(40):
        eng.push(_hdm(100.0 + i, 45.0))
    (w,) = [a for a in eng.alerts if a.code == "no_declination"]
    assert w.message.startswith("magnetic headings used as true: no GNSS fix")
    assert "set declination_deg" in w.message


def test_a_date_outside_the_models_years_is_unreliable_and_said():
    """The survey boat's receiver stamps its only fix in February 2009 (its clock unset):
    the WMM is extrapolated back from WMM-2010; the run says so, with the key to set."""
    feb_2009 = calendar.timegm((2009, 2, 14, 17, 49, 33))
    c = DeclinationCorrector("auto")
    message, details = c.observe_fix(GnssFix(t=feb_2009, lat_deg=32.88, lon_deg=-117.23))
    assert c.report.model == "WMM-2010 (extrapolated)"
    assert "extrapolated to 2009-02-14" in message and "declination_deg" in message
    assert "default date" in details
    inside = DeclinationCorrector("auto")
    assert inside.observe_fix(GnssFix(t=JULY_2026, lat_deg=32.88, lon_deg=-117.23)) is None


def test_the_model_is_evaluated_once_a_run_not_per_sample(monkeypatch):
    """pygeomag is pure Python (~1 ms a call): the engine evaluates it at the first fix
    only; each magnetic heading after that is one addition."""
    import onboard.engine.declination as declination

    calls = []
    real = declination.wmm_declination
    monkeypatch.setattr(declination, "wmm_declination",
                        lambda *a, **k: calls.append(a) or real(*a, **k))
    eng = Engine(Config(), pipelines=[])
    for i in range(50):  # 10 s at 5 Hz, the boat moving ~1 km north
        t = JULY_2026 + 0.2 * i
        eng.push(GnssFix(t=t, lat_deg=AKHIOK[0] + 2e-4 * i, lon_deg=AKHIOK[1]))
        eng.push(_hdm(t + 0.1, 10.0))
    assert len(calls) == 1 and eng.accepted[("heading", "")] == 50
    assert eng.declination.report.lat_deg == AKHIOK[0]  # the first fix's position

def test_the_config_key_takes_degrees_or_auto_and_nothing_else():
    assert Corrections().declination_deg == "auto"
    assert from_dict({"corrections": {"declination_deg": 12}}).corrections \
        .declination_deg == 12
    with pytest.raises(ConfigError, match="declination_deg"):
        from_dict({"corrections": {"declination_deg": "west"}})


# ------------------------------------------------------------------- the NMEA log

SPEED_MPS = 1.5
LEGS = [(0.0, 60.0), (90.0, 60.0), (180.0, 60.0), (270.0, 60.0)] * 2
"""(true heading deg, seconds): a square run twice, turns of 90 deg at 10 deg/s (9 min)."""
TURN_RATE_DPS = 10.0
RATE_HZ = 5.0


def _track() -> list[tuple[float, float]]:
    """(true heading deg, seconds) every 1/RATE_HZ s: straight legs joined by turns."""
    out: list[tuple[float, float]] = []
    psi = LEGS[0][0]
    for heading, dur in LEGS:
        while abs((heading - psi + 180.0) % 360.0 - 180.0) > 1e-9:  # the turn
            step = (heading - psi + 180.0) % 360.0 - 180.0
            psi += max(-TURN_RATE_DPS / RATE_HZ, min(TURN_RATE_DPS / RATE_HZ, step))
            out.append((psi % 360.0, 1.0 / RATE_HZ))
        out += [(heading, 1.0 / RATE_HZ)] * int(dur * RATE_HZ)
    return out


def write_magnetic_nmea_log(path: Path, declination_deg: float, magnetic: bool = True) -> None:
    """A text capture of a boat in still water at Akhiok in July 2026: GGA + RMC at 5 Hz
    and after each epoch an HDM (the true heading minus ``declination_deg``), or an HDT
    with ``magnetic`` False. No current: the course over ground is the heading."""
    lat, lon = AKHIOK
    north = east = 0.0
    lines = []
    t = JULY_2026
    for psi_deg, dt in _track():
        psi = math.radians(psi_deg)
        la = lat + math.degrees(north / 6378137.0)
        lo = lon + math.degrees(east / (6378137.0 * math.cos(math.radians(lat))))
        lines.append(encode_gga(t, la, lo))
        lines.append(encode_rmc(t, la, lo, SPEED_MPS, psi))
        lines.append(encode_hdm(psi - math.radians(declination_deg)) if magnetic
                     else encode_hdt(psi))
        north += SPEED_MPS * math.cos(psi) * dt
        east += SPEED_MPS * math.sin(psi) * dt
        t += dt
    path.write_bytes(b"".join(lines))


def _replay(tmp_path: Path, log: Path, name: str, overrides: dict | None = None):
    """``onboard replay`` of ``log`` (a ``[corrections]`` table of ``overrides``): the
    summary, the RMS current (m/s) after the first leg and turn, its RMS component
    across the course over ground (m/s), and the share of rows that publish it."""
    args = ["replay", str(log), "--out", str(tmp_path / name), "--no-plot"]
    if overrides:
        cfg = tmp_path / f"{name}.toml"
        cfg.write_text("[corrections]\n" + "".join(f"{k} = {v}\n" for k, v in overrides.items()))
        args += ["--config", str(cfg)]
    assert cli_main(args) == 0
    summary = json.loads((tmp_path / name / "summary.json").read_text())
    data = np.genfromtxt(tmp_path / name / "estimates.csv", delimiter=",", names=True)
    late = data["t"] - data["t"][0] > 80.0
    cn, ce = data["currentnorth"][late], data["currenteast"][late]
    cog = data["navcourse"][late]
    cross = ce * np.cos(cog) - cn * np.sin(cog)
    return (summary, float(np.sqrt(np.nanmean(cn ** 2 + ce ** 2))),
            float(np.sqrt(np.nanmean(cross ** 2))), float(np.mean(np.isfinite(cn))))


def test_an_nmea_log_with_magnetic_headings_shows_no_false_cross_track_current(tmp_path):
    dec = wmm_declination(*AKHIOK, decimal_year(JULY_2026))[0]  # 12.39 deg
    log = tmp_path / "akhiok-hdm.nmea"
    write_magnetic_nmea_log(log, dec)
    summary, rms, cross, shown = _replay(tmp_path, log, "auto")
    assert summary["declination"]["source"] == "wmm"
    assert summary["declination"]["deg"] == pytest.approx(dec, abs=1e-9)
    # measured: 0.003 m/s RMS (0.0013 across the course), published on every row
    assert rms < 0.02 and cross < 0.02
    assert shown == 1.0
    # the same log with the declination switched off (declination_deg = 0): a 12.4-degree
    # heading error puts 1.5 sin(12.4 deg) = 0.32 m/s across the course (measured 0.29;
    # 0.42 m/s in all: the filter then misreads the water speed along the track too)
    summary0, rms0, cross0, _ = _replay(tmp_path, log, "off", {"declination_deg": 0})
    assert summary0["declination"]["source"] == "config"
    assert cross0 == pytest.approx(SPEED_MPS * math.sin(math.radians(dec)), rel=0.25)
    assert rms0 > 0.25


def test_true_headings_in_the_same_log_are_left_alone(tmp_path):
    log = tmp_path / "akhiok-hdt.nmea"
    write_magnetic_nmea_log(log, 0.0, magnetic=False)
    summary, rms, _, _ = _replay(tmp_path, log, "hdt")
    # the model is computed (the first fix) but applied to no heading
    assert summary["declination"]["source"] == "wmm"
    assert rms < 0.02  # measured 0.003 m/s
