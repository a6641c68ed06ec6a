"""Probation of a restored water current: a chi-square test against a twin filter
(algorithms.md §3.5; docs/current.md, "Outputs", restored state).

A current restored from the state file may be stale: the service was down and the tide
turned. The restored current is therefore kept on probation. A twin joint filter
(:class:`.current_kf.CurrentKalmanFilter`) runs beside the pipeline's, from the restored
model but with the current at its prior, and sees the same data. On the components the
twin observes (its one-sigma, floored along the track while the surge model is unknown, at
most ``unknown_above_std``) the difference of the two currents is tested::

    d = c_restored - c_twin
    d^2 = d^T (P_restored + P_twin)^-1 d   >   chi2_quantile(1 - p, k)   ->  discard

with ``P_restored`` the restored current's covariance, ``P_twin`` the twin's, ``k`` the
number of observed components and ``p`` the false-alarm probability. A discarded current is replaced by the twin's; the current
is confirmed after ``hold_s`` seconds of data without a discard while the twin observes
both horizontal components.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from onboard.core.stats import chi2_quantile
from onboard.estimators.current_kf import (
    CurrentKalmanFilter,
    MeasurementKind,
    VelocityMeasurement,
)
from onboard.estimators.model_identification import floor_along_track
from onboard.estimators.vehicle_models import ModelInputs

Verdict = Literal["pending", "discard", "confirm"]
"""The outcome of one :meth:`RestoredCurrentCheck.evaluate`."""


class RestoredCurrentCheck:
    """The restored current on probation against a twin filter (module docstring).

    Attributes:
        twin: the twin joint filter (None while no probation runs).
        current: the restored current (m/s, earth axes; None while no probation runs).
        cov: its covariance (m^2/s^2).
        held_s: data time (s) the restored current has held while the twin observed both
            horizontal components.
        chi2: the last test statistic ``d^2`` (kept after the probation ends).
        n_axes: the number of components in that test.
    """

    def __init__(self, *, hold_s: float, false_alarm_p: float, unknown_above_std: float,
                 init_current_std: float) -> None:
        """Args:
            hold_s: data time (s) of agreement that confirms the restored current.
            false_alarm_p: false-alarm probability of the test per evaluation.
            unknown_above_std: a twin component with a larger one-sigma (m/s) is not
                tested.
            init_current_std: prior one-sigma of the current (m/s), the along-track floor
                of the twin's one-sigma while its surge model is unknown.
        """
        self.hold_s = hold_s
        self.false_alarm_p = false_alarm_p
        self.unknown_above_std = unknown_above_std
        self.init_current_std = init_current_std
        self.twin: CurrentKalmanFilter | None = None
        self.current: np.ndarray | None = None
        self.cov: np.ndarray | None = None
        self.held_s = 0.0
        self.chi2 = 0.0
        self.n_axes = 0

    @property
    def active(self) -> bool:
        """Whether a restored current is on probation."""
        return self.twin is not None

    def begin(self, twin: CurrentKalmanFilter, current: np.ndarray, cov: np.ndarray) -> None:
        """Put the restored ``current`` (m/s) with covariance ``cov`` on probation against
        ``twin`` (the restored model, the current at its prior)."""
        self.twin = twin
        self.current = current
        self.cov = cov
        self.held_s = 0.0

    def end(self) -> None:
        """End the probation (the last ``chi2`` stays)."""
        self.twin = None
        self.current = None
        self.cov = None
        self.held_s = 0.0

    def start(self, kind: MeasurementKind, z: np.ndarray, R: np.ndarray, yaw: float) -> None:
        """Start the twin from the first velocity measurement ``z`` (m/s), ``R`` the
        body-to-earth rotation, at heading ``yaw`` (rad)."""
        assert self.twin is not None
        self.twin.start(kind, z, R)
        self.twin.identification.headings.restart(yaw)

    def update(self, meas: list[VelocityMeasurement], R: np.ndarray) -> None:
        """The twin's updates with the tick's velocity measurements; a measurement that
        contradicts the twin's start starts it again (as the pipeline's filter)."""
        twin = self.twin
        assert twin is not None
        if twin.started:
            for m in meas:
                if twin.update(m.kind, m.z, m.std, R) == "contradicts_start":
                    twin.restart_from(m.kind, m.z, m.std, R)

    def evaluate(self, dt: float, yaw: float) -> Verdict:
        """The test of the module docstring after ``dt`` (s) of data at heading ``yaw``
        (rad): ``discard`` if the restored current contradicts the twin's, ``confirm``
        after ``hold_s`` of agreement on both horizontal components, else ``pending``."""
        assert self.twin is not None and self.current is not None and self.cov is not None
        twin, nd = self.twin, self.twin.nd
        floor = self.init_current_std if twin.identification.surge_unobservable() else 0.0
        std_twin = floor_along_track(twin.current_cov(), yaw, floor)
        axes = [i for i in range(nd) if std_twin[i] <= self.unknown_above_std]
        if not axes:
            return "pending"
        # d = c_restored - c_twin on the observed axes; d^2 = d^T (P_r + P_t)^-1 d
        d = (self.current - twin.x[nd:2 * nd])[axes]
        S = (self.cov + twin.current_cov())[np.ix_(axes, axes)]
        self.chi2 = float(d @ np.linalg.solve(S, d))
        self.n_axes = len(axes)
        if self.chi2 > chi2_quantile(1.0 - self.false_alarm_p, len(axes)):
            return "discard"
        if all(i in axes for i in range(2)):
            self.held_s += dt
            if self.held_s >= self.hold_s:
                return "confirm"
        return "pending"

    def advance(self, t: float, dt: float, inputs: ModelInputs, yaw: float) -> None:
        """The twin's schedule and prediction (:meth:`.CurrentKalmanFilter.advance`)."""
        assert self.twin is not None
        self.twin.advance(t, dt, inputs, yaw)
