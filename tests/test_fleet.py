"""``onboard fleet``: the fleet's current field, measured on synthetic fleets in analytic
fields (tests/helpers/fleet_scenarios.py), and its contract (architecture.md §4.4).

The measure is the issue's: the field fitted without one vehicle, predicted along that
vehicle's track (every 30 s), against the truth there: RMS error per component at most
0.03 m/s and 95 % coverage (``|error| < 1.96 sigma``) between 0.90 and 0.99. The
vehicles' estimates err as current estimators do: AR(1) with a 60 s correlation time and
0.03 m/s sigma per component, plus 0.01 m/s white, at 10 Hz.
"""

from __future__ import annotations

import dataclasses
import math
import random

import msgspec
import numpy as np
import pytest

from onboard.core.messages import EstimateRecord
from onboard.fleet.field import (
    ESTIMATE_MEMORY_S, CurrentField, Hyper, Observation, observation, one_blas_thread)
from onboard.fleet.messages import FleetCurrent, FleetGrid
from onboard.fleet.service import FleetService, parse_query
from tests.helpers.fleet_scenarios import FIELDS, UTC0, fleet

RMS_MAX = 0.03
COVERAGE = (0.90, 0.99)
WORLD_MEMORY_S = 10.0
"""The synthetic estimates' memory of the water along their track (s) in the slow test:
half the field's ``ESTIMATE_MEMORY_S``."""


NAIVE = Hyper(sigma_north=0.2, sigma_east=0.2, length_m=600.0, length_s=20000.0,
              scale=1.0 / math.sqrt(300.0), tau_s=1.0, white=1e-4)
"""Each 30-s window's records taken as independent measurements: sigma / sqrt(300), no
correlated error."""


def held_out(f, v: int, hyper: Hyper | None = None, every_s: float = 30.0,
             memory_s: float = ESTIMATE_MEMORY_S, calibrate: bool = True):
    """Errors (n, 2) and errors in sigmas (n, 2) of the field fitted without vehicle
    ``v`` (hyperparameters fitted, or ``hyper`` kept as given; its estimates' memory
    ``memory_s``; its sigma calibrated or not), along ``v``'s track."""
    field = CurrentField(hyper=hyper or Hyper(), memory_s=memory_s, calibrate=calibrate)
    for o in f.observations(skip=v):
        field.add(o)
    field.fit(hyperparameters=hyper is None)
    sel = np.flatnonzero((f.vehicle == v) & (np.mod(f.t, every_s) < 1e-6))
    lat, lon = f.plane.to_latlon(f.north_m[sel], f.east_m[sel])
    err, z = [], []
    with one_blas_thread():
        preds = [field.predict(float(lat[j]), float(lon[j]), UTC0 + float(f.t[i]))
                 for j, i in enumerate(sel)]
    for i, p in zip(sel, preds):
        assert p.north is not None, "a place between the other vehicles is known"
        e = np.array([p.north, p.east]) - f.truth[i]
        err.append(e)
        z.append(np.abs(e) / np.array([p.std_north, p.std_east]))
    return np.array(err), np.array(z)


def score(pairs):
    err = np.concatenate([e for e, _ in pairs])
    z = np.concatenate([z for _, z in pairs])
    return np.sqrt((err ** 2).mean(axis=0)), float((z < 1.96).mean())


def test_a_vehicle_left_out_is_predicted_within_3_cm_s_with_honest_sigmas():
    """One vehicle left out of each of the three fields, 10 vehicles for 30 minutes in a
    2-km square (a fast variant of the slow test below). Measured: RMS 0.016/0.022 m/s
    (north/east), coverage 0.91 (0.015/0.021 and 0.92 without the estimates' memory
    term; 0.89 by maximum likelihood, before the prior). Its 180 errors lie along three tracks, strongly
    correlated: the coverage of so few has a spread of several points, so the issue's
    0.90-0.99 is asserted over every vehicle of every field in the slow test, and here a
    band that still fails an overconfident field (the negative control below: 0.19)."""
    pairs = [held_out(fleet(name, seed=11 + k), v=k) for k, name in enumerate(FIELDS)]
    rms, coverage = score(pairs)
    assert np.all(rms <= RMS_MAX), rms
    assert 0.85 <= coverage <= COVERAGE[1], coverage


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(FIELDS))
def test_every_vehicle_left_out_on_held_out_seeds(name):
    """Every vehicle of a 10-vehicle, 30-minute fleet left out in turn, on two seeds the
    method was not set up on (docs/fleet.md "Measured" has the figures). The estimates
    remember the water along their track over ``WORLD_MEMORY_S``, as the vehicles'
    filters do (5-30 s on fleet-survey, validation/fleet_shared.py), off the field's own
    ``ESTIMATE_MEMORY_S``: measured RMS 0.005-0.026 m/s, coverage 0.93-0.99 (with estimates
    that remember nothing the memory term only widens: front seed 101 at 0.992)."""
    for seed in (101, 102):
        f = fleet(name, seed, memory_s=WORLD_MEMORY_S)
        rms, coverage = score([held_out(f, v) for v in range(10)])
        assert np.all(rms <= RMS_MAX), (seed, rms)
        assert COVERAGE[0] <= coverage <= COVERAGE[1], (seed, coverage)


