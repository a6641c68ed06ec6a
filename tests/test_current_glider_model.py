"""The current pipeline with a glider model (``[pipelines.current.glider]``) and the CSV and
input mapping a glider log needs: synthetic, no data files.

A glider that dives and climbs at 25 deg under a known current, its over-ground velocity
the model's through-water velocity plus the current: the pipeline must find the current,
along the track too (where, without a surge model, it publishes nothing), and drop the
glider model's measurement where the model cannot give the speed.
"""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest

import onboard.pipelines.current as current_mod
from onboard.core.config import CsvFormat, from_dict, load
from onboard.core.messages import (
    ActuatorColumn,
    ActuatorCommand,
    Attitude,
    Depth,
    Heading,
    VelocityOverGround,
)
from onboard.drivers.csvlog import CsvReader
from onboard.estimators.vehicle_models import GliderModel
from onboard.engine.inputs import InputMapper

CURRENT = (-0.2, 0.05)  # north, east (m/s)
GLIDER = {"lift_kl": 387.6, "lift_kl0": 0.0, "drag_kd0": 7.72, "drag_kd": 539.8,
          "water_density_kgm3": 1029.0, "neutral_pump_cc": 0.0,
          "vertical_water_std_mps": 0.02, "glide_angle_std_rad": 0.035,
          "min_glide_angle_rad": 0.21, "max_depth_interval_s": 30.0,
          "hold_s": 300.0}


def _config(glider: dict | None):
    data = msgspec.to_builtins(load("torpedo-auv"))
    sec: dict = {"identify": False, "dvl_velocity_std_mps": 0.1,
                 "current_walk_mps_rts": 0.01}
    if glider is not None:
        sec["glider"] = glider
    data["pipelines"] = {"current": sec}
    data["engine"] = {"rate_hz": 0.125}
    return from_dict(data)


def _yo(t: float) -> tuple[float, float, float]:
    """Pitch (rad), depth rate (m/s, down) and pump volume (cm^3) of a 10-minute
    dive/climb cycle at 25 deg, 0.2 m/s vertical (an unpowered Slocum)."""
    dive = (t // 600.0) % 2 == 0
    return (-0.436, 0.2, -250.0) if dive else (0.436, -0.2, 250.0)


def _run(glider: dict | None, duration: float = 2400.0, dt: float = 8.0):
    cfg = _config(glider)
    pipe = current_mod.create(cfg)
    model = GliderModel(k_l=387.6, k_d0=7.72, k_d=539.8, density=1029.0)
    depth, out = 50.0, []
    for k in range(int(duration / dt)):
        t = k * dt
        pitch, rate, pump = _yo(t)
        depth += rate * dt
        g = model.glide_from_depth_rate(pitch, rate, pump)
        assert g is not None
        samples = [
            Attitude(t=t, source="s", roll_rad=0.0, pitch_rad=pitch, yaw_rad=0.0,
                     yaw_rate_rps=0.0),
            Depth(t=t, source="s", depth_m=depth),
            ActuatorCommand(t=t, source="s", pump_cc=pump),
            VelocityOverGround(t=t, source="s", v_north_mps=g.u_h + CURRENT[0],
                               v_east_mps=CURRENT[1]),
        ]
        out.append((t, dict(pipe.step(t, samples))))
    return pipe, out


def test_glider_model_makes_the_along_track_current_known():
    pipe, out = _run(GLIDER)
    t, last = out[-1]
    # measured: north -0.2001, east 0.0500 (the model's own data), one-sigma 0.112 north
    # (the glide model's speed uncertainty, ~0.08 m/s at 25 deg) and 0.053 east
    assert last["north"] == pytest.approx(CURRENT[0], abs=0.02)
    assert last["east"] == pytest.approx(CURRENT[1], abs=0.02)
    assert last["std_north"] < 0.15 and last["std_east"] < 0.08
    assert pipe.samples.counters.glider_measurements == 299  # every tick but the first


def test_without_the_glider_model_the_along_track_current_is_unknown():
    _, out = _run(None, duration=800.0)
    assert "north" not in out[-1][1]  # heading north on a straight line: no surge model


def test_glider_model_declines_at_a_shallow_pitch():
    cfg = _config(GLIDER)
    pipe = current_mod.create(cfg)
    for k in range(5):
        t = 8.0 * k
        pipe.step(t, [Attitude(t=t, source="s", roll_rad=0.0, pitch_rad=0.05, yaw_rad=0.0,
                               yaw_rate_rps=0.0),
                      Depth(t=t, source="s", depth_m=20.0 + 0.01 * k),
                      VelocityOverGround(t=t, source="s", v_north_mps=0.3, v_east_mps=0.0)])
    assert pipe.samples.counters.glider_measurements == 0


def test_pump_and_battery_roles_read_their_columns():
    data = msgspec.to_builtins(load("torpedo-auv"))
    data["inputs"] = {
        "pump": {"source": "column", "column": "pump_vol", "neutral_us": 0.0,
                 "half_range_us": 1000.0, "full_scale": 1000.0},
        "battery": {"source": "column", "column": "batt_pos", "neutral_us": 0.0,
                    "half_range_us": 1.0, "full_scale": 1.0}}
    mapper = InputMapper(from_dict(data).inputs)
    a = mapper.map(ActuatorColumn(t=1.0, source="csv", column="pump_vol", value=-263.5))
    b = mapper.map(ActuatorColumn(t=1.0, source="csv", column="batt_pos", value=-0.008))
    assert a is not None and a.pump_cc == pytest.approx(-263.5)
    assert b is not None and b.battery_m == pytest.approx(-0.008)
    assert b.pump_cc == pytest.approx(-263.5)  # the other role keeps its value


def test_csv_earth_velocity_columns_and_heading_spikes(tmp_path):
    # headings 358, 2, 181 (a 0/360 interpolation artefact), 5, 190, 200, 205: the 181 is a
    # spike (its neighbours agree); 190 after 5 is a turn the next rows confirm
    heads = [358.0, 2.0, 181.0, 5.0, 190.0, 200.0, 205.0]
    path = tmp_path / "g.csv"
    path.write_text("time,yaw,r,roll,pitch,vn,ve\n" + "".join(
        f"{8 * i},{h},0,0,-25,0.7,0.1\n" for i, h in enumerate(heads)))
    fmt = CsvFormat(time="time", heading="yaw", heading_unit="deg", yaw_rate="r",
                    roll="roll", pitch="pitch", north_mps="vn", east_mps="ve",
                    heading_spike_deg=45.0)
    rd = CsvReader(path, fmt)
    samples = list(rd)
    got = [round(math.degrees(s.heading_rad)) for s in samples if isinstance(s, Heading)]
    assert got == [358, 2, 5, 190, 200, 205]
    assert sum(isinstance(s, Attitude) for s in samples) == 6
    assert rd.stats.rejected.get("heading_spike") == 1
    v = [s for s in samples if isinstance(s, VelocityOverGround)]
    assert len(v) == 7 and v[0].v_north_mps == 0.7 and v[0].v_east_mps == 0.1
    assert [s.t for s in samples] == sorted(s.t for s in samples)
    # off by default: every heading kept
    plain = list(CsvReader(path, CsvFormat(time="time", heading="yaw", heading_unit="deg")))
    assert len([s for s in plain if isinstance(s, Heading)]) == 7
    assert np.all(np.diff([s.t for s in plain]) >= 0)
