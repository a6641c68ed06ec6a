"""The input mapping: raw actuator outputs -> normalized :class:`ActuatorCommand`.

Which servo channel is which actuator, and how a pulse width scales, is configuration
(``[inputs]`` in the vehicle TOML, :class:`onboard.core.config.Inputs`). Pipelines only ever see
the normalized command, so the same estimator serves a Jaiabot, a BlueBoat or a Gavia.
"""

from __future__ import annotations

from onboard.core.config import ChannelMap, Inputs
from onboard.core.messages import ActuatorCommand, ActuatorOutputs, PropellerRpm, RcChannels, Sample

_ROLES = ("throttle", "rudder", "left", "right", "propeller_rpm", "stern_plane")
_FIELD = {"rudder": "rudder_rad", "stern_plane": "stern_plane_rad"}


def normalize_pwm(pwm_us: float, m: ChannelMap) -> float:
    """Pulse width (us) -> value in [-1, 1] times ``full_scale`` (see ChannelMap)."""
    x = pwm_us - m.neutral_us
    if abs(x) <= m.deadband_us:
        return 0.0
    x = x / m.half_range_us
    x = -x if m.reverse else x
    x = 1.0 if x > 1.0 else -1.0 if x < -1.0 else x
    return x * m.full_scale


class InputMapper:
    """Turns ActuatorOutputs / RcChannels / PropellerRpm samples into ActuatorCommand.

    A command is emitted whenever a source that feeds a mapped role arrives; roles fed by
    other sources keep their latest value, so a vehicle with PWM outputs and a separate
    RPM sensor gets one coherent command.
    """

    def __init__(self, inputs: Inputs) -> None:
        self.inputs = inputs
        self._roles = [(r, getattr(inputs, r)) for r in _ROLES if getattr(inputs, r) is not None]
        self._latest: dict[str, float] = {}
        self._thrusters: list[float] = [0.0] * len(inputs.thrusters)
        self.sources = {m.source for _, m in self._roles} | {m.source for m in inputs.thrusters}

    @property
    def active(self) -> bool:
        """Whether the configuration maps any actuator channel to a command."""
        return bool(self._roles or self.inputs.thrusters)

    def _value(self, m: ChannelMap, sample: Sample) -> float | None:
        if isinstance(sample, PropellerRpm):
            if m.source != "rpm" or m.channel > len(sample.rpm):
                return None
            return sample.rpm[m.channel - 1] * m.full_scale
        kind = "servo" if isinstance(sample, ActuatorOutputs) else "rc"
        if m.source != kind or m.channel > len(sample.pwm_us):  # type: ignore[attr-defined]
            return None
        pwm = sample.pwm_us[m.channel - 1]  # type: ignore[attr-defined]
        if pwm <= 0:  # unused channel
            return None
        return normalize_pwm(pwm, m)

    def map(self, sample: Sample) -> ActuatorCommand | None:
        """The command implied by ``sample``, or None if it feeds no mapped role."""
        if not isinstance(sample, (ActuatorOutputs, RcChannels, PropellerRpm)):
            return None
        changed = False
        for role, m in self._roles:
            v = self._value(m, sample)
            if v is not None:
                self._latest[role] = v
                changed = True
        for i, m in enumerate(self.inputs.thrusters):
            v = self._value(m, sample)
            if v is not None:
                self._thrusters[i] = v
                changed = True
        if not changed:
            return None
        kw = {_FIELD.get(r, r): v for r, v in self._latest.items()}
        if self.inputs.thrusters:
            kw["thrusters"] = tuple(self._thrusters)
        return ActuatorCommand(t=sample.t, source="mapped:" + sample.source, **kw)