def test_records_taken_as_independent_would_be_overconfident():
    """The negative control: the same fleet with each 30-s window's records taken as
    independent measurements (sigma / sqrt(300), no correlated error) covers far less
    than 95 % (measured 0.19): the per-vehicle error model is what makes sigma honest.
    The estimates' memory is left out here (``memory_s=0``; these synthetic estimates
    have none): its place variance alone, a 30-m place at 1.5 m/s, covers 0.85 of this
    naive field's misses, and would hide what this control is about; so is the sigma's
    calibration on the fleet's own data, which widens this naive field to cover 0.79
    (the test below)."""
    f = fleet("eddy", seed=11, vehicles=6, duration_s=1200.0)
    _, coverage = score([held_out(f, v=0, hyper=NAIVE, memory_s=0.0, calibrate=False)])
    assert coverage < COVERAGE[0] - 0.2, coverage


def test_an_overconfident_field_is_widened_by_the_fleets_own_misses():
    """The naive field above, its sigma calibrated on the fleet's own data (each window
    predicted from the other vehicles, algorithms.md §8.10): its variance is scaled up
    (measured 0.19 -> 0.79 covered); the negative control is the test above."""
    f = fleet("eddy", seed=11, vehicles=6, duration_s=1200.0)
    _, plain = score([held_out(f, v=0, hyper=NAIVE, memory_s=0.0, calibrate=False)])
    _, calibrated = score([held_out(f, v=0, hyper=NAIVE, memory_s=0.0)])
    assert calibrated > plain + 0.4, (plain, calibrated)


def test_the_misses_give_the_fields_scale_and_floor_apart_from_the_windows_own():
    """calibration's likelihood (algorithms.md §8.10) on misses drawn from its model: the
    field's variance ``v_f`` scaled by 2, a floor of (0.01 m/s)^2, the windows' own ``v_o``:
    both found (within the spread of 3,000 misses), and the published sigma is ``k v_f +
    b``. Without the floor the dense windows' misses (small ``v_f``) would be credited to
    the scale alone."""
    from onboard.fleet.field import SigmaCalibration, _ml_scale

    rng = np.random.default_rng(3)
    n = 3000
    v_f = rng.uniform(1e-5, 4e-4, n)   # dense cover to a place between vehicles
    v_o = rng.uniform(5e-5, 2e-4, n)
    r = rng.normal(0.0, np.sqrt(2.0 * v_f + 1e-4 + v_o))
    k, b = _ml_scale(r, v_f, v_o)
    assert k == pytest.approx(2.0, rel=0.25) and math.sqrt(b) == pytest.approx(0.01, rel=0.25)
    assert SigmaCalibration(k, b).std(0.02) == pytest.approx(math.sqrt(k * 4e-4 + b))
    # misses the field's own variance explains: neither widened
    k, b = _ml_scale(rng.normal(0.0, np.sqrt(v_f + v_o)), v_f, v_o)
    assert k < 1.15 and math.sqrt(b) < 0.004


def test_the_crossings_measure_the_windows_own_error():
    """own_scale (algorithms.md §8.10): where two vehicles' windows nearly meet, their
    difference is their own errors. The synthetic estimates remember nothing of their
    track; a field that takes them to remember 120 s of it (a 180-m place at 1.5 m/s)
    overstates each window's own variance, and the crossings say so (measured 0.32 and
    0.19, north and east); one that takes the memory they have is told about as much as it
    assumes (measured 1.2-2.3 with the field's 20 s against the estimates' 10 s)."""
    def own(memory_field_s: float, memory_world_s: float) -> tuple[float, float]:
        f = fleet("eddy", seed=11, vehicles=6, duration_s=1200.0, memory_s=memory_world_s)
        field = CurrentField(hyper=Hyper(), memory_s=memory_field_s)
        for o in f.observations(skip=0):
            field.add(o)
        field.fit()
        north, east = field.sigma_calibration
        return north.own, east.own

    assert max(own(120.0, 0.0)) < 0.5
    assert min(own(ESTIMATE_MEMORY_S, 10.0)) > 0.7


def test_late_and_out_of_order_records_give_the_same_field():
    f = fleet("front", seed=5, vehicles=4, duration_s=300.0, rate_hz=2.0)
    recs = [f.record(i) for i in range(len(f.t))]
    fields = []
    for order in (recs, random.Random(3).sample(recs, len(recs))):
        field = CurrentField(hyper=Hyper(length_m=500.0))
        for r in order:
            assert field.add_record(r)
        field.fit(hyperparameters=False)
        fields.append(field.predict(43.1, 5.9, UTC0 + 200.0))
    # the same up to the local plane's reference, the first record (measured 1e-5 m/s)
    assert fields[0].north == pytest.approx(fields[1].north, abs=1e-4)
    assert fields[0].std_east == pytest.approx(fields[1].std_east, abs=1e-4)
    assert fields[0].n_obs == fields[1].n_obs


