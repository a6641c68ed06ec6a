"""A Slocum glider's mission, written as the glider writes it: its ``.dbd`` flight log
(:mod:`sitl.slocum_out`) and, beside it, the truth of every dive's depth-averaged current.

The glider (:class:`sitl.plants.glider.SlocumGlider`, Merckelbach et al. 2019) flies a
transect between two waypoints 4 km apart in a sea of a tidal stream with a bed layer
(Soulsby's profile, 250 m deep), a drifting eddy and a background flow
(:mod:`sitl.current_field`), with a vertical water velocity of internal waves. A dive is
``yos`` yos between 10 m and its target depth, pumped to -``pump_cc`` down and
+``pump_cc`` up at a pitch of 26 deg; at the surface it floats (drifting with the surface
water) for ``surface_s``, its GPS fixing every cycle after ``GPS_ACQUIRE_S``.

Its log, a cycle every ``CYCLE_S``: ``m_present_time`` (UTC), ``m_depth`` (pressure
noise), ``m_pitch`` (a bias and noise), ``m_roll``, ``m_heading`` (the compass's
deviation, a sine of the heading, and noise), ``c_fin``, ``m_battpos``, ``m_de_oil_vol``
(where it changed), ``m_gps_lat`` / ``m_gps_lon`` (at the surface, with the receiver's
noise). What differs from seed to seed, none of it known to a config: the drag (fouling),
the ballast's trim, the pitch sensor's bias, the compass's deviation, the GPS's noise, the
sea's phase and eddy.

The truth of a dive: the water's velocity at the glider, averaged over the time from the
last fix before the dive to the first after it, as the glider met it (the depth-averaged
current of the OceanGliders DAC procedure, its surface drift included).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from onboard.sitl.current_field import LambOseenEddy, SeaField, TidalChannel, UniformFlow
from onboard.sitl.frames import GeoOrigin, wrap_pi
from onboard.sitl.plants.glider import SlocumGlider
from onboard.sitl.slocum_out import DbdWriter, ddmm

DT_S = 1.0
"""Simulation step (s)."""
CYCLE_S = 4.0
"""The glider's log cycle (s)."""
GPS_ACQUIRE_S = 60.0
"""Time (s) at the surface before the first fix."""
INFLECT_TOP_M = 10.0
"""Depth (m) at which a climb that is not the dive's last turns down again."""
DIVE_PITCH_RAD = math.radians(26.0)
"""The pitch set point of a dive and a climb (rad)."""
HEADING_TIME_CONSTANT_S = 30.0
"""Time constant (s) of the heading toward the waypoint's bearing."""
FIN_HUNT_RAD = math.radians(3.0)
"""Amplitude (rad) of the heading's hunting about its set point (period FIN_HUNT_S)."""
FIN_HUNT_S = 90.0
TRANSECT_M = 4000.0
"""Distance (m) between the two waypoints."""
ORIGIN = (36.60, -121.95)
"""The transect's first waypoint (lat, lon; deg)."""
T0_UTC = 1_790_000_000.0
"""The mission's start (s since the Unix epoch; 2026-09-21)."""
SENSORS = [("m_present_time", "timestamp", 8), ("m_gps_lat", "lat", 8),
           ("m_gps_lon", "lon", 8), ("m_heading", "rad", 4), ("m_pitch", "rad", 4),
           ("m_roll", "rad", 4), ("m_depth", "m", 4), ("c_fin", "rad", 4),
           ("m_battpos", "in", 4), ("m_de_oil_vol", "cc", 4)]
"""The flight log's sensors (name, units, bytes)."""


