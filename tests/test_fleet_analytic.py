"""The published flow the fleet's field is tested on (the Bickley jet of Rypina et al.
2007, :class:`onboard.sitl.current_field.BickleyJet`) and its sampling by a fleet with
per-vehicle AR(1) errors (validation/fleet_analytic.py); the long run is the validation
report itself (docs/fleet.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from onboard.fleet.field import Observation
from onboard.sitl.current_field import RYPINA_L_OVER_R0, BickleyJet, SeaField
from validation.fleet_analytic import ar1_at, error_model, sampled

UTC0 = 1_780_000_000.0


def stream(jet: BickleyJet, x, y, t):
    """Rypina et al. 2007 eq. 1, written out here apart from the class."""
    big_l, u0 = jet.half_width, jet.u0
    r0 = big_l / RYPINA_L_OVER_R0
    waves = sum(eps * np.cos(2.0 * n / r0 * (x - c * u0 * t))
                for n, (eps, c) in enumerate(zip(jet.eps, jet.c_over_u0), start=1))
    return -u0 * big_l * np.tanh(y / big_l) + u0 * big_l / np.cosh(y / big_l) ** 2 * waves


def test_the_jet_is_its_stream_functions_flow():
    """Along the jet (north here) ``u = -dpsi/dy``, across it ``v = dpsi/dx``, checked by
    central differences of the stream function; the peak on the axis is ``U0``."""
    jet = BickleyJet.coastal(0.3, 120.0, direction=0.0, t_ref=0.0)
    rng = np.random.default_rng(4)
    x, y, t = rng.uniform(-600, 600, 50), rng.uniform(-400, 400, 50), rng.uniform(0, 3600, 50)
    vn, ve = jet.velocity(x, y, 0.0, t)     # direction 0: x north, y east
    h = 1e-3
    u = -(stream(jet, x, y + h, t) - stream(jet, x, y - h, t)) / (2 * h)
    v = (stream(jet, x + h, y, t) - stream(jet, x - h, y, t)) / (2 * h)
    np.testing.assert_allclose(vn, u, atol=1e-8)
    np.testing.assert_allclose(ve, v, atol=1e-8)
    calm = BickleyJet.coastal(0.3, 120.0, eps=(0.0, 0.0, 0.0))
    assert calm.velocity(0.0, 0.0, 0.0, 0.0)[0] == pytest.approx(0.3)


def test_the_jet_turns_with_its_direction_and_survives_a_description():
    jet = BickleyJet.coastal(0.3, 120.0, direction=math.radians(60.0), t_ref=UTC0)
    along = BickleyJet.coastal(0.3, 120.0, direction=0.0, t_ref=UTC0)
    c, s = math.cos(math.radians(60.0)), math.sin(math.radians(60.0))
    x, y = 150.0, -40.0                     # in the jet's frame
    u, v = along.velocity(x, y, 0.0, UTC0 + 500.0)
    vn, ve = jet.velocity(x * c - y * s, x * s + y * c, 0.0, UTC0 + 500.0)
    assert (vn, ve) == pytest.approx((u * c - v * s, u * s + v * c))
    sea = SeaField((50.35, -4.15), (jet,))
    again = SeaField.from_description(sea.origin, sea.describe())
    assert again.local(10.0, 20.0, 0.0, UTC0) == pytest.approx(sea.local(10.0, 20.0, 0.0, UTC0))


def test_the_sampled_errors_have_the_measured_sigma_and_correlation_time():
    """A vehicle's AR(1) error at its records' irregular times, measured back: its RMS and
    its 1/e correlation time within sampling error (2 h at 2 Hz, 40 s)."""
    rng = np.random.default_rng(7)
    t = np.cumsum(rng.uniform(0.3, 0.7, 14400))
    err = np.column_stack([ar1_at(rng, t, 0.02, 40.0), ar1_at(rng, t, 0.03, 40.0)])
    rms, tau = error_model(t, err)
    assert rms == pytest.approx([0.02, 0.03], rel=0.15)
    assert tau == pytest.approx(40.0, rel=0.25)
    white = np.column_stack([rng.normal(0, 0.02, t.size)] * 2)
    assert error_model(t, white)[1] <= 1.0      # the negative control: no memory


def test_a_fleets_records_take_the_jets_current_plus_their_vehicles_error():
    jet = SeaField((50.35, -4.15), (BickleyJet.coastal(0.3, 120.0, t_ref=UTC0),))
    rows = [Observation("b", UTC0 + k, 50.35 + 1e-5 * k, -4.15, 9.0, 9.0, 0.03, 0.03,
                        0.1, 0.05) for k in range(600)]
    got = sampled({"b": rows}, jet, {"b": (np.array([0.02, 0.02]), 30.0)}, seed=3)["b"]
    c_n, c_e = jet.at(np.array([o.lat_deg for o in rows]), np.array([o.lon_deg for o in rows]),
                      0.0, np.array([o.utc for o in rows]))
    err = np.array([[o.north, o.east] for o in got]) - np.column_stack([c_n, c_e])
    assert 0.005 < np.sqrt((err ** 2).mean()) < 0.04
    assert got[5].down is None and got[5].std_north == 0.03 and got[5].utc == rows[5].utc
    again = sampled({"b": rows}, jet, {"b": (np.array([0.02, 0.02]), 30.0)}, seed=3)["b"]
    assert [o.north for o in again] == [o.north for o in got]
