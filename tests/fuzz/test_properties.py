"""Property tests of every parser (hypothesis, default suite): bad bytes never raise,
every rejection is counted, samples are finite, chunking does not change the result.

Each test runs 120 derandomized examples of a corpus (:mod:`tests.fuzz.corpora`,
:mod:`tests.fuzz.recording_corpora`) or of random bytes through a target
(:mod:`tests.fuzz.targets`) under the known-bug guard; the whole module takes ~15 s.
"""

from __future__ import annotations

import random

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from onboard.drivers import nmea
from onboard.drivers.base import ReadStats
from onboard.drivers.recording import FILE_MAGIC, RawRecord, encode_frame, read_records
from onboard.drivers.tlog import TlogReader
from tests.fuzz import targets
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
from tests.fuzz.mutation import mutate
from tests.fuzz.recording_corpora import recording_input, recording_v2_input
from tests.fuzz.scratch import SCRATCH
from tests.fuzz.targets import TARGETS, csv_format

FUZZ = settings(max_examples=120, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.filter_too_much])
"""Hypothesis settings of every property test: 120 examples, the same ones every run."""

run_nmea = guarded(targets.run_nmea)
run_mavlink = guarded(targets.run_mavlink)
run_dvl = guarded(targets.run_dvl)
run_pd6 = guarded(targets.run_pd6)
run_tlog = guarded(targets.run_tlog)
run_dataflash = guarded(targets.run_dataflash)
run_csv = guarded(targets.run_csv)
run_recording = guarded(targets.run_recording)
run_recording_v2 = guarded(targets.run_recording_v2)
run_text = guarded(targets.run_text)


@FUZZ
@given(seed=st.integers(0, 2**32 - 1), cuts=st.lists(st.integers(0, 10_000), max_size=6),
       utc=st.booleans())
def test_nmea_never_raises_and_counts(seed, cuts, utc):
    run_nmea(nmea_input(random.Random(seed)), cuts, "utc" if utc else "rx")


@FUZZ
@given(data=st.binary(max_size=600), cuts=st.lists(st.integers(0, 600), max_size=4))
def test_nmea_random_bytes(data, cuts):
    run_nmea(data, cuts)


def test_nmea_clean_stream_has_no_rejection():
    """Control: valid sentences give no rejection (the properties are not vacuous)."""
    p = nmea.NmeaParser()
    lines = [nmea.encode_gga(1.7e9 + k, 10.0, 20.0) for k in range(5)]
    lines += [nmea.encode_hdt(0.5 * k) for k in range(5)]
    for line in lines:
        p.feed(line, 1.0)
    p.flush()
    assert not p.stats.rejected and p.stats.records == len(lines)


@FUZZ
@given(seed=st.integers(0, 2**32 - 1), cuts=st.lists(st.integers(0, 4000), max_size=6))
def test_mavlink_stream_never_raises_and_is_chunking_invariant(seed, cuts):
    data, _ = mavlink_input(random.Random(seed))
    run_mavlink(data, cuts)


@FUZZ
@given(seed=st.integers(0, 2**32 - 1), cuts=st.lists(st.integers(0, 4000), max_size=6))
def test_mavlink_intact_frames_survive_garbage(seed, cuts):
    data, intact = mavlink_input(random.Random(seed), damaged=False)
    run_mavlink(data, cuts, intact)


@FUZZ
@given(data=st.binary(max_size=800), cuts=st.lists(st.integers(0, 800), max_size=4))
def test_mavlink_random_bytes(data, cuts):
    run_mavlink(data, cuts)


@FUZZ
@given(seed=st.integers(0, 2**32 - 1), cuts=st.lists(st.integers(0, 3000), max_size=5))
def test_dvl_json_never_raises_and_accounts_every_line(seed, cuts):
    run_dvl(dvl_input(random.Random(seed)), cuts)


@FUZZ
@given(data=st.binary(max_size=600), cuts=st.lists(st.integers(0, 600), max_size=4))
def test_dvl_json_random_bytes(data, cuts):
    run_dvl(data, cuts)


@FUZZ
@given(seed=st.integers(0, 2**32 - 1), cuts=st.lists(st.integers(0, 3000), max_size=5),
       time_base=st.sampled_from(("rx", "instrument")),
       frame=st.sampled_from(("ship", "instrument")))
def test_pd6_never_raises(seed, cuts, time_base, frame):
    run_pd6(pd6_input(random.Random(seed)), cuts, time_base, frame)


@FUZZ
@given(data=st.binary(max_size=600))
def test_pd6_random_bytes(data):
    run_pd6(data, [], "rx", "ship")


@FUZZ
@given(seed=st.integers(0, 2**32 - 1), ops=st.integers(1, 12))
def test_tlog_mutations_never_raise(seed, ops):
    rng = random.Random(seed)
    run_tlog(mutate(tlog_bytes(), rng, ops))


@FUZZ
@given(data=st.binary(max_size=2000))
def test_tlog_random_bytes(data):
    run_tlog(data)


def test_tlog_clean_file_has_no_rejection():
    """Control: the unmutated corpus tlog reads without a rejection."""
    p = SCRATCH / "clean.tlog"
    p.write_bytes(tlog_bytes())
    r = TlogReader(p)
    assert list(r) and not r.stats.rejected


@FUZZ
@given(seed=st.integers(0, 2**32 - 1), ops=st.integers(1, 12))
def test_dataflash_mutations_never_raise(seed, ops):
    run_dataflash(mutate(dataflash_bytes(), random.Random(seed), ops))


@FUZZ
@given(data=st.binary(max_size=2000))
def test_dataflash_random_bytes_after_a_fmt(data):
    base = dataflash_bytes()
    run_dataflash(base[:89] + data)


@FUZZ
@given(seed=st.integers(0, 2**32 - 1))
def test_csv_never_raises(seed):
    run_csv(csv_input(random.Random(seed)), csv_format())


@FUZZ
@given(seed=st.integers(0, 2**32 - 1))
def test_recording_never_raises(seed):
    data, _ = recording_input(random.Random(seed))
    run_recording(data, None)


@FUZZ
@given(seed=st.integers(0, 2**32 - 1))
def test_recording_damage_never_costs_an_intact_frame(seed):
    data, intact = recording_input(random.Random(seed))
    run_recording(data, intact)


@FUZZ
@given(seed=st.integers(0, 2**32 - 1))
def test_recording_clean_frames_all_read(seed):
    rng = random.Random(seed)
    p = SCRATCH / "clean.onbrec"
    recs = [RawRecord(t=float(i), source="s", kind="nmea", data=rng.randbytes(rng.randint(0, 50)))
            for i in range(rng.randint(1, 20))]
    p.write_bytes(FILE_MAGIC + b"".join(encode_frame(r) for r in recs))
    stats = ReadStats()
    assert list(read_records(p, stats)) == recs and not stats.rejected


@FUZZ
@given(seed=st.integers(0, 2**32 - 1))
def test_recording_v2_verdicts_never_raise_and_are_counted(seed):
    data, intact = recording_v2_input(random.Random(seed))
    run_recording_v2(data, intact)


@FUZZ
@given(seed=st.integers(0, 2**32 - 1))
def test_text_captures_never_raise(seed):
    run_text(text_capture_input(random.Random(seed)))


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_every_target_runs_on_its_corpus(name):
    """The campaign's registry: every target runs on inputs of its own corpus."""
    make, run = TARGETS[name]
    rng = random.Random(0)
    for _ in range(3):
        run(make(rng), rng)
