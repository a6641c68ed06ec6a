"""The parsers under fuzz, each fed one input with its properties checked.

``run_<name>(input, ...)`` raises on any exception of the parser (except
:class:`~drivers.base.UnreadableLog` when a file reader is opened on something that is not
its format, its documented contract) and on any broken property:

* every sample produced is typed, finitely timed, without NaN or infinity
  (:mod:`.properties`);
* the counters are sane, and where a parser exposes its accounting exactly, records seen
  = samples + rejected + ignored (DVL JSON), intact frames are all recovered (MAVLink,
  recordings), signing verdicts are paired and counted (recording version 2);
* stream parsers give the same samples however the stream is cut into chunks.
"""

from __future__ import annotations

import random
from collections import Counter
from collections.abc import Callable
from typing import Any

from onboard.drivers import dvl_json, nmea, pd6
from onboard.drivers.base import TIME_JUMP_S, ReadStats, UnreadableLog
from onboard.drivers.csvlog import CsvReader
from onboard.drivers.dataflash import DataflashReader
from onboard.drivers.mavlink import MavlinkParser
from onboard.drivers.recording import VERDICTS_KIND, RecordingReader, read_records, with_verdicts
from onboard.drivers.textlog import open_text_log
from onboard.drivers.tlog import TlogReader
from onboard.core import config as configmod
from onboard.core.config import Config
from onboard.engine import Engine
from onboard.service.recorder import replay_recording
from tests.fuzz.corpora import (
    csv_input,
    dataflash_bytes,
    dvl_input,
    mavlink_input,
    nmea_input,
    pd6_input,
    text_capture_input,
    tlog_bytes,
)
from tests.fuzz.known_bugs import guarded
from tests.fuzz.mutation import chunked, mutate
from tests.fuzz.properties import check_sample, check_stats, read_file_reader, rejected, sample_key
from tests.fuzz.recording_corpora import (
    HOSTILE_REASONS,
    SIGNING_REASONS,
    recording_input,
    recording_v2_input,
)
from tests.fuzz.scratch import SCRATCH


def run_nmea(data: bytes, cuts: list[int], time_base: str = "rx") -> None:
    """:class:`drivers.nmea.NmeaParser` over ``data`` cut at ``cuts``; rejections never
    exceed the sentences seen; in the UTC time base the samples come in time order, but for a
    step back of more than ``TIME_JUMP_S``, which the parser passes on for the engine's time
    line to judge (a clock reset or an outlier; drivers/nmea.py)."""
    p = nmea.NmeaParser(time_base=time_base)  # type: ignore[arg-type]
    out = []
    for i, c in enumerate(chunked(data, cuts)):
        out += p.feed(c, 100.0 + 0.01 * i)
    out += p.flush()
    for s in out:
        check_sample(s)
    check_stats(p.stats)
    assert rejected(p.stats) <= p.stats.records
    if time_base == "utc":
        ts = [s.t for s in out]
        back = [(a, b) for a, b in zip(ts, ts[1:]) if b < a]
        assert all(a - b > TIME_JUMP_S for a, b in back), \
            f"UTC time base: a step back within {TIME_JUMP_S} s was emitted: {back[:3]}"


FLUSH = bytes(300)
"""Enough bytes to complete any frame a corrupt length byte may still be waiting for."""


def run_mavlink(data: bytes, cuts: list[int], intact: int | None = None) -> None:
    """:class:`drivers.mavlink.MavlinkParser` over ``data`` whole and cut at ``cuts``: the
    same samples and counters either way; at least ``intact`` frames decoded."""
    whole = MavlinkParser()
    ref = whole.feed(data, 1.0) + whole.feed(FLUSH, 1.0)
    parts = MavlinkParser()
    out = []
    for c in chunked(data, cuts):
        out += parts.feed(c, 1.0)
    out += parts.feed(FLUSH, 1.0)
    for s in ref:
        check_sample(s)
    check_stats(whole.stats)
    # the result does not depend on how the stream is cut (drivers.mavlink docstring)
    assert [sample_key(s) for s in out] == [sample_key(s) for s in ref]
    assert parts.stats.records == whole.stats.records
    assert parts.stats.rejected == whole.stats.rejected
    if intact is not None:
        assert whole.stats.records >= intact, (whole.stats.records, intact)


def run_dvl(data: bytes, cuts: list[int]) -> None:
    """:class:`drivers.dvl_json.DvlJsonParser` over ``data`` cut at ``cuts``; every line is
    a sample, a rejection or ignored."""
    p = dvl_json.DvlJsonParser()
    out = []
    for i, c in enumerate(chunked(data, cuts)):
        out += p.feed(c, 1.7e9 + i)
    for s in out:
        check_sample(s)
    st_ = p.stats
    check_stats(st_)
    assert st_.samples == len(out)
    # exact accounting: every non-blank line is a sample, a rejection or ignored
    assert st_.records == st_.samples + rejected(st_) + st_.by_type.get("ignored", 0), st_