def test_a_biased_vehicle_is_left_out_as_an_outlier():
    """A vehicle whose estimate is 0.4 m/s off (a compass 30 deg off at 0.8 m/s) is
    judged against the others window by window as they close (the service refreshes the
    field every few seconds) and mostly left out. Measured: 27 of its 40 windows left out
    (the first dozen, while the field is young, are kept) and 18 of the other five
    vehicles' 200 (those judged against a field it had bent)."""
    f = fleet("eddy", seed=12, vehicles=6, duration_s=1200.0, rate_hz=2.0)
    f.est[f.vehicle == 3] += np.array([0.4, 0.0])
    field = CurrentField(hyper=Hyper(length_m=600.0, length_s=20000.0, scale=0.85,
                                     tau_s=80.0, white=1e-4))
    order = np.argsort(f.t, kind="stable")
    obs = list(f.observations())
    for j, i in enumerate(order):
        field.add(obs[i])
        if j % 600 == 599:   # every 50 s of the fleet's records
            field.fit(hyperparameters=False)
    field.fit(hyperparameters=False)
    kept = field.fitted.obs.keys
    biased = sum(v == "v3" for v, _ in kept)
    assert biased <= 40 - 25                                # most of its 40 windows out
    assert sum(v != "v3" for v, _ in kept) >= 5 * 40 - 25   # the others mostly kept
    assert field.rejected["outlier"] == 6 * 41 - len(kept)   # 40 windows and a partial each


def test_records_that_make_no_observation_are_counted_by_reason():
    base = dict(vehicle="b", pipeline="current", t=1.0, utc=UTC0, lat_deg=43.0,
                lon_deg=5.0, values={"north": 0.1, "east": 0.2},
                std={"north": 0.02, "east": 0.02})
    cases = {"no_time": dict(utc=None), "no_position": dict(lat_deg=None),
             "bad_time": dict(utc=5.0),       # a clock never set
             "bad_position": dict(lat_deg=1.7e308),
             "no_current": dict(values={}),   # both withheld (flagged)
             "no_std": dict(std={}), "not_converged": dict(std={"north": 2.0, "east": 2.0}),
             "too_fast": dict(values={"north": 9.0, "east": 0.0})}
    for why, change in cases.items():
        assert observation(EstimateRecord(**{**base, **change})) == (None, why)
    for change in (dict(utc=math.nan), dict(lat_deg=95.0), dict(lon_deg=500.0),
                   dict(lat_deg=math.nan), dict(lat_deg=0.0, lon_deg=0.0)):
        assert observation(EstimateRecord(**{**base, **change}))[1].startswith("bad_")
    assert observation(EstimateRecord(**base))[0] is not None
    # one component known (the other withheld as unknown, or its sigma not converged):
    # an observation of that component alone
    for change in (dict(values={"north": 0.1}), dict(std={"north": 0.02, "east": 2.0})):
        o, why = observation(EstimateRecord(**{**base, **change}))
        assert why == "" and (o.north, o.std_north, o.east, o.std_east) == (0.1, 0.02, None, None)


def test_a_bad_record_is_left_out_by_reason_and_shapes_nothing():
    """One record from any publisher can neither stop the service nor move its field: a
    position out of range or never fixed, a time in milliseconds or far ahead of this
    machine's clock, a record on another vehicle's key, a wrong encoding or schema, each
    is counted by its reason and leaves the grid (its box, its time, its vehicles) as it
    was. Negative control: the same records unchecked (as before) put the grid's time
    at 1.8e12 s and its box 22 km wide."""
    f = fleet("tidal_channel", seed=4, vehicles=3, duration_s=600.0, rate_hz=0.5)
    enc = msgspec.json.Encoder()
    now = UTC0 + 600.0
    service = FleetService(clock=lambda: now)
    for i in range(len(f.t)):
        rec = f.record(i)
        assert service.feed(enc.encode(rec), "application/json;onboard.Estimate.v2",
                            f"onboard/{rec.vehicle}/est/current")
    good = service.step(refit=True)
    last = f.record(len(f.t) - 1)

    def bad(**change):
        return enc.encode(msgspec.structs.replace(last, **change))
    v2, key = "application/json;onboard.Estimate.v2", f"onboard/{last.vehicle}/est/current"
    for payload, enc_, key_, why in (
            (bad(lat_deg=1.7e308), v2, key, "bad_position"),
            (bad(lat_deg=95.0, lon_deg=500.0), v2, key, "bad_position"),
            (bad(lat_deg=0.0, lon_deg=0.0), v2, key, "bad_position"),
            (bad(utc=now * 1000.0), v2, key, "future"),
            (bad(utc=1e300), v2, key, "future"),
            (bad(lat_deg=43.3, position_std_m=500.0), v2, key, "position_uncertain"),
            (bad(vehicle="v9"), v2, key, "vehicle_mismatch"),
            (bad(), v2, "onboard/v9/est/current", "vehicle_mismatch"),
            (bad(), "text/plain", key, "bad"), (bad(), "zenoh/bytes", key, "bad"),
            (bad(schema=9), "application/json;onboard.Estimate.v2", key, "bad")):
        before = service.left_out().get(why, 0)
        assert not service.feed(payload, enc_, key_)
        assert service.left_out()[why] == before + 1, why
    after = service.step(refit=True)
    assert (after.utc, after.spacing_m, len(after.cells)) == \
        (good.utc, good.spacing_m, len(good.cells))
    assert [v.vehicle for v in after.vehicles] == ["v0", "v1", "v2"]
    # the service keeps taking the vehicles' records
    assert service.feed(enc.encode(msgspec.structs.replace(last, utc=last.utc + 1.0)), v2, key)
    # a record whose current is not known yet still says where its vehicle is
    unknown = msgspec.structs.replace(last, vehicle="v3", values={}, utc=last.utc + 2.0)
    assert not service.feed(enc.encode(unknown), v2, "onboard/v3/est/current")
    assert "v3" in service.newest and service.left_out()["no_current"] == 1
    # negative control: unchecked, the same two records move the grid's time and box
    # (a clock that takes milliseconds for seconds: the grid's time follows its vehicles)
    unchecked = FleetService(clock=lambda: now * 1000.0)
    for i in range(len(f.t)):
        unchecked.feed(enc.encode(f.record(i)))
    unchecked._note(msgspec.structs.replace(last, utc=now * 1000.0))
    unchecked._note(msgspec.structs.replace(last, vehicle="v8", lat_deg=43.3))
    control = unchecked.step(refit=True)
    assert control.utc > 1e12 and control.spacing_m > 1000.0


