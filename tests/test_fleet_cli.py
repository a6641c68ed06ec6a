"""``onboard fleet`` as an operator starts it: its flags are checked before Zenoh opens
(exit 2, one line naming the flag), and its session goes where ``--connect``, else
``--zenoh-config``, says (docs/fleet.md "Running it")."""

from __future__ import annotations

import pytest

from onboard.cli import main as cli_main


@pytest.mark.parametrize("flags, words", [
    (["--prefix", "region/*"], "--prefix"),
    (["--prefix", "/onboard"], "--prefix"),
    (["--prefix", "a//b"], "--prefix"),
    (["--prefix", ""], "--prefix"),
    (["--period", "inf"], "--period"),
    (["--refit", "inf"], "--refit"),
    (["--period", "nan"], "--period"),
])
def test_a_bad_prefix_or_period_stops_the_fleet_before_it_connects(flags, words, capsys):
    # a Zenoh endpoint nobody serves: reaching it would be a different error
    rc = cli_main(["fleet", "--connect", "tcp/127.0.0.1:1", *flags])
    err = capsys.readouterr().err
    assert rc == 2
    assert words in err and "cannot reach" not in err, err
    assert len(err.strip().splitlines()) == 1, err


@pytest.mark.parametrize("module", ["onboard.fleet.service", "onboard.apps.shore"])
def test_the_zenoh_configs_endpoints_are_used_without_connect(module, tmp_path):
    """``--zenoh-config shore.json5`` alone (docs/security.md) connects where the file
    says, not to the default local router; ``--connect`` still wins over the file."""
    import importlib

    from onboard.core.errors import UsageError

    open_session = importlib.import_module(module).open_session
    conf = tmp_path / "shore.json5"
    conf.write_text('{ connect: { endpoints: ["tcp/127.0.0.1:2"] } }\n')
    with pytest.raises(UsageError, match=r"tcp/127\.0\.0\.1:2\b"):
        open_session(None, None, None, str(conf))
    with pytest.raises(UsageError, match=r"tcp/127\.0\.0\.1:3\b"):
        open_session(["tcp/127.0.0.1:3"], None, None, str(conf))
    with pytest.raises(UsageError, match=r"tcp/127\.0\.0\.1:7447"):
        open_session(None, None, None, "")


@pytest.mark.integration
def test_a_zenoh_config_alone_reaches_its_router(tmp_path):
    from onboard.apps.service_bench import free_tcp_port
    from onboard.fleet.service import open_session
    from onboard.service.publishers.zenoh_pub import open_router

    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    router = open_router(endpoint)
    conf = tmp_path / "shore.json5"
    conf.write_text(f'{{ connect: {{ endpoints: ["{endpoint}"] }} }}\n')
    try:
        session = open_session(None, None, None, str(conf))
        session.close()
    finally:
        router.close()


def test_the_first_records_are_fitted_at_once_not_a_refit_period_after_the_start():
    """The service starts before its vehicles publish: its first refresh, empty, does not
    use up the hyperparameters' fit (the first minute of records was served on the
    default hyperparameters, 1 km and 1 h)."""
    import msgspec

    from onboard.fleet.service import FleetService
    from tests.helpers.fleet_scenarios import fleet

    service = FleetService(refit_s=60.0)
    assert service.step() is None   # nothing yet
    f = fleet("eddy", seed=21, vehicles=4, duration_s=300.0, rate_hz=1.0)
    enc = msgspec.json.Encoder()
    for i in range(len(f.t)):
        service.feed(enc.encode(f.record(i)), "application/json;onboard.Estimate.v2")
    assert service.step() is not None
    assert service.field.log_likelihood is not None   # fitted on these records


