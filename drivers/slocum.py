"""Slocum glider binary logs (Teledyne Webb Research "dinkum binary" files) -> samples.

A Slocum glider writes its flight data as ``.dbd`` (every sensor it logs), ``.sbd``
(the short real-time subset sent home at each surfacing), ``.mbd`` (a medium subset) and
its science bay's as ``.ebd`` / ``.tbd`` / ``.nbd``; since 2020 the firmware can write
each of them LZ4-compressed (``.dcd``, ``.scd``, ``.mcd``, ``.ecd``, ``.tcd``, ``.ncd``).
One file is one mission segment, read here on its own.

The layout, as each file declares it (encoding version 5):

* an ASCII header of ``num_ascii_tags`` lines ``key: value`` (``sensors_per_cycle``,
  ``state_bytes_per_cycle``, ``sensor_list_crc``, ``sensor_list_factored``, ...);
* the sensor list, one line per sensor ``s: T|F <number> <index in cycle> <bytes>
  <name> <units>``, in the file, or, where ``sensor_list_factored`` is 1, in the cache
  file ``<sensor_list_crc>.cac`` (``.ccc`` compressed) that the glider's other files
  share (looked for beside the file, in its ``cac`` and ``cache`` folders, and in
  :data:`CACHE_ENV`);
* the known bytes: ``s``, ``a``, the integer 0x1234, the float 123.456 and the double
  123456789.12345, from which the byte order is read;
* one record per cycle: ``d``, two state bits per sensor in cycle order (four a byte,
  the first sensor in the high bits: 0 not updated, 1 updated with the value it had, 2
  updated with a new value, which follows), then the new values in cycle order, each
  of its sensor's size (1 byte a signed integer, 2 a signed integer, 4 a float, 8 a
  double); ``X`` ends the file.

The first cycles of a file carry every sensor's value as the glider had it when the
file was opened, fresh or hours old: the first cycle, and any that updates every sensor,
starts the values that later cycles repeat and gives no sample. A compressed file is a
sequence of LZ4 blocks, each after its length (two bytes, big-endian); it needs the
``lz4`` package.

Samples, each stamped with the cycle's ``m_present_time`` (POSIX s: UTC as is):

==================================  ===================================================
``m_gps_lat``, ``m_gps_lon``        GnssFix, where either was updated in the cycle (a
                                    fix: the glider at the surface). Degrees and
                                    decimal minutes (``DDMM.MMMM``, signed); 69696969 is
                                    the glider's "no value" and gives no fix.
``m_heading``, ``m_pitch``,         Attitude (rad; pitch nose up positive, as the glider
``m_roll``                          logs it), and Heading from ``m_heading``, where any
                                    was updated. The heading is taken as true north
                                    (:data:`HEADING_REFERENCE`).
``m_depth``                         Depth (m).
``c_fin``, ``m_battpos``,           ActuatorColumn, in the glider's units (rad, inches,
``m_de_oil_vol`` or                 cm^3), the pump's under column ``pump`` (a deep
``m_ballast_pumped``                glider's oil volume or a shallow one's ballast):
                                    the config's ``[inputs]`` maps them
                                    (``source = "column"``).
==================================  ===================================================

The glider's own depth-averaged current (``m_water_vx``, ``m_water_vy``) is not a sample:
it is the glider's estimate, not a measurement (pipeline ``dac`` makes its own, and
tests/test_slocum.py compares the two).

Rejections: ``"no_time"`` a cycle without ``m_present_time``; ``"truncated"`` a cycle
cut off by the end of the file; ``"garbage"`` a byte where a cycle's ``d`` should be (the
reader stops there: a state byte lost cannot be resynchronized); ``"no_fix"`` a
position that is the glider's "no value".
"""

from __future__ import annotations

import math
import os
import re
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from onboard.core.geo import wrap_2pi
from onboard.core.messages import ActuatorColumn, Attitude, Depth, GnssFix, Heading, Sample
from onboard.drivers.base import ReadStats, UnreadableLog, ddmm_degrees

LABEL = b"dbd_label:"
"""The first bytes of every (uncompressed) Slocum binary file."""
COMPRESSED_SUFFIXES = (".dcd", ".ecd", ".scd", ".tcd", ".mcd", ".ncd")
"""The LZ4-compressed files' suffixes (lower case)."""
FLIGHT_OF_SCIENCE = {".ebd": ".dbd", ".tbd": ".sbd", ".nbd": ".mbd", ".ecd": ".dcd",
                     ".tcd": ".scd", ".ncd": ".mcd"}
