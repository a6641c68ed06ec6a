"""Injected effects: the physical or sensor effects a scenario adds to the world.

A scenario lists the effects it **injects** and, separately, the names of those it
**declares** to the estimator (:attr:`sitl.scenarios.Scenario.declared`). Undeclared
effects are the test material for model closure (``onboard diagnose``): the estimator must
find them in the data. Effect names and parameters follow the vocabulary of
architecture.md §4.3, so a diagnosis can be scored directly against the truth file, where
every injected effect's parameters appear in ``TruthRecord.effects`` as
``"<name>.<param>"`` (for example ``"compass_deviation.amplitude"``).

=======================  ================================  ===================================
name                     params (units)                    what it does
=======================  ================================  ===================================
``water_current``        ``north``, ``east`` (m/s)         uniform current added to the sea
``tidal_current``        ``amplitude`` (m/s), ``period``   rectilinear tidal stream toward
                         (s), ``direction`` (rad),         ``direction``: mean + amplitude
                         ``mean`` (m/s), ``phase`` (rad)   cos(2 pi t / period + phase)
``nonuniform_current``   ``amplitude`` (m/s), ``length``   Fan et al.'s V = [0, -a sqrt((L+N)/L), 0]
                         (m)
``rotating_current``     ``speed`` (m/s), ``direction``    uniform current of constant speed whose
                         (rad), ``rate`` (rad/s)           direction turns: direction + rate t
``compass_deviation``    ``amplitude``, ``phase`` (rad)    heading error amplitude sin(psi+phase)
``soft_iron``            ``amplitude``, ``phase`` (rad)    heading error amplitude
                                                           sin(2 psi + phase) (second harmonic)
``heading_bias``         ``radians``                       constant heading error
``gyro_bias``            ``x``, ``y``, ``z`` (rad/s)       constant gyro bias
``gps_latency``          ``seconds``                       GNSS fixes reported late
``thrust_nonlinearity``  ``exponent``                      thrust ~ sign(th) abs(th)^exponent
                                                           instead of linear in throttle
``quadratic_drag``       ``coefficient`` (N s^2/m^2)       surge force -c u_r abs(u_r)
``surge_yaw_coupling``   ``coefficient`` (s)               speed lost in turns: surge
                                                           acceleration -c u_r r^2
``sideslip``             ``coefficient`` (N s^2/m^2)       side force c u_r abs(u_r): a steady
                                                           crab angle
``wave_oscillation``     ``period`` (s), ``height`` (m),   regular first-order waves
                         ``direction`` (rad)
``wind``                 ``speed`` (m/s), ``direction``    steady wind blowing toward
                         (rad), ``frontal_area``,          ``direction``: drag 0.5 rho_air
                         ``side_area`` (m^2)               A |V_rel| V_rel on the hull and
                                                           superstructure (surge: frontal area,
                                                           sway: side area)
``thrust_loss``          ``start`` (s), ``fraction``       a fouled propeller: from ``start``
                                                           the thrust is ``1 - fraction`` of
                                                           what it was
``gnss_jitter``          ``std_s`` (s)                     each fix's time tag off by a normal
                                                           error of ``std_s`` (no mean latency)
``external_force``       ``north``, ``east``, ``down``     constant world-frame force (the
                         (N)                               ESESO paper's disturbance)
``gnss_outage``          ``start``, ``duration`` (s)       sensor fault: no GNSS fix at all
                                                           in the window
``dvl_lock_loss``        ``start``, ``duration`` (s)       sensor fault: the DVL loses bottom
                                                           lock (reports ``valid=False``,
                                                           zeros) in the window
``compass_step``         ``start``, ``duration`` (s),      sensor fault: the heading reads
                         ``radians``                       ``radians`` more in the window
                                                           (duration inf: permanent)
=======================  ================================  ===================================

The three sensor faults are meant to be **declared** (the fault scenarios of
:mod:`sitl.scenarios` declare them): they are test material for the service's fault
handling, not for model closure. The truth records the fault's parameters and its
state (``sensor.gnss_outage``, ``sensor.dvl_locked``, ``sensor.heading_error``).

How they act: sea effects change the :class:`~sitl.environment.Environment`; sensor
effects change the sensor configuration (:func:`apply_to_sensors`); force effects are
added to the plant's external force at every control step (:func:`external_force_ned`, so
the truth's ``disturbance_*`` shows them); ``thrust_nonlinearity`` changes the plant's
thrust law where the plant supports it (:func:`apply_to_plant`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from onboard.sitl.environment import (
    CurrentField,
    Environment,
    NonuniformCurrent,
    TidalCurrent,
    UniformCurrent,
    WaveField,
)
from onboard.sitl.sensors import SensorSuiteConfig

VOCABULARY: dict[str, tuple[str, ...]] = {
    "water_current": ("north", "east"),
    "tidal_current": ("amplitude", "period", "direction", "mean", "phase"),
    "nonuniform_current": ("amplitude", "length"),
    "rotating_current": ("speed", "direction", "rate"),
    "compass_deviation": ("amplitude", "phase"),
    "soft_iron": ("amplitude", "phase"),
    "heading_bias": ("radians",),
    "gyro_bias": ("x", "y", "z"),
    "gps_latency": ("seconds",),
    "thrust_nonlinearity": ("exponent",),
    "quadratic_drag": ("coefficient",),
    "surge_yaw_coupling": ("coefficient",),
    "sideslip": ("coefficient",),
    "wave_oscillation": ("period", "height", "direction"),
    "wind": ("speed", "direction", "frontal_area", "side_area"),
    "thrust_loss": ("start", "fraction"),
    "gnss_jitter": ("std_s",),
    "external_force": ("north", "east", "down"),
    "gnss_outage": ("start", "duration"),
    "dvl_lock_loss": ("start", "duration"),
    "compass_step": ("start", "duration", "radians"),
}
"""Effect name -> its parameter names (all floats, SI units, see the module table)."""

_DEFAULTS: dict[str, dict[str, float]] = {
    "tidal_current": {"direction": 0.0, "mean": 0.0, "phase": 0.0},
    "nonuniform_current": {"amplitude": 0.3, "length": 500.0},
    "gyro_bias": {"x": 0.0, "y": 0.0, "z": 0.0},
    "wave_oscillation": {"height": 0.3, "direction": 0.0},
    "external_force": {"north": 0.0, "east": 0.0, "down": 0.0},
    "wind": {"frontal_area": 0.15, "side_area": 0.3},
    "compass_step": {"duration": math.inf},
}


@dataclass(frozen=True)
class Effect:
    """One injected effect: a vocabulary ``name`` and its ``params`` (SI units)."""

    name: str
    params: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.name not in VOCABULARY:
            raise ValueError(f"unknown effect {self.name!r}; known: {', '.join(VOCABULARY)}")
        allowed = VOCABULARY[self.name]
        full = dict(_DEFAULTS.get(self.name, {}))
        for k, v in self.params.items():
            if k not in allowed:
                raise ValueError(f"effect {self.name}: unknown parameter {k!r} "
                                 f"(expected {', '.join(allowed)})")
            full[k] = float(v)
        missing = [k for k in allowed if k not in full]
        if missing:
            raise ValueError(f"effect {self.name}: missing parameter(s) {', '.join(missing)}")
        object.__setattr__(self, "params", full)

    def truth_items(self) -> dict[str, float]:
        """``{"<name>.<param>": value}`` for the truth file."""
        return {f"{self.name}.{k}": v for k, v in self.params.items()}


@dataclass(frozen=True)
class RotatingCurrent(CurrentField):
    """A uniform current of ``speed`` (m/s) flowing toward ``direction + rate t`` (rad,
    clockwise from north; ``t`` in s): a tidal stream turning over a survey."""

    speed: float
    direction: float
    rate: float

    def velocity_ned(self, t: float, position_ned: np.ndarray) -> np.ndarray:
        a = self.direction + self.rate * t
        return np.array([self.speed * math.cos(a), self.speed * math.sin(a), 0.0])


def effect_params(effects: tuple[Effect, ...]) -> dict[str, float]:
    """All injected effects' parameters, keyed ``"<name>.<param>"``."""
    out: dict[str, float] = {}
    for e in effects:
        out.update(e.truth_items())
    return out


