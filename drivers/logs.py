"""Open any supported log by sniffing its content, not trusting its name alone.

Supported: MAVLink telemetry logs (``.tlog``), ArduPilot DataFlash (``.bin``), MCAP
recordings of BlueOS's MAVLink (``.mcap``), Slocum glider binary logs (:mod:`drivers.slocum`),
the service's own recordings, NMEA / Water Linked DVL JSON / PD6 text captures, and CSV
(one file or a directory of runs, which needs a ``[csv]`` mapping in the config).
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from onboard.drivers.base import LogReader, UnreadableLog

DATAFLASH_MAGIC = b"\xa3\x95"
MCAP_MAGIC = b"\x89MCAP0\r\n"
"""The first bytes of an MCAP file (a BlueOS 1.5 recording: :mod:`drivers.mcap_log`)."""
HEAD_BYTES = 4096
"""Bytes a file's binary headers are looked for in."""
TEXT_HEAD_BYTES = 65536
"""Bytes of a file without a NUL in its first :data:`HEAD_BYTES` that its text is judged
by (a capture's kind, a CSV table)."""
TLOG_STAMP_BYTES = 8
"""The time stamp before each frame of a tlog (us since the epoch, big-endian)."""


def sniff(path: str | Path) -> str:
    """The format of ``path``: tlog, dataflash, recording, mcap, slocum, csv, csv-dir or
    text.

    The content decides: a recording's, DataFlash's, MCAP's or Slocum's header; a MAVLink
    frame with a good checksum after a tlog's 8-byte time stamp (:func:`tlog_head`); text
    that a text capture's reader recognises (:func:`drivers.textlog.sniff_text`) or a CSV
    table (:func:`drivers.csvlog.looks_like_table`). The name breaks the ties: a ``.csv``
    file that is a table as well as a capture is read as CSV; content that is none of
    these is a tlog when its name ends ``.tlog`` or a start byte follows its first 8 bytes
    (a tlog damaged from its first record), CSV when it ends ``.csv`` (the CSV reader says
    what it lacks), else text (the text reader says what it looked for)."""
    p = Path(path)
    if p.is_dir():
        if any(p.glob("*.onbrec")):
            return "recording"
        if any(p.glob("*.csv")):
            return "csv-dir"
        raise UnreadableLog(f"{p}: a directory with no .csv or .onbrec files")
    try:
        with open(p, "rb") as f:
            head = f.read(HEAD_BYTES)
            text_head = b"" if b"\x00" in head else head + f.read(TEXT_HEAD_BYTES - len(head))
    except OSError as err:
        raise UnreadableLog(f"{p}: {err.strerror or err}") from None
    if not head:
        raise UnreadableLog(f"{p}: empty file")
    from onboard.drivers.recording import file_version

    if file_version(head) is not None:
        return "recording"
    if head.startswith(DATAFLASH_MAGIC):
        return "dataflash"
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    from onboard.drivers.mavlink_frame import MAGIC_V1, MAGIC_V2
    from onboard.drivers.slocum import is_slocum

    if is_slocum(head, p):
        return "slocum"
    if tlog_head(head):
        return "tlog"
    suffix = p.suffix.lower()
    if text_head:
        kind = _text_kind(text_head, suffix)
        if kind:
            return kind
    if suffix == ".tlog" or (len(head) > TLOG_STAMP_BYTES + 1
                             and head[TLOG_STAMP_BYTES] in (MAGIC_V1, MAGIC_V2)):
        return "tlog"
    if suffix == ".csv":
        return "csv"
    if b"\x00" in head:
        raise UnreadableLog(f"{p}: binary data in no format this tool reads")
    return "text"


def tlog_head(head: bytes) -> bool:
    """Whether ``head``, a file's first bytes, starts as a tlog: an 8-byte time stamp, then
    a MAVLink 1 or 2 frame of an id in the dialect with a good checksum, or, for an id
    outside it, followed by the next record's start byte (or the end of ``head``)."""
    from onboard.drivers.mavlink_frame import (CRC_EXTRA, MAGIC_V1, MAGIC_V2, crc_matches,
                                               header_at)

    j = TLOG_STAMP_BYTES
    hdr = header_at(head, j, len(head)) if len(head) > j else None
    if hdr is None:
        return False
    header_len, payload_len, _, _, _, msgid, end = hdr
    if msgid in CRC_EXTRA:
        return end <= len(head) and crc_matches(head, j, header_len, payload_len,
                                                CRC_EXTRA[msgid])
    nxt = end + TLOG_STAMP_BYTES
    return nxt >= len(head) or head[nxt] in (MAGIC_V1, MAGIC_V2)


def _text_kind(head: bytes, suffix: str) -> str:
    """``text`` or ``csv`` for the first bytes of a file without a NUL, by content (the
    name ``suffix`` breaks a tie: a ``.csv`` table that a capture's reader would also
    take is CSV); empty when it is neither."""
    from onboard.drivers.csvlog import looks_like_table
    from onboard.drivers.textlog import sniff_text

    table = looks_like_table(head)
    if sniff_text(head) and not (table and suffix == ".csv"):
        return "text"
    return "csv" if table else ""


