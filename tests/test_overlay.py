"""Config overlays (``--config base --config overlay``), the ``[corrections]`` the engine
applies to validated samples, and the overlay ``onboard diagnose --write-config`` writes.

The diagnose -> overlay -> replay round trip on a simulated log is in
tests/test_diagnose_roundtrip.py.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from onboard.cli import build_parser, main
from onboard.offline.closure import overlay
from onboard.core import config
from onboard.core.config import ConfigError
from onboard.core.messages import Attitude, GnssFix, Heading, Imu
from onboard.engine.corrections import SampleCorrector
from onboard.engine import Engine, TickQueue

# ----------------------------------------------------------------------------- merging


def _write(tmp_path, name: str, text: str):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_merge_tables_recursively_lists_replaced_later_wins():
    base = {"a": {"x": 1, "y": {"p": 1, "q": 2}}, "l": [1, 2, 3], "s": "base"}
    over = {"a": {"y": {"q": 20}}, "l": [9], "s": "over"}
    assert config.merge(base, over) == {"a": {"x": 1, "y": {"p": 1, "q": 20}},
                                        "l": [9], "s": "over"}
    assert base["a"]["y"]["q"] == 2  # inputs untouched


def test_single_config_is_exactly_load(tmp_path):
    assert config.load_all(["rudder-boat"]) == config.load("rudder-boat")
    assert config.load_all("rudder-boat") == config.load("rudder-boat")


def test_overlay_changes_only_its_keys(tmp_path):
    over = _write(tmp_path, "o.toml", "[inputs.throttle]\nchannel = 4\n"
                  "[corrections]\ngnss_latency_s = 0.5\n[pipelines.aie.surge]\ngain = 2.5\n")
    base = config.load("rudder-boat")
    cfg = config.load_all(["rudder-boat", str(over)])
    assert cfg.inputs.throttle.channel == 4
    # the rest of the inline table [inputs.throttle] kept from the base
    assert cfg.inputs.throttle.half_range_us == base.inputs.throttle.half_range_us
    assert cfg.inputs.rudder == base.inputs.rudder
    assert cfg.corrections.gnss_latency_s == 0.5
    assert cfg.pipelines.aie.surge.gain == 2.5
    assert cfg.pipelines.aie.surge.a == base.pipelines.aie.surge.a
    assert cfg.vehicle == base.vehicle and cfg.sensors == base.sensors


def test_three_layers_apply_in_order(tmp_path):
    a = _write(tmp_path, "a.toml", "[corrections]\nheading_offset_rad = 0.1\n")
    b = _write(tmp_path, "b.toml", "[corrections]\nheading_offset_rad = 0.2\n")
    assert config.load_all(["rudder-boat", a, b]).corrections.heading_offset_rad == 0.2
    assert config.load_all(["rudder-boat", b, a]).corrections.heading_offset_rad == 0.1


def test_unknown_key_in_an_overlay_names_that_file(tmp_path):
    bad = _write(tmp_path, "bad.toml", "[corrections]\ngnss_latency = 0.5\n")
    with pytest.raises(ConfigError) as err:
        config.load_all(["rudder-boat", bad])
    assert str(bad) in str(err.value)
    assert "corrections.gnss_latency: unknown key" in str(err.value)


def test_conflict_only_visible_after_merging_is_named(tmp_path):
    a = _write(tmp_path, "a.toml", "[corrections]\nheading_harmonics_sin = [0.1]\n")
    b = _write(tmp_path, "b.toml", "[corrections]\nheading_deviation_table = [[0, 1], [180, -1]]\n")
    with pytest.raises(ConfigError, match="one deviation model only") as err:
        config.load_all(["rudder-boat", a, b])
    assert "a.toml + " in str(err.value)


def test_latency_beyond_the_sample_age_is_a_clear_error():
    with pytest.raises(ConfigError, match="must be below engine.max_sample_age_s"):
        config.from_dict({"corrections": {"gnss_latency_s": 2.5}})


def test_cli_config_is_repeatable_and_single_config_unchanged():
    p = build_parser()
    for cmd in ("replay", "diagnose"):
        args = p.parse_args([cmd, "log.tlog", "--config", "a.toml", "--config", "b.toml"])
        assert args.config == ["a.toml", "b.toml"]
        assert p.parse_args([cmd, "log.tlog", "--config", "a.toml"]).config == ["a.toml"]
        assert p.parse_args([cmd, "log.tlog"]).config is None
    assert p.parse_args(["run", "--config", "a", "--config", "b"]).config == ["a", "b"]
    args = p.parse_args(["diagnose", "x.tlog", "--write-config", "o.toml"])
    assert args.write_config == "o.toml"


def test_cli_bad_overlay_exits_2_with_one_line(tmp_path, capsys):
    log = tmp_path / "x.csv"
    log.write_text("t,heading\n0,1\n")
    bad = _write(tmp_path, "bad.toml", "[corrections]\nnope = 1\n")
    assert main(["replay", str(log), "--config", "rudder-boat", "--config", str(bad),
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "corrections.nope: unknown key" in err


@pytest.mark.parametrize("command", ["replay", "run", "diagnose"])
@pytest.mark.parametrize("table, message", [
    # a misspelt pipeline, a misspelt key
    ("[pipelines.aei]\nstep_s = 0.1\n", "pipelines.aei: unknown key (misspelt?)"),
    ("[pipelines.kf.surge]\ngian = 2.0\n", "pipelines.kf.surge.gian: unknown key (misspelt?)"),
    # renamed keys and tables name their new one (onboard/core/config_renames.py)
    ("[pipelines.aie.surge]\nkf_v_d = 2.0\n",
     "pipelines.aie.surge.kf_v_d: renamed to pipelines.kf.surge.v_d"),
    ("[pipelines.diagnose]\nrate_hz = 5.0\n", "pipelines.diagnose: renamed to diagnose"),
    ("[pipelines.aie]\nnis_gate = 100.0\n",
     "pipelines.aie.nis_gate: renamed to pipelines.aie.gate_nis"),
])
def test_cli_bad_pipeline_table_in_an_overlay_exits_2_naming_file_and_key(
        tmp_path, capsys, command, table, message):
    log = tmp_path / "x.csv"
    log.write_text("t,heading\n0,1\n")
    bad = _write(tmp_path, "overlay.toml", table)
    stack = ["--config", "rudder-boat", "--config", str(bad)]
    argv = [command, *stack] if command == "run" else \
        [command, str(log), *stack, "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert f"{bad}: {message}" in err


def test_run_reports_the_overlay_chain_in_its_errors(tmp_path):
    from onboard.service import daemon

    over = _write(tmp_path, "o.toml", "[corrections]\ngnss_latency_s = 0.2\n")
    with pytest.raises(ConfigError, match=r"rudder-boat \+ .*o.toml: service.sources is empty"):
        daemon.main(SimpleNamespace(config=["rudder-boat", str(over)], state_dir=None))


# ------------------------------------------------------------------------- corrections


def _corrector(**kw) -> SampleCorrector:
    return SampleCorrector(config.from_dict({"corrections": kw}).corrections)


def test_no_corrections_no_corrector_in_the_engine():
    assert Engine(config.load("rudder-boat")).correct is None
    assert isinstance(Engine(config.load("rudder-boat")).queue, TickQueue)


def test_gnss_fix_restamped_earlier():
    c = _corrector(gnss_latency_s=0.6)
    fix = GnssFix(t=10.0, lat_deg=1.0, lon_deg=2.0)
    assert c(fix).t == pytest.approx(9.4)
    h = Heading(t=10.0, heading_rad=1.0)
    assert c(h) is h  # nothing else changes


def test_gyro_bias_subtracted_from_imu_and_attitude_rates():
    c = _corrector(gyro_bias_rps=[0.001, -0.002, 0.01])
    imu = c(Imu(t=0, accel_x=0, accel_y=0, accel_z=-9.8, gyro_x=0.1, gyro_y=0.2, gyro_z=0.3))
    assert (imu.gyro_x, imu.gyro_y, imu.gyro_z) == pytest.approx((0.099, 0.202, 0.29))
    att = c(Attitude(t=0, roll_rad=0, pitch_rad=0, yaw_rad=1.0, yaw_rate_rps=0.3))
    assert att.yaw_rate_rps == pytest.approx(0.29) and att.yaw_rad == 1.0
    assert att.roll_rate_rps is None


@pytest.mark.parametrize("amp, phase", [(0.12, 0.7), (0.1, -1.0), (0.2, 2.5)])
def test_compass_deviation_inverted_at_every_heading(amp, phase):
    c = _corrector(heading_harmonics_sin=[amp * math.cos(phase)],
                   heading_harmonics_cos=[amp * math.sin(phase)], heading_offset_rad=0.05)
    for true in np.linspace(0.0, 2 * math.pi, 73)[:-1]:
        measured = (true + 0.05 + amp * math.sin(true + phase)) % (2 * math.pi)
        got = c(Heading(t=0, heading_rad=measured)).heading_rad
        # three fixed-point rounds: error ~ amp^4
        assert abs(math.remainder(got - true, 2 * math.pi)) < 4 * amp ** 4 + 1e-9
        yaw = c(Attitude(t=0, roll_rad=0, pitch_rad=0,
                         yaw_rad=math.remainder(measured, 2 * math.pi))).yaw_rad
        assert -math.pi <= yaw < math.pi
        assert abs(math.remainder(yaw - true, 2 * math.pi)) < 4 * amp ** 4 + 1e-9


def test_deviation_card_interpolated_periodically():
    c = _corrector(heading_deviation_table=[[0, 2.0], [90, 4.0], [180, -2.0], [270, -4.0]])
    assert math.degrees(c.heading_error(math.radians(45))) == pytest.approx(3.0)
    assert math.degrees(c.heading_error(math.radians(315))) == pytest.approx(-1.0)
    assert math.degrees(c.heading_error(math.radians(-45))) == pytest.approx(-1.0)
    assert math.degrees(c.heading_error(math.radians(0))) == pytest.approx(2.0)


def test_heading_sources_limit_the_heading_correction():
    c = _corrector(heading_offset_rad=0.1, heading_sources=["compass"])
    assert c(Heading(t=0, source="compass", heading_rad=1.0)).heading_rad == pytest.approx(0.9)
    assert c(Heading(t=0, source="gnss-hdt", heading_rad=1.0)).heading_rad == 1.0


# ----------------------------------------------------------------------- the overlay


def _doc(*effects, base_params=None):
    return {"log": "x.tlog", "holdout_metric": "ground_velocity_rmse_mps",
            "holdout_error_before": 0.2, "holdout_error_after": 0.1,
            "base_params": base_params or {"x_p": 0.1},
            "effects": [{"name": n, "detected": True, "params": p,
                         "evidence": {"std": s}} for n, p, s in effects]}


def test_overlay_corrections_from_the_vocabulary(tmp_path):
    doc = _doc(("gps_latency", {"seconds": 0.57}, {"seconds": 0.06}),
               ("gyro_bias", {"bias": 0.0104}, {"bias": 0.0005}),
               ("heading_bias", {"bias": -0.05}, {"bias": 0.001}),
               ("compass_deviation", {"amplitude": 0.12, "phase": 0.7},
                {"amplitude": 0.007, "phase": 0.05}))
    base = config.from_dict({"corrections": {"gnss_latency_s": 0.1,
                                             "gyro_bias_rps": [0.0, 0.0, 0.001]}})
    text = overlay.overlay_text(doc, base)
    p = _write(tmp_path, "o.toml", text)
    c = config.load_all([_write(tmp_path, "b.toml", "[corrections]\ngnss_latency_s = 0.1\n"
                               "gyro_bias_rps = [0.0, 0.0, 0.001]\n"), p]).corrections
    assert c.gnss_latency_s == pytest.approx(0.67)          # added to the base's
    assert c.gyro_bias_rps == pytest.approx([0, 0, 0.0114])
    assert c.heading_offset_rad == pytest.approx(-0.05)
    # amplitude sin(psi + phase) as harmonics, the error the corrector then removes
    corr = SampleCorrector(c)
    for psi in (0.0, 1.0, 4.0):
        assert corr.heading_error(psi) == pytest.approx(-0.05 + 0.12 * math.sin(psi + 0.7),
                                                        abs=1e-5)
    assert "deviation card" in text and "+- 0.06 s" in text
    assert "deg" in text


def test_overlay_swaps_and_reverses_the_thruster_channels(tmp_path):
    base = config.load("twin-thruster-boat")
    doc = _doc(("actuator_mapping", {"swapped": True, "reversed_left": True,
                                     "reversed_right": False}, {}))
    p = _write(tmp_path, "o.toml", overlay.overlay_text(doc, base))
    cfg = config.load_all(["twin-thruster-boat", p])
    assert cfg.inputs.from_autopilot is False
    assert cfg.inputs.left.channel == base.inputs.right.channel
    assert cfg.inputs.left.reverse == base.inputs.right.reverse
    assert cfg.inputs.right.channel == base.inputs.left.channel
    assert cfg.inputs.right.reverse is (not base.inputs.left.reverse)


def test_overlay_surge_model_and_thrust_curve(tmp_path):
    doc = _doc(("thrust_nonlinearity", {"quadratic_gain": 1.0, "reverse_gain": 0.0}, {}),
               base_params={"a": 1.0, "b": 2.0, "c0": 0.1, "x_p": 0.1})
    c = np.linspace(0.0, 1.0, 101)
    sel = SimpleNamespace(final_fit=SimpleNamespace(theta={"thrust_nonlinearity":
                                                           np.array([1.0, 0.0])}),
                          final_split=SimpleNamespace(fit=SimpleNamespace(cmd_surge=c)))
    p = _write(tmp_path, "o.toml", overlay.overlay_text(doc, config.load("rudder-boat"), sel))
    pipelines = config.load_all(["rudder-boat", p]).pipelines
    surge = pipelines.aie.surge
    # the least-squares line of 2c + c^2 + 0.1 over the commands flown (c in [0, 1]:
    # slope 3, intercept near 0.1 - 1/6)
    slope, icpt = np.polyfit(c, 2 * c + c * c + 0.1, 1)
    assert surge.a == pytest.approx(1.0)
    assert surge.gain == pytest.approx(slope, rel=1e-5) and slope == pytest.approx(3.0)
    assert surge.offset == pytest.approx(icpt, rel=1e-5)
    # the KF baseline gets the same model
    kf = pipelines.kf.surge
    assert (kf.a, kf.gain, kf.offset) == (surge.a, surge.gain, surge.offset)
    assert icpt == pytest.approx(0.1 - 1 / 6, abs=3e-3)
    assert "thrust curve" in p.read_text()


def test_overlay_current_prior_and_what_it_cannot_write(tmp_path):
    doc = _doc(("water_current", {"north": 0.25, "east": -0.15}, {"north": 0.01, "east": 0.01}),
               ("sideslip", {"k": 0.05}, {"k": 0.01}))
    doc["effects"].append({"name": "unexplained", "detected": True, "params": {},
                           "evidence": {"heading": {"regressor": "heading harmonic 2"}}})
    text = overlay.overlay_text(doc, config.load("rudder-boat"))
    cfg = config.load_all(["rudder-boat", _write(tmp_path, "o.toml", text)])
    assert cfg.pipelines.current.initial_current_std_mps == pytest.approx(
        math.hypot(0.25, 0.15) + 3 * math.hypot(0.01, 0.01), abs=1e-3)
    assert "no config key the pipelines read: sideslip" in text
    assert "heading: heading harmonic 2" in text


def test_overlay_of_a_detected_config_stands_alone(tmp_path):
    det = config.load("twin-thruster-boat")
    text = overlay.overlay_text(_doc(), det, detected=True)
    cfg = config.load_all([_write(tmp_path, "o.toml", text)])
    assert cfg.vehicle == det.vehicle
    assert cfg.inputs == det.inputs


# ------------------------------------------------------------------ checking the overlay

from pathlib import Path  # noqa: E402

from onboard.offline.closure import overlay_check  # noqa: E402
from onboard.offline.replay import choose_config  # noqa: E402

GOLDEN_LOG = str(Path(__file__).parent / "data" / "replay" / "jaiabot-turns.tlog")


class _Part:
    """The test part of a fake selection: ticks ``t`` (s) with run labels."""

    def __init__(self, t, run, dt=0.1):
        self.t, self.run, self.dt = np.asarray(t, float), np.asarray(run, dtype=object), dt

    def __len__(self):
        return len(self.t)


def _whole_log_selection():
    """A selection whose test part is the whole golden log (its ticks are all scored)."""
    t = np.array([-1.0e12, 0.0, 1.0e12])
    return SimpleNamespace(split=SimpleNamespace(test=_Part(t, ["x"] * 3, dt=1.0e12)))


def test_held_out_ranges_merge_adjacent_blocks_and_keep_runs_apart():
    t = np.r_[np.arange(0.0, 10.0, 0.1), np.arange(10.0, 20.0, 0.1), np.arange(50.0, 60.0, 0.1)]
    run = ["a@1"] * 100 + ["a@2"] * 100 + ["b"] * 100
    sel = SimpleNamespace(split=SimpleNamespace(test=_Part(t, run)))
    ranges = overlay_check.held_out_ranges(sel)
    assert [(round(a, 1), round(b, 1)) for a, b in ranges] == [(0.0, 19.9), (50.0, 59.9)]


def test_implausible_surge_model_is_refused_with_the_parameter_named():
    # The BlueBoat folder's surge fit (issue 22): a 17 s time constant, but a top speed
    # of 51.9 m/s at full command.
    why = overlay_check.implausible("pipelines.aie.surge",
                                    {"a": 0.0582, "gain": 2.9652, "offset": 0.0572})
    assert why is not None and "51.9 m/s" in why and "10 m/s" in why
    why = overlay_check.implausible("pipelines.kf.surge", {"a": 0.01, "gain": 0.01})
    assert why is not None and "pipelines.kf.surge.a" in why and "100 s" in why
    assert overlay_check.implausible("pipelines.aie.heading", {"a": 2.0, "gain": 20.0})
    assert overlay_check.implausible("pipelines.aie.surge", {"a": 1.0, "gain": 3.0}) is None
    assert overlay_check.implausible("corrections", {"gnss_latency_s": 0.5}) is None


def test_a_section_that_lowers_the_held_out_error_is_written_one_that_raises_it_is_not():
    # Base: the golden Jaiabot log read with a planted 1 s GNSS latency (wrong: the
    # simulator has none). Good section: latency 0; bad section: latency 1 s again;
    # implausible section: a 100 s surge time constant.
    base, _ = choose_config(GOLDEN_LOG, None)
    base = overlay_check.with_layer(base, {"corrections": {"gnss_latency_s": 1.0}})
    sections = [
        overlay.Section("good", {"corrections": {"gnss_latency_s": 0.0}}),
        overlay.Section("bad", {"corrections": {"gnss_latency_s": 1.0}}),
        overlay.Section("implausible", {"pipelines.aie.surge": {"a": 0.01, "gain": 0.05}}),
        overlay.Section("needs bad", {"pipelines.kf.surge": {"a": 1.0, "gain": 3.0}},
                        needs=("bad",)),
    ]
    v = {x.section: x for x in overlay_check.check(sections, GOLDEN_LOG, base,
                                                   _whole_log_selection())}
    # measured (each filter's speed predicted for the next fix): aie 0.192 -> 0.111
    # m/s, kf 0.211 -> 0.125 m/s (0.168 -> 0.071 and 0.124 -> 0.027 against the speed
    # after each fix, before 2026-12-01)
    assert v["good"].written
    assert v["good"].after["aie"] < v["good"].before["aie"] - 0.05
    assert v["good"].after["kf"] < v["good"].before["kf"] - 0.05
    # judged on top of the good one: aie 0.111 -> 0.192 m/s
    assert not v["bad"].written and "raises" in v["bad"].reason
    assert v["bad"].before == v["good"].after
    assert not v["implausible"].written and "time constant" in v["implausible"].reason
    assert not v["needs bad"].written and "bad" in v["needs bad"].reason
    entry = v["bad"].as_dict()
    assert set(entry) == {"section", "written", "reason", "speed_rmse_before_mps",
                          "speed_rmse_after_mps"}


def test_a_noise_that_makes_the_filters_follow_the_receiver_is_refused():
    """The golden log's Doppler noise is 0.1 m/s, as its config declares. A section that
    declares it ten times smaller makes aie and kf follow each fix: their speed after the
    fix is then 0.084 -> 0.019 m/s (aie) and 0.111 -> 0.042 (kf) from the fix's, which a
    score against the fix they fused (the check before 2026-12-01) took for a better
    filter. Their speed predicted before each fix is worse, aie 0.111 -> 0.128 m/s:
    refused. Declaring it five times larger is refused too (kf 0.125 -> 0.204)."""
    base, _ = choose_config(GOLDEN_LOG, None)
    assert base.sensors.gnss.velocity_std_mps == 0.1
    sections = [overlay.Section("understated", {"sensors.gnss": {"velocity_std_mps": 0.01}}),
                overlay.Section("overstated", {"sensors.gnss": {"velocity_std_mps": 0.5}})]
    v = {x.section: x for x in overlay_check.check(sections, GOLDEN_LOG, base,
                                                   _whole_log_selection())}
    assert not v["understated"].written and "aie" in v["understated"].reason
    assert v["understated"].after["aie"] > v["understated"].before["aie"] + 0.01
    assert not v["overstated"].written and "kf" in v["overstated"].reason


def test_a_section_is_judged_together_with_the_section_fitted_on_it():
    # As the re-mapped inputs and the surge model fitted on them: "remap" alone (a 1.5 s
    # latency on the planted 1 s) raises the error, with "fitted" (latency 0 over it) the
    # pair lowers it; both are written. Its negative: with "fitted" implausible, "remap"
    # is judged alone and refused.
    base, _ = choose_config(GOLDEN_LOG, None)
    base = overlay_check.with_layer(base, {"corrections": {"gnss_latency_s": 1.0}})
    remap = overlay.Section("remap", {"corrections": {"gnss_latency_s": 1.5}})
    fitted = overlay.Section("fitted", {"corrections": {"gnss_latency_s": 0.0}},
                             needs=("remap",))
    v = {x.section: x for x in overlay_check.check([remap, fitted], GOLDEN_LOG, base,
                                                   _whole_log_selection())}
    assert list(v) == ["remap", "fitted"]
    assert v["remap"].written and v["fitted"].written
    assert "judged together" in v["remap"].reason
    assert v["remap"].after["kf"] < v["remap"].before["kf"] - 0.05
    implausible = overlay.Section("fitted", {"pipelines.aie.surge": {"a": 0.01, "gain": 0.05}},
                                  needs=("remap",))
    v = {x.section: x for x in overlay_check.check([remap, implausible], GOLDEN_LOG, base,
                                                   _whole_log_selection())}
    assert list(v) == ["remap", "fitted"]
    assert not v["remap"].written and "raises" in v["remap"].reason
    assert "judged together" not in v["remap"].reason
    assert not v["fitted"].written and "time constant" in v["fitted"].reason


def test_overlay_text_writes_a_refused_section_as_a_comment_only():
    doc = _doc(("heading_bias", {"bias": -0.05}, {"bias": 0.001}))
    cfg = config.load("rudder-boat")
    names = [s.name for s in overlay.sections(doc, cfg) if s.tables]
    assert "corrections" in names
    text = overlay.overlay_text(doc, cfg, refused={"corrections": "raises it"})
    assert "[corrections]" not in text and "# NOT WRITTEN: raises it" in text
    assert "[corrections]" in overlay.overlay_text(doc, cfg)


def test_signed_ground_speed_is_negative_going_astern():
    ahead = {"speed": 1.0, "v_north": 1.0, "v_east": 0.0, "heading": 0.1}
    astern = {"speed": 1.0, "v_north": -1.0, "v_east": 0.0, "heading": 0.1}
    assert overlay_check.signed_ground_speed(ahead) == 1.0
    assert overlay_check.signed_ground_speed(astern) == -1.0
    assert overlay_check.signed_ground_speed({"speed": 0.5}) == 0.5
    assert overlay_check.signed_ground_speed({"heading": 0.0}) is None