@dataclass(frozen=True)
class GliderErrors:
    """What makes one glider and its sea differ from another (drawn per seed)."""

    cd0: float
    hull_lift: float
    compressibility: float
    trim_cc: float
    pitch_bias_rad: float
    deviation_rad: float
    deviation_phase: float
    gps_std_m: float
    internal_wave_m: float
    wave_periods_s: tuple[float, float]
    wave_lengths_m: tuple[float, float]
    wave_phases: tuple[float, float]

    @classmethod
    def draw(cls, rng: np.random.Generator) -> GliderErrors:
        """A glider: drag 0.12-0.20, hull lift 2.8-4.8 /rad, compressibility 3-7e-10
        /Pa (Merckelbach et al.'s 0.15, 3.8 and 5e-10 within), trim +-15 cm^3 (one
        sigma), pitch bias 0.5 deg, compass deviation up to 4 deg, GPS 2-6 m, internal
        waves that displace the water by 1-8 m RMS in two modes (periods 20-120 min,
        vertical wavelengths 50-200 m)."""
        return cls(cd0=float(rng.uniform(0.12, 0.20)), hull_lift=float(rng.uniform(2.8, 4.8)),
                   compressibility=float(rng.uniform(3e-10, 7e-10)),
                   trim_cc=float(rng.normal(0, 15.0)),
                   pitch_bias_rad=float(rng.normal(0, math.radians(0.5))),
                   deviation_rad=float(rng.uniform(0, math.radians(4.0))),
                   deviation_phase=float(rng.uniform(0, 2 * math.pi)),
                   gps_std_m=float(rng.uniform(2.0, 6.0)),
                   internal_wave_m=float(rng.uniform(1.0, 8.0)),
                   wave_periods_s=_pair(rng.uniform(1200.0, 7200.0, 2)),
                   wave_lengths_m=_pair(rng.uniform(50.0, 200.0, 2)),
                   wave_phases=_pair(rng.uniform(0.0, 2 * math.pi, 2)))

    def vertical_water(self, t: float, depth: float) -> float:
        """The internal waves' vertical velocity (m/s, up) at ``t`` (s) and ``depth``
        (m): two modes, each displacing the water by ``internal_wave_m`` in amplitude
        (their sum's RMS), ``eta = a sin(2 pi (t / P + z / L) + phi)``, ``w = d eta /
        dt``."""
        return self.internal_wave_m * sum(
            2 * math.pi / p * math.cos(2 * math.pi * (t / p + depth / length) + phase)
            for p, length, phase in zip(self.wave_periods_s, self.wave_lengths_m,
                                        self.wave_phases))


def _pair(x: np.ndarray) -> tuple[float, float]:
    return float(x[0]), float(x[1])


def sea(rng: np.random.Generator) -> SeaField:
    """The glider's sea: a tidal stream (0.15-0.3 m/s, the M2 at a random phase) over a
    250-m bed, an eddy of 3 km core drifting across the transect, a background flow."""
    return SeaField(ORIGIN, (
        TidalChannel(amplitude=float(rng.uniform(0.15, 0.3)),
                     direction=float(rng.uniform(0, math.pi)), width=60_000.0,
                     phase=float(rng.uniform(0, 2 * math.pi)), t_ref=T0_UTC,
                     water_depth=250.0),
        LambOseenEddy.with_peak(float(rng.uniform(0.05, 0.15)), 3000.0,
                                north0=float(rng.uniform(-4000, 4000)),
                                east0=float(rng.uniform(-2000, 6000)),
                                drift_north=0.05, drift_east=-0.03, t_ref=T0_UTC),
        UniformFlow(north=float(rng.normal(0, 0.05)), east=float(rng.normal(0, 0.05))),
    ))


@dataclass
class GliderRun:
    """A mission's log and its truth."""

    path: Path
    dives: list[dict[str, float]] = field(default_factory=list)
    """Per dive: ``t_start``, ``t_end`` (UTC of its bounding fixes), ``north``, ``east``
    (m/s: the water's velocity at the glider averaged over them), ``lat_mid``,
    ``lon_mid`` (deg: the midpoint of the glider's true places at the two fixes)."""
    errors: GliderErrors | None = None


def log_stem(seed: int, name: str = "sim_glider") -> str:
    """The log's name without its suffix, as a Slocum names its files:
    ``<glider>-<year>-<day>-<mission>-<segment>``."""
    return f"{name}-2026-264-{seed}-0"


