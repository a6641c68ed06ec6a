"""Config files: every bundled file loads; a bad file names the key and what was expected."""

from __future__ import annotations

import pytest

from onboard.core import config
from onboard.core.config import ConfigError
from onboard.core.errors import UsageError


@pytest.mark.parametrize("name", config.bundled())
def test_every_bundled_config_loads(name):
    cfg = config.load(name)
    assert cfg.engine.rate_hz > 0


def test_vehicle_class_configs_exist():
    for name in ("rudder-boat", "twin-thruster-boat", "bluerov2", "torpedo-auv"):
        assert config.load(name).vehicle.vehicle_class == name


def test_twin_thruster_boat_uses_servo1_left_servo3_right():
    inputs = config.load("twin-thruster-boat").inputs
    assert (inputs.left.channel, inputs.right.channel) == (1, 3)


def test_torpedo_auv_convention():
    inputs = config.load("torpedo-auv").inputs
    assert inputs.propeller_rpm.source == "rpm" and inputs.propeller_rpm.channel == 1
    assert (inputs.rudder.channel, inputs.stern_plane.channel) == (1, 2)
    # +-500 us = +-15 deg
    assert inputs.rudder.half_range_us == 500
    assert inputs.rudder.full_scale == pytest.approx(0.2618, abs=1e-4)


@pytest.mark.parametrize(
    "text, expected",
    [
        ("[inputs]\nthrottle = { channel = 'three' }\n", "inputs.throttle.channel: expected int, got str"),
        ("[vehicle]\nclas = 'x'\n", "vehicle.clas: unknown key"),
        ("[vehicle]\nclass = 'boat'\n", "expected one of rudder-boat"),
        ("[engine]\nrate_hz = 'fast'\n", "engine.rate_hz: expected float"),
        ("[[service.sources]]\nkind = 'nmea'\n", "service.sources[0]: object missing required field url"),
        ("[vehicle\n", "not valid TOML"),
    ],
)
def test_bad_file_names_the_key(tmp_path, text, expected):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(ConfigError) as err:
        config.load(p)
    assert expected in str(err.value)
    assert str(p) in str(err.value)


def test_config_error_is_a_usage_error_so_the_cli_exits_2():
    assert issubclass(ConfigError, UsageError)


def test_missing_file_is_reported():
    with pytest.raises(ConfigError, match="no such config file"):
        config.load("/nonexistent/x.toml")


def test_pipeline_section_errors_name_the_pipeline_key():
    import msgspec

    class Section(msgspec.Struct, forbid_unknown_fields=True):
        order: int = 4

    cfg = config.from_dict({"pipelines": {"aie": {"order": "four"}}})
    with pytest.raises(ConfigError, match=r"pipelines\.aie\.order: expected int"):
        config.decode_section(cfg, "aie", Section)
    assert config.decode_section(config.Config(), "aie", Section).order == 4
