"""A log's format is sniffed from its content, its name only breaking ties
(drivers/logs.py, architecture.md §4.1): an NMEA capture saved as ``.tlog`` or ``.csv``,
a CSV log saved as ``.txt``, a tlog saved as ``.txt`` are each read as what they hold,
and every file read before by its name is read the same way."""

from __future__ import annotations

import shutil
from pathlib import Path

import msgspec
import pytest

from onboard.cli import main as cli_main
from onboard.core.config import CONFIG_DIR, load
from onboard.drivers.base import UnreadableLog
from onboard.drivers.csvlog import looks_like_table
from onboard.drivers.logs import open_log, sniff, tlog_head

DATA = Path(__file__).resolve().parent / "data"
NMEA = DATA / "nmea" / "gnss-compass.nmea"
CSV = DATA / "csv" / "blueboat-run.csv"
TLOG = DATA / "replay" / "jaiabot-turns.tlog"
DVL = DATA / "dvl_json" / "a50.jsonl"
PD6 = DATA / "pd6" / "ensembles.pd6"
ARDUINO = DATA / "survey_boat" / "arduino-gps.txt"
BLUEBOAT = CONFIG_DIR / "blueboat-ntnu-csv.toml"


def _copy(src: Path, dst: Path) -> Path:
    shutil.copyfile(src, dst)
    return dst


def _samples(path: Path, cfg=None) -> list[bytes]:
    _, reader = open_log(path, cfg.csv if cfg is not None else None)
    return [msgspec.json.encode(s) for s in reader]


@pytest.mark.parametrize("name", ["capture.tlog", "capture.csv", "capture.bin.txt"])
def test_an_nmea_capture_is_read_as_nmea_whatever_its_name(tmp_path, name):
    log = _copy(NMEA, tmp_path / name)
    assert sniff(log) == "text"
    assert _samples(log) == _samples(NMEA)


@pytest.mark.parametrize("src", [DVL, PD6], ids=["dvl-json", "pd6"])
def test_other_text_captures_named_tlog_or_csv_are_read_as_text(tmp_path, src):
    for suffix in (".tlog", ".csv"):
        log = _copy(src, tmp_path / f"capture{suffix}")
        assert sniff(log) == "text", suffix
        assert _samples(log) == _samples(src)


def test_a_csv_log_named_txt_is_read_as_csv(tmp_path):
    cfg = load(BLUEBOAT)
    log = _copy(CSV, tmp_path / "blueboat-run.txt")   # its runs are named by the stem
    assert sniff(log) == "csv"
    assert _samples(log, cfg) == _samples(CSV, cfg)
    # without a mapping it is refused as a CSV log is, naming the config that fits
    assert cli_main(["replay", str(log), "--out", str(tmp_path / "r"), "--no-plot"]) == 2


def test_a_csv_log_named_txt_replays_as_the_csv(tmp_path, capsys):
    log = _copy(CSV, tmp_path / "run.txt")
    for src, out in ((CSV, "a"), (log, "b")):
        assert cli_main(["replay", str(src), "--config", str(BLUEBOAT), "--out",
                         str(tmp_path / out), "--no-plot"]) == 0
    assert (tmp_path / "a" / "estimates.csv").read_bytes() == \
        (tmp_path / "b" / "estimates.csv").read_bytes()


def test_an_nmea_capture_named_tlog_replays(tmp_path, capsys):
    log = _copy(NMEA, tmp_path / "capture.tlog")
    assert cli_main(["replay", str(log), "--out", str(tmp_path / "r"), "--no-plot"]) == 0
    assert capsys.readouterr().out.startswith("text log")


@pytest.mark.parametrize("name", ["flight.txt", "flight.csv", "flight"])
def test_a_tlog_is_read_as_a_tlog_whatever_its_name(tmp_path, name):
    log = _copy(TLOG, tmp_path / name)
    assert tlog_head(log.read_bytes()[:4096]) and sniff(log) == "tlog"


def test_the_name_breaks_the_ties(tmp_path):
    # a tlog whose first record is damaged: still a tlog by its name
    data = bytearray(TLOG.read_bytes()[:20000])
    data[8:40] = b"\x00" * 32
    damaged = tmp_path / "damaged.tlog"
    damaged.write_bytes(bytes(data))
    assert not tlog_head(bytes(data)) and sniff(damaged) == "tlog"
    # prose named .tlog or .csv is for those readers to refuse, as before
    prose = "A note about the day's runs, with no log in it.\n"
    for suffix, fmt in ((".tlog", "tlog"), (".csv", "csv"), (".txt", "text")):
        p = tmp_path / f"note{suffix}"
        p.write_text(prose)
        assert sniff(p) == fmt
    # a CSV table that a capture's reader would also take: CSV when named so
    both = tmp_path / "both"
    both.write_text("t,sentence\n" + "".join(
        f'{i},"$GPHDT,{i}.0,T*{_nmea_checksum(f"GPHDT,{i}.0,T")}"\n' for i in range(10)))
    assert looks_like_table(both.read_bytes())
    assert sniff(_copy(both, tmp_path / "both.csv")) == "csv"
    assert sniff(_copy(both, tmp_path / "both.txt")) == "text"


def test_status_lines_with_commas_are_no_table():
    status = b"".join(b"2024-12-05 10:37:%02d INFO status: waiting for GNSS, battery 12.%d V, "
                      b"link ok\n" % (i, i % 10) for i in range(30))
    assert not looks_like_table(status)
    assert looks_like_table(CSV.read_bytes()[:65536])


def test_the_survey_boat_capture_is_no_table_and_binary_is_refused(tmp_path):
    assert not looks_like_table(ARDUINO.read_bytes())
    assert sniff(_copy(ARDUINO, tmp_path / "capture.csv")) == "text"
    junk = tmp_path / "junk.dat"
    junk.write_bytes(b"\x01\x00\x02" * 100)
    with pytest.raises(UnreadableLog, match="binary data"):
        sniff(junk)


def _nmea_checksum(body: str) -> str:
    c = 0
    for ch in body.encode():
        c ^= ch
    return f"{c:02X}"
