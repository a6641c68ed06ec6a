"""The base model of each vehicle class, or the one line saying there is none yet.

Model closure names what a vehicle model lacks, so the model must be the vehicle's. Two
exist:

* ``surface-boat`` (:mod:`onboard.offline.closure.model`): a hull that moves along its
  heading but for its sway in turns, a heading that turns with the gyro, a first-order
  surge speed from the commands; every effect of the catalog applies. For the classes of
  :data:`SURFACE_CLASSES`.
* ``glider``: a buoyancy-driven glider (a config with ``[pipelines.current.glider]``,
  whatever its class): the same lateral and heading channels, and along the heading the
  through-water speed of the steady glide from its pitch, depth rate and pump volume
  (:func:`onboard.offline.closure.dataset.glide_speed`, the current pipeline's model)
  in place of a surge model from commands. The effects that act on those channels
  apply (:data:`GLIDER_EFFECTS`); the others are not part of a glide.

The other classes are refused with one line (:class:`NoBaseModel`): a ``bluerov2`` (and a
``spheroid``) moves sideways by design on its thrusters, so "velocity across the heading
is the hull's sway in turns" is false for it, and the one ROV log at hand
(``ardusub_small_logs/small.tlog``) is a bench test under a fixed injected position that
could not check a replacement; a ``torpedo-auv`` is submerged, its velocity over ground a
DVL's or an INS's and its speed tied to depth and pitch changes, with no field log of one
to check a model on.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from onboard.core.config import Config
from onboard.core.errors import UsageError

# Vehicle-class traits, local until onboard/core/vehicles.py holds them (issue 31, roles).
SURFACE_CLASSES = ("rudder-boat", "twin-thruster-boat", "unknown")
"""Classes diagnosed with the surface boat's model: ``unknown`` is a log with no vehicle
evidence (an NMEA or logger capture), which carries GNSS fixes, so it is at the surface."""

GLIDER_EFFECTS = ("water_current", "compass_deviation", "heading_bias", "gyro_bias",
                  "sideslip")
"""The catalog effects that act on a glider's channels: a current (the glide is through
the water), the compass's errors, a gyro bias, a crab growing with speed."""

NOT_IN_A_GLIDE = {
    "gps_latency": "not in the glider model: its velocity over ground is the navigation "
                   "solution, whose time base no GNSS delay shows in",
    "wave_oscillation": "not in the glider model: a glider flies below the waves",
}
"""Why each effect outside :data:`GLIDER_EFFECTS` is not tried on a glider, where the
general reason (:data:`NO_SURGE_DYNAMICS`) does not say it."""

NO_SURGE_DYNAMICS = ("not in the glider model: its speed is the steady glide's, not a "
                     "surge response to commands")
"""Why the catalog's surge-dynamics effects (thrust law, drag, coupling, thruster
mapping, wind push) are not tried on a glider."""


class NoBaseModel(UsageError):
    """No base model exists for the config's vehicle class: ``onboard diagnose`` refuses
    the log with this one line (exit status 2)."""


@dataclass(frozen=True)
class BaseModel:
    """A class's base model: its ``name`` (``Dataset.base_model``), its ``description``
    (diagnosis.json ``model``), the ``effects`` tried on it (all of the catalog when
    empty) and why each other one is not (``excluded``: name -> reason)."""

    name: str
    description: str
    effects: tuple[str, ...] = ()
    excluded: dict[str, str] = field(default_factory=dict)

    def why_not(self, effect: str) -> str:
        """Why ``effect`` is not tried with this model ("" when it is)."""
        if not self.effects or effect in self.effects:
            return ""
        return self.excluded.get(effect, NO_SURGE_DYNAMICS)


SURFACE_BOAT = BaseModel(
    "surface-boat",
    "velocity over ground along the measured heading but for the hull's sway in turns "
    "(v = x_p r + x_pd r' + k_ur U r + k_urd (U r)'); heading rate equal to the gyro's; "
    "first-order surge model U' = -a U + b c + c0 from the normalized command through the "
    "shaft lag")

GLIDER = BaseModel(
    "glider",
    "velocity over ground along the measured heading but for the hull's sway in turns "
    "(v = x_p r + x_pd r' + k_ur U r + k_urd (U r)'); heading rate equal to the gyro's; "
    "through-water speed along the heading from the steady glide (pitch, depth rate, pump "
    "volume; [pipelines.current.glider])",
    GLIDER_EFFECTS, NOT_IN_A_GLIDE)

BY_NAME = {m.name: m for m in (SURFACE_BOAT, GLIDER)}
"""The base models by name (``Dataset.base_model``)."""

SUPPORTED = (f"{', '.join(SURFACE_CLASSES)} (a surface boat's model); a glider "
             "(a config with [pipelines.current.glider])")
"""The supported classes, as the refusal lists them."""


def for_config(cfg: Config) -> BaseModel:
    """The base model for ``cfg``'s vehicle (module docstring); a :class:`NoBaseModel`
    naming the class when there is none."""
    if cfg.pipelines.current.glider is not None:
        return GLIDER
    cls = cfg.vehicle.vehicle_class
    if cls in SURFACE_CLASSES:
        return SURFACE_BOAT
    raise NoBaseModel(f"no base model for the {cls} class yet (supported: {SUPPORTED})")
