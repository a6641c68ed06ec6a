"""Nothing lost without a loud word (issue 30, deliverable 2): the issue's damaged files,
tried as a new user would, through the command line.

Each replay ends with its outputs and, when little of the log could be used, one loud
line first among the warnings (``log_mostly_unread``: how much, what to do, why the rest
was not used); a diagnose that cannot work says the same in its one line and exits 2.
No printed or written span is negative or absurd. The issue's cases, before this change:

* a CSV whose first row is stamped 1e12 ms kept 2 of 486 rows, exit 0, and the warning
  said "dropped 1 record(s) ... the records after them were kept";
* a tlog with 10 % of its bytes randomised gave "0.0 s, 1 sample", exit 0, no word that
  almost nothing was read (the reader stopped at the first damaged time stamp it took
  as its reference);
* a byte-flipped tlog reported ``time_jump [-837399.4--837399.4 s]`` (its first stamp).
"""

from __future__ import annotations

import json
import random
import re
from pathlib import Path

import pytest

from onboard.cli import main as cli_main
from onboard.drivers.base import USED_SHARE_MIN
from onboard.drivers.tlog import TIMESTAMP_LEN
from tests.helpers.reset_tlog import write_reset_tlog

REPO = Path(__file__).resolve().parents[1]
TLOG = REPO / "tests/data/replay/jaiabot-turns.tlog"
"""A committed 40 s simulator log (136 kB)."""
BLUEBOAT = REPO / "config/blueboat-ntnu-csv.toml"
SPAN = re.compile(r"\[(-?[\d.]+)-(-?[\d.]+) s[;\]]")
"""A printed warning's span, ``[12.3-45.6 s]``."""


def randomised(src: Path, dst: Path, share: float, seed: int) -> Path:
    """``src`` with ``share`` of its bytes, chosen with ``seed``, replaced by random ones."""
    data = bytearray(src.read_bytes())
    rng = random.Random(seed)
    for i in rng.sample(range(len(data)), int(share * len(data))):
        data[i] = rng.randrange(256)
    dst.write_bytes(bytes(data))
    return dst


def replay(tmp_path: Path, log: Path, capsys, *config: str) -> tuple[dict, str]:
    """``onboard replay`` of ``log``: its summary and what it printed (exit status 0)."""
    out = tmp_path / "out"
    args = [a for c in config for a in ("--config", c)]
    assert cli_main(["replay", str(log), *args, "--out", str(out), "--no-plot"]) == 0
    return json.loads((out / "summary.json").read_text()), capsys.readouterr().out


def assert_spans_sane(summary: dict, printed: str) -> None:
    """Every printed span inside the log's duration, every written one in order."""
    duration = summary["time_span"]["duration_s"]
    for a, b in SPAN.findall(printed):
        assert 0.0 <= float(a) <= float(b) <= duration + 1.0, printed
    span = summary["time_span"]
    assert span["start"] <= span["end"]
    assert all(0.0 <= g["duration_s"] == g["end"] - g["start"] for g in span["segments"])
    for w in summary["warnings"]:
        assert w["t_start"] is None or w["t_start"] <= w["t_end"]


# ------------------------------------------------------------- most of the file damaged

@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_tlog_with_a_tenth_of_its_bytes_randomised_is_read_to_its_end_and_says_so(
        tmp_path, capsys, seed):
    """Measured (seeds 0-2): 39.0-39.4 s of the clean 40.0 s, 4.3-6.3 % used, the file's
    bytes in records read whole 6.3-8.4 % (before: 0.4 s, or no sample at all)."""
    clean, _ = replay(tmp_path / "clean", TLOG, capsys)
    s, printed = replay(tmp_path, randomised(TLOG, tmp_path / "r.tlog", 0.1, seed), capsys)
    read = s["read"]
    assert read["size_bytes"] == TLOG.stat().st_size
    assert 0.0 < read["used_bytes"] / read["size_bytes"] < 0.1
    assert s["time_span"]["duration_s"] > 0.9 * clean["time_span"]["duration_s"]
    first = s["warnings"][0]
    assert first["code"] == "log_mostly_unread"
    share = float(re.match(r"only ([\d.]+) % of r.tlog could be used: the file is damaged",
                           first["message"]).group(1))
    assert 0.0 < share < 100 * USED_SHARE_MIN
    assert printed.splitlines()[2].startswith("  log_mostly_unread: only ")  # first printed
    assert_spans_sane(s, printed)


def test_an_undamaged_tlog_is_used_whole_and_raises_no_such_warning(tmp_path, capsys):
    """The negative control of the test above."""
    s, printed = replay(tmp_path, TLOG, capsys)
    assert s["read"]["used_bytes"] == s["read"]["size_bytes"] == TLOG.stat().st_size
    assert "log_mostly_unread" not in printed


