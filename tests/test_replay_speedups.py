"""The replay's fast paths give the reference results: the early stop of
:func:`drivers.tlog.scan_header`, the discretization cached by the exact step, the
learned noise's products on floats."""

from __future__ import annotations

import random
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as mav

from onboard.drivers.tlog import TlogWriter, scan_header

T0 = 1.7e9


def _write(path: Path, params: list[tuple[bytes, float, int, int]], *, late: bool) -> None:
    """HEARTBEAT, PARAM_VALUEs (name, value, count, index), 200 ATTITUDE frames, and with
    ``late`` one more SERVO1_FUNCTION value at the end."""
    m = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    frames = [m.heartbeat_encode(11, 3, 81, 19, 4, 3).pack(m)]
    frames += [m.param_value_encode(n, v, 2, c, i).pack(m) for n, v, c, i in params]
    frames += [m.attitude_encode(k, 0.0, 0.0, 0.1, 0.0, 0.0, 0.0).pack(m) for k in range(200)]
    if late:
        frames.append(m.param_value_encode(b"SERVO1_FUNCTION", 33.0, 2, 2, 0).pack(m))
    with TlogWriter(path) as w:
        for k, f in enumerate(frames):
            w.write(T0 + 0.05 * k, f)


@pytest.mark.parametrize("complete", [True, False])
def test_scan_header_stops_once_the_parameter_set_is_complete(tmp_path: Path,
                                                              complete: bool) -> None:
    """With every index of ``param_count`` seen and a vehicle HEARTBEAT, the scan stops:
    a later change is not read. With an index missing it reads on to the last value."""
    p = tmp_path / "a.tlog"
    params = [(b"SERVO1_FUNCTION", 26.0, 2, 0), (b"SERVO3_FUNCTION", 70.0, 2, 1)]
    _write(p, params if complete else params[:1], late=True)
    infos, found = scan_header(p)
    assert [(v.mav_type, v.autopilot) for v in infos] == [(11, 3)]
    by_name = {x.name: x.value for x in found}
    assert by_name["SERVO1_FUNCTION"] == (26.0 if complete else 33.0)


def test_discretization_by_the_exact_step_is_the_rounded_one() -> None:
    """Discretization's cache by the unrounded (a, dt) returns what the rounded lookup
    computes, for repeated and fresh steps, across the caches' resets."""
    from onboard.estimators.axis_model import CACHE_SIZE, Discretization, discretize

    rng = random.Random(7)
    disc = Discretization()
    steps = [0.1 + rng.uniform(-1e-6, 1e-6) for _ in range(3 * CACHE_SIZE)]
    for dt in steps + steps[:20] + [1e-9, 0.2]:
        for a in (0.5, 2.0):
            assert disc(a, dt) == discretize(a, max(round(dt, 4), 1e-4))


def test_noise_scale_on_floats_is_the_numpy_one() -> None:
    """NoiseScale.observe on a float innovation (products without numpy) leaves the same
    state, to the bit, as on the same innovation as a 1-vector (np.dot)."""
    import numpy as np

    from onboard.estimators.noise_learning import NoiseScale

    rng = random.Random(3)
    a, b = NoiseScale("c", "k", 1.0, "m"), NoiseScale("c", "k", 1.0, "m")
    for _ in range(500):
        z, S, R = rng.gauss(0.0, 1.5), 1.0 + rng.random(), 1.0
        a.observe(z, S, R * a.applied)
        b.observe(np.array([z]), S, R * b.applied)
    fields = ("scale", "n", "mean", "forecast", "power", "lag")
    assert [getattr(a, f) for f in fields] == [getattr(b, f) for f in fields]
    assert a.n == 200 and a.lag != 0.0
