"""Synthetic fleets in analytic current fields, for the tests of ``onboard fleet``.

Three fields on a local plane (north, east in m about :data:`LAT0`, :data:`LON0`; time in
s since :data:`UTC0`), each a function ``(north_m, east_m, t_s) -> (c_north, c_east)``
(m/s), written here independently of the estimator:

* :func:`tidal_channel`: an M2 tidal stream along a channel running east, strongest on
  its axis and slowing toward the banks (a parabolic shear profile), with a weak
  cross-channel secondary flow;
* :func:`eddy`: a Gaussian vortex (azimuthal speed ``V (r/R) exp((1 - r^2/R^2)/2)``,
  largest ``V`` at ``r = R``) drifting across a weak background stream;
* :func:`front`: two water masses moving differently, a ``tanh`` front between them
  that meanders slowly.

A vehicle moves between random waypoints at its cruise speed; its current estimate is the
truth at its position plus its own error: per component an AR(1) process at the record
rate with correlation time ``tau_s`` and stationary sigma ``sigma`` (the sigma it reports
as its ``std``), plus white noise of ``white`` m/s: the error of a current estimator, which
wanders slowly, so ten records a second are not ten measurements. With ``memory_s`` its
estimate is also a memory of the water it crossed: the truth along its own track through
an exponential filter of that time constant (docs/algorithms.md §8.9).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import msgspec
import numpy as np

from onboard.core.messages import EstimateRecord
from onboard.fleet.field import Observation, Plane
from onboard.fleet.service import FleetService

LAT0, LON0 = 43.10, 5.90
"""Where the synthetic area is (deg)."""
UTC0 = 1_780_000_000.0
"""The scenarios' start (POSIX s, 2026-05-28)."""
M2_S = 44714.0
"""The M2 tidal period (s)."""

Field = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def tidal_channel(n, e, t):
    """A tidal channel 2.4 km wide along east (axis at north = 0): 0.8 m/s on the axis at
    the flood's peak, parabolic across, with a 0.05 m/s cross-channel flow."""
    phase = 2.0 * math.pi * t / M2_S + 0.6
    profile = np.clip(1.0 - (n / 1200.0) ** 2, 0.0, None)
    c_e = 0.8 * np.cos(phase) * profile
    c_n = 0.05 * np.sin(phase) * np.sin(math.pi * e / 2000.0)
    return c_n, c_e


def eddy(n, e, t):
    """A vortex of radius 500 m, 0.35 m/s at its rim, drifting east at 0.05 m/s across a
    0.1 m/s stream to the north-east."""
    n0, e0 = 0.0, -300.0 + 0.05 * t
    dn, de = n - n0, e - e0
    r2 = (dn ** 2 + de ** 2) / 500.0 ** 2
    w = 0.35 / 500.0 * np.exp(0.5 * (1.0 - r2))     # speed / r
    return 0.07 + w * de, 0.07 - w * dn


def front(n, e, t):
    """A front along east, 250 m wide, meandering 200 m on a 3 km wave that travels east
    at 0.1 m/s: 0.45 m/s east to its north, 0.1 m/s west and 0.1 m/s south to its south."""
    y = n - 200.0 * np.sin(2.0 * math.pi * (e - 0.1 * t) / 3000.0)
    s = 0.5 * (1.0 + np.tanh(y / 250.0))
    return -0.1 * (1.0 - s), 0.45 * s - 0.1 * (1.0 - s)


FIELDS: dict[str, Field] = {"tidal_channel": tidal_channel, "eddy": eddy, "front": front}


@dataclass
class Fleet:
    """A synthetic fleet's records as arrays: per record the vehicle index, time (s since
    UTC0), position (m), estimate and truth (m/s), and the reported sigma."""

    vehicle: np.ndarray
    t: np.ndarray
    north_m: np.ndarray
    east_m: np.ndarray
    est: np.ndarray
    truth: np.ndarray
    sigma: float
    plane: Plane

    def observations(self, skip: int = -1):
        """The records as :class:`Observation` (those of vehicle ``skip`` left out)."""
        lat, lon = self.plane.to_latlon(self.north_m, self.east_m)
        for i in np.flatnonzero(self.vehicle != skip):
            yield Observation(f"v{self.vehicle[i]}", UTC0 + self.t[i], float(lat[i]),
                              float(lon[i]), float(self.est[i, 0]), float(self.est[i, 1]),
                              self.sigma, self.sigma)

    def record(self, i: int) -> EstimateRecord:
        """Record ``i`` as the ``current`` pipeline's EstimateRecord (schema 2)."""
        lat, lon = self.plane.to_latlon(self.north_m[i], self.east_m[i])
        return EstimateRecord(vehicle=f"v{self.vehicle[i]}", pipeline="current",
                              t=float(self.t[i]), utc=UTC0 + float(self.t[i]),
                              lat_deg=float(lat), lon_deg=float(lon),
                              values={"north": float(self.est[i, 0]),
                                      "east": float(self.est[i, 1])},
                              std={"north": self.sigma, "east": self.sigma})

    def fitted_service(self) -> FleetService:
        """A fleet service that has taken every record, as received over Zenoh, and
        fitted its field on them."""
        service = FleetService()
        enc = msgspec.json.Encoder()
        for i in range(len(self.t)):
            service.feed(enc.encode(self.record(i)), "application/json;onboard.Estimate.v2")
        service.step(refit=True)
        return service


