"""Recorder (rotation, size cap, flush interval, crash safety) and the Intake gate."""

from __future__ import annotations

import json

from onboard.drivers.base import ReadStats
from onboard.drivers.nmea import encode_gga, encode_hdt, encode_rmc
from onboard.drivers.protocols import encode_sample
from onboard.drivers.recording import RawRecord, read_records
from onboard.core.config import Config
from onboard.core.messages import Imu
from onboard.engine import Engine
from onboard.service.intake import Intake
from onboard.service.recorder import Recorder, recording_files, recording_meta


class FakeClock:
    def __init__(self, t: float = 0.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def test_every_file_starts_with_a_meta_record_and_keeps_every_raw_record(tmp_path):
    clock = FakeClock()
    rec = Recorder(tmp_path, meta={"vehicle": "v1", "state": {"aie": {"a": 1}}}, clock=clock)
    for i in range(100):
        clock.t = i * 0.01
        rec.write(RawRecord(t=clock.t, source="gps", kind="nmea", data=b"$X%d\r\n" % i))
    rec.close()
    records = list(read_records(rec.files[0]))
    assert records[0].kind == "meta"
    meta = json.loads(records[0].data)
    assert meta["vehicle"] == "v1" and meta["state"] == {"aie": {"a": 1}} and meta["part"] == 0
    assert [r.data for r in records[1:]] == [b"$X%d\r\n" % i for i in range(100)]
    assert recording_meta(rec.files[0])["vehicle"] == "v1"


def test_files_rotate_at_the_size_limit_and_the_oldest_go_beyond_the_cap(tmp_path):
    clock = FakeClock()
    # 4096 B minimum rotation size; 10 kB cap -> at most ~3 files kept
    rec = Recorder(tmp_path, rotate_mb=0.004, max_total_mb=0.010, clock=clock, fsync=False)
    payload = bytes(200)
    for i in range(300):
        clock.t = i * 0.01
        rec.write(RawRecord(t=clock.t, source="imu", kind="mavlink", data=payload))
    rec.close()
    files = recording_files(tmp_path)
    assert rec.part >= 10  # 300 x ~220 B in 4 kB files
    assert rec.deleted, "the size cap deleted old parts"
    assert sum(f.stat().st_size for f in files) <= 10_000 + 4096 + 300
    for f in files:  # every surviving part is readable on its own and says which part it is
        first = next(read_records(f))
        assert first.kind == "meta" and json.loads(first.data)["part"] >= 0
        assert "state" not in json.loads(first.data) or json.loads(first.data)["part"] == 0


def test_records_reach_the_file_within_the_flush_interval(tmp_path):
    clock = FakeClock()
    rec = Recorder(tmp_path, flush_interval_s=0.5, clock=clock)
    rec.write(RawRecord(t=0.0, source="gps", kind="nmea", data=b"first"))
    clock.t = 0.6
    rec.poll(clock.t)  # the service calls this every tick
    rec._pending_sync.result()  # the fsync runs in the worker thread
    on_disk = [r.data for r in read_records(rec.path)]
    assert b"first" in on_disk  # without close(): what a crash would leave
    rec.close()


def test_a_torn_last_frame_after_a_crash_costs_only_that_frame(tmp_path):
    rec = Recorder(tmp_path, clock=FakeClock())
    for i in range(10):
        rec.write(RawRecord(t=float(i), source="s", kind="nmea", data=b"x" * 50))
    rec.close()
    path = rec.files[0]
    data = path.read_bytes()
    path.write_bytes(data[:-20])  # power cut in the middle of the last frame
    stats = ReadStats()
    got = list(read_records(path, stats))
    assert len(got) == 1 + 9 and stats.rejected["truncated"] == 1


def _cfg() -> Config:
    return Config()


def test_intake_holds_samples_stamped_after_the_tick_for_the_next_tick():
    engine = Engine(_cfg())
    intake = Intake(engine)
    intake.chunk("imu", "sample", encode_sample(Imu(t=1.00, accel_x=0, accel_y=0, accel_z=-9.8,
                                                     gyro_x=0, gyro_y=0, gyro_z=0)), 1.00)
    intake.chunk("imu", "sample", encode_sample(Imu(t=1.15, accel_x=0, accel_y=0, accel_z=-9.8,
                                                     gyro_x=0, gyro_y=0, gyro_z=0)), 1.15)
    intake.tick(1.1)
    assert sum(engine.accepted.values()) == 1 and len(intake.pending) == 1
    intake.tick(1.2)
    assert sum(engine.accepted.values()) == 2 and not intake.pending


def test_intake_counts_drops_when_the_queue_is_full_and_parser_rejections():
    engine = Engine(_cfg())
    intake = Intake(engine, queue_size=3)
    for i in range(5):
        intake.chunk("gps", "nmea", encode_hdt(0.1 * i), 1.0 + i * 0.01)
    intake.chunk("gps", "nmea", b"$GPHDT,1.0,T*FF\r\n", 1.1)  # bad checksum
    intake.chunk("gps", "nmea", b"\x00" * 1000 + b"\n", 1.1)  # oversize garbage line
    assert intake.dropped["gps"] == 2 and len(intake.pending) == 3
    rej = intake.parse_rejections()
    assert rej.get("parse:gps:checksum") == 1 and rej.get("parse:gps:too_long") == 1


def test_intake_rejects_samples_from_the_future_through_the_engine():
    engine = Engine(_cfg())
    intake = Intake(engine)
    intake.chunk("x", "sample", encode_sample(Imu(t=100.0, accel_x=0, accel_y=0, accel_z=0,
                                                   gyro_x=0, gyro_y=0, gyro_z=0)), 1.0)
    assert engine.rejected["imu:future"] == 1 and not intake.pending


def test_intake_never_raises_on_garbage_for_any_protocol():
    engine = Engine(_cfg())
    intake = Intake(engine)
    junk = bytes(range(256)) * 4 + b"\n{not json}\n:BS,1,2\n$GPGGA,,,*00\n\xfd\x09\x00"
    for kind in ("mavlink", "nmea", "dvl-json", "pd6", "sample"):
        intake.chunk(kind, kind, junk, 1.0)
    intake.tick(1.0)
    assert sum(intake.parse_rejections().values()) > 0


def test_nmea_fix_timestamps_survive_the_tick_between_its_sentences():
    """GGA at 1.00, tick at 1.05, RMC at 1.08: the fix (t=1.00) is pushed at tick 1.1."""
    engine = Engine(_cfg())
    intake = Intake(engine)
    tu = 1_767_225_600.0
    intake.chunk("gps", "nmea", encode_gga(tu, 41.0, -71.0), 1.00)
    intake.chunk("gps", "nmea", encode_rmc(tu, 41.0, -71.0, 1.0, 0.0), 1.01)
    intake.chunk("gps", "nmea", encode_gga(tu + 0.2, 41.0, -71.0), 1.20)
    intake.tick(1.21)
    intake.chunk("gps", "nmea", encode_rmc(tu + 0.2, 41.0, -71.0, 1.0, 0.0), 1.22)
    intake.tick(1.31)
    assert engine.accepted[("gnss", "gps")] == 2 or engine.accepted.get("gnss:gps") == 2


def test_a_parser_that_raises_is_counted_and_the_intake_carries_on():
    engine = Engine(_cfg())
    intake = Intake(engine)
    st = intake.add_source("gps", "nmea")

    def boom(data, t_rx):
        raise RuntimeError("parser bug")

    st.parser.feed = boom  # type: ignore[method-assign]
    assert intake.chunk("gps", "nmea", b"$GPHDT,1,T*00\r\n", 1.0) == 0
    intake.tick(1.0)
    assert intake.parse_rejections() == {"parse:gps:parser_error": 1}


def test_protocol_registry_gives_a_fresh_parser_per_kind_and_refuses_unknown_kinds():
    import pytest

    from onboard.drivers.protocols import KINDS, SampleParser, UnknownProtocol, parser_for

    for kind in KINDS:
        a, b = parser_for(kind, "src"), parser_for(kind, "src")
        assert a is not b and hasattr(a, "feed") and a.stats.records == 0
    with pytest.raises(KeyError):
        parser_for("ubx")
    with pytest.raises(UnknownProtocol, match="known: mavlink"):
        parser_for("ubx")
    p = SampleParser("sim")
    s = Imu(t=2.0, accel_x=0.1, accel_y=0, accel_z=-9.8, gyro_x=0, gyro_y=0, gyro_z=0.01)
    (back,) = p.feed(encode_sample(s), 2.0)
    assert back.t == 2.0 and back.accel_x == 0.1 and back.source == "sim"
    assert p.feed(b"\xc1junk", 2.1) == [] and p.stats.rejected["decode"] == 1


def test_recordings_are_grouped_by_run_with_parts_in_order(tmp_path):
    from onboard.service.recorder import recording_runs

    clock = FakeClock()
    a = Recorder(tmp_path, rotate_mb=0.004, clock=clock, fsync=False)
    for i in range(60):
        a.write(RawRecord(t=float(i), source="s", kind="nmea", data=bytes(200)))
    a.close()
    b = Recorder(tmp_path, clock=clock, fsync=False)  # a restart within the same second
    b.close()
    runs = recording_runs(tmp_path)
    assert runs[a.run_id] == a.files and len(a.files) >= 3
    assert runs[b.run_id] == b.files and a.run_id != b.run_id


def test_receive_then_parse_gives_what_chunk_gives_in_the_same_order(tmp_path):
    """The live service's split (``receive`` each chunk, ``parse`` them together at the
    tick or while waiting) queues, pushes and records exactly what ``chunk`` does: same
    samples in the same order, same counters, same recording (records in arrival order,
    before the tick that parsed them)."""
    from onboard.apps.service_bench import TrafficGenerator

    def feed(split: bool, d):
        engine = Engine(_cfg())
        rec = Recorder(d, clock=FakeClock(), fsync=False)
        intake = Intake(engine, recorder=rec, queue_size=50, max_backlog=7)
        gen = TrafficGenerator()
        pushed = []
        push = engine.push

        def spy(s, now=None):
            pushed.append((s, now))
            return push(s, now=now)

        engine.push = spy  # type: ignore[method-assign]
        out = []
        for k in range(200):
            t = k / 50.0
            chunks = [("ap", "mavlink", f) for f in gen.mavlink(t)] + \
                     [("gps", "nmea", f) for f in gen.nmea(t)]
            for i, (name, kind, data) in enumerate(chunks):
                t_rx = t + 0.001 * (i + 1)
                if split:
                    intake.receive(name, kind, data, t_rx)
                else:
                    intake.chunk(name, kind, data, t_rx)
            if split and k % 3 == 0:
                intake.parse()  # as the service does while it waits for a sample
            if k % 5 == 4:
                out.append(intake.tick((k + 1) / 50.0))
        rec.close()
        counts = {n: (st.chunks, st.bytes, st.samples) for n, st in intake.sources.items()}
        frames = [(r.t, r.source, r.kind, r.data) for f in rec.files for r in read_records(f)
                  if r.kind != "meta"]
        return out, pushed, counts, dict(intake.dropped), frames

    a = feed(False, tmp_path / "a")
    b = feed(True, tmp_path / "b")
    assert a[0] and sum(len(x) for x in a[0]) > 0
    assert a[1] == b[1] and len(a[1]) > 300  # every push, same sample, same order
    assert a[0] == b[0] and a[2] == b[2] and a[3] == b[3]
    assert a[4] == b[4]


def test_parse_after_counts_the_samples_stamped_after_it_and_when_the_first_came():
    """``parse(after=T)`` returns how many queued samples are stamped after ``T`` and sets
    ``fresh_rx`` to the receive time of the first chunk that queued one (the service
    predicts the next tick's wake-up from it); a chunk of older samples does not count."""
    def imu(t: float) -> bytes:
        return encode_sample(Imu(t=t, accel_x=0, accel_y=0, accel_z=-9.8, gyro_x=0, gyro_y=0,
                                 gyro_z=0))

    intake = Intake(Engine(_cfg()))
    intake.receive("imu", "sample", imu(0.99), 1.001)  # received after 1.0, stamped before
    intake.receive("gps", "nmea", encode_hdt(0.5), 1.002)  # stamped at its receipt
    intake.receive("imu", "sample", imu(1.01), 1.011)
    assert intake.parse(after=1.0) == 2
    assert intake.fresh_rx == 1.002 and len(intake.pending) == 3
    intake.receive("imu", "sample", imu(0.98), 1.02)
    assert intake.parse(after=1.0) == 0 and intake.fresh_rx is None
    intake.receive("imu", "sample", imu(1.03), 1.03)
    assert intake.parse() == 1 and len(intake.pending) == 5  # all, without ``after``


def test_an_event_is_logged_once_whoever_takes_it(tmp_path, caplog):
    """The service logs the events it is handed (``on_event``): the recorder logs one
    itself only when nobody takes it (before: twice in the service's journal)."""
    import logging

    caplog.set_level(logging.INFO, logger="onboard.service.recorder")
    taken: list[str] = []
    rec = Recorder(tmp_path, clock=FakeClock(), on_event=taken.append)
    rec._note("recorder: disk full")
    rec.poll(0.0)
    rec.close()
    alone = Recorder(tmp_path / "b", clock=FakeClock())
    alone._note("recorder: write failed")
    alone.close()
    logged = [r.getMessage() for r in caplog.records if r.name == "onboard.service.recorder"]
    assert taken == ["recorder: disk full"]
    assert "recorder: disk full" not in logged and "recorder: write failed" in logged
