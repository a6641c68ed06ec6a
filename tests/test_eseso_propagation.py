"""The ESESO's structured covariance propagation against its readable reference.

:func:`~onboard.estimators.eseso_filter.propagate_covariance` applies the error-state
transition by its blocks; :func:`~onboard.estimators.eseso_filter.transition_matrix` is the
dense ``F`` it stands for. They must agree to rounding on any symmetric covariance and any
transition, earth-fixed and body-fixed disturbance alike, and through a filter's
propagation.
"""

from __future__ import annotations

import msgspec
import numpy as np
import pytest

from onboard.core.pipeline_config import EsesoConfig
from onboard.core.so3 import exp_so3, right_jacobian, skew
from onboard.estimators.eseso_filter import (
    N_ERR,
    EsesoFilter,
    Transition,
    propagate_covariance,
    transition_matrix,
)
from onboard.pipelines.eseso import filter_params

TOL = 1e-12
"""Largest difference allowed, relative to the covariance's largest entry."""


def _random_transition(rng: np.random.Generator, earth_fixed: bool) -> Transition:
    dt = float(rng.uniform(0.005, 0.5))
    R = exp_so3(rng.normal(size=3))
    w, f, xi = rng.normal(size=3), rng.normal(0.0, 5.0, size=3), rng.normal(0.0, 30.0, size=3)
    dRt = exp_so3(w * dt).T
    Jr = right_jacobian(w * dt)
    xi_bg = -(dRt @ skew(xi) @ right_jacobian(-w * dt)) * dt if earth_fixed else None
    return Transition(dt, R @ skew(f), R, dRt, -Jr * dt, xi_bg, float(rng.uniform(0.0, 1.0)))


def _random_covariance(rng: np.random.Generator) -> np.ndarray:
    A = rng.normal(size=(N_ERR, N_ERR)) * rng.uniform(0.01, 10.0, size=N_ERR)
    return A @ A.T


@pytest.mark.parametrize("earth_fixed", [True, False])
def test_structured_propagation_agrees_with_dense(earth_fixed: bool) -> None:
    rng = np.random.default_rng(29)
    for _ in range(200):
        tr = _random_transition(rng, earth_fixed)
        P = _random_covariance(rng)
        q = rng.uniform(0.0, 1e-2, size=N_ERR)
        F = transition_matrix(tr)
        want = F @ P @ F.T + np.diag(q)
        got = propagate_covariance(P, tr, q)
        assert np.max(np.abs(got - want)) <= TOL * np.max(np.abs(want))


def test_transition_matrix_has_the_documented_structure() -> None:
    """The blocks the structured product leaves alone are identity or zero in ``F``."""
    tr = _random_transition(np.random.default_rng(1), earth_fixed=True)
    F = transition_matrix(tr)
    changed = list(range(0, 9)) + list(range(18, 23))  # P, V, TH, XI, BI rows
    kept = [i for i in range(N_ERR) if i not in changed]
    assert np.array_equal(F[kept], np.eye(N_ERR)[kept])


@pytest.mark.parametrize("model", ["earth_fixed", "body_fixed"])
def test_filter_propagation_matches_the_dense_reference(model: str) -> None:
    """Through the filter: each propagation's covariance is ``F P F^T + Q`` of its own
    ``F`` (the property the filter exposes), over a run of varied samples."""
    c = EsesoConfig()
    c = msgspec.structs.replace(c, process=msgspec.structs.replace(
        c.process, disturbance_model=model))
    f = EsesoFilter(filter_params(c))
    f.initialize(exp_so3(np.array([0.1, -0.2, 2.0])), np.zeros(3))
    f.xi = np.array([40.0, -25.0, 10.0])
    rng = np.random.default_rng(7)
    for _ in range(100):
        P0 = f.P.copy()
        f_m = np.array([0.0, 0.0, -9.81]) + rng.normal(0.0, 0.5, size=3)
        w_m = rng.normal(0.0, 0.5, size=3)
        dt = float(rng.uniform(0.01, 0.05))
        f.propagate(f_m, w_m, dt)
        q = f._process_noise(dt, f.transition.phi_ins)
        F = f.F
        want = F @ P0 @ F.T + np.diag(q)
        assert np.max(np.abs(f.P - want)) <= TOL * np.max(np.abs(want))