def open_log(path: str | Path, csv_format=None,
             actuator_columns: Sequence[str] = ()) -> tuple[str, LogReader]:
    """(format, reader) for ``path``. ``csv_format`` is the config's [csv] section;
    ``actuator_columns`` the columns ``[inputs]`` maps with ``source = "column"``, read
    by the CSV reader as ``ActuatorColumn`` samples (other formats have no columns:
    :class:`UnreadableLog`)."""
    fmt = sniff(path)
    if fmt == "slocum":
        from onboard.drivers.slocum import SlocumReader

        return fmt, SlocumReader(path)
    if actuator_columns and fmt not in ("csv", "csv-dir"):
        raise UnreadableLog(
            f"{path}: [inputs] reads column(s) {', '.join(map(repr, actuator_columns))} "
            f'(source = "column"), but a {fmt} log has no columns')
    if fmt == "tlog":
        from onboard.drivers.tlog import TlogReader

        return fmt, TlogReader(path)
    if fmt == "dataflash":
        from onboard.drivers.dataflash import DataflashReader

        return fmt, DataflashReader(path)
    if fmt == "mcap":
        from onboard.drivers.mcap_log import McapReader

        return fmt, McapReader(path)
    if fmt == "recording":
        from onboard.drivers.recording import RecordingReader

        if Path(path).is_dir():
            files = sorted(Path(path).glob("*.onbrec"))
            return fmt, RecordingReader(files[0])
        return fmt, RecordingReader(path)
    if fmt in ("csv", "csv-dir"):
        if csv_format is None or not (csv_format.lat_deg or csv_format.north_m):
            raise UnreadableLog(
                f"{path}: CSV logs need --config with a [csv] column mapping "
                "(e.g. config/blueboat-ntnu-csv.toml)")
        from onboard.drivers.csvlog import CsvReader

        return fmt, CsvReader(path, csv_format, actuator_columns=actuator_columns)
    from onboard.drivers.textlog import open_text_log

    return fmt, open_text_log(path)


# ---------------------------------------------------------------- which files are logs

LOG_SUFFIXES = frozenset({".tlog", ".bin", ".mcap", ".onbrec"})
"""File name endings that mark a log: such a file that cannot be read fails (a broken
log), where any other file the readers do not recognise is skipped (not a log)."""
DOCUMENT_SUFFIXES = frozenset({".md", ".rst", ".adoc", ".htm", ".html", ".tex"})
"""File name endings of documents: in a folder searched for logs they are skipped, even
when they quote a few log lines (a data set's README with a sample NMEA sentence)."""
TIME_NAMES = frozenset({"t", "ts", "utc", "date", "datetime", "epoch", "sec", "secs",
                        "seconds", "ms", "tow"})
"""CSV column names (lower case) that name a time; so does any name with ``time`` or
``stamp`` in it, and the ``[csv] time`` of a ``--config``. A CSV file found in a folder
with none of them is a table, not a log (a log is a time series)."""


def is_log_dir(p: Path, times: frozenset[str] = frozenset()) -> bool:
    """A folder that is one log, as ``onboard replay`` reads it: it holds ``.onbrec``
    files (a service recording), or ``.csv`` files with one header that has a time
    column (runs of one CSV log) and no other file the readers recognise (a README
    beside them is fine; a folder of CSV files and tlogs, or of CSV files with different
    headers, is searched instead, each CSV file a log)."""
    from onboard.drivers.csvlog import run_files

    if not p.is_dir():
        return False
    if any(p.glob("*.onbrec")):
        return True
    try:
        first = run_files(p)[0]
    except UnreadableLog:   # no .csv, or not one logger's runs
        return False
    return not _untimed(first, times) and all(
        is_log(f, times) for f in p.iterdir() if f.is_file() and f.suffix.lower() != ".csv")


def is_log(path: Path, times: frozenset[str] = frozenset()) -> str:
    """Empty when the readers recognise ``path`` as a log (or its name says it is one,
    :data:`LOG_SUFFIXES`); else why it is not one (a document, :data:`DOCUMENT_SUFFIXES`,
    never is; nor is a CSV table without a time column, :data:`TIME_NAMES`, ``times``)."""
    if path.suffix.lower() in LOG_SUFFIXES:
        return ""
    if path.suffix.lower() in DOCUMENT_SUFFIXES:
        return f"a document ({path.suffix.lower()})"
    from onboard.drivers.slocum import not_a_log

    glider_file = not_a_log(path)   # a glider's science file or sensor cache
    if glider_file:
        return glider_file
    try:
        fmt = sniff(path)
    except UnreadableLog as err:
        return _reason(err, path)
    if fmt == "csv":
        return _untimed(path, times)
    if fmt != "text":
        return ""
    from onboard.drivers.textlog import open_text_log

    try:
        open_text_log(path)
    except UnreadableLog as err:
        return _reason(err, path)
    return ""


def _untimed(path: Path, times: frozenset[str]) -> str:
    """Why the CSV file ``path`` is a table and not a log: its header names no time
    (:data:`TIME_NAMES`, ``times``), or holds control characters (binary data named
    ``.csv``); empty when it names a time."""
    from onboard.drivers.csvlog import csv_header

    try:
        with open(path, "rb") as f:
            first = f.read(HEAD_BYTES).split(b"\n", 1)[0]
    except OSError as err:
        return err.strerror or str(err)
    if any(b < 32 and b not in b"\t\r" for b in first):
        return "binary data in no format this tool reads"
    header = csv_header(path)
    for name in header:
        n = name.lower()
        if n in TIME_NAMES or n in times or "time" in n or "stamp" in n:
            return ""
    shown = ", ".join(header[:6]) + (", ..." if len(header) > 6 else "")
    return (f"a CSV table with no time column ({shown}); a CSV log's time column is its "
            "config's [csv] time, give it with --config")


def _reason(err: BaseException, path: Path | str) -> str:
    """The one-line reason of ``err``, without the path it names (its lines joined with
    ``; ``)."""
    text = "; ".join(ln.strip() for ln in str(err).strip().splitlines() if ln.strip())
    prefix = f"{path}: "
    return text[len(prefix):] if text.startswith(prefix) else text
