"""A fleet in the simulator (sitl/fleet.py): several vehicles in one current field, each
with its own clock, id and config, written offline with the truth beside, and replayed:
each vehicle's current against the true current at its position.

The default suite writes short runs (a few simulated seconds; one boat for 150 s for the
replay); the whole fleet-channel (600 s, three vehicles) is ``slow``. Tolerances are the
measured figures with margin (the comments say which)."""

from __future__ import annotations

import csv
import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest

from onboard.core.config import load_all
from onboard.core.errors import UsageError
from onboard.sitl.fleet import (
    FLEETS, BASE_CONFIGS, FleetVehicle, get_fleet, read_manifest, read_sea, replace_vehicles,
    write_fleet)
from onboard.sitl.runner import read_truth

CHANNEL = FLEETS["fleet-channel"]


def small_fleet(*vids: str) -> object:
    """fleet-channel with only the vehicles ``vids``."""
    return replace_vehicles(CHANNEL, tuple(CHANNEL.vehicle(v) for v in vids))


def test_offline_fleet_writes_each_vehicle_its_clock_and_the_truth(tmp_path):
    fleet = small_fleet("boat-1", "auv-1")
    m = write_fleet(fleet, tmp_path, seed=3, duration_s=42.0)
    assert [v["id"] for v in m["vehicles"]] == ["boat-1", "auv-1"]
    boat, auv = m["vehicles"]
    # own protocol, own config, own clock
    assert (tmp_path / boat["files"]["nmea"]).read_bytes().startswith(b"$")
    assert json.loads((tmp_path / auv["files"]["dvl_json"]).read_text().splitlines()[0])
    assert boat["configs"] == [BASE_CONFIGS["rudder-boat"], "boat-1.toml"]
    cfg = load_all([BASE_CONFIGS["torpedo-auv"], str(tmp_path / "auv-1.toml")])
    assert (cfg.vehicle.id, cfg.vehicle.system_id) == ("auv-1", 13)
    assert auv["utc_start"] == CHANNEL.utc0 + 40.0 and auv["duration_s"] == 2.0
    for v in (boat, auv):
        stamp = struct.unpack(">Q", (tmp_path / v["files"]["tlog"]).read_bytes()[:8])[0]
        assert stamp / 1e6 == pytest.approx(v["utc_start"] + v["clock_offset_s"])
    # the truth: each record's current is the field at its position and UTC
    rows = list(csv.DictReader(open(tmp_path / "truth-current.csv")))
    assert {r["vehicle"] for r in rows} == {"boat-1", "auv-1"}
    assert len(rows) == len(read_truth(tmp_path / "boat-1.truth.jsonl")) + 21
    lat, lon, depth, utc, vn, ve = (np.array([float(r[k]) for r in rows]) for k in (
        "lat_deg", "lon_deg", "depth_m", "utc", "current_north", "current_east"))
    fn, fe = fleet.sea.at(lat, lon, depth, utc)
    np.testing.assert_allclose(fn, vn, atol=2e-6)
    np.testing.assert_allclose(fe, ve, atol=2e-6)
    assert np.ptp(vn) > 0.01  # the boat sees the field change along its track
    # the field rebuilt from fleet.json gives the same truth
    rn, re_ = read_sea(tmp_path).at(lat, lon, depth, utc)
    np.testing.assert_allclose(rn, vn, atol=2e-6)
    np.testing.assert_allclose(re_, ve, atol=2e-6)
    # the AUV starts afloat for its fix (not at its 5 m): bobbing to 0.42 m in its first
    # 2 s, settling at 0.09 m within 15 s (measured)
    assert depth[[r["vehicle"] == "auv-1" for r in rows]].max() < 0.5
    # negative control: the same records against a uniform current are far off
    assert np.abs(vn - vn.mean()).max() > 10 * 2e-6


def test_field_grid_is_the_field(tmp_path):
    fleet = small_fleet("boat-2")
    write_fleet(fleet, tmp_path, seed=1, duration_s=60.0)
    g = json.loads((tmp_path / "field-grid.json").read_text())
    north = np.asarray(g["north"])
    assert north.shape == (len(g["utc"]), len(g["depth_m"]), len(g["lat_deg"]), len(g["lon_deg"]))
    assert g["utc"] == [CHANNEL.utc0, CHANNEL.utc0 + 60.0]
    k, d, i, j = 1, 1, len(g["lat_deg"]) // 2, len(g["lon_deg"]) // 3
    vn, ve = fleet.sea.at(g["lat_deg"][i], g["lon_deg"][j], g["depth_m"][d], g["utc"][k])
    assert north[k, d, i, j] == pytest.approx(float(vn), abs=1e-6)
    assert g["east"][k][d][i][j] == pytest.approx(float(ve), abs=1e-6)
    # the grid covers the track
    rows = list(csv.DictReader(open(tmp_path / "truth-current.csv")))
    lats = [float(r["lat_deg"]) for r in rows]
    assert g["lat_deg"][0] < min(lats) and max(lats) < g["lat_deg"][-1]