def apply_to_environment(effects: tuple[Effect, ...], env: Environment) -> Environment:
    """The environment with the sea effects (currents, waves) added."""
    cur: CurrentField = env.current
    waves = env.waves
    for e in effects:
        p = e.params
        if e.name == "water_current":
            cur = cur + UniformCurrent(p["north"], p["east"], 0.0)
        elif e.name == "tidal_current":
            cur = cur + TidalCurrent(amplitude=p["amplitude"], direction=p["direction"],
                                     period=p["period"], phase=p["phase"], mean=p["mean"])
        elif e.name == "rotating_current":
            cur = cur + RotatingCurrent(p["speed"], p["direction"], p["rate"])
        elif e.name == "nonuniform_current":
            cur = cur + NonuniformCurrent(amplitude=p["amplitude"], length=p["length"])
        elif e.name == "wave_oscillation":
            waves = WaveField.regular(p["height"], p["period"], p["direction"])
    return dataclasses.replace(env, current=cur, waves=waves)


def apply_to_sensors(effects: tuple[Effect, ...], cfg: SensorSuiteConfig) -> SensorSuiteConfig:
    """The sensor suite with the sensor effects (compass, gyro, GNSS latency) and the
    sensor faults (GNSS outage, DVL lock loss, compass step) applied."""
    for e in effects:
        p = e.params
        if e.name == "compass_deviation" and cfg.compass is not None:
            cfg = dataclasses.replace(cfg, compass=dataclasses.replace(
                cfg.compass, hard_iron_rad=p["amplitude"], hard_iron_phase_rad=p["phase"]))
        elif e.name == "soft_iron" and cfg.compass is not None:
            cfg = dataclasses.replace(cfg, compass=dataclasses.replace(
                cfg.compass, soft_iron_rad=p["amplitude"], soft_iron_phase_rad=p["phase"]))
        elif e.name == "heading_bias" and cfg.compass is not None:
            cfg = dataclasses.replace(cfg, compass=dataclasses.replace(
                cfg.compass, offset_rad=cfg.compass.offset_rad + p["radians"]))
        elif e.name == "gyro_bias" and cfg.imu is not None:
            cfg = dataclasses.replace(cfg, imu=dataclasses.replace(
                cfg.imu, gyro_bias_injected=(p["x"], p["y"], p["z"])))
        elif e.name == "gps_latency" and cfg.gnss is not None:
            cfg = dataclasses.replace(cfg, gnss=dataclasses.replace(
                cfg.gnss, latency_s=cfg.gnss.latency_s + p["seconds"]))
        elif e.name == "gnss_jitter" and cfg.gnss is not None:
            cfg = dataclasses.replace(cfg, gnss=dataclasses.replace(
                cfg.gnss, time_jitter_std_s=p["std_s"]))
        elif e.name == "gnss_outage" and cfg.gnss is not None:
            cfg = dataclasses.replace(cfg, gnss=dataclasses.replace(
                cfg.gnss, outage_windows=cfg.gnss.outage_windows + ((p["start"], p["duration"]),)))
        elif e.name == "dvl_lock_loss" and cfg.dvl is not None:
            cfg = dataclasses.replace(cfg, dvl=dataclasses.replace(
                cfg.dvl, lock_loss_windows=cfg.dvl.lock_loss_windows
                + ((p["start"], p["duration"]),)))
        elif e.name == "compass_step" and cfg.compass is not None:
            cfg = dataclasses.replace(cfg, compass=dataclasses.replace(
                cfg.compass, steps=cfg.compass.steps
                + ((p["start"], p["duration"], p["radians"]),)))
    return cfg


