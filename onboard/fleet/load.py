"""The fleet service's cost, measured with simulated vehicles (``onboard bench``'s fleet
figures, docs/fleet.md).

:func:`measure` runs a :class:`~onboard.fleet.service.FleetService` without a network on a
simulated fleet: ``vehicles`` vehicles, each publishing its ``current`` record (JSON,
schema 2) at ``rate_hz`` while it sails a circle through a tidal stream, over
``duration_s`` seconds of fleet time, after the field's history (:data:`HISTORY_S` of
each vehicle's windows) was filled in. The service's own work is timed in CPU seconds:
decoding and adding every record (what the Zenoh subscriber's callback does), a step
(refresh, grid) every :data:`~onboard.fleet.service.GRID_PERIOD_S` of fleet time with the
hyperparameters fitted every :data:`~onboard.fleet.service.REFIT_PERIOD_S`, and queries
at random places and times in the fleet's area. The CPU share is that CPU time over the
fleet time (1.0: one core busy); a query's latency is its CPU time (the machine's other
load does not show in it; its wall time is in the detail).
"""

from __future__ import annotations

import math
import statistics
import time

import msgspec
import numpy as np

from onboard.core.messages import EstimateRecord
from onboard.fleet.field import HISTORY_S, THIN_S, Observation, Plane
from onboard.fleet.service import GRID_PERIOD_S, REFIT_PERIOD_S, FleetService

LAT0, LON0 = 43.10, 5.90
"""The simulated fleet's area (deg)."""
AREA_M = 5000.0
"""Side of the square the vehicles' circles are centred in (m)."""
CIRCLE_M = 400.0
"""Radius of each vehicle's circle (m)."""
SPEED_MPS = 1.5
"""The vehicles' speed (m/s)."""
UTC0 = 1_780_000_000.0
"""The simulated fleet's start (POSIX s)."""


M2_S = 44714.0
"""The M2 tidal period (s)."""


def tide(north_m: np.ndarray, t_s: float) -> tuple[np.ndarray, np.ndarray]:
    """A tidal stream (m/s, north and east) along east, sheared across the area (slowest
    at its north and south edges), with a weak northward drift."""
    along = 0.6 * math.cos(2.0 * math.pi * t_s / M2_S) * (1.0 - (north_m / AREA_M) ** 2)
    return np.full_like(north_m, 0.05), along