def test_deterministic_by_seed(tmp_path):
    fleet = small_fleet("boat-2")
    for name, seed in (("a", 5), ("b", 5), ("c", 6)):
        write_fleet(fleet, tmp_path / name, seed=seed, duration_s=25.0)
    a, b, c = ((tmp_path / n / "boat-2.tlog").read_bytes() for n in "abc")
    assert a == b and a != c
    assert (tmp_path / "a" / "truth-current.csv").read_bytes() == \
        (tmp_path / "b" / "truth-current.csv").read_bytes()


def test_unknown_fleet_kind_or_pattern_is_a_usage_error():
    with pytest.raises(UsageError):
        get_fleet("no-such-fleet")
    with pytest.raises(UsageError):
        FleetVehicle("x", "hovercraft", "loiter", 1)
    with pytest.raises(UsageError):
        FleetVehicle("x", "rudder-boat", "zigzag", 1)


def test_cli_lists_and_writes_a_fleet(tmp_path, capsys):
    from onboard.cli import main

    assert main(["sitl", "--list"]) == 0
    assert "fleet-channel" in capsys.readouterr().out
    assert main(["sitl", "--fleet", "fleet-channel"]) == 2  # offline needs --out
    assert "give --out DIR" in capsys.readouterr().err
    out_dir = tmp_path / "fleet"   # created, as every --out DIR
    assert main(["sitl", "--fleet", "fleet-channel", "--out", str(out_dir), "--duration",
                 "3", "--seed", "2"]) == 0
    out = capsys.readouterr().out
    assert "onboard replay" in out and "boat-1.tlog" in out
    # the others launch after 3 s
    assert [v["id"] for v in read_manifest(out_dir)["vehicles"]] == ["boat-1"]
    # a previous fleet's folder is written over only with --force
    assert main(["sitl", "--fleet", "fleet-channel", "--out", str(out_dir), "--duration",
                 "3"]) == 2
    assert "--force" in capsys.readouterr().err


# --------------------------------------------------------------------------- replayed


def replay_current(out: Path, entry: dict) -> dict[str, np.ndarray]:
    """Replay one vehicle's log with its own configs; its current records against its
    truth: t, estimate, sigma and truth per component."""
    from onboard.offline.replay import replay

    cfg = load_all([entry["configs"][0], str(out / entry["configs"][1])])
    rep = out / f"replay-{entry['id']}"
    summary = replay(str(out / entry["files"]["tlog"]), cfg, rep, plot=False)
    assert summary["vehicle_id"] == entry["id"]
    rows = list(csv.DictReader(open(rep / "estimates.csv")))
    truth = read_truth(out / entry["files"]["truth"])
    tt = np.array([r.t for r in truth])
    res: dict[str, np.ndarray] = {"t": np.array([float(r["t"]) for r in rows])}
    for q in ("north", "east"):
        res[q] = np.array([float(r[f"current.{q}"]) if r[f"current.{q}"] else math.nan
                           for r in rows])
        res[f"std_{q}"] = np.array([float(r[f"current.std_{q}"]) if r[f"current.std_{q}"]
                                    else math.nan for r in rows])
        res[f"true_{q}"] = np.interp(res["t"], tt, [getattr(r, f"current_{q}") for r in truth])
    return res