def run_pd6(data: bytes, cuts: list[int], time_base: str, frame: str) -> None:
    """:class:`drivers.pd6.Pd6Parser` over ``data`` cut at ``cuts``; samples counted
    exactly; in the instrument time base in time order, but for a step back of more than
    ``TIME_JUMP_S``, which the parser passes on for the engine's time line to judge (a
    clock reset or an outlier; drivers.base.TimeOrder)."""
    p = pd6.Pd6Parser(time_base=time_base, velocity_frame=frame)  # type: ignore[arg-type]
    out = []
    for i, c in enumerate(chunked(data, cuts)):
        out += p.feed(c, 50.0 + i)
    for s in out:
        check_sample(s)
    check_stats(p.stats)
    assert p.stats.samples == len(out)
    if time_base == "instrument":
        ts = [s.t for s in out]
        back = [(a, b) for a, b in zip(ts, ts[1:]) if b < a]
        assert all(a - b > TIME_JUMP_S for a, b in back), \
            f"instrument time base: a step back within {TIME_JUMP_S} s was emitted: {back[:3]}"


def run_tlog(data: bytes, name: str = "f.tlog") -> None:
    """:class:`drivers.tlog.TlogReader` on ``data`` written to the scratch file ``name``."""
    p = SCRATCH / name
    p.write_bytes(data)
    read_file_reader(TlogReader, p)


def run_dataflash(data: bytes, name: str = "f.bin") -> None:
    """:class:`drivers.dataflash.DataflashReader` on ``data`` as the scratch file ``name``."""
    p = SCRATCH / name
    p.write_bytes(data)
    read_file_reader(DataflashReader, p)


def csv_format():
    """The CSV mapping the CSV target reads with (``config/blueboat-ntnu-csv.toml``)."""
    return configmod.load(configmod.resolve("blueboat-ntnu-csv")).csv


def run_csv(data: bytes, fmt, name: str = "f.csv") -> None:
    """:class:`drivers.csvlog.CsvReader` with mapping ``fmt`` on ``data`` as ``name``."""
    p = SCRATCH / name
    p.write_bytes(data)
    read_file_reader(lambda q: CsvReader(q, fmt), p)


def run_recording(data: bytes, intact: int | None, name: str = "f.onbrec") -> None:
    """:func:`drivers.recording.read_records` and :class:`~drivers.recording.RecordingReader`
    on ``data`` as ``name``; at least ``intact`` records read."""
    p = SCRATCH / name
    p.write_bytes(data)
    stats = ReadStats()
    try:
        recs = list(read_records(p, stats))
    except UnreadableLog:
        return
    check_stats(stats)
    assert stats.records == len(recs)
    if intact is not None:
        # "one bad sector never costs the rest of the file" (drivers.recording docstring)
        assert len(recs) >= intact, (len(recs), intact, stats)
    read_file_reader(RecordingReader, p, ordered=False)


class FrameCrcSpy:
    """A verifier that accepts every frame and notes each one's CRC-16 per chunk: the
    oracle of what a replay's :class:`VerdictPlayer` sees."""

    def __init__(self) -> None:
        self.crcs: list[int] = []

    def check(self, buf, start, crc_end, sysid, compid, inc_flags):
        """Note the frame's CRC-16 and accept it."""
        self.crcs.append(buf[crc_end - 2] | (buf[crc_end - 1] << 8))
        return None


def verdicts_oracle(recs: list) -> tuple[Counter, Counter, int, int]:
    """What a replay of ``recs`` (the intact records) must count: (signing rejections of
    the verdicts that match their chunk, at most that plus the ones of damaged verdicts,
    number of chunks with damaged verdicts, verdicts orphaned). Checks the pairing's own
    accounting: every verdicts record is paired with the MAVLink chunk just before it or
    counted ``verdicts_orphan``."""
    exact, loose, bad, paired = Counter(), Counter(), 0, 0
    spies: dict[str, tuple[MavlinkParser, FrameCrcSpy]] = {}
    pstats = ReadStats()
    for rec, v in with_verdicts(recs, pstats):
        if v is not None:
            paired += 1
            assert rec.kind == "mavlink", ("verdicts paired with a non-MAVLink record", rec.kind)
        if rec.kind != "mavlink":
            continue
        if rec.source not in spies:
            spy = FrameCrcSpy()
            spies[rec.source] = (MavlinkParser(verifier=spy), spy)
        parser, spy = spies[rec.source]
        spy.crcs = []
        parser.feed(rec.data, rec.t)
        if v is None:
            continue
        crcs = spy.crcs
        idx = [int(i) for i, _, _ in v.rejected]
        ok = (v.checks == len(crcs) and len(set(idx)) == len(idx)
              and all(0 <= i < len(crcs) and crcs[i] == c and reason in SIGNING_REASONS
                      for i, reason, c in v.rejected))
        for i, reason, c in v.rejected:
            (exact if ok else loose)[reason] += 1
        bad += not ok
    n_verdicts = sum(r.kind == VERDICTS_KIND for r in recs)
    assert n_verdicts == paired + pstats.rejected["verdicts_orphan"], (n_verdicts, paired, pstats)
    return exact, loose, bad, pstats.rejected["verdicts_orphan"]


