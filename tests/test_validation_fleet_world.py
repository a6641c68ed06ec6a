"""validation/fleet_world.py's scoring: a left-out vehicle's points split by whether another
vehicle's window is within reach (the field interpolates) or not (it extrapolates)."""

import numpy as np
import pytest

from onboard.fleet.field import CurrentField, Hyper, Observation, Plane
from validation import fleet_world

UTC0 = 1.7e9
TRUE = (0.10, 0.20)   # m/s, the same everywhere


class UniformSea:
    """A sea of one current everywhere (what validation.fleet_world asks of a sea)."""

    def at(self, lat_deg, lon_deg, depth_m, utc):
        return TRUE


def test_points_near_the_others_windows_and_beyond_them_are_scored_apart(monkeypatch):
    """Two boats crossing a line back and forth for 20 minutes, a third vehicle on the same
    line for its first 10 minutes and 150 m off it (1.5 length scales of a field whose
    scales are fixed at 100 m and 10 minutes) for its last 10: its first half's points are
    within the others' reach, its last half's beyond it; both are known to the field
    (within 3 scales), so every point is scored and each is counted once."""
    plane = Plane(43.1, 5.9)
    rng = np.random.default_rng(3)
    obs: dict[str, list] = {"a": [], "b": [], "x": []}
    for k in range(1200):
        for v, north in (("a", 0.0), ("b", 10.0), ("x", 5.0 if k < 600 else 155.0)):
            lat, lon = plane.to_latlon(north, 100.0 * np.sin(k / 60.0))
            obs[v].append(Observation(v, UTC0 + k, float(lat), float(lon),
                                      TRUE[0] + rng.normal(0.0, 0.005),
                                      TRUE[1] + rng.normal(0.0, 0.005), 0.01, 0.01))

    def fused(observations, leave):
        field = CurrentField(hyper=Hyper(length_m=100.0, length_s=600.0))
        for vid, rows in observations.items():
            if vid not in leave:
                for o in rows:
                    field.add(o)
        field.fit(hyperparameters=False)
        return field

    monkeypatch.setattr(fleet_world, "fused", fused)
    depth = {v: (np.array([UTC0, UTC0 + 1200.0]), np.zeros(2)) for v in obs}
    fig = fleet_world.score(UniformSea(), depth, obs, "x", set(), every=50)
    assert fig["points"] == 24
    assert fig["near"]["points"] == pytest.approx(12, abs=1)
    assert fig["near"]["points"] + fig["far"]["points"] == 24
    assert np.all(fig["near"]["rms"] < 0.01)
    text = fleet_world.describe(fig)
    assert "within the others' reach" in text and "beyond it" in text