def apply_to_plant(effects: tuple[Effect, ...], plant: object) -> None:
    """Plant-parameter effects: ``thrust_nonlinearity`` sets ``params.thrust_exponent``
    on plants whose parameters have one (see :mod:`sitl.scenarios`); ``thrust_loss`` sets
    the plant's ``thrust_loss`` = (start, fraction) where it has that attribute."""
    for e in effects:
        if e.name == "thrust_loss":
            if not hasattr(plant, "thrust_loss"):
                raise ValueError(f"plant {getattr(plant, 'name', plant)!r} has no thrust_loss")
            plant.thrust_loss = (e.params["start"], e.params["fraction"])
        if e.name == "thrust_nonlinearity":
            params = getattr(plant, "params", None)
            if params is None or not hasattr(params, "thrust_exponent"):
                raise ValueError(f"plant {getattr(plant, 'name', plant)!r} has no "
                                 "thrust_exponent parameter for thrust_nonlinearity")
            plant.params = dataclasses.replace(params, thrust_exponent=e.params["exponent"])


FORCE_EFFECTS = ("quadratic_drag", "surge_yaw_coupling", "sideslip", "external_force", "wind")
AIR_DENSITY = 1.225
"""kg/m^3 at sea level, 15 deg C."""


def external_force_ned(effects: tuple[Effect, ...], u_r: float, r: float, yaw: float,
                       surge_mass_kg: float) -> np.ndarray | None:
    """Sum of the force effects (N, NED) for a vehicle with surge speed through the water
    ``u_r`` (m/s), yaw rate ``r`` (rad/s) and heading ``yaw`` (rad); None when there are
    none. ``surge_mass_kg`` (the plant's effective surge mass) turns the
    ``surge_yaw_coupling`` acceleration into a force. Body forces are turned into the
    earth frame with the heading only (surface vehicles)."""
    fx = fy = 0.0
    f_ned = np.zeros(3)
    any_force = False
    u = u_r
    for e in effects:
        p = e.params
        if e.name == "quadratic_drag":
            fx -= p["coefficient"] * u * abs(u)
        elif e.name == "surge_yaw_coupling":
            fx -= surge_mass_kg * p["coefficient"] * u * r * r
        elif e.name == "sideslip":
            fy += p["coefficient"] * u * abs(u)
        elif e.name == "external_force":
            f_ned += (p["north"], p["east"], p["down"])
        elif e.name == "wind":
            # apparent wind in body axes (the boat's sway is small against its surge)
            rel = p["direction"] - yaw
            wx = p["speed"] * math.cos(rel) - u
            wy = p["speed"] * math.sin(rel)
            w = math.hypot(wx, wy)
            fx += 0.5 * AIR_DENSITY * p["frontal_area"] * w * wx
            fy += 0.5 * AIR_DENSITY * p["side_area"] * w * wy
        else:
            continue
        any_force = True
    if not any_force:
        return None
    if fx or fy:
        c, s = math.cos(yaw), math.sin(yaw)
        f_ned[0] += c * fx - s * fy
        f_ned[1] += s * fx + c * fy
    return f_ned
