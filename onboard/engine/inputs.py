"""The input mapping: raw actuator outputs -> normalized :class:`ActuatorCommand`.

Which servo channel is which actuator, and how a pulse width scales, is configuration
(``[inputs]`` in the vehicle TOML, :class:`onboard.core.config.Inputs`). Pipelines only ever see
the normalized command, so the same estimator serves a Jaiabot, a BlueBoat or a Gavia.
"""

from __future__ import annotations

from typing import Any

import msgspec
from mypy_extensions import mypyc_attr

from onboard.core.config import ChannelMap, Inputs
from onboard.core.messages import (
    ActuatorColumn,
    ActuatorCommand,
    ActuatorOutputs,
    PropellerRpm,
    RcChannels,
    Sample,
)

_ROLES = ("throttle", "rudder", "left", "right", "propeller_rpm", "stern_plane", "pump",
          "battery")
_FIELD = {"rudder": "rudder_rad", "stern_plane": "stern_plane_rad", "pump": "pump_cc",
          "battery": "battery_m"}


ROLE_FUNCTIONS: dict[str, tuple[int, ...]] = {
    "rudder": (26, 21), "throttle": (70,), "left": (73,), "right": (74,), "stern_plane": (19,),
}
"""Role -> ArduPilot ``SERVOn_FUNCTION`` values that drive it: 26 GroundSteering, 21 Rudder,
70 Throttle, 73/74 ThrottleLeft/Right, 19 Elevator; thruster ``i`` is Motor ``i+1`` (33+i)."""
MOTOR1 = 33


def remap(inputs: Inputs, functions: dict[int, int]) -> tuple[Inputs, list[str]]:
    """``inputs`` with every servo-mapped role on the output whose function drives it
    (``functions``: output channel -> SERVOn_FUNCTION; the lowest channel when several);
    roles whose function no output has keep their channel. Also the changes, as text."""
    by_function: dict[int, int] = {}
    for out in sorted(functions, reverse=True):
        by_function[functions[out]] = out
    changes: list[str] = []
    kw: dict = {}
    for role, funcs in ROLE_FUNCTIONS.items():
        m = getattr(inputs, role)
        ch: int | None = next((by_function[f] for f in funcs if f in by_function), None)
        if m is None or m.source != "servo" or ch is None or ch == m.channel:
            continue
        kw[role] = msgspec.structs.replace(m, channel=ch)
        changes.append(f"{role} on SERVO{ch} (SERVO{ch}_FUNCTION={functions[ch]}), "
                       f"configured SERVO{m.channel}")
    thr = list(inputs.thrusters)
    for i, m in enumerate(thr):
        ch = by_function.get(MOTOR1 + i)
        if m.source == "servo" and ch is not None and ch != m.channel:
            thr[i] = msgspec.structs.replace(m, channel=ch)
            changes.append(f"thruster {i + 1} on SERVO{ch} (SERVO{ch}_FUNCTION={MOTOR1 + i}), "
                           f"configured SERVO{m.channel}")
    if thr != list(inputs.thrusters):
        kw["thrusters"] = thr
    return (msgspec.structs.replace(inputs, **kw) if kw else inputs), changes


def column_names(inputs: Inputs) -> list[str]:
    """The log columns the roles with ``source = "column"`` read, in role order."""
    maps = [getattr(inputs, r) for r in _ROLES] + list(inputs.thrusters)
    return [m.column for m in maps if m is not None and m.source == "column"]


def normalize_pwm(pwm_us: float, m: ChannelMap) -> float:
    """Pulse width (us), or a column's value in its own units -> value in [-1, 1] times
    ``full_scale`` (see ChannelMap)."""
    x = pwm_us - m.neutral_us
    if abs(x) <= m.deadband_us:
        return 0.0
    x = x / m.half_range_us
    x = -x if m.reverse else x
    x = 1.0 if x > 1.0 else -1.0 if x < -1.0 else x
    return x * m.full_scale


@mypyc_attr(allow_interpreted_subclasses=True)
class InputMapper:
    """Turns ActuatorOutputs / RcChannels / PropellerRpm / ActuatorColumn samples into
    ActuatorCommand.

    A command is emitted whenever a source that feeds a mapped role arrives; roles fed by
    other sources keep their latest value, so a vehicle with PWM outputs and a separate
    RPM sensor gets one coherent command.
    """

    def __init__(self, inputs: Inputs) -> None:
        self.configured = inputs
        self.functions: dict[int, int] = {}
        """Output channel -> SERVOn_FUNCTION, from the parameters seen."""
        self._setup(inputs)

    def _setup(self, inputs: Inputs) -> None:
        self.inputs = inputs
        self._roles = [(r, getattr(inputs, r)) for r in _ROLES if getattr(inputs, r) is not None]
        self._latest: dict[str, float] = {}
        self._thrusters: list[float] = [0.0] * len(inputs.thrusters)
        self.sources = {m.source for _, m in self._roles} | {m.source for m in inputs.thrusters}

    def parameter(self, name: str, value: float) -> list[str]:
        """Take an autopilot parameter; a ``SERVOn_FUNCTION`` re-targets the roles when
        ``inputs.from_autopilot`` (see :func:`remap`). Returns the mapping changes."""
        if not (self.configured.from_autopilot and name.startswith("SERVO")
                and name.endswith("_FUNCTION")):
            return []
        try:
            ch = int(name[5:-9])
        except ValueError:
            return []
        if self.functions.get(ch) == int(value):
            return []
        self.functions[ch] = int(value)
        inputs, _ = remap(self.configured, self.functions)
        if inputs == self.inputs:
            return []
        _, changes = remap(self.inputs, self.functions)
        self._setup(inputs)
        return changes

    @property
    def active(self) -> bool:
        """Whether the configuration maps any actuator channel to a command."""
        return bool(self._roles or self.inputs.thrusters)

    def _value(self, m: ChannelMap, sample: Sample) -> float | None:
        if isinstance(sample, ActuatorColumn):
            if m.source != "column" or m.column != sample.column:
                return None
            return normalize_pwm(sample.value, m)
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
        if not isinstance(sample, (ActuatorOutputs, RcChannels, PropellerRpm,
                                   ActuatorColumn)):
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
        kw: dict[str, Any] = {_FIELD.get(r, r): v for r, v in self._latest.items()}
        if self.inputs.thrusters:
            kw["thrusters"] = tuple(self._thrusters)
        return ActuatorCommand(t=sample.t, source="mapped:" + sample.source, **kw)