def test_a_vehicle_silent_longer_than_the_history_leaves_the_grid():
    """A boat heard once at its base 10 km away, then silent for 7 h while three others
    survey: the grid covers the survey (cells of about 100 m) and lists the three (the
    base's boat stretched the box to 11 km, cells of 700 m, for as long as the service
    ran, though the field had forgotten its records)."""
    import msgspec

    from onboard.core.messages import EstimateRecord
    from onboard.fleet.field import Plane
    from onboard.fleet.service import FleetService
    from tests.helpers.fleet_scenarios import LAT0, LON0, UTC0

    plane, enc = Plane(LAT0, LON0), msgspec.json.Encoder()
    service = FleetService()

    def put(vehicle, utc, north_m, east_m):
        lat, lon = map(float, plane.to_latlon(north_m, east_m))
        service.feed(enc.encode(EstimateRecord(
            vehicle=vehicle, pipeline="current", t=0.0, utc=utc, lat_deg=lat, lon_deg=lon,
            values={"north": 0.1, "east": 0.0}, std={"north": 0.03, "east": 0.03})),
            "application/json;onboard.Estimate.v2")

    put("base", UTC0, 10_000.0, 0.0)
    assert service.step() is not None
    t0 = UTC0 + 7 * 3600.0
    for k in range(60):
        for j, vehicle in enumerate(("a", "b", "c")):
            put(vehicle, t0 + 5.0 * k, 300.0 * j, 2.0 * k)
    grid = service.step()
    assert [v.vehicle for v in grid.vehicles] == ["a", "b", "c"]
    assert grid.spacing_m < 150.0, grid.spacing_m
    assert sorted(service.newest) == ["a", "b", "c"]


@pytest.mark.integration
@pytest.mark.parametrize("module", ["onboard.fleet.service", "onboard.apps.shore"])
def test_a_listening_peer_dials_nobody(module, monkeypatch):
    """``--mode peer --listen E`` (docs/fleet.md's history example): the vehicles connect to
    it; it joined whatever Zenoh network answered on the default local endpoint as well
    (another service's router on 127.0.0.1:7447). A client still dials the default."""
    import importlib
    import time

    from onboard.apps.service_bench import free_tcp_port
    from onboard.service.publishers.zenoh_pub import open_router

    from onboard.service.publishers import zenoh_pub

    mod = importlib.import_module(module)
    default = f"tcp/127.0.0.1:{free_tcp_port()}"
    monkeypatch.setattr(zenoh_pub, "SHORE_CONNECT", default)
    router = open_router(default)
    try:
        peer = mod.open_session(None, [f"tcp/127.0.0.1:{free_tcp_port()}"], "peer", "")
        client = mod.open_session(None, None, None, "")
        time.sleep(0.5)
        assert list(peer.info.routers_zid()) == []
        assert len(list(client.info.routers_zid())) == 1
        peer.close()
        client.close()
    finally:
        router.close()


def test_vehicles_whose_currents_are_not_known_yet_are_in_a_grid_of_unknown_cells():
    """The fleet's first minutes: every vehicle publishes its place, its current not
    converged yet (withheld). The grid is published every period all the same, the
    vehicles listed and every cell unknown (nothing was published, so the page and a
    vehicle subscribed to the grid saw no fleet at all, and the MCAP began later)."""
    import msgspec

    from onboard.core.messages import EstimateRecord
    from onboard.fleet.service import FleetService
    from tests.helpers.fleet_scenarios import LAT0, LON0, UTC0

    service, enc = FleetService(), msgspec.json.Encoder()
    for k, vehicle in enumerate(("a", "b")):
        service.feed(enc.encode(EstimateRecord(
            vehicle=vehicle, pipeline="current", t=0.0, utc=UTC0 + k, lat_deg=LAT0 + 0.001 * k,
            lon_deg=LON0, values={}, std={})), "application/json;onboard.Estimate.v2")
    grid = service.step()
    assert grid is not None and [v.vehicle for v in grid.vehicles] == ["a", "b"]
    assert grid.utc == UTC0 + 1 and grid.cells
    assert all(c.north is None and c.n_obs == 0 for c in grid.cells)
    assert service.left_out() == {"no_current": 2}