def tracks(rng: np.random.Generator, vehicles: int, duration_s: float, rate_hz: float,
           half_width_m: float, speed_mps: float) -> tuple[np.ndarray, ...]:
    """Each vehicle's (t, north, east) at ``rate_hz`` between random waypoints in the
    square of ``half_width_m`` about the origin, at ``speed_mps``."""
    t = np.arange(0.0, duration_s, 1.0 / rate_hz)
    out = []
    for _ in range(vehicles):
        pos = rng.uniform(-half_width_m, half_width_m, 2)
        path = [pos]
        length = speed_mps * duration_s
        while length > 0:
            nxt = rng.uniform(-half_width_m, half_width_m, 2)
            length -= np.linalg.norm(nxt - path[-1])
            path.append(nxt)
        path = np.array(path)
        seg = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))]
        s = speed_mps * t
        out.append((np.interp(s, seg, path[:, 0]), np.interp(s, seg, path[:, 1])))
    return t, out


def ar1(rng: np.random.Generator, n: int, rate_hz: float, tau_s: float,
        sigma: float) -> np.ndarray:
    """An AR(1) sequence of ``n`` steps at ``rate_hz`` with correlation time ``tau_s`` and
    stationary sigma ``sigma``, started in its stationary distribution."""
    phi = math.exp(-1.0 / (rate_hz * tau_s))
    drive = rng.normal(0.0, sigma * math.sqrt(1.0 - phi * phi), n)
    drive[0] = rng.normal(0.0, sigma)
    from scipy.signal import lfilter

    return lfilter([1.0], [1.0, -phi], drive)


def remembered(truth: np.ndarray, rate_hz: float, memory_s: float) -> np.ndarray:
    """The truth along a track (n, 2) at ``rate_hz`` through an exponential filter of time
    constant ``memory_s`` (s), started on its first value (``truth`` itself for 0)."""
    if memory_s <= 0.0:
        return truth
    from scipy.signal import lfilter

    phi = math.exp(-1.0 / (rate_hz * memory_s))
    return np.column_stack([lfilter([1.0 - phi], [1.0, -phi], col - col[0]) + col[0]
                            for col in truth.T])


def fleet(field: str, seed: int, vehicles: int = 10, duration_s: float = 1800.0,
          rate_hz: float = 10.0, half_width_m: float = 1000.0, speed_mps: float = 1.5,
          sigma: float = 0.03, tau_s: float = 60.0, white: float = 0.01,
          t_start: float = 0.0, memory_s: float = 0.0) -> Fleet:
    """A fleet of ``vehicles`` in ``field`` (one of :data:`FIELDS`) for ``duration_s`` at
    ``rate_hz``, the estimates' error AR(1) (``sigma``, ``tau_s``) plus white, about the
    truth along the track remembered over ``memory_s`` (s; 0: the truth where it is)."""
    rng = np.random.default_rng(seed)
    t, paths = tracks(rng, vehicles, duration_s, rate_hz, half_width_m, speed_mps)
    t = t + t_start
    cols: dict[str, list] = {k: [] for k in ("v", "t", "n", "e", "est", "truth")}
    for k, (n, e) in enumerate(paths):
        c_n, c_e = FIELDS[field](n, e, t)
        truth = np.column_stack([c_n, c_e])
        err = np.column_stack([ar1(rng, t.size, rate_hz, tau_s, sigma) for _ in range(2)])
        err += rng.normal(0.0, white, err.shape)
        seen = remembered(truth, rate_hz, memory_s)
        for key, val in (("v", np.full(t.size, k)), ("t", t), ("n", n), ("e", e),
                         ("est", seen + err), ("truth", truth)):
            cols[key].append(val)
    cat = {k: np.concatenate(v) for k, v in cols.items()}
    return Fleet(cat["v"], cat["t"], cat["n"], cat["e"], cat["est"], cat["truth"],
                 math.hypot(sigma, white), Plane(LAT0, LON0))
