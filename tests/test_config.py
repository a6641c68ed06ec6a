"""Config files: every bundled file loads; a bad file names the key and what was expected."""

from __future__ import annotations

import msgspec
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
        ("[engine]\nrate_hz = 0\n", "engine.rate_hz: expected float > 0.0"),
        ("[service.mavlink]\nrate_hz = -5\n", "service.mavlink.rate_hz: expected float > 0.0"),
        ("[service]\nstate_save_interval_s = -1\n", "service.state_save_interval_s: expected float >= 0.0"),
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


@pytest.mark.parametrize("text, key", [("[engine]\nrate_hz = 0\n", "engine.rate_hz"),
                                       ("[engine]\nrate_hz = -5\n", "engine.rate_hz"),
                                       ("[service.mavlink]\nrate_hz = 0\n",
                                        "service.mavlink.rate_hz")])
def test_a_service_with_a_rate_of_zero_or_below_is_refused_before_it_starts(tmp_path, capsys,
                                                                            text, key):
    """A tick or output rate <= 0 (a service that says ready and never ticks, or one that
    ticks on every loop) is a config error: one line, exit 2, nothing started."""
    from onboard.cli import main as cli_main

    p = tmp_path / "bad.toml"
    p.write_text(text)
    assert cli_main(["run", "--config", str(p), "--state-dir", str(tmp_path / "st")]) == 2
    out = capsys.readouterr()
    assert out.err == f"onboard run: {p}: {key}: expected float > 0.0\n"
    assert out.out == "" and not (tmp_path / "st").exists()


def test_a_missing_extra_is_one_line_and_exit_2(monkeypatch, capsys):
    """A command whose optional extra is not installed (its import names the ``pip
    install``): one line, exit 2, no traceback; any other ImportError is a bug, raised."""
    import importlib

    from onboard.cli import main as cli_main

    def missing(name: str):
        raise ImportError("the simulator needs pymap3d: pip install 'onboard[sim]'")
    monkeypatch.setattr(importlib, "import_module", missing)
    assert cli_main(["sitl", "--list"]) == 2
    err = capsys.readouterr().err
    assert err == "onboard sitl: the simulator needs pymap3d: pip install 'onboard[sim]'\n"

    def broken(name: str):
        raise ImportError("cannot import name 'x' from 'onboard.sitl'")
    monkeypatch.setattr(importlib, "import_module", broken)
    with pytest.raises(ImportError):
        cli_main(["sitl", "--list"])


def test_missing_file_is_reported():
    with pytest.raises(ConfigError, match="no such config file"):
        config.load("/nonexistent/x.toml")


def test_pipeline_tables_are_decoded_when_the_config_loads():
    with pytest.raises(ConfigError, match=r"pipelines\.aie\.surge\.n_c: expected int"):
        config.from_dict({"pipelines": {"aie": {"surge": {"n_c": "four"}}}})
    cfg = config.from_dict({"pipelines": {"current": {"observer": "hgo"}}})
    assert cfg.pipelines.current.observer == "hgo"
    assert cfg.pipelines.aie == config.Config().pipelines.aie


@pytest.mark.parametrize("table, key", [
    ({"aei": {}}, "pipelines.aei"),
    ({"kf": {"adaptive": True}}, "pipelines.kf.adaptive"),
    ({"nav": {"stale_s": 2.0}}, "pipelines.nav.stale_s"),
    ({"eseso": {"mass_kgg": 3.0}}, "pipelines.eseso.mass_kgg"),
    ({"eseso": {"vehicle": {"mass_kgg": 3.0}}}, "pipelines.eseso.vehicle.mass_kgg"),
    ({"current": {"hgo": {"gama": 1.0}}}, "pipelines.current.hgo.gama"),
    ({"current": {"flow": {"pitch_rad": 1.0}}}, "pipelines.current.flow.pitch_rad"),
])
def test_unknown_pipeline_name_or_key_is_an_error_naming_the_file_and_key(tmp_path, table,
                                                                           key):
    """A key that never existed (a renamed one names its new one: test_config_renames.py)."""
    import tomllib

    f = tmp_path / "overlay.toml"
    f.write_text(_toml({"pipelines": table}))
    assert tomllib.loads(f.read_text()) == {"pipelines": table}
    with pytest.raises(ConfigError) as err:
        config.load(f)
    assert str(err.value) == f"{f}: {key}: unknown key (misspelt?)"