def test_a_diagnose_that_cannot_work_on_a_damaged_tlog_says_it_is_damaged(tmp_path, capsys):
    """One line and exit 2 (before: "no velocity over ground", as if the log had none)."""
    log = randomised(TLOG, tmp_path / "r.tlog", 0.1, 0)
    assert cli_main(["diagnose", str(log), "--out", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert re.search(r"only [\d.]+ % of r.tlog could be used: the file is damaged", err)


def test_prose_quoting_a_few_nmea_sentences_says_most_of_it_is_not_log_records(
        tmp_path, capsys):
    """A README quoting NMEA sentences in its prose (the Shenzhen data set's
    README_upstream.md: 4 sentences, 12.6 % used) replays as a 0.0 s log; before, with no
    word that most of the file was not read."""
    from onboard.drivers.nmea import encode_gga, encode_hdt

    prose = [f"Line {k} of a description of the data set, its receiver and its antennas."
             for k in range(16)]
    t = 1_733_365_638.8
    nmea = [encode_gga(t, 22.5, 113.9).decode().strip(), encode_hdt(1.0).decode().strip()]
    log = tmp_path / "README.md"
    log.write_text("\n".join(prose[:8] + nmea + prose[8:]) + "\n")
    s, printed = replay(tmp_path, log, capsys)
    first = s["warnings"][0]
    assert first["code"] == "log_mostly_unread"
    assert "of README.md could be used: the file is damaged, or mostly not log records" in (
        first["message"])
    assert s["read"]["used_bytes"] / s["read"]["size_bytes"] < 0.2  # measured 0.079


@pytest.mark.data
def test_small_tlog_with_a_tenth_of_its_bytes_randomised_is_read_to_its_end(
        tmp_path, capsys, shared_data):
    """The issue's own case: ArduSub's small.tlog, 10 % of its bytes randomised (seed 1).
    Before: "0.0 s, 1 sample"; measured now: 262.3 of 263.4 s, 6.1 % used."""
    log = randomised(shared_data / "ardusub_small_logs/small.tlog", tmp_path / "r.tlog",
                     0.1, 1)
    s, printed = replay(tmp_path, log, capsys)
    assert s["time_span"]["duration_s"] > 250.0
    assert s["warnings"][0]["code"] == "log_mostly_unread"
    assert_spans_sane(s, printed)


# ------------------------------------------------------------------ a damaged first stamp

@pytest.mark.parametrize("bit, words", [
    (40, "1,099,512 s (12.7 days) before the log's clock"),
    (39, "549,756 s (6.4 days) after the log's clock")], ids=["back", "ahead"])
def test_a_tlog_whose_first_stamp_has_a_flipped_bit_loses_that_record_only(
        tmp_path, capsys, bit, words):
    """A flipped bit of the first record's time: before, the log started on it and the
    rest came as a clock jump, a segment of one sample, a pipeline restart and a warning
    printed at ``[1099511.6-1099511.6 s]`` (bit 40) or ``[-549755.8--549755.8 s]``
    (bit 39); now it is one outlier and the log is whole."""
    data = bytearray(TLOG.read_bytes())
    data[TIMESTAMP_LEN - 1 - bit // 8] ^= 1 << (bit % 8)  # big-endian microseconds
    log = tmp_path / "flipped.tlog"
    log.write_bytes(bytes(data))
    clean, _ = replay(tmp_path / "clean", TLOG, capsys)
    s, printed = replay(tmp_path, log, capsys)
    assert len(s["time_span"]["segments"]) == 1
    assert s["time_span"]["duration_s"] == pytest.approx(clean["time_span"]["duration_s"])
    assert sum(n for k, n in s["rejected"].items() if k.endswith(":time_outlier")) == 1
    assert {w["code"] for w in s["warnings"]} - {w["code"] for w in clean["warnings"]} == {
        "time_outlier"}
    assert words in printed
    assert_spans_sane(s, printed)


@pytest.mark.data
@pytest.mark.parametrize("ms", [1e12, -1e12])
def test_a_blueboat_csv_whose_first_row_is_stamped_far_off_loses_that_row_only(
        tmp_path, capsys, shared_data, ms):
    """The issue's case: fixed_00000216.csv (486 rows, ms since boot) with its first
    row's time set to 1e12 ms (and -1e12). Before: 1 row kept, the rest time_backwards."""
    src = shared_data / "blueboat_sysid_ntnu/fixed_00000216.csv"
    lines = src.read_text().splitlines()
    cells = lines[1].split(",")
    cells[1] = repr(ms)
    lines[1] = ",".join(cells)
    log = tmp_path / "first.csv"
    log.write_text("\n".join(lines) + "\n")
    s, printed = replay(tmp_path, log, capsys, str(BLUEBOAT))
    assert s["read"]["records"] == 486 and s["read"]["by_type"]["row"] == 485
    assert s["read"]["rejected"]["time_outlier"] == 1
    assert "time_backwards" not in s["read"]["rejected"]
    assert s["time_span"]["duration_s"] == pytest.approx(48.4, abs=0.05)  # measured 48.4 s
    assert "log_mostly_unread" not in printed
    assert_spans_sane(s, printed)


# ------------------------------------------------------------ a real clock jump, in words

def test_a_clock_reset_prints_where_it_happened_and_from_what_stamp_to_what(
        tmp_path, capsys):
    """A logger clock that went back 1000 s after 10 s: before, the jump was printed at
    ``[-1000.0--1000.0 s]`` and ``time_span.end`` came before ``start``."""
    log = write_reset_tlog(tmp_path / "reset.tlog")
    s, printed = replay(tmp_path, log, capsys)
    (line,) = [ln for ln in printed.splitlines() if "time_jump" in ln]
    # its rows in estimates.csv, whose t counts from the first segment, named beside
    assert line.startswith("  time_jump [9.9-9.9 s; estimates.csv t -1000.0 to -1000.0]: "
                           "the log's clock went back 1,010 s "
                           "(16.8 min), from 2023-11-14 22:13:29.9 UTC to "
                           "2023-11-14 21:56:40.0 UTC")
    assert_spans_sane(s, printed)
