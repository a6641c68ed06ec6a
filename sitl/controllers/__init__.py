"""Reference controllers for the simulator: PID, NMPC and the adaptive NMPC (AMPC).

The BlueROV2 paper's comparison (``../shared/papers/eseso-ampc-bluerov2.txt`` §V,
figs. 4-5): the same circle under a constant push, flown by a PID, a plain NMPC and the
NMPC whose prediction model carries the ESESO's disturbance estimate.

Every controller has the same interface (:class:`Controller`): once per control period it
gets the time, the *published* ESESO estimate record (the interface any external consumer
uses, never the pipeline's internals) and the reference, and returns a
:class:`ControlOutput`: the generalized wrench ``[X, Y, Z, N]`` (N, N, N, N m; body FRD)
and the normalized thruster commands that produce it.

The controllers see only the record: running the ESESO that publishes it is the
closed-loop runner's job (:mod:`sitl.closed_loop`, which imports this package, never the
other way round).

Frames: NED earth, FRD body, ZYX Euler angles, SI units.
"""

from __future__ import annotations

from onboard.sitl.controllers.base import (
    Bluerov2Params,
    CircleReference,
    ControlOutput,
    Controller,
    ReferencePoint,
    state_from_record,
)

__all__ = [
    "Bluerov2Params",
    "CircleReference",
    "ControlOutput",
    "Controller",
    "ReferencePoint",
    "make_controller",
    "state_from_record",
]


def make_controller(name: str, params: Bluerov2Params | None = None, **kw: object) -> Controller:
    """``pid``, ``nmpc``, ``nmpc-of`` (offset-free) or ``ampc`` with default tuning (keyword overrides passed on)."""
    params = params or Bluerov2Params()
    if name == "pid":
        from onboard.sitl.controllers.pid import PidController

        return PidController(params, **kw)  # type: ignore[arg-type]
    if name == "nmpc":
        from onboard.sitl.controllers.nmpc import Nmpc

        return Nmpc(params, **kw)  # type: ignore[arg-type]
    if name == "ampc":
        from onboard.sitl.controllers.ampc import Ampc

        return Ampc(params, **kw)  # type: ignore[arg-type]
    if name == "nmpc-of":
        from onboard.sitl.controllers.nmpc import OffsetFreeNmpc

        return OffsetFreeNmpc(params, **kw)  # type: ignore[arg-type]
    raise ValueError(f"unknown controller {name!r} (pid, nmpc, nmpc-of, ampc)")
