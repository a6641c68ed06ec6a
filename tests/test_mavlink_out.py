"""MAVLink out: component 191, HEARTBEAT, estimates, health, events, signing (architecture §4.5)."""

from __future__ import annotations

import math
import os
import socket

import msgspec
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from onboard.core.config import ConfigError, MavlinkOut
from onboard.core.messages import ChannelHealth, EstimateRecord, HealthRecord
from onboard.service.publishers.mavlink_pub import MavlinkPublisher, load_signing_key
from tests.helpers.mavlink_listener import receive_mavlink


@pytest.fixture
def listener():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(5.0)
    yield s
    s.close()


def _records():
    cur = EstimateRecord(vehicle="b", pipeline="current", t=1.0,
                         values={"north": 0.3, "east": -0.2, "down": 0.0, "std_north": 0.05,
                                 "std_east": 0.04},
                         std={"north": 0.05, "east": 0.04})
    aie = EstimateRecord(vehicle="b", pipeline="aie", t=1.0,
                         values={"surge_input": 0.8, "yaw_input": -0.1, "speed": 1.4,
                                 "north": 3.0, "east": 4.0, "heading": 1.0})
    eseso = EstimateRecord(vehicle="b", pipeline="eseso", t=1.0,
                           values={"dist_x": 1.0, "dist_y": 2.0, "dist_z": 3.0,
                                   "dist_north": 4.0, "dist_east": 5.0, "dist_down": 6.0})
    return [cur, aie, eseso]


@pytest.mark.integration
def test_heartbeat_estimates_and_health_from_component_191(listener):
    port = listener.getsockname()[1]
    pub = MavlinkPublisher(MavlinkOut(url=f"udpout:127.0.0.1:{port}"), system_id=7,
                           clock=lambda: 10.0)
    pub.start()
    pub.publish_estimates(_records(), now=10.0)
    pub.publish_health(HealthRecord(
        vehicle="b", t=10.0, rejected={"gnss:submerged": 3}, events=["gps: lost (EIO)"],
        innovations={"current": {"velocity": ChannelHealth(n=5, dof=2, test_ratio_max=1.0)},
                     "aie": {"heading.increment": ChannelHealth(n=9, dof=1,
                                                                test_ratio_max=0.5),
                             "surge.rate": ChannelHealth(n=9, dof=1, test_ratio_max=0.25)}}),
        now=10.0)
    pub.close()
    msgs = receive_mavlink(listener)
    assert {(m.get_srcSystem(), m.get_srcComponent()) for m in msgs} == {(7, 191)}
    by = {}
    for m in msgs:
        by.setdefault(m.get_type(), []).append(m)
    hb = by["HEARTBEAT"][0]
    assert hb.type == mavlink2.MAV_TYPE_ONBOARD_CONTROLLER
    assert hb.autopilot == mavlink2.MAV_AUTOPILOT_INVALID
    named = {m.name: m.value for m in by["NAMED_VALUE_FLOAT"]}
    assert named["CUR_N"] == pytest.approx(0.3) and named["CUR_E"] == pytest.approx(-0.2)
    assert named["THR_EST"] == pytest.approx(0.8) and named["TRQ_EST"] == pytest.approx(-0.1)
    assert named["SPD_EST"] == pytest.approx(1.4)
    vec = {m.name: (m.x, m.y, m.z) for m in by["DEBUG_VECT"]}
    assert vec["DIST"] == (1.0, 2.0, 3.0) and vec["DIST_NED"] == (4.0, 5.0, 6.0)
    w = by["WIND_COV"][0]  # the water current, drawn by ground stations as wind
    assert (w.wind_x, w.wind_y, w.wind_z) == pytest.approx((0.3, -0.2, 0.0))
    assert w.var_horiz == pytest.approx(0.05 ** 2 + 0.04 ** 2)
    assert w.horiz_accuracy == pytest.approx(math.hypot(0.05, 0.04))
    assert math.isnan(w.var_vert) and w.vert_accuracy == 0.0  # no sigma of the down
    st = by["ESTIMATOR_STATUS"][0]
    assert st.vel_ratio == pytest.approx(1.0)  # the worst velocity channel: at its gate
    assert st.mag_ratio == pytest.approx(0.5)
    assert st.pos_horiz_ratio == 0.0 and st.pos_vert_ratio == 0.0   # no such channel
    assert st.flags & mavlink2.ESTIMATOR_GPS_GLITCH
    assert by["STATUSTEXT"][0].text.startswith("gps: lost")
    assert "ODOMETRY" not in by  # only when configured