def test_a_current_its_vehicle_doubts_is_left_out_until_its_health_clears_it():
    """A vehicle's health record flagging its ``current`` pipeline ``nis_out_of_band``
    with its innovations above their dimension (its sigma claims too much) holds its
    records back (``doubted``); a clear health record lets them in again, and so does the
    same flag with the innovations below (its sigma too large: the values are not in
    doubt). A health record on another vehicle's key, or of another encoding, changes
    nothing."""
    from onboard.core.messages import ChannelHealth, HealthRecord
    from onboard.core.wire import HEALTH_SCHEMA

    f = fleet("tidal_channel", seed=4, vehicles=2, duration_s=120.0, rate_hz=0.5)
    enc = msgspec.json.Encoder()
    service = FleetService(clock=lambda: UTC0 + 120.0)
    v2, h3 = "application/json;onboard.Estimate.v2", f"application/json;{HEALTH_SCHEMA}"
    recs = [f.record(i) for i in range(len(f.t))]
    rec = next(r for r in recs if r.vehicle == "v0")
    key = "onboard/v0/est/current"

    def health(flags, vehicle="v0", nis=5.0):
        velocity = ChannelHealth(n=100, dof=2, nis_recent=nis)
        return enc.encode(HealthRecord(vehicle=vehicle, t=rec.t, flags=flags,
                                       innovations={"current": {"velocity": velocity}}))
    assert service.feed(enc.encode(rec), v2, key)
    doubt = {"current": ["nis_out_of_band"]}
    assert not service.feed_health(health(doubt), h3, "onboard/v1/health")  # wrong key
    assert not service.feed_health(health(doubt), "text/plain", "onboard/v0/health")
    assert service.feed(enc.encode(rec), v2, key)
    assert service.feed_health(health(doubt), h3, "onboard/v0/health")
    assert not service.feed(enc.encode(rec), v2, key)
    assert service.left_out()["doubted"] == 1
    assert service.feed_health(health({"aie": ["speed_mismatch"]}), h3, "onboard/v0/health")
    assert service.feed(enc.encode(rec), v2, key)
    assert service.feed_health(health(doubt, nis=0.6), h3, "onboard/v0/health")   # timid
    assert service.feed(enc.encode(rec), v2, key)


def test_a_vehicle_with_a_fast_clock_does_not_set_the_grids_time():
    """One vehicle's clock 30 min ahead (records within the hour ``future`` allows): the
    grid stays at the others' newest time; when every vehicle is ahead of this machine's
    clock (this machine's is slow), the grid follows them (the control)."""
    f = fleet("tidal_channel", seed=4, vehicles=3, duration_s=300.0, rate_hz=0.5)
    enc = msgspec.json.Encoder()
    v2 = "application/json;onboard.Estimate.v2"
    now = UTC0 + 300.0
    service = FleetService(clock=lambda: now)
    for i in range(len(f.t)):
        rec = f.record(i)
        if rec.vehicle == "v2":
            rec = msgspec.structs.replace(rec, utc=rec.utc + 1800.0)
        service.feed(enc.encode(rec), v2, f"onboard/{rec.vehicle}/est/current")
    grid = service.step(refit=True)
    assert grid.utc <= now and grid.utc == max(
        v.utc for v in service.newest.values() if v.vehicle != "v2")
    slow = FleetService(clock=lambda: UTC0 - 3000.0)   # every record 'ahead'
    for i in range(len(f.t)):
        rec = f.record(i)
        slow.feed(enc.encode(rec), v2, f"onboard/{rec.vehicle}/est/current")
    assert slow.step(refit=True).utc == max(v.utc for v in slow.newest.values())