def run_recording_v2(data: bytes, intact: int | None, name: str = "f2.onbrec") -> None:
    """read_records, RecordingReader and replay_recording (an engine without pipelines:
    the intake and the engine's sample checks, fast) never raise; every damaged verdicts
    record is counted (orphan or ``verdict_mismatch``), matching ones give exactly the
    recorded rejections, and no reason a verdicts record names other than a verifier's
    reaches the counters."""
    p = SCRATCH / name
    p.write_bytes(data)
    stats = ReadStats()
    try:
        recs = list(read_records(p, stats))
    except UnreadableLog:
        return
    check_stats(stats)
    if intact is not None:
        assert len(recs) >= intact, (len(recs), intact, stats)
    exact, loose, bad, orphans = verdicts_oracle(recs)

    got = read_file_reader(RecordingReader, p, ordered=False)
    assert got is not None
    reader = got[0]
    rej = reader.stats.rejected
    for reason in SIGNING_REASONS:
        # every frame a matching verdicts record rejects is rejected, under its reason;
        # damaged verdicts never add more than they name
        assert exact[reason] <= rej[reason] <= exact[reason] + loose[reason], (
            reason, rej, exact, loose)
    assert rej["verdict_mismatch"] >= bad, (rej, bad)
    if not bad:
        assert "verdict_mismatch" not in rej, rej
    assert not set(HOSTILE_REASONS) & set(rej), rej
    assert rej["verdicts_orphan"] == orphans, (rej, orphans)

    ticks: list[float] = []
    res = replay_recording(p, Engine(Config(), []), lambda t, r: ticks.append(t))
    check_stats(res.stats)
    assert res.ticks == len(ticks)
    by_reason: Counter[str] = Counter()
    for key, n in res.rejected.items():
        assert n > 0, (key, n)
        by_reason[key.split(":", 2)[2]] += n
    if len({(r.source, r.kind) for r in recs if r.kind != "verdicts"}) == len(
            {r.source for r in recs if r.kind != "verdicts"}):
        # one protocol per input name (as live): the replay rejects what the reader does
        for reason in (*SIGNING_REASONS, "verdict_mismatch"):
            assert by_reason[reason] == rej[reason], (reason, res.rejected, rej)
    assert res.stats.rejected["verdicts_orphan"] == rej["verdicts_orphan"]
    assert not set(HOSTILE_REASONS) & set(by_reason), res.rejected


def run_text(data: bytes, name: str = "f.txt") -> None:
    """:func:`drivers.textlog.open_text_log` on ``data`` as ``name`` (the format sniffed)."""
    p = SCRATCH / name
    p.write_bytes(data)
    read_file_reader(open_text_log, p)


TARGETS: dict[str, tuple[Callable[[random.Random], Any], Callable[[Any, random.Random], None]]] = {
    "nmea": (nmea_input, guarded(lambda d, r: run_nmea(d, [r.randrange(len(d) + 1)],
                                                       r.choice(("rx", "utc"))))),
    "mavlink": (lambda r: mavlink_input(r, damaged=r.random() < 0.5),
                guarded(lambda d, r: run_mavlink(d[0], [r.randrange(len(d[0]) + 1)]))),
    "dvl_json": (dvl_input, guarded(lambda d, r: run_dvl(d, [r.randrange(len(d) + 1)]))),
    "pd6": (pd6_input, guarded(lambda d, r: run_pd6(d, [r.randrange(len(d) + 1)],
                                                    r.choice(("rx", "instrument")),
                                                    r.choice(("ship", "instrument"))))),
    "csv": (csv_input, guarded(lambda d, r: run_csv(d, csv_format(), "c.csv"))),
    "tlog": (lambda r: mutate(tlog_bytes(), r, r.randint(1, 12)),
             guarded(lambda d, r: run_tlog(d, "c.tlog"))),
    "dataflash": (lambda r: mutate(dataflash_bytes(), r, r.randint(1, 12)),
                  guarded(lambda d, r: run_dataflash(d, "c.bin"))),
    "recording": (recording_input, guarded(lambda d, r: run_recording(d[0], d[1], "c.onbrec"))),
    "recording_v2": (recording_v2_input,
                     guarded(lambda d, r: run_recording_v2(d[0], d[1], "c2.onbrec"))),
    "text": (text_capture_input, guarded(lambda d, r: run_text(d, "c.txt"))),
}
"""name -> (make an input from an RNG, run the parser on it under the known-bug guard and
check the properties); the campaign (test_campaign.py) makes its inputs with these."""