def fly(out_dir: Path | str, seed: int, dives: int = 4, yos: int = 3,
        depth_m: float = 180.0, pump_cc: float = 220.0, surface_s: float = 420.0,
        name: str = "sim_glider") -> GliderRun:
    """Fly ``dives`` dives and write ``out_dir/<log_stem>.dbd`` and its truth
    ``<log_stem>.truth.json`` (module docstring)."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x5100C]))
    err = GliderErrors.draw(rng)
    water = sea(rng)
    geo = GeoOrigin(*ORIGIN)
    glider = SlocumGlider(cd0=err.cd0, hull_lift=err.hull_lift,
                          compressibility=err.compressibility, trim_cc=err.trim_cc)
    noise = np.random.default_rng(np.random.SeedSequence([seed, 0x6E015E]))

    north = east = 0.0
    heading = 0.0
    target = 1
    t = 0.0
    phase = "surface"
    surfaced_at = 0.0
    yo = 0
    down = True
    last_pump = math.nan
    cycles: list[dict[str, float | None]] = []
    water_t: list[tuple[float, float, float]] = []   # (t, north, east) at each step
    fixes: list[tuple[float, float, float]] = []   # (t, north, east) true
    next_cycle = 0.0
    done = 0
    while done < dives or phase != "surface" or t - surfaced_at < surface_s:
        # the mission: surface -> yos -> surface
        if phase == "surface" and t - surfaced_at >= surface_s and done < dives:
            phase, yo, down = "dive", 0, True
        if phase == "dive":
            if down and glider.depth >= depth_m:
                down = False
            elif not down and yo < yos - 1 and glider.depth <= INFLECT_TOP_M:
                yo, down = yo + 1, True
            elif not down and yo == yos - 1 and glider.depth <= 0.0:
                phase, surfaced_at, done = "surface", t, done + 1
        if phase == "surface":
            pitch_set, pump_set = 0.0, pump_cc
        else:
            pitch_set = -DIVE_PITCH_RAD if down else DIVE_PITCH_RAD
            pump_set = -pump_cc if down else pump_cc
        # steer to the waypoint under water; at the surface the heading holds
        goal = (0.0, 0.0) if target == 0 else (0.0, TRANSECT_M)
        if math.hypot(goal[0] - north, goal[1] - east) < 200.0:
            target = 1 - target
        bearing = math.atan2(goal[1] - east, goal[0] - north)
        if phase == "dive":
            hunt = FIN_HUNT_RAD * math.sin(2 * math.pi * t / FIN_HUNT_S)
            heading = wrap_pi(heading + wrap_pi(bearing + hunt - heading)
                              * DT_S / HEADING_TIME_CONSTANT_S)
        depth = glider.depth
        wave = err.vertical_water(t, depth) if depth > 0.0 else 0.0
        cn, ce = water.local_point(north, east, depth, T0_UTC + t)
        water_t.append((t, cn, ce))
        if t >= next_cycle:
            next_cycle += CYCLE_S
            cycles.append(_cycle(t, glider, heading, err, noise, geo, north, east,
                                 phase == "surface" and t - surfaced_at >= GPS_ACQUIRE_S,
                                 pump_set, last_pump, fixes))
            last_pump = glider.pump_cc
        glider.step(DT_S, pitch_set, pump_set, vertical_water=wave)
        north += (glider.u * math.cos(heading) + cn) * DT_S
        east += (glider.u * math.sin(heading) + ce) * DT_S
        t += DT_S

    stem = log_stem(seed, name)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = DbdWriter(SENSORS, stem).write(out / f"{stem}.dbd", cycles)
    run = GliderRun(path, _true_dives(np.array(water_t), fixes, geo), err)
    (out / f"{stem}.truth.json").write_text(json.dumps(
        {"seed": seed, "errors": err.__dict__, "field": water.describe(),
         "dives": run.dives}, indent=1))
    return run


def _cycle(t: float, glider: SlocumGlider, heading: float, err: GliderErrors,
           noise: np.random.Generator, geo: GeoOrigin, north: float, east: float,
           fixing: bool, pump_set: float, last_pump: float,
           fixes: list[tuple[float, float, float]]) -> dict[str, float | None]:
    """One log cycle's values (module docstring), a fix's time and true place into
    ``fixes``."""
    deviation = err.deviation_rad * math.sin(heading + err.deviation_phase)
    measured = heading + deviation + noise.normal(0, math.radians(1.0))
    c: dict[str, float | None] = {
        "m_present_time": T0_UTC + t,
        "m_depth": max(glider.depth + noise.normal(0, 0.05), 0.0),
        "m_pitch": glider.pitch + err.pitch_bias_rad + noise.normal(0, math.radians(0.2)),
        "m_roll": noise.normal(0, math.radians(1.0)),
        "m_heading": measured % (2 * math.pi),
        "c_fin": 0.0 if glider.depth <= 0.0 else max(-0.4, min(0.4, 2.0 * deviation)),
        "m_battpos": -pump_set / 500.0 if glider.depth <= 0.0 else glider.pitch / 0.5,
    }
    if glider.pump_cc != last_pump:
        c["m_de_oil_vol"] = glider.pump_cc
    if fixing:
        n = north + noise.normal(0, err.gps_std_m)
        e = east + noise.normal(0, err.gps_std_m)
        lat, lon = geo.to_latlon(n, e)
        c["m_gps_lat"], c["m_gps_lon"] = ddmm(lat), ddmm(lon)
        fixes.append((t, north, east))
    return c


def _true_dives(water: np.ndarray, fixes: list[tuple[float, float, float]],
                geo: GeoOrigin) -> list[dict[str, float]]:
    """Each dive between consecutive fixes more than a cycle apart: the water's mean
    velocity at the glider from the earlier fix to the later, and the midpoint of its
    places at the two."""
    out = []
    t = water[:, 0]
    for (a, na, ea), (b, nb, eb) in zip(fixes, fixes[1:]):
        if b - a <= CYCLE_S + 1e-6:
            continue
        sel = (t >= a) & (t < b)
        lat, lon = geo.to_latlon(0.5 * (na + nb), 0.5 * (ea + eb))
        out.append({"t_start": T0_UTC + a, "t_end": T0_UTC + b,
                    "north": float(water[sel, 1].mean()),
                    "east": float(water[sel, 2].mean()), "lat_mid": lat, "lon_mid": lon})
    return out

