"""Fan et al.'s nonlinear observer (pipelines.flow_observer): pole placement, v_r from the
heading, current from over-ground minus through-water velocity."""

from __future__ import annotations

import numpy as np

from onboard.estimators.flow_observer import ackermann_observer_gain
from tests.helpers.current_plants import (
    TORPEDO_TRUE,
    current_errors,
    current_pipeline,
    simulate_torpedo,
)


def test_ackermann_places_the_poles():
    A = np.array([[0.0, 1.0, 0.0], [0.0, -0.8, 0.6], [0.0, -0.5, -1.2]])
    C = np.array([[1.0, 0.0, 0.0]])
    poles = [-0.6, -0.8, -1.0]
    L = ackermann_observer_gain(A, C, poles)
    eig = np.sort(np.linalg.eigvals(A - np.outer(L, C[0])).real)
    assert np.allclose(eig, sorted(poles), atol=1e-9)


def test_flow_observer_current_on_synthetic_torpedo_with_known_model():
    pipe = current_pipeline("torpedo-auv", model=TORPEDO_TRUE, identify=False, observer="flow")
    rms, cover, e, s = current_errors(pipe, simulate_torpedo(300.0), after=120.0)
    print("flow rms", rms, "cover", cover, "sigma", s.mean(0))
    # measured: rms [0.016, 0.018] m/s, sigma [0.028, 0.036], 2-sigma coverage [0.99, 1.0]
    assert np.all(rms < 0.05)
    assert np.all(cover > 0.9)
    assert pipe.flow.unobservable == 0