@pytest.mark.integration
def test_odometry_only_when_configured(listener):
    port = listener.getsockname()[1]
    pub = MavlinkPublisher(MavlinkOut(url=f"udpout:127.0.0.1:{port}", odometry=True), 1)
    pub.start()
    pub.publish_estimates(_records(), now=1.0)
    pub.close()
    odo = [m for m in receive_mavlink(listener) if m.get_type() == "ODOMETRY"]
    assert odo and (odo[0].x, odo[0].y) == (3.0, 4.0)


@pytest.mark.integration
def test_statustext_is_rate_limited_and_suppressions_are_reported(listener):
    port = listener.getsockname()[1]
    pub = MavlinkPublisher(MavlinkOut(url=f"udpout:127.0.0.1:{port}"), 1)
    pub.start()
    sent = [pub.event(f"event {i}", now=0.0) for i in range(20)]
    assert sum(sent) == 5 and pub.suppressed == 15  # burst of 5
    assert pub.event("later", now=10.0)
    pub.close()
    texts = [m.text for m in receive_mavlink(listener) if m.get_type() == "STATUSTEXT"]
    assert "onboard: 15 msgs suppressed" in texts and texts[-1] == "later"


@pytest.mark.integration
def test_a_long_event_reaches_the_ground_station_whole_in_chunks(listener):
    """A warning with its remedy is longer than STATUSTEXT's 50 bytes: it is sent as
    MAVLink's long statustext (chunks of one ``id``, ``chunk_seq`` 0, 1, ...), which
    joined give the event, key and value included; a short one is one message, id 0."""
    port = listener.getsockname()[1]
    pub = MavlinkPublisher(MavlinkOut(url=f"udpout:127.0.0.1:{port}"), 1)
    pub.start()
    long = ("nis_out_of_band: current velocity: mean NIS 6.05 outside [1.22, 2.82]; "
            "set [sensors.gnss] velocity_std_mps = 0.275 (declared 0.1 m/s)")
    exact = "x" * 100                                  # a multiple of 50: an empty chunk ends it
    assert pub.event(long, now=0.0) and pub.event("short", now=0.0)
    assert pub.event(exact, now=0.0)
    pub.close()
    msgs = [m for m in receive_mavlink(listener) if m.get_type() == "STATUSTEXT"]
    by_id: dict[int, list] = {}
    for m in msgs:
        by_id.setdefault(m.id, []).append(m)
    assert [m.text for m in by_id[0]] == ["short"]
    joined = {i: "".join(m.text for m in sorted(ms, key=lambda m: m.chunk_seq))
              for i, ms in by_id.items() if i}
    assert sorted(joined.values()) == sorted([long, exact])
    assert [m.chunk_seq for m in by_id[2]] == [0, 1, 2]


@pytest.mark.integration
def test_frames_are_signed_when_a_key_file_is_configured(listener, tmp_path):
    port = listener.getsockname()[1]
    key_file = tmp_path / "mav.key"
    key_file.write_text("a1" * 32)
    os.chmod(key_file, 0o600)
    key = load_signing_key(key_file)
    assert key == bytes.fromhex("a1" * 32)
    pub = MavlinkPublisher(MavlinkOut(url=f"udpout:127.0.0.1:{port}",
                                      signing_key_file=str(key_file), require_signing=True), 1)
    pub.start()
    pub.publish_estimates(_records(), now=0.0)
    pub.close()
    good = receive_mavlink(listener, key)
    assert good and all(m._signed for m in good)
    # a receiver with another key rejects every frame
    pub2 = MavlinkPublisher(MavlinkOut(url=f"udpout:127.0.0.1:{port}",
                                       signing_key_file=str(key_file)), 1)
    pub2.start()
    pub2.publish_estimates(_records(), now=0.0)
    pub2.close()
    assert receive_mavlink(listener, b"\x00" * 32) == []


