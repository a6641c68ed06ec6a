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


def sniff(path: str | Path) -> str:
    """The format of ``path``: tlog, dataflash, recording, mcap, slocum, csv, csv-dir or
    text."""
    p = Path(path)
    if p.is_dir():
        if any(p.glob("*.onbrec")):
            return "recording"
        if any(p.glob("*.csv")):
            return "csv-dir"
        raise UnreadableLog(f"{p}: a directory with no .csv or .onbrec files")
    try:
        with open(p, "rb") as f:
            head = f.read(4096)
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
    suffix = p.suffix.lower()
    if suffix == ".tlog" or (len(head) > 9 and head[8] in (MAGIC_V1, MAGIC_V2)):
        return "tlog"
    if suffix == ".csv":
        return "csv"
    if b"\x00" in head:
        raise UnreadableLog(f"{p}: binary data in no format this tool reads")
    return "text"


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
