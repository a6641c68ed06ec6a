"""Vehicle class and input mapping are detected from HEARTBEAT and SERVOn_FUNCTION."""

from onboard.offline.autodetect import detect
from onboard.core.messages import Parameter, VehicleInfo


def p(name, value):
    return Parameter(t=1.0, name=name, value=value)


def test_skid_steering_functions_give_a_twin_thruster_boat():
    cfg, why = detect([p("SERVO2_FUNCTION", 73), p("SERVO4_FUNCTION", 74),
                       p("SERVO4_TRIM", 1510), p("SERVO4_MIN", 1100), p("SERVO4_MAX", 1900)])
    assert cfg.vehicle.vehicle_class == "twin-thruster-boat"
    assert (cfg.inputs.left.channel, cfg.inputs.right.channel) == (2, 4)
    assert cfg.inputs.right.neutral_us == 1510 and cfg.inputs.right.half_range_us == 390
    assert "73" in why


def test_steering_and_throttle_functions_give_a_rudder_boat():
    cfg, _ = detect([p("SERVO2_FUNCTION", 26), p("SERVO5_FUNCTION", 70)])
    assert cfg.vehicle.vehicle_class == "rudder-boat"
    assert (cfg.inputs.rudder.channel, cfg.inputs.throttle.channel) == (2, 5)


def test_submarine_heartbeat_gives_a_bluerov2():
    cfg, why = detect([VehicleInfo(t=1, system_id=1, component_id=1, mav_type=12, autopilot=3)])
    assert cfg.vehicle.vehicle_class == "bluerov2"
    assert [m.channel for m in cfg.inputs.thrusters] == [1, 2, 3, 4, 5, 6]


def test_ground_station_heartbeats_are_ignored():
    cfg, why = detect([VehicleInfo(t=1, system_id=255, component_id=190, mav_type=6, autopilot=8)])
    assert cfg.vehicle.vehicle_class == "rudder-boat"
    assert "defaults" in why


def test_submarine_with_rudder_and_elevator_is_a_torpedo_auv():
    cfg, why = detect([VehicleInfo(t=1, system_id=1, component_id=1, mav_type=12, autopilot=3),
                       p("SERVO1_FUNCTION", 21), p("SERVO2_FUNCTION", 19), p("SERVO3_FUNCTION", 70)])
    assert cfg.vehicle.vehicle_class == "torpedo-auv"
    assert (cfg.inputs.rudder.channel, cfg.inputs.stern_plane.channel) == (1, 2)
    assert cfg.inputs.propeller_rpm.source == "rpm"


def test_a_boat_configuration_on_a_submarine_log_is_a_class_mismatch():
    from onboard.offline.autodetect import consistency
    from onboard.core import config

    sub = VehicleInfo(t=1, system_id=1, component_id=1, mav_type=12, autopilot=3)
    codes = [c for c, _ in consistency(config.load("rudder-boat"), [sub])]
    assert codes == ["class_mismatch"]
    assert consistency(config.load("bluerov2"), [sub]) == []


def test_a_class_mismatch_names_the_config_that_fits_the_log():
    from onboard.offline.autodetect import consistency
    from onboard.core import config

    sub = VehicleInfo(t=1, system_id=1, component_id=1, mav_type=12, autopilot=3)
    ((_, message),) = consistency(config.load("rudder-boat"), [sub])
    assert "a bluerov2's" in message and "--config bluerov2 fits the log" in message
    boat = VehicleInfo(t=1, system_id=1, component_id=1, mav_type=11, autopilot=3)
    ((_, message),) = consistency(config.load("bluerov2"), [boat])
    assert "--config rudder-boat fits the log" in message


def test_five_of_six_rov_motors_is_an_incomplete_mapping():
    from onboard.offline.autodetect import consistency
    from onboard.core import config

    five = [p(f"SERVO{i}_FUNCTION", 32 + i) for i in range(1, 6)]   # Motor1-5
    (code, message), = consistency(config.load("bluerov2"), five)
    assert code == "actuator_mapping_incomplete" and "[6]" in message
    six = five + [p("SERVO6_FUNCTION", 38)]
    assert consistency(config.load("bluerov2"), six) == []


def test_a_survey_boat_arduino_capture_is_replayed_with_its_bundled_config(tmp_path):
    """The survey boat's Arduino capture (IMU and RC rows between NMEA, that boat's logger
    alone) takes config/survey-boat-csv.toml without --config, named in the note, and
    replays as with it given; an NMEA capture has no vehicle evidence still."""
    from pathlib import Path

    from onboard.cli import main as cli_main
    from onboard.core.config import CONFIG_DIR
    from onboard.offline.replay import choose_config

    data = Path(__file__).resolve().parent / "data"
    capture = data / "survey_boat" / "arduino-gps.txt"
    cfg, note = choose_config(str(capture), None)
    assert cfg.vehicle.id == "survey-boat" and cfg.vehicle.vehicle_class == "rudder-boat"
    assert note.startswith("detected:") and note.endswith(": survey-boat-csv")
    assert cfg.inputs.throttle.channel == 1 and cfg.inputs.rudder.channel == 2
    cfg, note = choose_config(str(data / "nmea" / "gnss-compass.nmea"), None)
    assert cfg.vehicle.id == "vehicle" and "generic config" in note
    given = str(CONFIG_DIR / "survey-boat-csv.toml")
    for out, extra in (("detected", []), ("given", ["--config", given])):
        assert cli_main(["replay", str(capture), "--out", str(tmp_path / out),
                         "--no-plot", *extra]) == 0
    assert (tmp_path / "detected" / "estimates.csv").read_bytes() == \
        (tmp_path / "given" / "estimates.csv").read_bytes()