def test_a_key_file_readable_by_others_or_a_missing_required_key_is_a_config_error(tmp_path):
    key_file = tmp_path / "mav.key"
    key_file.write_text("passphrase")
    os.chmod(key_file, 0o644)
    with pytest.raises(ConfigError, match="chmod 600"):
        load_signing_key(key_file)
    with pytest.raises(ConfigError, match="require_signing"):
        MavlinkPublisher(MavlinkOut(require_signing=True), 1).start()
    os.chmod(key_file, 0o600)
    import hashlib

    assert load_signing_key(key_file) == hashlib.sha256(b"passphrase").digest()


@pytest.mark.parametrize("channel,kind", [
    ("surge.increment", "position"), ("surge.rate", "velocity"),
    ("heading.increment", "heading"), ("velocity", "velocity"), ("dvl", "velocity"),
    ("vog", "velocity"), ("attitude", "heading"), ("depth", "depth"), ("thrust", None),
    ("yaw_rls", "heading"), ("gnss_pos", "position"), ("gnss_vel", "velocity"),
    ("water_track", "velocity"), ("hgo.velocity", "velocity"), ("flow.heading", "heading")])
def test_each_innovation_channel_feeds_the_estimator_status_ratio_of_its_kind(channel, kind):
    from onboard.service.publishers.mavlink_pub import ratio_kind

    assert ratio_kind(channel) == kind


@pytest.mark.integration
def test_the_position_accuracy_is_a_positions_never_the_currents(listener):
    """``pos_horiz_accuracy`` (m) is the largest position sigma of the pipelines that
    publish a position; the current's ``north``/``east`` are m/s and never count. With
    no position published (withheld, or none), no relative position is claimed and its
    accuracy is NaN, not 0."""
    port = listener.getsockname()[1]
    pub = MavlinkPublisher(MavlinkOut(url=f"udpout:127.0.0.1:{port}"), system_id=7,
                           clock=lambda: 10.0)
    pub.start()
    cur, aie, _ = _records()
    cur = msgspec.structs.replace(cur, std={"north": 0.3, "east": 0.4})
    placed = msgspec.structs.replace(aie, std={"north": 2.5, "east": 1.5})
    withheld = msgspec.structs.replace(aie, values={"speed": 1.4}, std={"north": 2.5})
    for t, recs in ((10.0, [cur, placed]), (11.0, [cur, withheld])):
        pub.publish_estimates(recs, now=t)
        pub.publish_health(HealthRecord(vehicle="b", t=t), now=t)
    pub.close()
    st = [m for m in receive_mavlink(listener) if m.get_type() == "ESTIMATOR_STATUS"]
    assert st[0].flags & mavlink2.ESTIMATOR_POS_HORIZ_REL and st[0].pos_horiz_accuracy == 2.5
    assert not st[1].flags & mavlink2.ESTIMATOR_POS_HORIZ_REL
    assert math.isnan(st[1].pos_horiz_accuracy)


@pytest.mark.integration
@pytest.mark.parametrize("flag, claim", [
    ("position_residual", mavlink2.ESTIMATOR_POS_HORIZ_REL),
    ("speed_mismatch", mavlink2.ESTIMATOR_VELOCITY_HORIZ)])
def test_an_estimate_flagged_by_the_integrity_checks_is_not_claimed(listener, flag, claim):
    """ESTIMATOR_STATUS claims a relative horizontal position only while no pipeline's
    position disagrees with GNSS beyond its sigma (``position_residual``), and a horizontal
    velocity only while no pipeline's speed disagrees with the Doppler or DVL speed
    (``speed_mismatch``)."""
    port = listener.getsockname()[1]
    pub = MavlinkPublisher(MavlinkOut(url=f"udpout:127.0.0.1:{port}"), system_id=7,
                           clock=lambda: 10.0)
    pub.start()
    pub.publish_estimates(_records(), now=10.0)
    pub.publish_health(HealthRecord(vehicle="b", t=10.0), now=10.0)
    pub.publish_health(HealthRecord(vehicle="b", t=11.0, flags={"aie": [flag]}), now=11.0)
    pub.close()
    st = [m for m in receive_mavlink(listener) if m.get_type() == "ESTIMATOR_STATUS"]
    assert st[0].flags & claim
    assert not st[1].flags & claim