def test_the_grid_covers_the_box_of_its_vehicles():
    """The grid's rows and columns cover the vehicles' box and its margin, centred on it,
    in at most ``GRID_CELLS`` cells along its longer side."""
    from onboard.fleet.field import Plane
    from onboard.fleet.service import GRID_CELLS, GRID_MARGIN_M, grid_points

    plane = Plane(43.1, 5.9)
    lats, lons = zip(*(plane.to_latlon(n, e) for n, e in ((0.0, 0.0), (213.0, 1130.0))))
    rows, cols, spacing = grid_points(plane, list(lats), list(lons))
    north = [float(plane.to_ne(la, 5.9)[0]) for la in rows]
    east = [float(plane.to_ne(43.1, lo)[1]) for lo in cols]
    assert len(cols) == GRID_CELLS and len(rows) < GRID_CELLS
    for centres, lo, hi in ((north, 0.0, 213.0), (east, 0.0, 1130.0)):
        assert centres[0] - spacing / 2 <= lo - GRID_MARGIN_M + 1e-6
        assert centres[-1] + spacing / 2 >= hi + GRID_MARGIN_M - 1e-6
        assert np.allclose(np.diff(centres), spacing)
        assert (centres[0] + centres[-1]) / 2 == pytest.approx((lo + hi) / 2, abs=1e-6)


def test_a_record_of_one_component_informs_that_component_alone():
    """A vehicle that publishes its east current alone (its north withheld as unknown, as
    a boat's along-track current is until it has turned) informs the field's east along
    its track and leaves its north to the others. Measured (eddy, seed 2, four vehicles,
    fixed hyperparameters, along v3's track): without v3, RMS 0.023 / 0.053 m/s north /
    east, median sigma 0.043 / 0.043; with v3's east only, 0.026 / 0.011 and 0.044 /
    0.018."""
    f = fleet("eddy", seed=2, vehicles=4, duration_s=600.0, rate_hz=1.0)
    sel = np.flatnonzero((f.vehicle == 3) & (np.mod(f.t, 30.0) < 1e-6))
    lat, lon = f.plane.to_latlon(f.north_m[sel], f.east_m[sel])

    def along_v3(east_only: bool):
        field = CurrentField(hyper=Hyper(length_m=500.0, length_s=3600.0))
        for o in f.observations(skip=-1 if east_only else 3):
            field.add(dataclasses.replace(o, north=None, std_north=None)
                      if o.vehicle == "v3" else o)
        field.fit(hyperparameters=False)
        with one_blas_thread():
            p = [field.predict(float(lat[j]), float(lon[j]), UTC0 + float(f.t[i]))
                 for j, i in enumerate(sel)]
        err = np.array([[q.north, q.east] for q in p]) - f.truth[sel]
        sd = np.array([[q.std_north, q.std_east] for q in p])
        return np.sqrt((err ** 2).mean(axis=0)), np.median(sd, axis=0), field

    (rms_without, sd_without, _), (rms_with, sd_with, field) = along_v3(False), along_v3(True)
    assert rms_with[1] < 0.5 * rms_without[1] and sd_with[1] < 0.6 * sd_without[1]
    assert sd_with[0] == pytest.approx(sd_without[0], rel=0.1)   # north: the others'
    obs = field.fitted.obs   # v3's windows carry no north (NaN), never a north of 0
    v3 = np.array([k[0] == "v3" for k in obs.keys])
    assert v3.any() and np.isnan(obs.y[v3, 0]).all() and np.isfinite(obs.y[v3, 1]).all()
    assert np.isfinite(obs.y[~v3, :2]).all()


def test_a_place_far_from_every_vehicle_is_unknown():
    f = fleet("eddy", seed=2, vehicles=3, duration_s=300.0, rate_hz=1.0)
    field = CurrentField(hyper=Hyper(length_m=500.0, length_s=3600.0))
    for o in f.observations():
        field.add(o)
    field.fit(hyperparameters=False)
    assert field.predict(43.1, 5.9, UTC0 + 100.0).north is not None
    far = field.predict(43.3, 5.9, UTC0 + 100.0)       # 22 km north
    assert far.north is None and far.std_east is None and far.n_obs == 0
    assert field.predict(43.1, 5.9, UTC0 + 86400.0).north is None   # tomorrow


def test_the_query_parameters_are_checked():
    assert parse_query({"lat": "43.1", "lon": "-5.9", "utc": "1780000000"}) == \
        (43.1, -5.9, 1780000000.0)
    assert parse_query({"lat": "-.5", "lon": "+1.", "utc": "1.78e9"}) == (-0.5, 1.0, 1.78e9)
    for bad, words in (({"lon": "1", "utc": "1"}, "lat is missing"),
                       ({"lat": "x", "lon": "1", "utc": "1"}, "not a number"),
                       ({"lat": "91", "lon": "1", "utc": "1"}, "out of range"),
                       ({"lat": "1", "lon": "1", "utc": "1e400"}, "out of range"),
                       ({"lat": "1", "lon": "1", "utc": "nan"}, "not a number"),
                       ({"lat": "1_0", "lon": "1", "utc": "1"}, "not a number"),
                       ({"lat": " 1", "lon": "1", "utc": "1"}, "not a number"),
                       ({"lat": "1&lon=x&utc=3"}, "lon='x' is not a number"),
                       ({"utc": "1&lat=1"}, "lon is missing")):
        with pytest.raises(ValueError, match=words):
            parse_query(bad)
    # '&' separates parameters as ';' does (a URL's query, Zenoh before 1.0), in any order
    for params in ({"lat": "1&lon=2&utc=3"}, {"utc": "3&lat=1&lon=2"},
                   {"lat": "1&lon=2", "utc": "3"}, {"lon": "2", "utc": "3&lat=1"}):
        assert parse_query(params) == (1.0, 2.0, 3.0), params


