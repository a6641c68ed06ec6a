"""The contract every estimation pipeline fulfils.

A pipeline is pure and synchronous: numbers in, numbers out. No I/O, no clock, no
asyncio, no global state. The engine calls :meth:`Pipeline.step` once per fixed-rate tick
with the samples that arrived since the previous tick, in time order. Because the
pipeline sees only its inputs, live operation and replay give identical results.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Protocol, Sequence, runtime_checkable

from onboard.core.config import Config
from onboard.core.messages import Innovation, Sample


@runtime_checkable
class Pipeline(Protocol):
    """One estimator family, e.g. ``aie`` or ``current``.

    Attributes:
        name: the pipeline name, the prefix of its columns in estimates.csv and its
            Zenoh key ``onboard/<id>/est/<name>``.
        columns: the quantities it can estimate (without the prefix), in the order they
            appear in estimates.csv. Fixed at construction.

    Optional: ``events``, a list of human-readable event strings; after each step the
    engine moves them into its health events (prefixed with the pipeline name) and
    empties the list.
    """

    name: str
    columns: tuple[str, ...]

    def step(self, t: float, samples: Sequence[Sample]) -> Mapping[str, float]:
        """Advance to tick time ``t`` (s) given the new ``samples`` (time-ordered, all
        with ``sample.t <= t``); return the current estimates by quantity name. A quantity
        with no estimate yet is simply absent from the mapping."""
        ...

    def innovations(self) -> list[Innovation]:
        """The :class:`~onboard.core.messages.Innovation` records of the measurement
        updates since the last call, one per update (accepted or rejected, with the
        reason); the pipeline keeps none of them after the call."""
        ...

    def health(self) -> Mapping[str, float]:
        """Counters and diagnostics by name, e.g. ``{"surge.steps": 120, "surge.diverged":
        0, "surge.V_d": 0.1}``: the pipeline's own numbers beside its innovations."""
        ...

    def get_state(self) -> dict[str, Any]:
        """Adaptive state worth keeping across a restart (JSON-serializable)."""
        ...

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restore what :meth:`get_state` returned; ignore what does not fit."""
        ...


def unused_measurement(channel: str, t: float, dof: int, reason: str,
                       source: str = "") -> Innovation:
    """The record of a measurement rejected before any update (invalid, not finite, ...):
    without a forecast its innovation, covariance and NIS are not numbers."""
    nan = math.nan
    return Innovation(channel=channel, t=t, z=(nan,) * dof, S=(nan,) * (dof * dof),
                      nis=nan, dof=dof, accepted=False, reason=reason, source=source)


class PipelineFactory(Protocol):
    """The ``create(cfg)`` function every pipeline module exposes
    (:func:`onboard.pipelines.build` calls it)."""

    def __call__(self, cfg: Config) -> Pipeline | None:
        """Build the pipeline for this configuration, or None if it does not apply."""
        ...
