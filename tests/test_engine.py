"""The engine: validation with counted reasons, fixed-rate ticks, determinism."""

from __future__ import annotations

import math

import msgspec

from onboard.core.config import Config, from_dict
from onboard.core.geo import LocalFrame
from onboard.core.messages import (
    ActuatorCommand,
    ActuatorOutputs,
    Depth,
    GnssFix,
    HealthRecord,
    Heading,
    Imu,
    Innovation,
    Pressure,
    Sample,
)
from onboard.engine import Engine, run
from onboard.pipelines.base import NoHealth, PipelineDefaults


class Steps(msgspec.Struct, frozen=True):
    """The health of :class:`Recorder`: its ticks."""

    steps: int

    def flat(self) -> dict[str, float]:
        return {"x.steps": float(self.steps)}


class Recorder(PipelineDefaults):
    """A pipeline that remembers what it was given (to test the engine's contract)."""

    name = "rec"
    columns = ("n",)

    def __init__(self):
        self.calls: list[tuple[float, list[Sample]]] = []

    def step(self, t, samples):
        self.calls.append((t, list(samples)))
        return {"n": float(len(samples))}

    def innovations(self):
        """One update per tick: accepted (NIS 1) on odd ticks, rejected on even ones."""
        n = len(self.calls)
        return [Innovation(channel="x", t=float(n), z=(2.0,), S=(4.0,), nis=1.0, dof=1,
                           gate=4.0, accepted=n % 2 == 1, reason="" if n % 2 else "gate")]

    def health(self):
        return Steps(len(self.calls))

    def get_state(self):
        return {"k": len(self.calls)}

    def set_state(self, state):
        self.restored = state


def fix(t, lat=48.0, lon=-124.0, **kw):
    return GnssFix(t=t, lat_deg=lat, lon_deg=lon, **kw)


def imu(t, ax=0.0):
    return Imu(t=t, accel_x=ax, accel_y=0.0, accel_z=-9.81, gyro_x=0.0, gyro_y=0.0, gyro_z=0.0)


def test_each_tick_sees_exactly_the_samples_up_to_its_time():
    rec = Recorder()
    eng = Engine(Config(), [rec])
    samples = [fix(100.0), imu(100.05), imu(100.1), imu(100.15), fix(100.25)]
    run(eng, samples, lambda t, r: None)
    ticks = [t for t, _ in rec.calls]
    assert ticks == [100.0, 100.1, 100.2, 100.3]
    for t, batch in rec.calls:
        assert all(s.t <= t for s in batch)
    assert sum(len(b) for _, b in rec.calls) == len(samples)


def test_rejections_are_counted_with_reasons():
    eng = Engine(Config(), [Recorder()])
    assert not eng.push(imu(float("nan")))
    assert not eng.push(imu(10.0, ax=float("inf")))
    assert not eng.push(fix(10.0, lat=123.0))
    assert not eng.push(imu(0.0))
    assert eng.push(imu(10.0))
    assert not eng.push(imu(9.0))  # backwards for the same source
    assert not eng.push(fix(20.0, fix_quality=0))
    assert eng.push(imu(20.0))
    assert not eng.push(Heading(t=5.0, heading_rad=0.1))  # 15 s older than the newest
    assert not eng.push(imu(200.0), now=100.0)  # from the future, live
    assert dict(eng.rejected) == {
        "imu:nan": 2, "gnss:range": 1, "imu:zero_time": 1, "imu:backwards": 1,
        "gnss:no_fix": 1, "heading:late": 1, "imu:future": 1,
    }


def test_gnss_is_rejected_while_submerged_and_accepted_at_the_surface():
    eng = Engine(Config(), [Recorder()])
    assert eng.push(Depth(t=1.0, depth_m=5.0))
    assert eng.mode == "submerged"
    assert not eng.push(fix(1.1))
    assert eng.push(Depth(t=2.0, depth_m=0.1))
    assert eng.push(fix(2.1))
    assert eng.rejected["gnss:submerged"] == 1


def test_pressure_becomes_depth():
    rec = Recorder()
    eng = Engine(Config(), [rec])
    eng.push(Pressure(t=1.0, pressure_pa=101325.0 + 1025.0 * 9.80665 * 10.0))
    eng.tick(1.0)
    (depth,) = rec.calls[0][1]
    assert isinstance(depth, Depth) and math.isclose(depth.depth_m, 10.0, rel_tol=1e-9)
    assert eng.mode == "submerged"


