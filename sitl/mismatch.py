"""Model mismatch: named perturbations of a simulated plant against the nominal model.

The estimators and controllers are told the *nominal* vehicle (the plant's published
parameters, a bundled config, a model identified on the nominal plant); these cases make
the simulated vehicle differ from it, from outside the plant files: a copy of the plant's
parameter dataclass with some coefficients scaled, a plant subclass whose actuators lag
behind the command or give less thrust, and a sensor suite with more noise than the
estimator's configuration declares. docs/mismatch.md has the campaign over these cases.

Cases (:data:`CASES`):

* ``mass+20`` / ``mass-20``: rigid-body mass and inertia and the added masses x 1.2 / 0.8
  (the weight and buoyancy stay: the vehicle's trim is not the question);
* ``damping+30`` / ``damping-30``: the linear and quadratic damping (drag) x 1.3 / 0.7;
* ``thrust-15``: every thruster gives 85 % of the thrust the nominal curve says for a
  command (a tired battery, a fouled propeller);
* ``lag0.15``: the thrusters follow the command with a first-order lag of 0.15 s (motor
  and ESC dynamics; rudders and fins are not lagged);
* ``noise2x``: every sensor's white noise doubled (biases and drifts unchanged), the
  estimator still told the nominal noise;
* ``worst``: all at once in the direction that hurts a tracking controller most (mass
  +20 %, damping -30 %, thrust -15 %, lag 0.15 s, noise x2).

What "mass", "damping" and "thrust" mean per plant (:func:`perturb_params`):

* BlueROV2 (:class:`sitl.plants.bluerov2.BlueROV2Params`): ``m``, ``inertia``,
  ``added_mass``; ``d_lin``, ``d_quad``; the thrust through the commands (thrust is
  ``40 c|c|``, so a command scaled by ``sqrt(k)`` gives ``k`` times the thrust; the
  estimator sees the unscaled command).
* Torpedo AUV (:class:`sitl.plants.torpedo_auv.TorpedoParams`): the mass ``W/g`` through a
  parameter subclass (weight unchanged), ``i_xx..i_zz``, the added masses (``*dot``) and
  Prestero's added-mass Coriolis coefficients (``x_wq`` ... ``n_pq``); the drag
  coefficients (``x_uu``, ``y_vv``, ``y_rr``, ``z_ww``, ``z_qq``, ``k_pp``, ``m_ww``,
  ``m_qq``, ``n_vv``, ``n_rr``; the body-lift terms unchanged); ``x_prop_ref`` (thrust at
  the reference rpm; the rpm sensor reads the true shaft speed, which is unchanged).
* Rudder boat (:class:`sitl.plants.rudder_boat.RudderBoatParams`): ``m``, ``x_udot``,
  ``y_vdot``, ``i_z``, ``n_rdot``; ``d_u``, ``d_uu``, ``y_v0``, ``y_vu``, ``y_vv``,
  ``n_r0``, ``n_ru``, ``n_rr``; ``t_max``.

A parameter named here that a plant no longer has is an error (:class:`MismatchError`),
not a silent no-op.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from onboard.sitl.plants.base import Command

__all__ = [
    "CASES",
    "MismatchCase",
    "MismatchError",
    "NOISE_FIELDS",
    "get",
    "perturb_params",
    "perturb_plant",
    "perturb_scenario",
    "perturb_sensors",
    "scale_noise",
]


class MismatchError(ValueError):
    """A case cannot be applied to this plant (unknown plant, parameter missing)."""


@dataclass(frozen=True)
class MismatchCase:
    """One perturbation of the plant against the nominal model (factors are multipliers,
    1 = nominal).

    Attributes:
        name: the case's name in tables and on the command line.
        mass_scale: rigid-body mass and inertia and added mass.
        damping_scale: linear and quadratic damping.
        thrust_scale: thrust for a given command.
        lag_s: first-order time constant of the thrusters (s), 0 = none.
        noise_scale: white noise of every sensor.
    """

    name: str
    mass_scale: float = 1.0
    damping_scale: float = 1.0
    thrust_scale: float = 1.0
    lag_s: float = 0.0
    noise_scale: float = 1.0

    @property
    def is_nominal(self) -> bool:
        """True when the case changes nothing."""
        return (self.mass_scale == self.damping_scale == self.thrust_scale
                == self.noise_scale == 1.0 and self.lag_s == 0.0)

    def describe(self) -> str:
        """One line: what differs from nominal."""
        parts = []
        if self.mass_scale != 1.0:
            parts.append(f"mass x{self.mass_scale:g}")
        if self.damping_scale != 1.0:
            parts.append(f"damping x{self.damping_scale:g}")
        if self.thrust_scale != 1.0:
            parts.append(f"thrust x{self.thrust_scale:g}")
        if self.lag_s:
            parts.append(f"thruster lag {self.lag_s:g} s")
        if self.noise_scale != 1.0:
            parts.append(f"sensor noise x{self.noise_scale:g}")
        return ", ".join(parts) or "plant = model"


CASES: dict[str, MismatchCase] = {c.name: c for c in (
    MismatchCase("nominal"),
    MismatchCase("mass+20", mass_scale=1.2),
    MismatchCase("mass-20", mass_scale=0.8),
    MismatchCase("damping+30", damping_scale=1.3),
    MismatchCase("damping-30", damping_scale=0.7),
    MismatchCase("thrust-15", thrust_scale=0.85),
    MismatchCase("lag0.15", lag_s=0.15),
    MismatchCase("noise2x", noise_scale=2.0),
    MismatchCase("worst", mass_scale=1.2, damping_scale=0.7, thrust_scale=0.85, lag_s=0.15,
                 noise_scale=2.0),
)}
"""The named cases, nominal first (module docstring)."""


def get(name: str | MismatchCase) -> MismatchCase:
    """The case called ``name`` (a case is returned as is)."""
    if isinstance(name, MismatchCase):
        return name
    try:
        return CASES[name]
    except KeyError:
        raise MismatchError(f"unknown mismatch case {name!r} ({', '.join(CASES)})") from None


# --------------------------------------------------------------------------- parameters

_BLUEROV2 = {"mass": ("m", "inertia", "added_mass"), "damping": ("d_lin", "d_quad"),
             "thrust": ()}
_TORPEDO_ADDED = ("x_udot", "y_vdot", "y_rdot", "z_wdot", "z_qdot", "k_pdot", "m_wdot",
                  "m_qdot", "n_vdot", "n_rdot", "x_wq", "x_qq", "x_vr", "x_rr", "y_wp",
                  "y_pq", "z_vp", "z_rp", "m_vp", "m_rp", "n_wp", "n_pq")
_TORPEDO = {"mass": ("mass_scale", "i_xx", "i_yy", "i_zz") + _TORPEDO_ADDED,
            "damping": ("x_uu", "y_vv", "y_rr", "z_ww", "z_qq", "k_pp", "m_ww", "m_qq",
                        "n_vv", "n_rr"),
            "thrust": ("x_prop_ref",)}
_RUDDER_BOAT = {"mass": ("m", "x_udot", "y_vdot", "i_z", "n_rdot"),
                "damping": ("d_u", "d_uu", "y_v0", "y_vu", "y_vv", "n_r0", "n_ru", "n_rr"),
                "thrust": ("t_max",)}


def _table(params: Any) -> dict[str, tuple[str, ...]]:
    from onboard.sitl.plants.bluerov2 import BlueROV2Params
    from onboard.sitl.plants.rudder_boat import RudderBoatParams
    from onboard.sitl.plants.torpedo_auv import TorpedoParams

    if isinstance(params, BlueROV2Params):
        return _BLUEROV2
    if isinstance(params, TorpedoParams):
        return _TORPEDO
    if isinstance(params, RudderBoatParams):
        return _RUDDER_BOAT
    raise MismatchError(f"no mismatch table for {type(params).__name__} "
                        "(BlueROV2Params, TorpedoParams, RudderBoatParams)")


def _mass_scaled_torpedo(params: Any) -> Any:
    """``params`` as a :class:`TorpedoParams` subclass whose mass ``W/g`` is multiplied by
    a ``mass_scale`` field (the weight, hence the trim, unchanged)."""
    from onboard.sitl.integrate import GRAVITY
    from onboard.sitl.plants.torpedo_auv import TorpedoParams

    if hasattr(params, "mass_scale"):
        return params

    @dataclass(frozen=True)
    class MassScaledTorpedoParams(TorpedoParams):
        mass_scale: float = 1.0

        @property
        def m(self) -> float:  # type: ignore[override]
            """Mass ``mass_scale W / g`` (kg)."""
            return self.mass_scale * self.weight / GRAVITY

    fields = {f.name: getattr(params, f.name) for f in dataclasses.fields(params) if f.init}
    return MassScaledTorpedoParams(**fields)


def _scaled(value: Any, k: float) -> Any:
    if isinstance(value, tuple):
        return tuple(float(v) * k for v in value)
    return float(value) * k


def perturb_params(params: Any, case: MismatchCase | str) -> Any:
    """A copy of a plant's parameter dataclass with the case's mass, damping and thrust
    factors applied (module docstring for which fields). The thrust of a BlueROV2 has no
    parameter and is applied by :func:`perturb_plant` instead.

    Args:
        params: the plant's parameters (BlueROV2Params, TorpedoParams, RudderBoatParams).
        case: the case or its name.
    """
    case = get(case)
    table = _table(params)
    from onboard.sitl.plants.torpedo_auv import TorpedoParams

    if isinstance(params, TorpedoParams) and case.mass_scale != 1.0:
        params = _mass_scaled_torpedo(params)
    changes: dict[str, Any] = {}
    for group, k in (("mass", case.mass_scale), ("damping", case.damping_scale),
                     ("thrust", case.thrust_scale)):
        if k == 1.0:
            continue
        for name in table[group]:
            if not hasattr(params, name):
                raise MismatchError(f"{type(params).__name__} has no parameter {name!r} "
                                    f"for the {group} perturbation")
            changes[name] = _scaled(getattr(params, name), k)
    return dataclasses.replace(params, **changes) if changes else params


# --------------------------------------------------------------------------- plants

_THRUST_FIELDS = ("throttle", "left", "right", "propeller_rpm")


class _ActuatorMismatch:
    """Mixin placed before a plant class: the command the plant receives is the held
    command through a first-order lag (``_mm_lag_s``, exact discretisation over each
    step) on the propulsion fields (throttle, left, right, propeller rpm, thrusters), and
    the BlueROV2 thruster commands scaled by ``_mm_command_scale``."""

    _mm_lag_s: float = 0.0
    _mm_command_scale: float = 1.0
    _mm_state: dict[str, Any] | None = None

    def step(self, dt: float, command: Command, env: Any, t: float) -> None:
        """Advance the plant (as the plant's own ``step``) under the perturbed command."""
        super().step(dt, self._mm_command(dt, command), env, t)  # type: ignore[misc]

    def _mm_command(self, dt: float, command: Command) -> Command:
        changes: dict[str, Any] = {}
        if self._mm_lag_s > 0.0:
            a = 1.0 - math.exp(-dt / self._mm_lag_s)
            state = self._mm_state if self._mm_state is not None else {}
            for name in _THRUST_FIELDS:
                u = getattr(command, name)
                if u is None:
                    continue
                y = state.get(name, float(u))
                y += a * (float(u) - y)
                state[name] = y
                changes[name] = y
            if command.thrusters is not None:
                u6 = [float(c) for c in command.thrusters]
                y6 = state.get("thrusters", u6)
                y6 = [y + a * (u - y) for u, y in zip(u6, y6)]
                state["thrusters"] = y6
                changes["thrusters"] = tuple(y6)
            self._mm_state = state
        if self._mm_command_scale != 1.0:
            thr = changes.get("thrusters", command.thrusters)
            if thr is not None:
                changes["thrusters"] = tuple(self._mm_command_scale * c for c in thr)
        return dataclasses.replace(command, **changes) if changes else command


_SUBCLASSES: dict[type, type] = {}


def perturb_plant(plant: Any, case: MismatchCase | str) -> Any:
    """A new plant of ``plant``'s class (reset to rest at the origin) with the case's
    parameters and actuator mismatch; ``plant`` itself is returned for the nominal case.
    Sensor noise is not a plant property (:func:`perturb_sensors`).

    Args:
        plant: a BlueROV2, torpedo AUV or rudder-boat plant (subclasses included).
        case: the case or its name.
    """
    from onboard.sitl.plants.bluerov2 import BlueROV2

    case = get(case)
    if (case.mass_scale == case.damping_scale == case.thrust_scale == 1.0
            and case.lag_s == 0.0):
        return plant
    params = perturb_params(plant.params, case)
    cls = type(plant)
    sub = _SUBCLASSES.get(cls)
    if sub is None:
        sub = type(f"Mismatched{cls.__name__}", (_ActuatorMismatch, cls), {})
        _SUBCLASSES[cls] = sub
    new = sub(params, dt=plant.dt)
    new._mm_lag_s = float(case.lag_s)
    if isinstance(plant, BlueROV2) and case.thrust_scale != 1.0:
        new._mm_command_scale = math.sqrt(case.thrust_scale)
    return new


# --------------------------------------------------------------------------- sensors

NOISE_FIELDS = ("position_std_m", "altitude_std_m", "velocity_std_mps", "velocity_std_per_m",
                "accel_noise_std", "gyro_noise_std", "noise_std_rad",
                "attitude_noise_std_rad", "depth_std_m", "noise_std_rpm")
"""The white-noise standard deviations of :mod:`sitl.sensors` configs that ``noise_scale``
multiplies (biases, drifts and their walks are not noise and stay)."""


def scale_noise(cfg: Any, k: float) -> Any:
    """A copy of one sensor config (a :mod:`sitl.sensors` ``*Config``) with its white
    noise (:data:`NOISE_FIELDS`) multiplied by ``k``.

    Args:
        cfg: the sensor's config dataclass.
        k: the factor.
    """
    if k == 1.0 or cfg is None:
        return cfg
    changes = {f.name: getattr(cfg, f.name) * k for f in dataclasses.fields(cfg)
               if f.name in NOISE_FIELDS}
    return dataclasses.replace(cfg, **changes)


def perturb_sensors(suite: Any, case: MismatchCase | str) -> Any:
    """A :class:`sitl.sensors.SensorSuiteConfig` with every fitted sensor's white noise
    multiplied by the case's ``noise_scale`` (actuator outputs unchanged).

    Args:
        suite: the scenario's sensor suite.
        case: the case or its name.
    """
    case = get(case)
    if case.noise_scale == 1.0:
        return suite
    changes = {f.name: scale_noise(getattr(suite, f.name), case.noise_scale)
               for f in dataclasses.fields(suite) if f.name != "actuators"}
    return dataclasses.replace(suite, **changes)


def perturb_scenario(scenario: Any, case: MismatchCase | str) -> Any:
    """A :class:`sitl.scenarios.Scenario` (or its name) whose plant and sensors carry the
    case; its name gets ``+<case>``. The estimator configuration a caller uses is not
    touched: it keeps the nominal model and the nominal sensor noise.

    Args:
        scenario: a scenario or its registered name.
        case: the case or its name.
    """
    from onboard.sitl import scenarios as scenarios_mod

    case = get(case)
    sc = scenarios_mod.get(scenario) if isinstance(scenario, str) else scenario
    if case.is_nominal:
        return sc
    make = sc.vehicle.make_plant
    vehicle = dataclasses.replace(sc.vehicle, make_plant=lambda: perturb_plant(make(), case))
    return dataclasses.replace(sc, name=f"{sc.name}+{case.name}", vehicle=vehicle,
                               sensors=perturb_sensors(sc.sensors, case))
