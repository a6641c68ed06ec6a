"""A first-order boat: the AIE and KF pipelines' own plant model, simulated, for testing
them against truth.

Surge and yaw are the first-order models of algorithms.md §1.1, ``v' = -a v + u`` and
``r' = -a_psi r + u_psi``: the very model the AIE and KF pipelines assume. On this plant
the estimators' model is exact, so a test here checks that the estimators implement their
equations and reach their own noise floor; it is not a validation against a different
vehicle (the SITL plants in ``sitl/plants`` are that, tests/test_aie_sitl.py). Optional
effects the pipelines do not model can be switched on: quadratic surge drag, a thrust map
quadratic in throttle, a yaw moment proportional to speed squared (rudder boats), and a
constant water current. Sensors: GNSS at ``gps_hz`` with white noise, compass at
``compass_hz``, commands at 10 Hz.

The "true input" is what the AIE normalization calls the input: everything in the
acceleration except the model's linear damping, ``u = v' + a v`` (m/s^2, rad/s^2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from onboard.core.geo import LocalFrame, wrap_pi_array
from onboard.core.messages import ActuatorCommand, GnssFix, Heading, Sample


@dataclass
class SimConfig:
    """Plant and sensors of the synthetic boat (SI units)."""

    kind: str = "twin"                 # "twin" (left/right) or "rudder" (throttle/rudder)
    duration: float = 400.0
    a: float = 1.0                     # surge damping (1/s)
    a_psi: float = 2.0                 # yaw damping (1/s)
    gain: float = 3.0                  # surge accel per unit command (m/s^2)
    gain_psi: float = 2.0              # yaw accel per unit command (rad/s^2)
    quad_drag: float = 0.0             # extra surge drag c v|v| (1/m)
    thrust_quadratic: bool = False     # thrust ~ cmd |cmd| instead of cmd
    yaw_speed_scaling: bool = False    # yaw moment ~ (v/v_ref)^2 (rudder)
    current: tuple[float, float] = (0.0, 0.0)
    gps_hz: float = 5.0
    gps_std: float = 1.5
    compass_hz: float = 10.0
    compass_std: float = 0.03
    seed: int = 0
    schedule: list[tuple[float, float, float]] = field(default_factory=list)
    """(t_start, surge_cmd, yaw_cmd); default: a turning pattern."""


def default_schedule(duration: float, seed: int) -> list[tuple[float, float, float]]:
    """Cruise legs with turns both ways and speed changes (a 'turns' mission)."""
    rng = np.random.default_rng(seed + 1000)
    out = [(0.0, 0.0, 0.0), (5.0, 0.5, 0.0)]
    t = 20.0
    while t < duration:
        s = float(rng.choice([0.35, 0.5, 0.65]))
        y = float(rng.choice([-0.35, -0.2, 0.0, 0.2, 0.35]))
        out.append((t, s, y))
        t += float(rng.uniform(8.0, 25.0))
    return out


@dataclass
class SimResult:
    """The samples the pipelines read (time-ordered) and the truth on a 10 Hz grid."""

    samples: list[Sample]
    t: np.ndarray                      # truth times (s), 10 Hz
    north: np.ndarray
    east: np.ndarray
    heading: np.ndarray                # unwrapped (rad)
    speed: np.ndarray                  # through-water surge (m/s)
    sog: np.ndarray                    # path speed over ground (m/s)
    yaw_rate: np.ndarray
    surge_input: np.ndarray            # u = v' + a v (m/s^2)
    yaw_input: np.ndarray
    lat0: float = 44.0
    lon0: float = -71.0


def simulate(cfg: SimConfig) -> SimResult:
    """Run the synthetic boat; samples time-ordered, truth on a 10 Hz grid."""
    rng = np.random.default_rng(cfg.seed)
    sched = cfg.schedule or default_schedule(cfg.duration, cfg.seed)
    h = 0.01
    n_steps = int(round(cfg.duration / h))
    frame = LocalFrame(44.0, -71.0)
    N = E = 0.0
    psi = 0.3
    v = r = 0.0
    si = 0
    samples: list[Sample] = []
    tr: dict[str, list[float]] = {k: [] for k in
                                  ("t", "n", "e", "psi", "v", "sog", "r", "us", "uy")}
    gps_next, cmp_next, cmd_next, truth_next = 0.05, 0.0, 0.0, 0.0
    vref = 1.5
    for i in range(n_steps + 1):
        t = i * h
        while si + 1 < len(sched) and sched[si + 1][0] <= t:
            si += 1
        sc, yc = sched[si][1], sched[si][2]
        thrust = cfg.gain * (sc * abs(sc) if cfg.thrust_quadratic else sc)
        us = thrust - cfg.quad_drag * v * abs(v)
        scale = (v / vref) ** 2 if cfg.yaw_speed_scaling else 1.0
        uy = cfg.gain_psi * yc * scale
        if t >= truth_next - 1e-9:
            truth_next += 0.1
            vn = v * math.cos(psi) + cfg.current[0]
            ve = v * math.sin(psi) + cfg.current[1]
            for k, x in zip(tr, (t, N, E, psi, v, math.hypot(vn, ve), r, us, uy)):
                tr[k].append(x)
        if t >= cmd_next - 1e-9:
            cmd_next += 0.1
            if cfg.kind == "twin":
                samples.append(ActuatorCommand(t=t, left=sc + yc, right=sc - yc))
            else:
                samples.append(ActuatorCommand(t=t, throttle=sc, rudder_rad=yc))
        if t >= cmp_next - 1e-9:
            cmp_next += 1.0 / cfg.compass_hz
            samples.append(Heading(t=t, heading_rad=math.remainder(
                psi + cfg.compass_std * rng.standard_normal(), 2 * math.pi)))
        if t >= gps_next - 1e-9:
            gps_next += 1.0 / cfg.gps_hz
            lat, lon = frame.to_latlon(N + cfg.gps_std * rng.standard_normal(),
                                       E + cfg.gps_std * rng.standard_normal())
            samples.append(GnssFix(t=t, lat_deg=lat, lon_deg=lon))
        # integrate (exact enough at h = 10 ms): midpoint
        dv = -cfg.a * v + us
        dr = -cfg.a_psi * r + uy
        vm, rm = v + 0.5 * h * dv, r + 0.5 * h * dr
        psim = psi + 0.5 * h * r
        N += h * (vm * math.cos(psim) + cfg.current[0])
        E += h * (vm * math.sin(psim) + cfg.current[1])
        psi += h * rm
        v += h * (-cfg.a * vm + thrust - cfg.quad_drag * vm * abs(vm))
        r += h * (-cfg.a_psi * rm + uy)
    samples.sort(key=lambda s: s.t)
    a = {k: np.asarray(x) for k, x in tr.items()}
    return SimResult(samples, a["t"], a["n"], a["e"], a["psi"], a["v"], a["sog"], a["r"],
                     a["us"], a["uy"])


def run_pipelines(samples: list[Sample], pipelines: list, t_ticks: np.ndarray
                  ) -> list[dict[str, np.ndarray]]:
    """Feed samples to pipelines on the given ticks; estimates as arrays (NaN = none)."""
    outs: list[dict[str, list[float]]] = [{c: [] for c in p.columns} for p in pipelines]
    j = 0
    ns = len(samples)
    for t in t_ticks:
        batch = []
        while j < ns and samples[j].t <= t + 1e-9:
            batch.append(samples[j])
            j += 1
        for p, o in zip(pipelines, outs):
            est = p.step(float(t), batch)
            for c in p.columns:
                o[c].append(est.get(c, math.nan))
    return [{c: np.asarray(v) for c, v in o.items()} for o in outs]


def rmse(x: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Root mean square of the finite entries of ``x`` (where ``mask``); NaN if none."""
    m = np.isfinite(x) if mask is None else (np.isfinite(x) & mask)
    return float(np.sqrt(np.mean(x[m] ** 2))) if m.any() else math.nan


def score(sim: SimResult, est: dict[str, np.ndarray], t_min: float = 60.0,
          speed_truth: str = "sog") -> dict[str, float]:
    """RMSE of speed (m/s), heading (rad), position (m) and inputs after ``t_min``."""
    m = sim.t >= t_min
    truth_v = sim.sog if speed_truth == "sog" else sim.speed
    out = {
        "speed": rmse(est["speed"] - truth_v, m),
        "heading": rmse(wrap_pi_array(est["heading"] - sim.heading), m),
        "yaw_rate": rmse(est["yaw_rate"] - sim.yaw_rate, m),
        "position": rmse(np.hypot(est["north"] - sim.north, est["east"] - sim.east), m),
    }
    if "surge_input" in est:
        out["surge_input"] = rmse(est["surge_input"] - sim.surge_input, m)
        out["yaw_input"] = rmse(est["yaw_input"] - sim.yaw_input, m)
    return out