def test_the_grid_covers_the_vehicles_with_the_contracts_objects():
    f = fleet("tidal_channel", seed=4, vehicles=4, duration_s=600.0, rate_hz=1.0)
    service = FleetService()
    assert service.step(refit=True) is None     # no record yet: no grid, no error
    assert service.answer(43.1, 5.9, UTC0).north is None
    enc = msgspec.json.Encoder()
    for i in range(len(f.t)):
        assert service.feed(enc.encode(f.record(i)), "application/json;onboard.Estimate.v2")
    assert not service.feed(b'{"schema": 1}', "application/json;onboard.Estimate.v1")
    assert not service.feed(b"{}", "application/json;onboard.Health.v3")
    assert service.received == {"est.v2": len(f.t), "bad": 2}
    grid = msgspec.json.decode(enc.encode(service.step(refit=True)), type=FleetGrid)
    assert grid.schema == 1 and grid.utc == pytest.approx(UTC0 + f.t.max())
    assert 50.0 <= grid.spacing_m <= 300.0 and 16 <= len(grid.cells) <= 16 * 16
    assert sum(c.north is not None for c in grid.cells) > len(grid.cells) // 2
    assert [v.vehicle for v in grid.vehicles] == ["v0", "v1", "v2", "v3"]
    doc = msgspec.json.decode(enc.encode(grid))
    assert set(doc["cells"][0]) == {"lat", "lon", "utc", "north", "east", "std_north",
                                    "std_east", "n_obs", "down", "std_down"}
    assert set(doc["vehicles"][0]) == {"vehicle", "utc", "lat", "lon", "north", "east",
                                       "std_north", "std_east", "down", "std_down"}
    # boats give no down: the field knows nothing of it, and says null
    assert all(c.down is None and c.std_down is None for c in grid.cells)
    assert isinstance(grid.cells[0], FleetCurrent)


def down_fleet(boats_say_zero: bool):
    """A fleet of six in the eddy for 20 minutes, vehicle v0 an underwater vehicle whose
    records give a down of 0.04 m/s (sigma 0.01, its error white), the others boats
    (no down; with ``boats_say_zero`` they say 0 instead, the negative control); the
    field fitted on all of it, and v0's track every 60 s."""
    f = fleet("eddy", seed=21, vehicles=6, duration_s=1200.0, rate_hz=2.0)
    rng = np.random.default_rng(21)
    field = CurrentField()
    for o in f.observations():
        if o.vehicle == "v0":
            o = dataclasses.replace(o, down=0.04 + rng.normal(0.0, 0.01), std_down=0.01)
        elif boats_say_zero:
            o = dataclasses.replace(o, down=0.0, std_down=0.01)
        field.add(o)
    field.fit()
    sel = np.flatnonzero((f.vehicle == 0) & (np.mod(f.t, 60.0) < 1e-6))
    lat, lon = f.plane.to_latlon(f.north_m[sel], f.east_m[sel])
    with one_blas_thread():
        return field, [field.predict(float(la), float(lo), UTC0 + float(f.t[i]))
                       for la, lo, i in zip(lat, lon, sel)]


def test_down_is_fused_where_given_and_a_boat_is_not_a_down_of_zero():
    """The down of the one vehicle that gives it is the field's down along its track
    (measured 0.0406 m/s against 0.04, at most 0.001 off; one vehicle, so its spread
    stays at 0.02 and its mean is estimated in each neighbourhood); its sigma no smaller
    than the vehicle's own, which a common error keeps (0.0113-0.0130); the boats'
    windows have no down (NaN, not 0). The negative control: the boats' records taken as
    a down of 0 pull it to 0.017."""
    field, preds = down_fleet(boats_say_zero=False)
    downs = np.array([p.down for p in preds])
    assert np.all(np.abs(downs - 0.04) < 0.005), downs
    assert all(p.std_down is not None and 0.01 <= p.std_down < 0.015 for p in preds)
    obs = field.fitted.obs
    boats = obs.vehicle != obs.vehicle[field.fitted.down_rows[0]]
    assert boats.sum() == 5 * 41 and np.isnan(obs.y[boats, 2]).all()  # no down in theirs
    control = np.array([p.down for p in down_fleet(boats_say_zero=True)[1]])
    assert np.mean(control) < 0.03, control


