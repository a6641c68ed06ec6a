"""The current pipeline feeds roll and pitch to the model (gravity/buoyancy regressors).

The torpedo model's ``sin(theta)``, ``cos(theta)sin(phi)``, ``cos(theta)cos(phi)`` (Kim et
al. 2018 eq. 3-5) and the ROV's heave term are evaluated at the roll and pitch of the
newest Attitude sample at or before the step (the DVL's own as a fallback), through
``inp.roll`` / ``inp.pitch``.
"""

from __future__ import annotations

import math

import numpy as np

from onboard.core.messages import Attitude, DvlPosition, Heading
from onboard.core.so3 import euler_to_matrix
from tests.helpers.current_plants import (
    TORPEDO_TRUE,
    current_errors,
    current_pipeline,
    simulate_torpedo,
)

# TORPEDO_TRUE with net buoyancy: 7 N up on a ~30 kg (surge) / ~65 kg (sway, heave)
# mass term, as the REMUS plant (sitl/plants/torpedo_auv.py): -(W - B) / (m - X_udot) > 0,
# (W - B) / (m - Y_vdot) < 0
BUOYANT_TRUE = {k: dict(v) for k, v in TORPEDO_TRUE.items()}
BUOYANT_TRUE["surge"]["sin(theta)"] = 0.23
BUOYANT_TRUE["sway"]["cos(theta)sin(phi)"] = -0.1
BUOYANT_TRUE["heave"]["cos(theta)cos(phi)"] = -0.1


def _att(t: float, roll: float, pitch: float, yaw: float = 0.3) -> Attitude:
    return Attitude(t=t, roll_rad=roll, pitch_rad=pitch, yaw_rad=yaw, roll_rate_rps=0.0,
                    pitch_rate_rps=0.0, yaw_rate_rps=0.0)


def test_pitched_attitude_sample_changes_the_gravity_regressors():
    pipe = current_pipeline("torpedo-auv")
    pipe.step(1.0, [_att(0.9, 0.1, 0.3)])
    assert (pipe.inp.roll, pipe.inp.pitch) == (0.1, 0.3)
    surge, sway, heave = pipe.model.regressor_rows([1.0, 0.0, 0.0], pipe.inp, dofs_only=True)
    terms = pipe.model.terms
    assert surge[terms["surge"].index("sin(theta)")] == math.sin(0.3)
    assert sway[terms["sway"].index("cos(theta)sin(phi)")] == math.cos(0.3) * math.sin(0.1)
    assert heave[terms["heave"].index("cos(theta)cos(phi)")] == math.cos(0.3) * math.cos(0.1)
    rov = current_pipeline("bluerov2")
    rov.step(1.0, [_att(1.0, -0.2, 0.25)])
    h = rov.model.regressor_rows([0.0, 0.0, 0.0], rov.inp)[2]
    assert h[rov.model.terms["heave"].index("cos(theta)cos(phi)")] == (
        math.cos(0.25) * math.cos(-0.2))


def test_newest_attitude_at_or_before_the_step_time():
    # the sample adapter's own ordering, without the late-sample hold (test_latency.py)
    pipe = current_pipeline("torpedo-auv", max_late_hold_s=0.0)
    # time-ordered batch: the newest sample at or before the tick wins
    pipe.step(1.0, [_att(0.8, 0.0, 0.1), _att(0.9, 0.0, 0.2)])
    assert pipe.inp.pitch == 0.2 and pipe.pitch == 0.2
    # an older stamp arriving late does not replace a newer attitude
    pipe.step(1.1, [_att(0.85, 0.0, 0.9)])
    assert pipe.inp.pitch == 0.2
    # a sample stamped after the tick is held until a tick reaches its time
    pipe.step(1.2, [_att(1.25, 0.05, 0.4)])
    assert pipe.inp.pitch == 0.2
    pipe.step(1.3, [])
    assert (pipe.inp.roll, pipe.inp.pitch) == (0.05, 0.4)
    # the rotation uses the same attitude
    assert np.allclose(pipe._R(), euler_to_matrix(0.05, 0.4, pipe.yaw))


def test_dvl_attitude_is_a_fallback_only():
    pipe = current_pipeline("torpedo-auv")
    dvl = DvlPosition(t=0.5, north_m=0.0, east_m=0.0, down_m=5.0, roll_rad=0.02,
                      pitch_rad=-0.1, yaw_rad=0.0)
    pipe.step(1.0, [Heading(t=0.4, heading_rad=0.0), dvl])
    assert pipe.inp.pitch == -0.1  # no Attitude sample: the DVL's own
    pipe.step(2.0, [_att(1.9, 0.0, 0.2)])
    dvl2 = DvlPosition(t=2.05, north_m=0.0, east_m=0.0, down_m=5.0, roll_rad=0.0,
                       pitch_rad=-0.3, yaw_rad=0.0)
    pipe.step(2.1, [dvl2])
    assert pipe.inp.pitch == 0.2  # the attitude reference comes first


def test_pitching_buoyant_torpedo_known_model():
    """A positively buoyant torpedo pitching +-0.25 rad and rolling +-0.1 rad: the gravity
    terms change surge, sway and heave accelerations by up to 0.06 / 0.01 / 0.003 m/s^2
    through the attitude. A model evaluated at zero attitude would be wrong by that and the
    current would take the blame."""
    pipe = current_pipeline("torpedo-auv", model=BUOYANT_TRUE, identify=False)
    gen = simulate_torpedo(300.0, truth=BUOYANT_TRUE, pitch=(0.25, 2 * math.pi / 60.0),
                           roll=(0.1, 2 * math.pi / 23.0))
    rms, cover, _, _ = current_errors(pipe, gen, after=100.0)
    # measured: rms N/E 0.004 / 0.004 m/s, coverage 1.00 / 1.00; with the model's attitude
    # held at zero the same run gives 0.058 / 0.126 m/s, coverage 0.90 / 0.76
    assert np.all(rms < 0.02)
    assert np.all(cover > 0.9)