"""The science bay's files by suffix (CTD and other science sensors, stamped
``sci_m_present_time``: no navigation, not a log of the vehicle) and the suffix of the
flight file of the same name, which is."""
CACHE_ENV = "ONBOARD_SLOCUM_CACHE"
"""An environment variable naming one more folder of sensor-list cache files."""
NO_VALUE = 69696969.0
"""The glider's "no value" (e.g. an unset position)."""
HEADING_REFERENCE = "true"
"""``m_heading``'s north, as taken: the frame the glider navigates in (its waypoints and
dead reckoning are latitude and longitude). Not verified from the logs: the dead
reckoning (``m_lat``, ``m_lon``, less the glider's depth-averaged current) runs at a
constant angle to ``m_heading``, -1.0 deg on amadeus 2014-204-05-000 and +2.3 deg on
ammonite 2008-028-01-000, where the WMM declination is +1.3 and +0.8 deg: an offset the
glider applies, not the declination."""
SOURCE = "slocum"
"""The samples' ``source``."""
COLUMNS = {"c_fin": "c_fin", "m_battpos": "m_battpos", "m_de_oil_vol": "pump",
           "m_ballast_pumped": "pump"}
"""Sensors read as :class:`ActuatorColumn` samples, by the column each is read as: the
buoyancy pump's volume is ``m_de_oil_vol`` on a deep glider and ``m_ballast_pumped`` on a
shallow one (a file has one of them), column ``pump`` either way."""
GLIDER_NAME = re.compile(r"^(.+)-\d{4}-\d+-\d+-\d+$")
"""A file's full name: the glider's name, the year, the day, the mission and segment."""
KNOWN_INT = 0x1234
"""The integer of the known bytes."""

LZ4_BLOCK_MAX = 1 << 16
"""The largest decompressed block (bytes) the buffer takes: a block's compressed length is
two bytes, and the glider's blocks decompress to less."""

_VALUE_FORMATS = {1: "b", 2: "h", 4: "f", 8: "d"}


@dataclass(frozen=True)
class Sensor:
    """One sensor of a file's cycle."""

    name: str
    units: str
    size: int
    """Bytes of its value (1, 2, 4 or 8)."""


def _lz4_blocks(data: bytes, path: str | os.PathLike) -> bytes:
    """The bytes of a compressed file's LZ4 blocks, each after its two-byte length."""
    try:
        import lz4.block
    except ImportError:
        raise UnreadableLog(f"{path}: a compressed Slocum file needs the lz4 package "
                            "(pip install lz4, or 'onboard[batch]')") from None
    out = bytearray()
    i = 0
    while i + 2 <= len(data):
        (n,) = struct.unpack_from(">H", data, i)
        i += 2
        try:
            out += lz4.block.decompress(data[i:i + n], uncompressed_size=LZ4_BLOCK_MAX)
        except lz4.block.LZ4BlockError:
            raise UnreadableLog(f"{path}: a damaged LZ4 block at byte {i - 2}") from None
        i += n
    return bytes(out)


def read_bytes(path: str | os.PathLike) -> bytes:
    """A Slocum file's bytes, decompressed where it is compressed."""
    data = Path(path).read_bytes()
    if Path(path).suffix.lower() in (*COMPRESSED_SUFFIXES, ".ccc"):
        return _lz4_blocks(data, path)
    return data


def is_slocum(head: bytes, path: str | os.PathLike) -> bool:
    """Whether a file beginning with ``head`` is a Slocum binary file (a compressed one:
    by its suffix and the label in its first block's literal bytes)."""
    if head.startswith(LABEL):
        return True
    return Path(path).suffix.lower() in COMPRESSED_SUFFIXES and LABEL in head[:32]


def not_a_log(path: str | os.PathLike) -> str:
    """Why the file ``path`` of a glider's folder is not a vehicle log, by the glider's
    naming (a science-bay file, a sensor-list cache), or empty."""
    suffix = Path(path).suffix.lower()
    if suffix in (".cac", ".ccc"):
        return "a Slocum sensor-list cache file (the binary logs' sensor names)"
    if suffix not in FLIGHT_OF_SCIENCE:
        return ""
    return (f"a Slocum science-bay file ({suffix}: CTD and other science sensors, no "
            f"navigation); the flight file of the same name ({FLIGHT_OF_SCIENCE[suffix]}) "
            f"is the glider's log")