def test_a_bias_every_diving_vehicle_shares_stays_in_the_downs_sigma(monkeypatch):
    """Two diving vehicles whose downs share a bias of 0.06 m/s where the water has none
    (each record 0.06 plus white noise of 0.005, sigma 0.05: what the simulator's AUVs
    give, docs/fleet.md): the field's down is the bias, and its sigma keeps the vehicles'
    own, so the true 0 is within 1.96 sigma everywhere (measured: sigma 0.053-0.054).
    The negative control: without the common error's variance the windows average it
    away over time and over the two vehicles, sigma 0.016-0.019 and the 0 never within."""
    import onboard.fleet.field as field_module
    from onboard.fleet.field import Plane

    def downs():
        plane = Plane(43.1, 5.9)
        rng = np.random.default_rng(5)
        field = CurrentField(hyper=Hyper(length_m=300.0, length_s=3600.0))
        for k in range(900):
            for v, north, down in (("b1", -100.0, None), ("b2", 100.0, None),
                                   ("auv-1", -50.0, 0.06), ("auv-2", 50.0, 0.06)):
                lat, lon = plane.to_latlon(north, 1.5 * k)
                d = None if down is None else down + rng.normal(0.0, 0.005)
                field.add(Observation(v, UTC0 + k, float(lat), float(lon), 0.1, 0.2,
                                      0.02, 0.02, d, None if d is None else 0.05))
        field.fit(hyperparameters=False)
        out = []
        for k in range(60, 900, 60):
            lat, lon = plane.to_latlon(0.0, 1.5 * k)
            p = field.predict(float(lat), float(lon), UTC0 + k)
            out.append((p.down, p.std_down))
        return np.array(out)

    got = downs()
    assert np.all(np.abs(got[:, 0] - 0.06) < 0.005), got
    assert np.all(got[:, 1] >= 0.05) and np.all(np.abs(got[:, 0]) < 1.96 * got[:, 1])
    monkeypatch.setattr(field_module, "down_bias_variance", lambda h, s: 0.0)
    control = downs()
    assert np.all(np.abs(control[:, 0]) > 1.96 * control[:, 1]), control


def test_a_place_no_diving_vehicle_saw_has_no_down():
    """Two boats 3 km south of a diving vehicle: there the field has a north and east but
    no down (null), by the diving vehicle its down; a record's down counts only with a
    converged sigma."""
    from onboard.fleet.field import Plane

    plane = Plane(43.1, 5.9)
    field = CurrentField(hyper=Hyper(length_m=300.0, length_s=3600.0))
    for k in range(600):
        t = UTC0 + k
        for v, north, down in (("b1", -3000.0, None), ("b2", -3050.0, None),
                               ("auv", 0.0, 0.02)):
            lat, lon = plane.to_latlon(north, 2.0 * k)
            field.add(Observation(v, t, float(lat), float(lon), 0.1, 0.2, 0.02, 0.02,
                                  down, None if down is None else 0.005))
    field.fit(hyperparameters=False)
    lat, lon = plane.to_latlon(-3000.0, 600.0)
    boats = field.predict(float(lat), float(lon), UTC0 + 300.0)
    assert boats.north == pytest.approx(0.1, abs=0.01)
    assert boats.down is None and boats.std_down is None
    lat, lon = plane.to_latlon(0.0, 600.0)
    auv = field.predict(float(lat), float(lon), UTC0 + 300.0)
    assert auv.down == pytest.approx(0.02, abs=1e-3) and 0.0 < auv.std_down < 0.01
    rec = EstimateRecord(vehicle="a", pipeline="current", t=1.0, utc=UTC0, lat_deg=43.0,
                         lon_deg=5.0, values={"north": 0.1, "east": 0.2, "down": 0.03},
                         std={"north": 0.02, "east": 0.02, "down": 0.01})
    assert observation(rec)[0].down == 0.03 and observation(rec)[0].std_down == 0.01
    no_sigma = msgspec.structs.replace(rec, std={"north": 0.02, "east": 0.02})
    assert observation(no_sigma)[0].down is None


def test_a_position_sigma_adds_the_fields_mean_square_difference_over_it():
    """place_variance against a Monte Carlo of its definition: the mean of
    ``2 sigma_f^2 (1 - exp(-|d|^2 / (2 l^2)))`` (the squared-exponential field's
    ``E[(c(x + d) - c(x))^2]``) over ``d`` normal of sigma ``place`` per axis; 0 for a fix,
    ``2 sigma_f^2`` for a place lost far beyond the length scale."""
    from onboard.fleet.field import place_variance

    rng = np.random.default_rng(7)
    sigma_f, length = 0.2, 400.0
    for place in (5.0, 100.0, 400.0, 2000.0):
        d = rng.normal(0.0, place, (200_000, 2))
        mc = np.mean(2 * sigma_f ** 2 * (1 - np.exp(-(d ** 2).sum(1) / (2 * length ** 2))))
        assert float(place_variance(sigma_f, length, np.array(place))) == \
            pytest.approx(mc, rel=0.01)
    assert place_variance(sigma_f, length, np.zeros(1))[0] == 0.0
    assert place_variance(sigma_f, length, np.array([1e6]))[0] == \
        pytest.approx(2 * sigma_f ** 2, rel=1e-6)


