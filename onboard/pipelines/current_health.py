"""The health of pipeline ``current``: the counters of the pipeline itself and of each of
its collaborators (each keeps its own), and the diagnostics, as typed values
(:class:`CurrentHealth`) and in the flat form of the health record (docs/current.md,
"Outputs"; docs/architecture.md §4.4).
"""

from __future__ import annotations

from dataclasses import dataclass

import msgspec
from mypy_extensions import mypyc_attr

from onboard.estimators.current_kf import FilterCounters
from onboard.pipelines.current_samples import SampleCounters

AXES = ("north", "east", "down")
"""The earth axes of the current, in column order."""


@mypyc_attr(allow_interpreted_subclasses=True)
@dataclass
class PipelineCounters:
    """What :class:`~onboard.pipelines.current.CurrentPipeline` itself counted (its
    collaborators count their own)."""

    rejected_late: int = 0
    """Velocity measurements too old to fuse (``current.LATE_FUSE_MAX_S``)."""
    hgo_rls_updates: int | None = None
    """Updates of the high-gain observer's own RLS (None before its first step)."""
    hgo_rls_rejected: int | None = None
    """Its rejected updates (None before its first step)."""
    restore_discarded: int = 0
    """Restored currents the data contradicted."""
    restore_confirmed: int = 0
    """Restored currents the data confirmed."""
    unknown: int = 0
    """Ticks published with neither horizontal component known (each one-sigma above
    ``unknown_above_std_mps``, or the model ran away)."""


class LateHold(msgspec.Struct, frozen=True):
    """The late-sample hold (:class:`onboard.pipelines.base.LateSampleHold`) once a
    sample came late."""

    samples: int
    """Samples that arrived behind the horizon already passed."""
    hold_s: float
    """The current hold (s)."""
    beyond_hold: int
    """Of those, samples later than ``max_late_hold_s``."""


class CurrentHealth(msgspec.Struct, frozen=True, kw_only=True):
    """The health of pipeline ``current``
    (:meth:`onboard.pipelines.current.CurrentPipeline.health`): the counters of the
    pipeline and of each collaborator, and the diagnostics. A field that is None
    does not apply (no such observer or channel, nothing counted yet)."""

    samples: SampleCounters
    filter: FilterCounters
    pipeline: PipelineCounters
    rls_updates: int
    """Updates of the yaw RLS."""
    hgo_diverged: int
    """Divergences of the high-gain observer (0 without it)."""
    q_scale: float
    """The joint filter's process-noise scale from the calibration."""
    gnss_velocity_std: float
    """The GNSS velocity one-sigma of the newest fused fix (m/s)."""
    theta_std_max: float | None
    """The largest coefficient one-sigma, relative (None: no coefficients)."""
    yaw_rls_sigma: float | None
    """The yaw RLS's residual one-sigma (rad/s^2; None: no yaw channel)."""
    gamma: float | None
    """The high-gain observer's gain, its gamma* and the Lipschitz bound of the model it
    runs (None without it)."""
    gamma_star: float | None
    lipschitz: float | None
    flow_gain_kept: int | None
    """Steps the flow observer kept its gain (unobservable; None without it)."""
    flow_diverged: int | None
    """Divergences of the flow observer (None without it)."""
    observable: tuple[bool, ...]
    """Per earth axis, whether the published component was known."""
    along_track_unobservable: bool
    heading_diversity: float
    """Mean doubled-heading length of the recent headings (1: one line)."""
    late: LateHold | None
    """The late-sample hold (None while no sample came late)."""
    restore_probation_s: float | None
    """Data time (s) a restored current on probation has held (None: no probation)."""
    restore_chi2: float | None
    """The probation's last test statistic (None: no probation)."""
    noise: dict[str, float] = {}
    """The learned measurement noise of the channels that had updates
    (:meth:`.ChannelNoise.health`)."""

    def flat(self) -> dict[str, float]:
        """The counters (``rejected_invalid_dvl``, ``rejected_gate``,
        ``rejected_nonfinite``, ``updates``, ``rls_updates``, then those that appear once
        counted, in the order a measurement meets them), then the diagnostics by name
        (docs/current.md)."""
        s, f, p = self.samples, self.filter, self.pipeline
        h: dict[str, float] = {
            "rejected_invalid_dvl": s.rejected_invalid_dvl, "rejected_gate": f.rejected_gate,
            "rejected_nonfinite": s.rejected_nonfinite, "updates": f.updates,
            "rls_updates": self.rls_updates}
        once = (("glider_measurements", s.glider_measurements),
                ("rejected_late", p.rejected_late), ("restarted", f.restarted),
                ("diverged", f.diverged), ("runaway", f.runaway),
                ("hgo_diverged", self.hgo_diverged))
        h.update((k, v) for k, v in once if v)
        if p.hgo_rls_updates is not None:
            h["hgo_rls_updates"] = p.hgo_rls_updates
        if p.hgo_rls_rejected is not None:
            h["hgo_rls_rejected"] = p.hgo_rls_rejected
        h.update((k, v) for k, v in (("restore_discarded", p.restore_discarded),
                                     ("restore_confirmed", p.restore_confirmed),
                                     ("unknown", p.unknown)) if v)
        h["q_scale"] = self.q_scale
        h["velocity.gnss_std"] = self.gnss_velocity_std
        _put(h, "theta.std_max", self.theta_std_max)
        _put(h, "rls.yaw.sigma", self.yaw_rls_sigma)
        _put(h, "gamma", self.gamma)
        _put(h, "gamma_star", self.gamma_star)
        _put(h, "lipschitz", self.lipschitz)
        _put(h, "flow.gain_kept", self.flow_gain_kept)
        _put(h, "flow.diverged", self.flow_diverged)
        for ax, known in zip(AXES, self.observable):
            h[f"observable.{ax}"] = float(known)
        h["observable"] = float(all(self.observable[:2]))
        h["along_track_unobservable"] = float(self.along_track_unobservable)
        h["heading_diversity"] = self.heading_diversity
        if self.late is not None:
            h.update(late_samples=self.late.samples, late_hold_s=self.late.hold_s,
                     late_beyond_hold=self.late.beyond_hold)
        _put(h, "restore_probation_s", self.restore_probation_s)
        _put(h, "restore_chi2", self.restore_chi2)
        h.update(self.noise)
        return h


def _put(h: dict[str, float], key: str, value: float | None) -> None:
    """``h[key] = value`` as a float unless ``value`` is None."""
    if value is not None:
        h[key] = float(value)
