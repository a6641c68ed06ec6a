"""Synthetic plants for the current pipeline: the pipeline's own regression models
(:class:`onboard.estimators.vehicle_models.RegressionModel`) with "true" coefficients, a
known water current and sensor noise, and the scoring of the pipeline's current estimate.

A plant built from the estimator's own model is a specification test (the estimator
should be nearly exact on it), not a validation: the SITL scenarios (other plants, other
models) are that. Units: SI, angles in rad, NED/FRD axes; current (north, east[, down]) m/s.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator

import numpy as np

from onboard.core.config import from_dict
from onboard.core.geo import wrap_pi
from onboard.core.messages import ActuatorCommand, Attitude, DvlVelocity, GnssFix, Heading, Sample
from onboard.core.so3 import euler_to_matrix
from onboard.estimators.vehicle_models import ModelInputs, RegressionModel
from onboard.pipelines import current as current_mod

BOAT_TRUE: dict[str, dict[str, float]] = {
    "surge": {"u|u|": -0.08, "u": -0.05, "vr": 0.3, "tau_u": 0.3},
    "sway": {"v": -1.2, "v|v|": -0.5, "ur": -0.4, "r": 0.05},
    "yaw": {"r": -1.5, "r|r|": -0.5, "uv": 0.1, "u|u|dr": 0.8, "n|n|dr": 0.3},
}
"""Coefficients of the ``surface-rudder`` model (per DOF: regressor term -> value) of the
boat plant :func:`simulate_boat`."""
TORPEDO_TRUE: dict[str, dict[str, float]] = {
    "surge": {"u|u|": -0.045, "wq": -0.9, "q^2": 0.0, "vr": 0.9, "r^2": 0.0,
              "sin(theta)": 0.0, "n|n|": 0.12},
    "sway": {"v|v|": -1.5, "r|r|": 0.0, "uv": -0.9, "ur": -0.5, "wp": 0.0, "pq": 0.0,
             "cos(theta)sin(phi)": 0.0, "u|u|dr": 0.1},
    "heave": {"w|w|": -1.5, "q|q|": 0.0, "uw": -0.9, "uq": 0.5, "vp": 0.0, "rp": 0.0,
              "cos(theta)cos(phi)": 0.0, "u|u|ds": -0.1},
    "yaw": {"r": -0.8, "r|r|": -0.3, "uv": 0.6, "u|u|dr": -1.2},
}
"""Coefficients of the ``torpedo`` model (neutrally buoyant: no gravity terms) of the
torpedo plant :func:`simulate_torpedo`."""


def simulate_boat(duration: float = 600.0, current: tuple[float, float] = (0.3, -0.2),
                  seed: int = 0, tick: float = 0.1, leg_s: float = 60.0,
                  current_fn: Callable[[float], tuple[float, float]] | None = None
                  ) -> Iterator[tuple[float, list[Sample], np.ndarray]]:
    """Rudder boat on zig-zag heading legs; yields ``(t, samples, true current (n, e))``
    every ``tick`` s.

    The plant is :data:`BOAT_TRUE` integrated at 10 ms (Euler) with throttle 0.8 and a
    heading autopilot changing the reference every ``leg_s`` s. Samples per tick: the
    command, a compass heading and an attitude (0.01 rad noise), a yaw rate (0.005 rad/s);
    every second tick a GNSS SOG/COG (0.05 m/s noise per axis). ``current_fn(t)`` (m/s)
    replaces the constant ``current`` when given."""
    rng = np.random.default_rng(seed)
    m = RegressionModel("surface-rudder")
    th = m.thetas_from_mapping(BOAT_TRUE)
    x = ModelInputs()
    x.n = 0.8
    nu = np.array([1.0, 0.0])
    psi, r = 0.0, 0.0
    north = east = 0.0
    h = 0.01
    n_sub = int(round(tick / h))
    headings = [0.0, 1.6, 3.2, -1.6, 0.8, 2.4, -2.4, -0.8]
    t = 0.0
    k = 0
    while t < duration - 1e-9:
        samples = []
        for _ in range(n_sub):
            ref = headings[int(t // leg_s) % len(headings)]
            x.dr = float(np.clip(0.6 * math.remainder(ref - psi, 2 * math.pi) - 0.3 * r, -0.5, 0.5))
            x.r = r
            phis = m.regressors(nu, x)
            acc = np.array([phis[i] @ th[i] for i in range(3)])
            nu = nu + h * acc[:2]
            r = r + h * acc[2]
            psi = psi + h * r
            t += h
            c = np.array(current_fn(t) if current_fn else current)
            rot = np.array([[math.cos(psi), -math.sin(psi)], [math.sin(psi), math.cos(psi)]])
            vg = rot @ nu + c
            north += h * vg[0]
            east += h * vg[1]
        k += 1
        samples.append(ActuatorCommand(t=t, throttle=x.n, rudder_rad=x.dr))
        samples.append(Heading(t=t, heading_rad=wrap_pi(psi + rng.normal(0, 0.01))))
        samples.append(Attitude(t=t, roll_rad=0.0, pitch_rad=0.0,
                                yaw_rad=wrap_pi(psi + rng.normal(0, 0.01)),
                                yaw_rate_rps=r + rng.normal(0, 0.005)))
        if k % 2 == 0:
            vgn = vg + rng.normal(0, 0.05, 2)
            samples.append(GnssFix(t=t, lat_deg=0.0, lon_deg=0.0, sog_mps=float(np.hypot(*vgn)),
                                   cog_rad=float(math.atan2(vgn[1], vgn[0]))))
        yield t, samples, c


def simulate_torpedo(duration: float = 600.0,
                     current: tuple[float, float, float] = (-0.6, 0.3, 0.02), seed: int = 0,
                     tick: float = 0.1, leg_s: float = 100.0, water_track: bool = False,
                     truth: dict[str, dict[str, float]] = TORPEDO_TRUE,
                     pitch: tuple[float, float] = (0.05, 0.05),
                     roll: tuple[float, float] = (0.0, 0.0)
                     ) -> Iterator[tuple[float, list[Sample], np.ndarray]]:
    """Torpedo AUV at constant depth on heading legs; yields ``(t, samples, true current
    (n, e, d))`` every ``tick`` s.

    Samples per tick: the command (1050 rpm) and the attitude with its rates, exact; every
    second tick (5 Hz) a DVL velocity with 0.01 m/s noise, bottom track (over ground, body
    axes) or with ``water_track`` through water. ``pitch``, ``roll``: (amplitude rad,
    angular frequency rad/s) of an attitude oscillation the stern plane does not cause (a
    depth-keeping autopilot on a wavy profile); ``truth``: the model coefficients of the
    plant."""
    rng = np.random.default_rng(seed)
    m = RegressionModel("torpedo")
    th = m.thetas_from_mapping(truth)
    (pa, wq), (ra, wp) = pitch, roll
    x = ModelInputs()
    x.n = 1.5 * 0.7  # 1500 rpm / rpm_scale 1000 ~ cruise
    nu = np.array([1.5, 0.0, 0.0])
    psi, r = 0.0, 0.0
    h = 0.01
    n_sub = int(round(tick / h))
    headings = [0.0, 2.0, -2.0, 1.0, 3.0, -1.0]
    t = 0.0
    k = 0
    c = np.array(current, float)
    while t < duration - 1e-9:
        samples = []
        for _ in range(n_sub):
            ref = headings[int(t // leg_s) % len(headings)]
            err = math.remainder(ref - psi, 2 * math.pi)
            x.dr = float(np.clip(-0.5 * err + 0.3 * r, -0.3, 0.3))
            x.r = r
            x.pitch = pa * math.sin(wq * t)
            x.q = pa * wq * math.cos(wq * t)
            x.roll = ra * math.sin(wp * t)
            x.p = ra * wp * math.cos(wp * t)
            phis = m.regressors(nu, x)
            acc = np.array([phis[i] @ th[i] for i in range(4)])
            nu = nu + h * acc[:3]
            r = r + h * acc[3]
            psi = psi + h * r
            t += h
        k += 1
        R = euler_to_matrix(x.roll, x.pitch, psi)
        samples.append(ActuatorCommand(t=t, propeller_rpm=x.n * 1000.0, rudder_rad=x.dr,
                                       stern_plane_rad=0.0))
        samples.append(Attitude(t=t, roll_rad=x.roll, pitch_rad=x.pitch, yaw_rad=wrap_pi(psi),
                                roll_rate_rps=x.p, pitch_rate_rps=x.q, yaw_rate_rps=r))
        if k % 2 == 0:
            if water_track:
                z = nu + rng.normal(0, 0.01, 3)
            else:
                z = nu + R.T @ c + rng.normal(0, 0.01, 3)
            samples.append(DvlVelocity(t=t, vx=z[0], vy=z[1], vz=z[2],
                                       track="water" if water_track else "bottom"))
        yield t, samples, c


def current_errors(pipe, gen: Iterator[tuple[float, list[Sample], np.ndarray]],
                   after: float = 120.0
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Run ``pipe`` over a plant's ticks; ``(rms, coverage, errors, sigmas)`` of the
    horizontal current (north, east) from ``after`` s on: RMS error (m/s), the fraction of
    ticks with the error within two published sigmas, and the per-tick arrays."""
    errs, stds = [], []
    for t, samples, c in gen:
        out = pipe.step(t, samples)
        if t >= after and "north" in out:
            errs.append([out["north"] - c[0], out["east"] - c[1]])
            stds.append([out["std_north"], out["std_east"]])
    e, s = np.array(errs), np.array(stds)
    rms = np.sqrt(np.mean(e ** 2, axis=0))
    cover = np.mean(np.abs(e) <= 2 * s, axis=0)
    return rms, cover, e, s


def current_pipeline(vclass: str, **section):
    """The ``current`` pipeline for vehicle class ``vclass`` with ``[pipelines.current]``
    keys ``section`` (None when ``enabled = false``)."""
    cfg = from_dict({"vehicle": {"class": vclass}, "pipelines": {"current": section}})
    return current_mod.create(cfg)