def test_raw_pwm_is_mapped_to_a_normalized_command():
    cfg = from_dict({"inputs": {
        "throttle": {"channel": 3, "neutral_us": 1500, "half_range_us": 500},
        "rudder": {"channel": 1, "neutral_us": 1500, "half_range_us": 500, "full_scale": 0.5}}})
    rec = Recorder()
    eng = Engine(cfg, [rec])
    eng.push(ActuatorOutputs(t=1.0, pwm_us=(1750.0, 0.0, 2100.0)))
    eng.tick(1.0)
    cmd = rec.calls[0][1][-1]
    assert isinstance(cmd, ActuatorCommand)
    assert cmd.throttle == 1.0  # saturated at full scale
    assert math.isclose(cmd.rudder_rad, 0.25)


def test_a_long_gap_jumps_the_tick_grid():
    rec = Recorder()
    eng = Engine(Config(), [rec])
    # three stamps after the gap confirm it (one alone would be a time outlier)
    run(eng, [imu(100.0), imu(100.05), imu(3700.0), imu(3700.05), imu(3700.1)],
        lambda t, r: None)
    assert len(rec.calls) < 10  # not 36,000 empty ticks
    assert rec.calls[-1][0] >= 3700.0


def test_replay_with_recorded_tick_times_uses_them():
    rec = Recorder()
    eng = Engine(Config(), [rec])
    run(eng, [imu(1.0), imu(1.5), imu(2.0)], lambda t, r: None, tick_times=[1.2, 1.7, 2.3])
    assert [t for t, _ in rec.calls] == [1.2, 1.7, 2.3]
    assert [len(b) for _, b in rec.calls] == [1, 1, 1]


def test_same_input_gives_the_same_output():
    def once():
        eng = Engine(Config())
        out = []
        samples = [fix(100 + 0.2 * i, lat=48 + 1e-6 * i, sog_mps=1.0) for i in range(50)]
        run(eng, samples, lambda t, r: out.append((t, [x.values for x in r])))
        return out

    assert once() == once()


def test_health_collects_innovations_counters_and_rejections():
    eng = Engine(Config(), [Recorder()])
    eng.push(imu(float("nan")))
    for t in (1.0, 2.0, 3.0):
        eng.tick(t)
    h = eng.health(3.0)
    x = h.innovations["rec"]["x"]
    assert (x.n, x.rejected, x.reasons, x.dof) == (3, 1, {"gate": 1}, 1)
    assert x.nis_mean == 1.0 and x.test_ratio == 0.25 and x.z == [2.0] and x.S == [4.0]
    assert h.counters == {"rec": {"x.steps": 3.0}}
    assert h.rejected == {"imu:nan": 1}
    again = eng.health(4.0).innovations["rec"]["x"]
    assert again.n == 3 and again.test_ratio_max == 0.0   # the maximum starts afresh
    decoded = msgspec.json.decode(msgspec.json.encode(h), type=HealthRecord)
    assert decoded == h


def test_state_round_trip():
    rec = Recorder()
    eng = Engine(Config(), [rec])
    eng.tick(1.0)
    state = eng.get_state()
    eng.set_state(state)
    assert rec.restored == {"k": 1}


class Broken(Recorder):
    name = "broken"

    def step(self, t, samples):
        if samples:
            raise ValueError("shapes (3,) and (26,) not aligned")
        return {"n": 0.0}


def test_a_failing_pipeline_is_counted_restarted_and_the_others_carry_on(monkeypatch):
    import onboard.engine.engine as engine_mod

    monkeypatch.setattr(engine_mod, "build", lambda cfg, only=None: [Broken()])
    rec = Recorder()
    eng = Engine(Config(), [Broken(), rec])
    eng.push(imu(1.0))
    records = eng.tick(1.0)
    assert [r.pipeline for r in records] == ["rec"]
    assert eng.pipeline_errors["broken"] == 1
    h = eng.health(1.0)
    assert h.rejected["pipeline:broken:error"] == 1
    assert any("broken failed (ValueError" in e for e in h.events)