def errors(res: dict[str, np.ndarray], q: str, after: float,
           truth_key: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The known estimates' errors and sigmas of component ``q`` after ``after`` s."""
    ok = np.isfinite(res[q]) & (res["t"] > after)
    return res[q][ok] - res[truth_key or f"true_{q}"][ok], res[f"std_{q}"][ok]


def test_replayed_boat_current_is_the_field_at_its_position(tmp_path):
    """The fast variant: a twin-thruster boat loitering (a lap in 30 s) north of the front
    for 120 s, replayed with its own configs; its current after 60 s (not yet converged:
    its sigma is still ~0.15 m/s) against the field at its position. Measured (seed 1):
    rms north 0.043, east 0.028 m/s, every error within 1.96 sigma; against the current
    at the fleet's origin (a uniform-current truth) north is off by 0.116 m/s."""
    boat = FleetVehicle("boat-f", "twin-thruster", "loiter", 21, start_north=230.0,
                        start_east=150.0, leg_s=30.0, speed=1.2)
    m = write_fleet(replace_vehicles(CHANNEL, (boat,)), tmp_path, seed=1, duration_s=120.0)
    res = replay_current(tmp_path, m["vehicles"][0])
    for q in ("north", "east"):
        err, sd = errors(res, q, after=60.0)
        assert len(err) == 600
        assert np.sqrt(np.mean(err**2)) < 0.06
        assert np.mean(np.abs(err) < 1.96 * sd) > 0.9
    # negative control: a uniform current (the field at the origin at the fleet's start)
    # as the truth fails the same bound
    n0, _ = CHANNEL.sea.local(0.0, 0.0, 0.0, CHANNEL.utc0)
    ok = np.isfinite(res["north"]) & (res["t"] > 60.0)
    assert np.sqrt(np.mean((res["north"][ok] - float(n0)) ** 2)) > 0.06


@pytest.mark.slow
def test_fleet_channel_replayed_each_vehicle_near_its_truth(tmp_path):
    """The whole fleet-channel (600 s, seed 1), every vehicle replayed with its own
    configs, its known current after 60 s against the field at its position. Measured
    (rms north / east m/s, mean one-sigma, share within 1.96 sigma): boat-1 (lawnmower)
    0.013 / 0.011, 0.046 / 0.040, 1.00; boat-2 (loiter) 0.011 / 0.017, 0.045 / 0.047,
    1.00; auv-1 (afloat 30 s, then a lawnmower at 5 m) 0.013 / 0.024, 0.062, 1.00
    (docs/sitl.md "A fleet")."""
    m = write_fleet(CHANNEL, tmp_path, seed=1)
    for entry in m["vehicles"]:
        res = replay_current(tmp_path, entry)
        for q in ("north", "east"):
            err, sd = errors(res, q, after=60.0)
            assert len(err) > 3500, (entry["id"], q)
            rms = np.sqrt(np.mean(err**2))
            assert rms < 0.03, (entry["id"], q)
            assert np.mean(np.abs(err) < 1.96 * sd) > 0.9, (entry["id"], q)
        if entry["id"] == "boat-1":
            # negative control: the lawnmower crosses the field (0.23-0.42 m/s north);
            # a constant current, its own mean truth, misses it by several times more
            ok = np.isfinite(res["north"]) & (res["t"] > 60.0)
            flat = res["north"][ok] - res["true_north"][ok].mean()
            assert np.sqrt(np.mean(flat**2)) > 3 * 0.0127


SEAS = FLEETS["fleet-survey-seas"]


def _parts(sea) -> dict[str, dict]:
    return {d["kind"]: d for d in sea.describe()}


def test_a_drawn_sea_is_the_seeds_own_and_within_its_ranges():
    # sitl.fleet.drawn_survey_sea's docstring: the ranges each feature is drawn from
    assert SEAS.at_seed(4).sea.describe() == SEAS.at_seed(4).sea.describe()
    assert SEAS.at_seed(4).sea.describe() != SEAS.at_seed(5).sea.describe()
    assert SEAS.at_seed(0).sea.describe() == SEAS.sea.describe()
    assert FLEETS["fleet-survey"].at_seed(7) is FLEETS["fleet-survey"]
    cn, ce = 0.0, -50.0
    turns = set()
    for seed in range(60):
        p = _parts(SEAS.at_seed(seed).sea)
        ch, eddy, front, drift = (p["TidalChannel"], p["LambOseenEddy"], p["TanhFront"],
                                  p["UniformFlow"])
        assert 0.3 <= ch["amplitude"] <= 0.7 and 800.0 <= ch["width"] <= 1600.0
        assert 10.0 <= math.degrees(ch["direction"]) <= 50.0
        assert ce - 300.0 <= ch["centre_east"] <= ce
        assert 80.0 <= eddy["core_radius"] <= 200.0
        assert math.hypot(eddy["north0"] - cn, eddy["east0"] - ce) <= 150.0
        turns.add(math.copysign(1.0, eddy["circulation"]))
        jump = math.hypot(front["b_north"], front["b_east"])
        assert 0.06 <= jump <= 0.15 and 25.0 <= front["half_width"] <= 80.0
        assert math.hypot(front["north0"] - cn, front["east0"] - ce) <= 150.0
        assert abs(front["speed"]) <= 0.03
        assert max(abs(drift["north"]), abs(drift["east"])) <= 0.05
    assert turns == {-1.0, 1.0}


def test_a_fleet_written_with_a_seed_flies_and_records_that_seeds_sea(tmp_path):
    m = write_fleet(replace_vehicles(SEAS, (SEAS.vehicle("keeper"),)), tmp_path, seed=3,
                    duration_s=8.0)
    assert [v["id"] for v in m["vehicles"]] == ["keeper"]
    assert read_sea(tmp_path).describe() == SEAS.at_seed(3).sea.describe()
    rows = list(csv.DictReader(open(tmp_path / "truth-current.csv")))
    lat, lon, depth, utc, vn, ve = (np.array([float(r[k]) for r in rows]) for k in (
        "lat_deg", "lon_deg", "depth_m", "utc", "current_north", "current_east"))
    fn, fe = SEAS.at_seed(3).sea.at(lat, lon, depth, utc)
    np.testing.assert_allclose(fn, vn, atol=2e-6)
    np.testing.assert_allclose(fe, ve, atol=2e-6)
    other = SEAS.at_seed(4).sea.at(lat, lon, depth, utc)[0]
    assert np.abs(other - vn).max() > 0.01  # another seed's sea is not this one


def test_the_live_demo_flies_every_vehicle_in_the_fleets_sea_not_its_own_seeds():
    from onboard.apps.demo import LinkPlan, _child_simulation

    plan = LinkPlan(scenario="auv-2", duration_s=1.0, seed=9, speed=1.0,
                    mavlink_udp_port=0, dvl_tcp_port=None, truth_path="",
                    fleet="fleet-survey-seas", fleet_seed=3)
    sim, _ = _child_simulation(plan)
    current = sim.scenario.environment().current
    assert current.sea.describe() == SEAS.at_seed(3).sea.describe()