def _count_sends(pub: MavlinkPublisher) -> dict[str, list[float]]:
    """Wrap the publisher's estimate and heartbeat senders: their send times (its clock)."""
    sent: dict[str, list[float]] = {"est": [], "hb": []}
    send_est, heartbeat = pub._send_estimates, pub._heartbeat

    def est(now: float) -> None:
        sent["est"].append(now)
        send_est(now)

    def hb() -> None:
        sent["hb"].append(pub.clock())
        heartbeat()
    pub._send_estimates = est  # type: ignore[method-assign]
    pub._heartbeat = hb  # type: ignore[method-assign]
    return sent


def test_estimates_and_heartbeat_keep_their_rates_on_a_jittered_tick():
    """Called from a 10 Hz tick loop whose ticks come up to 10 ms early or late, the
    estimates go out at ``rate_hz`` (5 Hz) and HEARTBEAT at 1 Hz over a minute, not less
    (a tick a little before the due time does not push the schedule by a whole tick);
    after a 5 s gap the schedule starts again from the first tick, without a burst."""
    import random

    rng = random.Random(1)
    now = [0.0]
    pub = MavlinkPublisher(MavlinkOut(rate_hz=5.0), 1, clock=lambda: now[0])  # not started
    sent = _count_sends(pub)
    recs = _records()
    duration = 60.0
    for k in range(int(duration * 10)):
        now[0] = 100.0 + 0.1 * k + rng.uniform(-0.01, 0.01)
        pub.publish_estimates(recs)
    assert len(sent["est"]) == pytest.approx(5.0 * duration, abs=1)
    assert len(sent["hb"]) == pytest.approx(duration, abs=1)
    gaps = [b - a for a, b in zip(sent["est"], sent["est"][1:])]
    assert max(gaps) < 0.2 + 0.1 + 0.02 and min(gaps) > 0.2 - 0.1 - 0.02

    n_est, n_hb = len(sent["est"]), len(sent["hb"])
    for k in range(10):  # 1 s of ticks after the gap
        now[0] = 100.0 + duration + 5.0 + 0.1 * k
        pub.publish_estimates(recs)
    assert len(sent["est"]) - n_est == 5 and len(sent["hb"]) - n_hb == 1


@pytest.mark.integration
def test_wind_cov_says_unknown_as_common_xml_does(listener):
    """A surface boat's current has no down: ``wind_z`` and ``var_vert`` NaN ("NAN if
    unknown"), ``vert_accuracy`` 0 ("0 if unknown"); an underwater vehicle's down and its
    sigma are sent; a horizontal sigma not known yet: ``var_horiz`` NaN, accuracy 0."""
    port = listener.getsockname()[1]
    pub = MavlinkPublisher(MavlinkOut(url=f"udpout:127.0.0.1:{port}"), 1)
    pub.start()
    boat = EstimateRecord(vehicle="b", pipeline="current", t=1.0,
                          values={"north": 0.3, "east": -0.2},
                          std={"north": 0.05, "east": 0.04})
    auv = EstimateRecord(vehicle="b", pipeline="current", t=2.0,
                         values={"north": 0.3, "east": -0.2, "down": 0.01},
                         std={"north": 0.05, "east": 0.04, "down": 0.02})
    fresh = EstimateRecord(vehicle="b", pipeline="current", t=3.0,
                           values={"north": 0.0, "east": 0.0}, std={})
    dived = EstimateRecord(vehicle="b", pipeline="nav", t=2.0, values={"depth": 12.5})
    for i, rec in enumerate((boat, auv, fresh)):
        pub.publish_estimates([rec] + ([dived] if rec is auv else []), now=1.0 * i)
    pub.close()
    w = [m for m in receive_mavlink(listener) if m.get_type() == "WIND_COV"]
    assert len(w) == 3
    # wind_alt, the altitude (MSL) it was measured at: the surface, then 12.5 m down
    assert w[0].wind_alt == 0.0 and w[1].wind_alt == pytest.approx(-12.5)
    assert math.isnan(w[0].wind_z) and math.isnan(w[0].var_vert) and w[0].vert_accuracy == 0.0
    assert w[0].horiz_accuracy == pytest.approx(math.hypot(0.05, 0.04))
    assert w[1].wind_z == pytest.approx(0.01) and w[1].var_vert == pytest.approx(0.02 ** 2)
    assert w[1].vert_accuracy == pytest.approx(0.02)
    assert math.isnan(w[2].var_horiz) and w[2].horiz_accuracy == 0.0