def _toml(data: dict, prefix: str = "") -> str:
    """A small TOML writer for nested tables of numbers, booleans and empty tables."""
    scalars = {k: v for k, v in data.items() if not isinstance(v, dict)}
    out = [f"[{prefix}]"] if prefix and (scalars or not data) else []
    out += [f"{k} = {str(v).lower() if isinstance(v, bool) else v}" for k, v in scalars.items()]
    for k, v in data.items():
        if isinstance(v, dict):
            out.append(_toml(v, f"{prefix}.{k}" if prefix else k))
    return "\n".join(out)


def test_kf_defaults_are_the_aie_models_and_its_own_tuned_noise():
    """``[pipelines.kf]`` was split off ``[pipelines.aie]``: it shares the axis models and
    the measurement handling, and has its own noise parameters from the one tuning
    protocol (docs/aie.md section 2.1): ``v_d`` "auto" (the pair tuned with and without
    the Doppler speed, section 2.2) and the tuned ``bias_q``."""
    from onboard.core.pipeline_config import (
        AUTO, KF_HEADING_V_D, KF_SURGE_V_D, AieConfig, KfConfig, SurgeHeadingConfig)

    aie, kf = AieConfig(), KfConfig()
    for name in SurgeHeadingConfig.__struct_fields__:
        assert getattr(kf, name) == getattr(aie, name), name
    for axis in ("surge", "heading"):
        a, k = getattr(aie, axis), getattr(kf, axis)
        assert (k.a, k.gain, k.offset, k.u_max, k.q_v) == (a.a, a.gain, a.offset, a.u_max,
                                                           a.q_v), axis
        assert k.v_d == AUTO
    assert kf.surge.tuned("v_d", True) == KF_SURGE_V_D.pick(True)
    assert kf.heading.tuned("v_d", False) == KF_HEADING_V_D.pick(False)
    assert (kf.surge.bias_q, kf.heading.bias_q) == (0.00086, 7.4e-5)


def test_diagnose_settings_are_a_top_level_table():
    cfg = config.from_dict({"diagnose": {"known": {"surge_yaw_coupling": [0.2]},
                                         "holdout_metric": "ground_velocity_rmse_mps",
                                         "rate_hz": 5.0, "declared": ["sideslip"],
                                         "base_terms": ["none"]}})
    assert cfg.diagnose.known == {"surge_yaw_coupling": [0.2]}
    assert cfg.diagnose.rate_hz == 5.0 and cfg.diagnose.declared == ["sideslip"]
    assert config.Config().diagnose.base_terms == []


@pytest.mark.parametrize("name", ["nav", "aie", "kf", "current"])
def test_enabled_false_leaves_a_pipeline_out(name):
    from onboard.pipelines import build

    on = {p.name for p in build(config.load("rudder-boat"))}
    assert name in on
    off = config.from_dict({"vehicle": {"class": "rudder-boat"},
                            "pipelines": {name: {"enabled": False}}})
    assert {p.name for p in build(off)} == on - {name}


def test_eseso_enabled_true_builds_it_for_any_class_and_false_never():
    from onboard.pipelines import build

    assert "eseso" not in {p.name for p in build(config.load("rudder-boat"))}
    assert "eseso" in {p.name for p in build(config.load("bluerov2"))}
    anyclass = config.from_dict({"vehicle": {"class": "rudder-boat"},
                                 "pipelines": {"eseso": {"enabled": True}}})
    assert "eseso" in {p.name for p in build(anyclass)}
    never = config.from_dict({"vehicle": {"class": "bluerov2"},
                              "pipelines": {"eseso": {"enabled": False}}})
    assert "eseso" not in {p.name for p in build(never)}



def test_every_key_of_the_key_catalogue_reaches_its_field():
    """tests/data/config/every-key.toml sets the keys no behavioural test sets, each to a
    value other than its default: every one is decoded into its field with that value."""
    import tomllib
    from pathlib import Path

    path = Path(__file__).parent / "data" / "config" / "every-key.toml"
    data = tomllib.loads(path.read_text())
    cfg, default = config.load(path), config.Config()

    def leaves(table, prefix=()):
        for k, v in table.items():
            if isinstance(v, dict):
                yield from leaves(v, (*prefix, k))
            elif isinstance(v, list) and v and isinstance(v[0], dict):
                for i, item in enumerate(v):
                    yield from leaves(item, (*prefix, k, i))
            else:
                yield (*prefix, k), v

    def get(node, key):
        if isinstance(key, int):
            return node[key] if node is not None else None
        field = next(f.name for f in msgspec.structs.fields(node) if f.encode_name == key)
        return getattr(node, field)

    n = 0
    for key, value in leaves(data):
        node, base = cfg, default
        for part in key:
            node = get(node, part)
            base = get(base, part) if base is not None and not (
                isinstance(part, int) and part >= len(base)) else None
        assert node == value, key
        assert node != base, key
        n += 1
    assert n > 80
