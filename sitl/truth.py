"""The simulator's hidden truth: what really happened, for scoring estimators.

Truth is written to a separate file (JSON lines of :class:`TruthRecord`) that no
estimator reads. Frames: NED earth, FRD body; SI units; angles in rad.
"""

from __future__ import annotations

import msgspec


class TruthRecord(msgspec.Struct, kw_only=True):
    """The true vehicle and environment state at time ``t`` (s since scenario start).

    Velocities: ``u, v, w`` are body-frame velocity over ground; ``u_r, v_r, w_r`` the
    body-frame velocity through water (over ground minus current); ``current_*`` the water
    current in the earth frame. ``surge_input`` and ``yaw_input`` are the true unknown
    inputs in the AIE normalization (force/mass in m/s^2, moment/inertia in rad/s^2);
    ``force_*``/``moment_z`` the true propulsion wrench in body axes (N, N m);
    ``disturbance_*`` a true external force in body axes (N).
    """

    t: float
    north: float
    east: float
    down: float
    roll: float
    pitch: float
    yaw: float
    u: float
    v: float
    w: float
    p: float
    q: float
    r: float
    u_r: float
    v_r: float
    w_r: float
    current_north: float = 0.0
    current_east: float = 0.0
    current_down: float = 0.0
    surge_input: float | None = None
    yaw_input: float | None = None
    force_x: float | None = None
    force_y: float | None = None
    force_z: float | None = None
    moment_z: float | None = None
    disturbance_x: float | None = None
    disturbance_y: float | None = None
    disturbance_z: float | None = None
    lat_deg: float | None = None
    lon_deg: float | None = None
    effects: dict[str, float] = {}
    """Parameters of injected effects at this time (e.g. ``gyro_bias_z``)."""
