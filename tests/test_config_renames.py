"""Renamed configuration keys (onboard/core/config_renames.py): an old key is an error
that names its new one, in every file of a stacked ``--config``, on the command line (exit
2, one line) and in the web page's editor; never silently accepted. A service recording's
configuration, written by the program before a rename, is read under the new names."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
import typing
from pathlib import Path

import msgspec
import pytest

from onboard.core import config
from onboard.core.config import Config, ConfigError
from onboard.core.config_renames import RENAMED, migrate, renamed_key

EVERY_KEY = Path(__file__).parent / "data" / "config" / "every-key.toml"


def _nested(dotted: str, value: object) -> dict:
    """``{"a": {"b": value}}`` for ``"a.b"``."""
    *path, key = dotted.split(".")
    out: dict = {key: value}
    for part in reversed(path):
        out = {part: out}
    return out


def _schema_node(dotted: str) -> object | None:
    """The type a dotted key of a configuration file decodes into (its field's type, a
    Struct for a table); None when no field has that name."""
    node: object = Config
    for part in dotted.split("."):
        while not (isinstance(node, type) and issubclass(node, msgspec.Struct)):
            args = [a for a in typing.get_args(node) if a is not type(None)]
            if not args:
                return None
            node = args[0]
        hints = typing.get_type_hints(node)
        fields = {f.encode_name: f.name for f in msgspec.structs.fields(node)}
        if part not in fields:
            return None
        node = hints[fields[part]]
    return node


def test_every_old_key_is_an_error_naming_its_new_one():
    assert len(RENAMED) >= 80
    for old, new in RENAMED.items():
        with pytest.raises(ConfigError) as err:
            config.from_dict(_nested(old, {} if old == "pipelines.diagnose" else 1.0),
                             "my.toml")
        assert str(err.value) == f"my.toml: {old}: renamed to {new}"


def test_an_old_key_in_a_file_names_the_file_the_old_key_and_the_new_one(tmp_path):
    f = tmp_path / "my.toml"
    f.write_text("[pipelines.aie]\nnis_gate = 100.0\n")
    with pytest.raises(ConfigError) as err:
        config.load(f)
    assert str(err.value) == f"{f}: pipelines.aie.nis_gate: renamed to pipelines.aie.gate_nis"
    # beside its new key, the old one is still an error, not a value silently dropped
    f.write_text("[pipelines.current]\ninit_current_std = 0.5\n"
                 "initial_current_std_mps = 0.5\n")
    with pytest.raises(ConfigError, match="init_current_std: renamed to "
                                          "pipelines.current.initial_current_std_mps"):
        config.load(f)


def test_the_new_keys_decode_to_the_numbers_the_old_keys_set():
    cfg = config.from_dict({"pipelines": {
        "aie": {"gate_nis": 100.0, "gnss_position_std_m": 0.3},
        "current": {"hgo": {"gamma": 4.0, "identify": "always"},
                    "flow": {"pitch": True}, "current_walk_mps_rts": 0.03},
        "eseso": {"vehicle": {"mass_kg": 12.0}, "noise": {"adapt_updates": 10},
                  "initial": {"gravity_mps2": 9.8}}}})
    p = cfg.pipelines
    assert (p.aie.gate_nis, p.aie.gnss_position_std_m) == (100.0, 0.3)
    assert (p.current.hgo.gamma, p.current.hgo.identify, p.current.flow.pitch,
            p.current.current_walk_mps_rts) == (4.0, "always", True, 0.03)
    assert (p.eseso.vehicle.mass_kg, p.eseso.noise.adapt_updates,
            p.eseso.initial.gravity_mps2) == (12.0, 10, 9.8)


def test_each_file_of_a_stacked_config_is_checked_for_old_keys(tmp_path):
    base, overlay = tmp_path / "base.toml", tmp_path / "overlay.toml"
    base.write_text("[pipelines.aie]\ngate_nis = 100.0\n")
    overlay.write_text("[pipelines.eseso]\nmass_kg = 12.0\n")
    with pytest.raises(ConfigError) as err:
        config.load_all([base, overlay])
    assert str(err.value) == (f"{overlay}: pipelines.eseso.mass_kg: renamed to "
                              "pipelines.eseso.vehicle.mass_kg")
    # the old key in the first file, the overlay setting the new one: still the first
    # file's error (a later file never hides an earlier one's old key)
    base.write_text("[pipelines.kf]\nnis_gate = 100.0\n")
    overlay.write_text("[pipelines.kf]\ngate_nis = 50.0\n")
    with pytest.raises(ConfigError) as err:
        config.load_all([base, overlay])
    assert str(err.value) == f"{base}: pipelines.kf.nis_gate: renamed to pipelines.kf.gate_nis"


def test_an_old_key_on_the_command_line_exits_2_with_one_line(tmp_path):
    f = tmp_path / "old.toml"
    f.write_text("[pipelines.current]\nflow_pitch = true\n")
    log = tmp_path / "missing-is-not-reached.tlog"
    log.write_bytes(b"")
    r = subprocess.run([sys.executable, "-m", "onboard", "replay", str(log), "--config",
                        str(f), "--out", str(tmp_path / "out")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [
        f"onboard replay: {f}: pipelines.current.flow_pitch: renamed to "
        "pipelines.current.flow.pitch"]


def test_the_web_editor_refuses_an_old_key_naming_the_new_one(tmp_path):
    from onboard.service.web.config_edit import ConfigEditor

    source = "[[service.sources]]\nkind = 'nmea'\nurl = 'udp:0.0.0.0:10110'\n"
    path = tmp_path / "onboard.toml"
    path.write_text(source)
    editor = ConfigEditor([path], editable=True)
    assert editor.check(source + "[pipelines.aie]\nnis_gate = 100.0\n") == [
        f"{path}: pipelines.aie.nis_gate: renamed to pipelines.aie.gate_nis"]
    assert editor.check(source + "[pipelines.aie]\ngate_nis = 50.0\n") == []


def test_the_renames_lead_from_keys_that_are_gone_to_keys_of_the_schema():
    for old, new in RENAMED.items():
        assert _schema_node(old) is None, old
        assert _schema_node(new) is not None, new
    # negative control: the walk finds a live key and misses a made-up one
    assert _schema_node("pipelines.current.hgo.gamma") is not None
    assert _schema_node("pipelines.eseso.noise") is not None
    assert _schema_node("pipelines.current.hgo.gama") is None
    assert _schema_node("pipelines.aie.nis_gate") is None


def test_no_bundled_or_test_config_uses_an_old_key():
    repo = Path(__file__).resolve().parent.parent
    files = sorted([*(repo / "config").glob("*.toml"), *(repo / "tests").rglob("*.toml")])
    assert len(files) > 10
    for f in files:
        assert renamed_key(tomllib.loads(f.read_text())) is None, f


def _old_spelling(data: dict) -> dict:
    """``data`` with every key of :data:`RENAMED` moved back to its old place."""
    out = json.loads(json.dumps(data))
    for old, new in RENAMED.items():
        *new_path, new_key = new.split(".")
        node = out
        for part in new_path:
            node = node.get(part) if isinstance(node, dict) else None
        if not isinstance(node, dict) or new_key not in node:
            continue
        *old_path, old_key = old.split(".")
        target = out
        for part in old_path:
            target = target.setdefault(part, {})
        target[old_key] = node.pop(new_key)
    return out


def test_a_recordings_config_with_old_keys_is_read_under_the_new_names(tmp_path):
    from onboard.service.recorder import Recorder, recording_config

    cfg = config.load(EVERY_KEY)
    old = _old_spelling(config.to_dict(cfg))
    assert renamed_key(old) is not None  # the spelling of a recording made before
    assert config.from_dict(migrate(old)) == cfg
    rec = Recorder(tmp_path, meta={"vehicle": "v1", "config": old})
    rec.close()
    assert recording_config(tmp_path) == cfg
    # negative control: without the migration the old recording would not load
    with pytest.raises(ConfigError, match="renamed to"):
        config.from_dict(old)