def _header(data: bytes, path: str | os.PathLike) -> tuple[dict[str, str], int]:
    """The ASCII header's tags and the offset after it."""
    tags: dict[str, str] = {}
    pos = 0
    while "num_ascii_tags" not in tags or len(tags) < int(tags["num_ascii_tags"]):
        end = data.find(b"\n", pos)
        if end < 0 or len(tags) > 100:
            raise UnreadableLog(f"{path}: the Slocum header ends early")
        key, sep, value = data[pos:end].decode("ascii", "replace").partition(":")
        if not sep:
            raise UnreadableLog(f"{path}: not a Slocum header line: {data[pos:end][:40]!r}")
        tags[key.strip()] = value.strip()
        pos = end + 1
        if not tags.get("num_ascii_tags", "0").isdigit():
            raise UnreadableLog(f"{path}: num_ascii_tags is {tags['num_ascii_tags']!r}")
    return tags, pos


def _sensor_lines(text: bytes, count: int, path: str | os.PathLike
                  ) -> tuple[list[Sensor], int]:
    """The in-cycle sensors of ``count`` sensor lines at the start of ``text`` (in cycle
    order) and the offset after them."""
    cycle: dict[int, Sensor] = {}
    pos = 0
    for _ in range(count):
        end = text.find(b"\n", pos)
        if end < 0:
            raise UnreadableLog(f"{path}: the Slocum sensor list ends early")
        parts = text[pos:end].decode("ascii", "replace").split()
        pos = end + 1
        try:
            if len(parts) < 6 or parts[0] != "s:":
                raise ValueError
            in_use, index, size = parts[1] == "T", int(parts[3]), int(parts[4])
        except ValueError:
            raise UnreadableLog(f"{path}: not a Slocum sensor line: {parts[:3]}") from None
        if in_use and index >= 0:
            if size not in _VALUE_FORMATS:
                raise UnreadableLog(f"{path}: sensor {parts[5]} of {size} bytes")
            cycle[index] = Sensor(parts[5], parts[6] if len(parts) > 6 else "", size)
    return [cycle[i] for i in sorted(cycle)], pos


def _cache_dirs(path: str | os.PathLike) -> list[Path]:
    folder = Path(path).resolve().parent
    dirs = [folder, folder / "cac", folder / "cache", folder.parent / "cac"]
    if os.environ.get(CACHE_ENV):
        dirs.append(Path(os.environ[CACHE_ENV]))
    return dirs


def _cached_sensors(crc: str, count: int, path: str | os.PathLike) -> list[Sensor]:
    """The sensor list of cache file ``<crc>.cac`` (or ``.ccc``)."""
    looked = _cache_dirs(path)
    for d in looked:
        for name in (f"{crc}.cac", f"{crc.upper()}.CAC", f"{crc}.ccc", f"{crc.upper()}.CCC"):
            f = d / name
            if f.is_file():
                return _sensor_lines(read_bytes(f), count, f)[0]
    raise UnreadableLog(
        f"{path}: its sensor list is in the glider's cache file {crc}.cac, found in none "
        f"of {', '.join(str(d) for d in looked)} (copy the glider's cache folder beside "
        f"the logs as cac/, or name it in {CACHE_ENV})")