def test_what_the_fit_learned_is_said_in_a_line():
    """``onboard fleet``'s line per grid ends with the fit's scales and the sigma's
    calibration (algorithms.md §8.10); nothing before a fit."""
    f = fleet("eddy", seed=11, vehicles=6, duration_s=1200.0)
    field = CurrentField()
    assert field.learned() == ""
    for o in f.observations(skip=-1):
        field.add(o)
    field.fit()
    north, east = field.sigma_calibration
    text = field.learned()
    assert text.startswith(f"{field.fitted.hyper.length_m:.0f} m, ")
    assert f"sigma x{math.sqrt(north.scale):.2f} + " in text and text.endswith("cm/s east")


def far_first_field(degrees_off: float) -> CurrentField:
    """The eddy's fleet fused after one record of another vehicle ``degrees_off`` north
    and east of it (a boat at its home port, a record from last week's site)."""
    f = fleet("eddy", seed=21, vehicles=4, duration_s=900.0, rate_hz=1.0)
    obs = list(f.observations())
    field = CurrentField()
    first = obs[0]
    field.add(dataclasses.replace(first, vehicle="far", lat_deg=first.lat_deg + degrees_off,
                                  lon_deg=first.lon_deg + degrees_off))
    for o in obs:
        field.add(o)
    field.fit()
    places = [f.plane.to_latlon(n, e) for n, e in ((100.0, -200.0), (-300.0, 100.0),
                                                    (400.0, 400.0))]
    field.answers = [field.predict(float(la), float(lo), UTC0 + 800.0) for la, lo in places]
    return field


def test_the_plane_follows_the_fleet_not_its_first_record(monkeypatch):
    """A first record 330 or 1,100 km from the fleet (3 or 10 degrees) leaves the field
    where the fleet is the same to the digit: the plane moves to the windows' middle.
    The negative control, the plane kept at the first record: the stretched plane shifts
    the fitted length scale (536 -> 522 and 484 m) and the answers by up to 0.025 m/s."""
    near, far = far_first_field(3.0), far_first_field(10.0)
    assert math.hypot(*near.plane.to_ne(far.plane.lat0, far.plane.lon0)) < 1.0
    for a, b in zip(near.answers, far.answers):
        assert a.north == pytest.approx(b.north, abs=1e-9)
        assert a.east == pytest.approx(b.east, abs=1e-9)
        assert a.std_north == pytest.approx(b.std_north, abs=1e-9)
    monkeypatch.setattr("onboard.fleet.field.PLANE_RECENTRE_M", math.inf)
    near, far = far_first_field(3.0), far_first_field(10.0)
    shift = max(abs(a.north - b.north) + abs(a.east - b.east)
                for a, b in zip(near.answers, far.answers))
    assert shift > 0.01, shift


def fleet_at(lon0: float) -> tuple[FleetService, object]:
    """The eddy's fleet (6 vehicles, 10 min at 1 Hz) about (17 S, ``lon0``), its records'
    longitudes within [-180, 180] as a GNSS gives them, fused and fitted."""
    from onboard.fleet.field import Plane

    f = fleet("eddy", seed=21, vehicles=6, duration_s=600.0, rate_hz=1.0)
    f = dataclasses.replace(f, plane=Plane(-17.0, lon0))
    service, enc = FleetService(), msgspec.json.Encoder()
    for i in range(len(f.t)):
        rec = f.record(i)
        rec = msgspec.structs.replace(rec, lon_deg=(rec.lon_deg + 180.0) % 360.0 - 180.0)
        service.feed(enc.encode(rec), "application/json;onboard.Estimate.v2")
    service.step(refit=True)
    return service, f


def test_a_fleet_across_the_antimeridian_is_the_field_it_is_anywhere_else():
    """Off Fiji the vehicles' longitudes jump from 179.99 to -179.99: the field, its
    answers on either side and its grid are those of the same fleet at 5.9 E (a window's
    places were averaged to about 0 deg and the two sides taken 40 000 km apart: the
    side past the antimeridian answered from its own few windows, and the grid's
    longitudes went past 180, which a query cannot ask)."""
    here, f_here = fleet_at(5.9)
    there, f_there = fleet_at(179.998)
    assert there.field.added == here.field.added == len(f_here.t)
    crossed = 0
    for north_m, east_m in ((100.0, -300.0), (100.0, 0.0), (-200.0, 400.0), (100.0, 800.0)):
        a = here.answer(*map(float, f_here.plane.to_latlon(north_m, east_m)), UTC0 + 300.0)
        lat, lon = map(float, f_there.plane.to_latlon(north_m, east_m))
        crossed += lon < 0.0
        b = there.answer(lat, lon, UTC0 + 300.0)
        assert b.n_obs == a.n_obs
        for k in ("north", "east", "std_north", "std_east"):
            assert getattr(b, k) == pytest.approx(getattr(a, k), abs=1e-5), (k, east_m)
    assert crossed == 2   # two of the places are past the antimeridian
    grid = there.grid(list(there.newest.values()))
    assert all(-180.0 <= c.lon <= 180.0 for c in grid.cells)
    assert sum(c.north is not None for c in grid.cells) == \
        sum(c.north is not None for c in here.grid(list(here.newest.values())).cells)