class HalfKnown(Recorder):
    """A pipeline whose position is not known (NaN) while its heading is."""

    name = "half"
    columns = ("heading", "north", "std_north", "speed")

    def step(self, t, samples):
        return {"heading": 1.0, "north": math.nan, "std_north": math.inf, "speed": -math.inf}


def test_non_finite_estimates_are_left_out_of_the_record_and_counted():
    """A record carries only finite values: JSON has no NaN (msgspec writes null, and a
    subscriber decoding EstimateRecord drops the whole record, the finite heading with
    it); the unknown quantities are absent, counted per pipeline in health's
    ``withheld`` (outputs), never among the inputs ``rejected``."""
    import msgspec

    from onboard.core.messages import EstimateRecord

    eng = Engine(Config(), [HalfKnown(), Recorder()])
    eng.push(imu(1.0))
    (half, rec) = eng.tick(1.0)
    assert half.values == {"heading": 1.0} and half.std == {}
    assert rec.values == {"n": 1.0}
    decoded = msgspec.json.decode(msgspec.json.encode(half), type=EstimateRecord)
    assert decoded.values == {"heading": 1.0}
    health = eng.health(1.0)
    assert health.withheld["pipeline:half:nonfinite"] == 3
    assert "pipeline:rec:nonfinite" not in health.withheld
    assert not any(k.startswith("pipeline:half") for k in health.rejected)


def test_estimates_withheld_by_integrity_are_outputs_counted_apart_from_rejected_inputs(
        monkeypatch):
    """The values the integrity monitor withholds (a heading/course mismatch) are counted
    per value and per row in health's ``withheld``, never among the inputs ``rejected``
    (before: ``pipeline:<name>:flagged`` in ``rejected``, summed as rejected inputs)."""
    eng = Engine(Config(), [Recorder()])
    monkeypatch.setattr(eng.integrity, "withheld", lambda name: ("n",))
    for t in (1.0, 2.0, 3.0):
        eng.push(imu(t))
        (rec,) = eng.tick(t)
        assert rec.values == {}
    health = eng.health(3.0)
    assert health.withheld == {"pipeline:rec:flagged": 3}
    assert eng.integrity.withheld_rows == {"rec": 3}
    assert not any(k.startswith("pipeline:") for k in health.rejected)


class WithStd(Recorder):
    """A pipeline with a standard deviation column."""

    name = "withstd"
    columns = ("north", "std_north")

    def step(self, t, samples):
        if samples and samples[0].t == 2.0:
            raise ValueError("restart me")
        return {"north": 1.0, "std_north": 0.5}


def test_std_columns_follow_the_pipeline_also_after_a_restart(monkeypatch):
    """The ``std_<q>`` columns are read from each pipeline's columns when it is built or
    restarted, by its name."""
    import onboard.engine.engine as engine_mod

    monkeypatch.setattr(engine_mod, "build", lambda cfg, only=None: [WithStd()])
    eng = Engine(Config(), [WithStd(), Recorder()])
    (rec_a, _) = eng.tick(1.0)
    eng.push(imu(2.0))
    eng.tick(2.0)  # WithStd raises and is restarted
    (rec_b, _) = eng.tick(3.0)
    assert rec_a.std == rec_b.std == {"north": 0.5}
    assert eng.pipeline_errors["withstd"] == 1


class _FastAie(PipelineDefaults):
    """An ``aie`` that publishes 2.0 m/s (sigma 0.05) whatever it is given, its speed
    declared as such."""

    name = "aie"
    columns = ("speed", "std_speed")
    speed = ("speed",)

    def step(self, t, samples):
        return {"speed": 2.0, "std_speed": 0.05}

    def innovations(self):
        return []

    def health(self):
        return NoHealth()

    def get_state(self):
        return {}

    def set_state(self, state):
        pass


def test_a_speed_that_disagrees_with_the_doppler_speed_is_flagged_in_the_health_record():
    """The integrity monitor's ``speed_mismatch`` (onboard/monitor/integrity.py) reaches the health
    record's flags (and from there ESTIMATOR_STATUS) and the warnings, as the other
    checks do: 2.0 m/s published against fixes at 1.2 m/s over ground."""
    eng = Engine(Config(), pipelines=[_FastAie()])
    samples = [fix(0.5 * k, sog_mps=1.2, cog_rad=0.0) for k in range(40)]
    run(eng, samples, lambda t, recs: None)
    assert eng.health(20.0).flags == {"aie": ["speed_mismatch"]}
    assert "speed_mismatch" in eng.alerts.codes()