class SlocumReader:
    """Iterate a Slocum binary file's samples (module docstring); ``stats`` fills as you
    go. ``tags`` is the file's header, ``sensors`` its cycle."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = path
        why = not_a_log(path)
        if why:
            raise UnreadableLog(f"{path}: {why}")
        self.stats = ReadStats()
        self.data = read_bytes(path)
        self.stats.size_bytes = len(self.data)
        self.tags, pos = _header(self.data, path)
        try:
            n_cycle = int(self.tags["sensors_per_cycle"])
            n_total = int(self.tags.get("total_num_sensors", n_cycle))
            self.state_bytes = int(self.tags["state_bytes_per_cycle"])
        except (KeyError, ValueError) as err:
            raise UnreadableLog(f"{path}: a Slocum header without {err}") from None
        if self.tags.get("sensor_list_factored", "0") == "1":
            self.sensors = _cached_sensors(self.tags.get("sensor_list_crc", "").lower(),
                                           n_total, path)
        else:
            self.sensors, used = _sensor_lines(self.data[pos:], n_total, path)
            pos += used
        if len(self.sensors) != n_cycle or self.state_bytes != (n_cycle + 3) // 4:
            raise UnreadableLog(f"{path}: {len(self.sensors)} sensors in cycle where the "
                                f"header says {n_cycle}")
        self._start = self._known_bytes(pos)

    @property
    def glider(self) -> str:
        """The glider's name, from the header's ``full_filename`` (``<glider>-<year>-<day>-
        <mission>-<segment>``, e.g. ``amadeus`` of ``amadeus-2014-204-5-0``); empty where
        the header has none."""
        m = GLIDER_NAME.match(self.tags.get("full_filename", ""))
        return m.group(1) if m else ""

    def _known_bytes(self, pos: int) -> int:
        """Read the byte order from the known bytes at ``pos``; the offset after them."""
        data = self.data
        if data[pos:pos + 2] != b"sa":
            raise UnreadableLog(f"{self.path}: no known-bytes record after the sensor list")
        for order in (">", "<"):
            if struct.unpack_from(order + "h", data, pos + 2)[0] == KNOWN_INT:
                self.order = order
                return pos + 16
        raise UnreadableLog(f"{self.path}: known bytes of no byte order")

    def __iter__(self) -> Iterator[Sample]:
        stats = self.stats
        wanted = {s.name: i for i, s in enumerate(self.sensors)}
        i_time = wanted.get("m_present_time")
        if i_time is None:
            raise UnreadableLog(
                f"{self.path}: a Slocum file without m_present_time: no navigation (a "
                f"flight file, .dbd, .sbd or .mbd, is a glider's log)")
        for values, updated in self.cycles():
            if i_time not in updated:
                stats.reject("no_time")
                continue
            for s in self._samples(values[i_time], values, updated, wanted):
                stats.samples += 1
                stats.by_type[type(s).__name__] += 1
                yield s

    def cycles(self) -> Iterator[tuple[list[float], set[int]]]:
        """Each cycle's values (every sensor's newest, in :attr:`sensors` order; the
        list is reused) and the indices of those updated in it, but for the dumps of
        every value that start a file (module docstring)."""
        data, stats = self.data, self.stats
        sizes = [s.size for s in self.sensors]
        fmts = [struct.Struct(self.order + _VALUE_FORMATS[s.size]) for s in self.sensors]
        n = len(sizes)
        values: list[float] = [math.nan] * n
        n_state = self.state_bytes
        pos, first = self._start, True
        stats.used_bytes = pos
        while pos < len(data):
            tag = data[pos]
            if tag == ord("X"):
                stats.used_bytes += 1
                break
            if tag != ord("d"):
                stats.reject("garbage")
                break
            state = data[pos + 1:pos + 1 + n_state]
            if len(state) < n_state:
                stats.reject("truncated")
                break
            p = pos + 1 + n_state
            updated: set[int] = set()
            try:
                for k in range(n):
                    bits = (state[k >> 2] >> (6 - 2 * (k & 3))) & 3
                    if bits:
                        updated.add(k)
                        if bits == 2:
                            values[k] = fmts[k].unpack_from(data, p)[0]
                            p += sizes[k]
            except struct.error:
                stats.reject("truncated")
                break
            stats.records += 1
            stats.used_bytes += p - pos
            pos = p
            if first or len(updated) == n:  # a dump of every value: the start
                first = False
                continue
            yield values, updated

    def _samples(self, t: float, values: list[float], updated: set[int],
                 wanted: dict[str, int]) -> Iterator[Sample]:
        """The samples of one cycle at ``t`` (module docstring's table)."""
        def new(name: str) -> bool:
            i = wanted.get(name)
            return i is not None and i in updated

        def value(name: str) -> float:
            i = wanted.get(name)
            return values[i] if i is not None else math.nan

        if new("m_gps_lat") or new("m_gps_lon"):
            lat, lon = _degrees(value("m_gps_lat"), 90.0), _degrees(value("m_gps_lon"), 180.0)
            if lat is None or lon is None:
                self.stats.reject("no_fix")
            else:
                yield GnssFix(t=t, source=SOURCE, lat_deg=lat, lon_deg=lon)
        if new("m_heading") or new("m_pitch") or new("m_roll"):
            psi, pitch, roll = wrap_2pi(value("m_heading")), value("m_pitch"), value("m_roll")
            if math.isfinite(psi) and math.isfinite(pitch) and math.isfinite(roll):
                yield Attitude(t=t, source=SOURCE, roll_rad=roll, pitch_rad=pitch, yaw_rad=psi)
            if new("m_heading") and math.isfinite(psi):
                yield Heading(t=t, source=SOURCE, heading_rad=psi, reference=HEADING_REFERENCE)
        if new("m_depth") and math.isfinite(value("m_depth")):
            yield Depth(t=t, source=SOURCE, depth_m=value("m_depth"))
        for name, column in COLUMNS.items():
            if new(name) and math.isfinite(value(name)):
                yield ActuatorColumn(t=t, source=SOURCE, column=column, value=value(name))


def _degrees(ddmm: float, max_deg: float) -> float | None:
    """Degrees of a signed ``DDMM.MMMM``; None where it is no position (the glider's
    "no value", minutes of 60 or more, beyond ``max_deg``)."""
    d = ddmm_degrees(ddmm) if ddmm != NO_VALUE else None
    return d if d is not None and abs(d) <= max_deg else None