class SimFleet:
    """``vehicles`` vehicles on circles in the area, each with a random phase and an AR(1)
    error on its current estimate (60 s, 0.03 m/s)."""

    def __init__(self, vehicles: int, seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        self.rng = rng
        self.ids = [f"sim{k:03d}" for k in range(vehicles)]
        self.centre = rng.uniform(-AREA_M / 2, AREA_M / 2, (vehicles, 2))
        self.phase = rng.uniform(0.0, 2.0 * math.pi, vehicles)
        self.err = rng.normal(0.0, 0.03, (vehicles, 2))
        self.plane = Plane(LAT0, LON0)

    def at(self, t_s: float, dt_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(lat, lon, current (n, 2)) of every vehicle at ``t_s`` (s since UTC0), the
        errors stepped by ``dt_s``."""
        a = self.phase + SPEED_MPS * t_s / CIRCLE_M
        n = self.centre[:, 0] + CIRCLE_M * np.cos(a)
        e = self.centre[:, 1] + CIRCLE_M * np.sin(a)
        phi = math.exp(-dt_s / 60.0)
        self.err = phi * self.err + self.rng.normal(0.0, 0.03 * math.sqrt(1 - phi * phi),
                                                   self.err.shape)
        c_n, c_e = tide(n, t_s)
        lat, lon = self.plane.to_latlon(n, e)
        return lat, lon, np.column_stack([c_n, c_e]) + self.err

    def records(self, t_s: float, dt_s: float) -> list[bytes]:
        """Every vehicle's ``current`` record at ``t_s``, as JSON."""
        lat, lon, c = self.at(t_s, dt_s)
        enc = msgspec.json.encode
        return [enc(EstimateRecord(vehicle=v, pipeline="current", t=t_s, utc=UTC0 + t_s,
                                   lat_deg=float(lat[k]), lon_deg=float(lon[k]),
                                   values={"north": float(c[k, 0]), "east": float(c[k, 1])},
                                   std={"north": 0.03, "east": 0.03}))
                for k, v in enumerate(self.ids)]


def prefill(service: FleetService, sim: SimFleet, history_s: float) -> None:
    """The field's history: one observation per vehicle per window over ``history_s``
    before the start (the windows a service running that long holds)."""
    for t in np.arange(-history_s, 0.0, THIN_S):
        lat, lon, c = sim.at(float(t), THIN_S)
        for k, v in enumerate(sim.ids):
            service.field.add(Observation(v, UTC0 + float(t), float(lat[k]), float(lon[k]),
                                          float(c[k, 0]), float(c[k, 1]), 0.03, 0.03))


def measure(vehicles: int, duration_s: float = 120.0, rate_hz: float = 10.0,
            queries: int = 200, history_s: float = HISTORY_S, seed: int = 0) -> dict:
    """The service's CPU share and query latency on a simulated fleet (module
    docstring): ``cpu_share``, ``query_p50_ms``, ``query_p99_ms`` (CPU), ``query_wall_p99_ms``,
    and the counts behind them."""
    sim = SimFleet(vehicles, seed)
    service = FleetService()
    prefill(service, sim, history_s)
    service.step(refit=True)      # the history's first fit, before the clock runs
    dt = 1.0 / rate_hz
    steps = int(round(duration_s * rate_hz))
    every_query = max(1, steps // queries)
    cpu, q_cpu, q_wall = 0.0, [], []
    next_step, next_refit = GRID_PERIOD_S, REFIT_PERIOD_S
    for i in range(1, steps + 1):
        t = i * dt
        payloads = sim.records(t, dt)
        c0 = time.process_time()
        for p in payloads:
            service.feed(p)
        if t >= next_step:
            service.step(refit=t >= next_refit)
            next_step += GRID_PERIOD_S
            next_refit += REFIT_PERIOD_S if t >= next_refit else 0.0
        cpu += time.process_time() - c0
        if i % every_query == 0:
            q_cpu.append(_query(service, sim, t, q_wall))
    q = sorted(q_cpu)
    return {"vehicles": vehicles, "rate_hz": rate_hz, "duration_s": duration_s,
            "cpu_s": round(cpu, 3), "cpu_share": cpu / duration_s,
            "query_p50_ms": 1e3 * statistics.median(q),
            "query_p99_ms": 1e3 * q[min(len(q) - 1, int(0.99 * len(q)))],
            "query_wall_p99_ms": 1e3 * sorted(q_wall)[min(len(q) - 1, int(0.99 * len(q)))],
            "queries": len(q), "records": service.field.added,
            "super_observations": len(service.field.fitted.obs.y)
            if service.field.fitted else 0, "grids": service.grids}


def _query(service: FleetService, sim: SimFleet, t: float, walls: list[float]) -> float:
    """One query at a random place in the area at a random time of the last hour, as the
    queryable answers it; its CPU time (s), its wall time appended to ``walls``."""
    n, e = sim.rng.uniform(-AREA_M / 2, AREA_M / 2, 2)
    lat, lon = sim.plane.to_latlon(n, e)
    params = {"lat": repr(float(lat)), "lon": repr(float(lon)),
              "utc": repr(UTC0 + t - float(sim.rng.uniform(0.0, 3600.0)))}
    w0, c0 = time.perf_counter(), time.thread_time()
    service.reply(params)
    cpu = time.thread_time() - c0
    walls.append(time.perf_counter() - w0)
    return cpu