class _Undeclared(_FastAie):
    """The same numbers under the same name, its speed not declared."""

    speed = ()


class _Renamed(_FastAie):
    """The same numbers and role under a name no check has ever heard of."""

    name = "mine"


def test_the_speed_check_follows_the_declared_role_not_the_name():
    """Integrity reads what a pipeline declares: an ``aie`` that declares no speed is not
    checked, a pipeline of any name that declares one is."""
    samples = [fix(0.5 * k, sog_mps=1.2, cog_rad=0.0) for k in range(40)]
    flags = {}
    for cls in (_Undeclared, _Renamed):
        eng = Engine(Config(), pipelines=[cls()])
        run(eng, samples, lambda t, recs: None)
        flags[cls.__name__] = eng.health(20.0).flags
    assert flags == {"_Undeclared": {}, "_Renamed": {"mine": ["speed_mismatch"]}}


class _FarAie(_FastAie):
    """An ``aie`` whose declared position is 50 m north of every fix, stated to 1 m."""

    columns = ("north", "east", "std_north", "std_east")
    speed = ()
    position = ("north", "east")
    frame = LocalFrame(48.0, -124.0)

    def step(self, t, samples):
        return {"north": 50.0, "east": 0.0, "std_north": 1.0, "std_east": 1.0}


def test_a_position_withheld_by_another_check_is_still_judged(monkeypatch):
    """The position check reads the positions as computed, as the speed check reads the
    speeds: while a heading mismatch withholds them (here any check: ``withheld``
    patched), a position 50 m off the fixes with a 1 m sigma is still found out, and its
    flag can clear or stand on what the pipeline computes, not on the absence of it."""
    eng = Engine(Config(), pipelines=[_FarAie()])
    monkeypatch.setattr(eng.integrity, "withheld",
                        lambda name: ("north", "east", "std_north", "std_east"))
    published = []
    run(eng, [fix(0.5 * k) for k in range(80)], lambda t, recs: published.extend(recs))
    assert published and all("north" not in r.values for r in published)
    assert "position_residual" in eng.health(40.0).flags["aie"]


class _Eventful(Recorder):
    """A pipeline that reports one event at its second tick."""

    name = "eventful"

    def take_events(self):
        return ["restored state discarded"] if len(self.calls) == 2 else []


def test_a_pipelines_events_reach_the_health_events_prefixed_with_its_name():
    eng = Engine(Config(), pipelines=[_Eventful(), Recorder()])
    for t in (1.0, 2.0, 3.0):
        eng.tick(t)
    assert eng.health(3.0).events == ["eventful: restored state discarded"]


class _Offset(Recorder):
    """A pipeline whose positions are about its own frame, offset from its origin."""

    name = "offset"
    position = ("north", "east")
    frame = LocalFrame(48.0, -124.0)
    frame_offset = (5.0, -3.0)


def test_the_local_frame_of_a_pipeline_is_its_declared_frame_and_offset():
    eng = Engine(Config(), pipelines=[_Offset(), Recorder()])
    assert eng.local_frame("offset") == (_Offset.frame, (5.0, -3.0))
    assert eng.local_frame("rec") is None  # no frame declared
    assert eng.local_frame("absent") is None


def test_a_parameter_sent_once_is_never_reported_stale_a_stream_that_stops_is():
    """An autopilot sends its parameters when asked, once: no ``stale`` event for them,
    however long ago; an IMU that stops is stale after ``STALE_AFTER_S`` (the control)."""
    from onboard.core.messages import Parameter
    from onboard.engine.engine import STALE_AFTER_S

    eng = Engine(Config(), [Recorder()])
    assert eng.push(Parameter(t=1.0, name="SERVO1_FUNCTION", value=26.0, source="mavlink:1"))
    assert eng.push(imu(1.0))
    events = [e for k in range(1, int(STALE_AFTER_S + 30)) for e in eng.health(1.0 + k).events]
    stale = [e for e in events if "stale" in e]
    assert stale and all(e.startswith("imu:") for e in stale), events
