"""MAVLink telemetry logs (``.tlog``, as written by QGroundControl, MAVProxy, Mission Planner).

A tlog is a sequence of records ``[8-byte big-endian receive time, us since the epoch]
[one MAVLink 1 or 2 frame]`` with nothing in between. :class:`TlogReader` walks it by
record: the frame's length byte gives the next record's start, so unneeded messages are
skipped without being decoded. Every frame whose id is in the dialect is CRC-checked
(about 0.6 us, see :mod:`drivers.mavlink`).

Time base: ``Sample.t`` is the record's receive time in seconds since the epoch (the
logger's clock), never the autopilot's boot time inside the message.

Rejections (``stats.rejected``): ``"crc"`` bad checksum; ``"garbage"`` bytes that are not a
record (the reader resynchronizes on the next plausible record: start byte, fitting frame,
valid CRC; for an id outside the dialect, whose CRC cannot be checked, a time stamp within
[-1 s, +1 day] of the last good record and the start of another record after it); ``"truncated"``
an incomplete record at the end of the file; ``"incompat"`` unknown MAVLink 2
incompatibility flags; ``"timestamp"`` a record whose time stamp (which the CRC does not
cover) jumps more than a second ahead of both its neighbours; ``"time_backwards"`` a
record older than the last sample emitted by up to ``drivers.base.TIME_JUMP_S`` (dropped,
so samples come out in time order; one further back is passed on for the engine's time
line: a clock reset starts a segment, a single bad stamp is a counted outlier); plus the content rejections of the
handlers (``"no_fix"``, ``"empty"``, ``"nan"``, ``"invalid"``, ...).
"""

from __future__ import annotations

import binascii
import os
import struct
import time
from collections import Counter
from pathlib import Path
from typing import BinaryIO, Iterable, Iterator

from mypy_extensions import mypyc_attr

from onboard.drivers.base import (
    RELEASE_BYTES, TIME_JUMP_S, LogBytes, MappedLog, ReadStats, UnreadableLog)
from onboard.drivers.mavlink import (
    DecodeContext,
    Spec,
    _layout,
    select,
    type_name,
    wanted_types,
)
from onboard.drivers.mavlink_frame import (
    BIT_REVERSED,
    BIT_REVERSED_BYTE,
    BIT_REVERSED_HIGH,
    CRC_EXTRA,
    CRC_LEN,
    HEADER_LEN_V1,
    HEADER_LEN_V2,
    IFLAG_SIGNED,
    MAGIC_V1,
    MAGIC_V2,
    SIGNATURE_LEN,
    START_BYTES,
    crc_matches,
    header_at,
)
from onboard.core.messages import Parameter, Sample, VehicleInfo

_TS = struct.Struct(">Q")
TIMESTAMP_LEN = _TS.size
"""Bytes of a record's receive time, before its frame."""
_PROBE_BYTES = 1 << 16
"""How far into the file :class:`TlogReader` looks for a first valid record."""
_RESYNC_BACK_US = 1_000_000
_RESYNC_AHEAD_US = 86_400_000_000


def _frame_at(data: LogBytes, p: int, n: int) -> tuple[int, int, int, int, int, bool] | None:
    """Framing of the record starting at ``p``: (end, msgid, payload start, payload length,
    incompat flags, v2), or None when the bytes there cannot be a complete record (a time
    stamp of 2^56 us or more, no start byte, a frame running past ``n``)."""
    if p < 0 or p + TIMESTAMP_LEN + 1 > n or data[p] != 0:
        return None
    h = header_at(data, p + TIMESTAMP_LEN, n)
    if h is None:
        return None
    hdr, plen, inc, _, _, msgid, end = h
    if end > n:
        return None
    return end, msgid, p + TIMESTAMP_LEN + hdr, plen, inc, hdr == HEADER_LEN_V2


def _crc_ok(data: LogBytes, p: int, msgid: int, plen: int, v2: bool) -> bool | None:
    """CRC of the frame of the record at ``p``: True/False, None when the id is unknown."""
    extra = CRC_EXTRA.get(msgid)
    if extra is None:
        return None
    hdr = HEADER_LEN_V2 if v2 else HEADER_LEN_V1
    return crc_matches(data, p + TIMESTAMP_LEN, hdr, plen, extra)


_JUMP_US = 1_000_000
"""A record more than this far (us) ahead of the previous one, while the next record is
back nearer the previous one than to it, has a damaged time stamp."""
_BACK_US = int(TIME_JUMP_S * 1e6)
"""A record further back than this (us) is passed on for the engine's time line."""


def _plausible(data: LogBytes, p: int, n: int, lo: int, hi: int) -> int:
    """End of a believable record at ``p``, else -1: framing and a valid CRC, whatever
    its time stamp (which the CRC does not cover: a damaged one must not make the reader
    skip the rest of the file), or, for an id outside the dialect (no CRC to check), a
    time stamp in [lo, hi] and a following record start."""
    f = _frame_at(data, p, n)
    if f is None:
        return -1
    end, msgid, _, plen, inc, v2 = f
    if inc & ~IFLAG_SIGNED:
        return -1
    ok = _crc_ok(data, p, msgid, plen, v2)
    if ok is None:
        ok = lo <= _TS.unpack_from(data, p)[0] <= hi and (
            end == n or (end + TIMESTAMP_LEN + 1 <= n and data[end] == 0
                         and data[end + TIMESTAMP_LEN] in (MAGIC_V1, MAGIC_V2)))
    return end if ok else -1


def _resync(data: LogBytes, start: int, n: int, lo: int, hi: int) -> int:
    """Start of the first believable record at or after ``start``, or -1."""
    for m in START_BYTES.finditer(data, start + TIMESTAMP_LEN):
        p = m.start() - TIMESTAMP_LEN
        if _plausible(data, p, n, lo, hi) >= 0:
            return p
    return -1


@mypyc_attr(allow_interpreted_subclasses=True)
class TlogReader:
    """Samples of a MAVLink telemetry log, in time order (see the module docstring).

    ``types`` restricts the samples produced (Sample classes or tags such as ``"imu"``);
    only the messages producing them are decoded. ``verify`` = ``"all"`` (default)
    CRC-checks every frame of a known id, so a corrupt frame of any message is counted;
    ``"needed"`` checks only the decoded ones (faster, for quick scans).
    ``include_gcs`` keeps ground-station HEARTBEATs.

    Raises :class:`UnreadableLog` at construction when the file cannot be read, is empty,
    or has no valid tlog record in its first 64 KiB. Nothing else raises: ``stats``
    (reset at each iteration) counts what was skipped.
    """

    def __init__(self, path: str | os.PathLike, *, types: Iterable[type | str] | None = None,
                 verify: str = "all", include_gcs: bool = False) -> None:
        if verify not in ("all", "needed"):
            raise ValueError("verify must be 'all' or 'needed'")
        self.path = Path(path)
        self.stats = ReadStats()
        self._specs = select(types)
        self._want = wanted_types(types)
        self._verify_all = verify == "all"
        self._include_gcs = include_gcs
        try:
            with open(self.path, "rb") as f:
                head = f.read(_PROBE_BYTES + 300)
        except OSError as e:
            raise UnreadableLog(f"{self.path}: {e.strerror or e}") from e
        if not head:
            raise UnreadableLog(f"{self.path}: empty file")
        self._first = _resync(head, 0, len(head), 0, 1 << 63)
        if self._first < 0 or self._first > _PROBE_BYTES:
            raise UnreadableLog(f"{self.path}: not a MAVLink telemetry log (no valid tlog record)")

    release_bytes = RELEASE_BYTES
    """Pages behind the reader are released every this many bytes (:class:`MappedLog`)."""

    def _open(self) -> MappedLog:
        """The log's bytes, mapped (:class:`MappedLog`)."""
        return MappedLog(self.path, self.release_bytes)

    def __iter__(self) -> Iterator[Sample]:
        mapped = self._open()
        try:
            yield from self._walk(mapped)
        finally:
            mapped.close()

    def _walk(self, mapped: MappedLog) -> Iterator[Sample]:
        data = mapped.data
        release = mapped.release
        stats = self.stats = ReadStats()
        ctx = DecodeContext(stats, self._include_gcs)
        counts: Counter[int] = Counter()
        n = len(data)
        specs = self._specs
        spec_get = specs.get
        crc_get = CRC_EXTRA.get
        verify_all = self._verify_all
        want = self._want
        ts_unpack = _TS.unpack_from
        crc_hqx = binascii.crc_hqx
        rev, rev_byte, rev_high = BIT_REVERSED, BIT_REVERSED_BYTE, BIT_REVERSED_HIGH
        V2, V1 = MAGIC_V2, MAGIC_V1
        TS, SIGNED, SIG = TIMESTAMP_LEN, IFLAG_SIGNED, SIGNATURE_LEN
        HDR2, HDR1 = HEADER_LEN_V2, HEADER_LEN_V1
        TAIL2, TAIL1 = HEADER_LEN_V2 + CRC_LEN, HEADER_LEN_V1 + CRC_LEN
        pos = self._first
        if pos > 0:
            stats.reject("garbage")
        last_us = 0  # time stamp of the last record decoded (us)
        good = -1  # start of the last good record
        records = 0
        used = 0  # bytes of the records read whole
        n_samples = 0
        try:
            while pos < n:
                if pos >= mapped.next_release:
                    release(pos)
                # ---- framing: _frame_at and drivers.mavlink_frame.header_at inlined, for
                # speed (offsets from the frame's start byte f as in mavlink_frame)
                reason = None
                end = -1
                f = pos + TS
                if f < n and data[pos] == 0:
                    m = data[f]
                    if m == V2:
                        if f + HDR2 <= n:
                            plen = data[f + 1]
                            inc = data[f + 2]
                            end = f + TAIL2 + plen + (SIG if inc & SIGNED else 0)
                            msgid = data[f + 7] | (data[f + 8] << 8) | (data[f + 9] << 16)
                            hdr, v2 = HDR2, True
                    elif m == V1:
                        if f + HDR1 <= n:
                            plen = data[f + 1]
                            end = f + TAIL1 + plen
                            msgid = data[f + 5]
                            hdr, v2, inc = HDR1, False, 0
                    else:
                        reason = "garbage"
                    if reason is None and (end < 0 or end > n):
                        reason = "truncated"
                else:
                    reason = "garbage" if f < n else "truncated"
                if reason is None:
                    next_ok = end == n or (end + TS < n and data[end] == 0
                                           and data[end + TS] in (V1, V2))
                    if inc & ~SIGNED:
                        reason = "incompat"
                    else:
                        extra = crc_get(msgid)
                        spec = spec_get(msgid)
                        if extra is None:
                            if not next_ok:
                                reason = "garbage"
                        elif spec is not None or verify_all:
                            # drivers.mavlink_frame.crc_matches inlined
                            ce = f + hdr + plen
                            c = crc_hqx(data[f + 1:ce].translate(rev), 0xFFFF)
                            c = crc_hqx(rev_byte[extra], c)
                            if (rev_high[c & 0xFF] | rev[c >> 8]) != data[ce] | (data[ce + 1] << 8):
                                reason = "crc"
                    if reason is None:
                        records += 1
                        used += end - pos
                        counts[msgid if extra is not None else -1 - msgid] += 1
                        good = pos
                        if spec is not None:
                            ts = ts_unpack(data, pos)[0]
                            if last_us - _BACK_US <= ts < last_us:
                                stats.reject("time_backwards")
                            elif (last_us and ts > last_us + _JUMP_US and end + TS <= n
                                  and ts_unpack(data, end)[0] < (ts + last_us) // 2):
                                # The time stamp is outside the CRC: a damaged one jumps far
                                # ahead of both its neighbours. Trusting it would drop every
                                # later record as "backwards".
                                stats.reject("timestamp")
                            else:
                                last_us = ts
                                ps = f + hdr
                                if plen >= spec.size:
                                    values = spec.struct.unpack_from(data, ps)
                                else:  # v2 zero-truncated payload (or v1 without extensions)
                                    values = spec.struct.unpack(data[ps:ps + plen]
                                                                + bytes(spec.size - plen))
                                if v2:
                                    res = spec.handler(values, ts / 1e6, data[f + 5], data[f + 6],
                                                       msgid, True, ctx)
                                else:
                                    res = spec.handler(values, ts / 1e6, data[f + 3], data[f + 4],
                                                       msgid, False, ctx)
                                if res is not None:
                                    if isinstance(res, list):
                                        for s in res:
                                            if want is None or isinstance(s, want):
                                                n_samples += 1
                                                yield s
                                    elif want is None or isinstance(res, want):
                                        n_samples += 1
                                        yield res
                        if next_ok:
                            pos = end
                            continue
                        # the frame was fine but what follows is not a record
                        pos = end - 1
                        reason = "garbage" if end + TS < n else "truncated"
                    elif next_ok and reason in ("crc", "incompat"):
                        # a corrupt frame inside intact framing: skip just this record
                        records += 1
                        stats.reject(reason)
                        pos = end
                        continue
                # ---- lost the framing: count once, resynchronize
                stats.reject(reason)
                stats.records = records
                stats.samples = n_samples
                ref = ts_unpack(data, good)[0] if good >= 0 else last_us
                lo = max(0, ref - _RESYNC_BACK_US) if good >= 0 else 0
                hi = ref + _RESYNC_AHEAD_US if good >= 0 else 1 << 63
                nxt = _resync(data, pos + 1, n, lo, hi)
                if nxt < 0:
                    break
                pos = nxt
        finally:
            stats.records = records
            stats.samples = n_samples
            stats.size_bytes = n
            stats.used_bytes = used
            for k, c in counts.items():
                stats.by_type[type_name(k)] += c


_PARAM_VALUE = "PARAM_VALUE"
_GCS_MAV_TYPES = frozenset({6, 18, 26})
"""HEARTBEAT MAV_TYPEs of ground stations, companion computers, gimbals: not the vehicle
(as in :mod:`onboard.offline.autodetect`)."""


def scan_header(path: str | os.PathLike) -> tuple[list[VehicleInfo], list[Parameter]]:
    """Quick pass over a tlog decoding only HEARTBEAT and PARAM_VALUE.

    Returns the distinct vehicle heartbeats (first occurrence of each (system, component,
    MAV_TYPE, MAV_AUTOPILOT); ground stations excluded) and the parameters, the last value
    of each (source, name), in order of first appearance. Used to detect the vehicle class
    and the ``SERVOn_FUNCTION`` mapping. Raises :class:`UnreadableLog` like the reader.

    The pass stops early once the parameter set is complete (every sender of PARAM_VALUE
    has sent every index up to its ``param_count``) and a vehicle HEARTBEAT was seen:
    the usual log, whose parameter download comes at its start, is not read to the end.
    A parameter changed later in such a log keeps its downloaded value.
    """
    reader = TlogReader(path, types=(VehicleInfo, Parameter), verify="needed")
    # Parameter samples carry no index: count PARAM_VALUE's param_count/param_index on
    # the way, per sender, by wrapping the handler of this reader's own table.
    msgid, _, idx = _layout(_PARAM_VALUE)
    i_count, i_index = idx["param_count"], idx["param_index"]
    missing: dict[tuple[int, int], set[int]] = {}   # (system, component) -> indices to go
    inner = reader._specs[msgid].handler

    def counting(v, t, sysid, compid, mid, v2, ctx):  # type: ignore[no-untyped-def]
        todo = missing.get((sysid, compid))
        if todo is None:
            todo = missing[(sysid, compid)] = set(range(v[i_count]))
        todo.discard(v[i_index])
        return inner(v, t, sysid, compid, mid, v2, ctx)

    reader._specs[msgid] = Spec(_PARAM_VALUE, counting, (Parameter,))
    vehicles: dict[tuple[int, int, int, int], VehicleInfo] = {}
    params: dict[tuple[str, str], Parameter] = {}
    vehicle_seen = False
    for s in reader:
        if isinstance(s, VehicleInfo):
            vehicles.setdefault((s.system_id, s.component_id, s.mav_type, s.autopilot), s)
            vehicle_seen = vehicle_seen or s.mav_type not in _GCS_MAV_TYPES
        elif isinstance(s, Parameter):
            params[(s.source, s.name)] = s
        if vehicle_seen and missing and not any(missing.values()):
            break
    return list(vehicles.values()), list(params.values())


class TlogWriter:
    """Write a tlog: ``write(t, frame)`` appends ``[t as big-endian us][frame]``.

    ``frame`` is one packed MAVLink frame, e.g. ``MAVLink(None, 1, 1).attitude_encode(...)
    .pack(mav)``; ``t`` is the receive time in seconds (epoch for real logs; any monotonic
    origin for simulations). Use as a context manager or call :meth:`close`.
    """

    def __init__(self, path: str | os.PathLike, *, append: bool = False) -> None:
        self.path = Path(path)
        self._f: BinaryIO = open(self.path, "ab" if append else "wb")

    def write(self, t: float, mav_msg_bytes: bytes) -> None:
        """Append one record received at ``t`` (s, >= 0)."""
        self._f.write(_TS.pack(round(t * 1e6)) + bytes(mav_msg_bytes))

    def flush(self) -> None:
        """Write the buffered records to the file."""
        self._f.flush()

    def close(self) -> None:
        """Close the file."""
        self._f.close()

    def __enter__(self) -> "TlogWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def pymavlink_parse_seconds(path: str | os.PathLike) -> float:
    """Wall time (s) of pymavlink's plain parse-only loop over a tlog: the reference figure
    of ``onboard bench`` (``mavutil.mavlink_connection(path)`` then ``recv_match()`` until
    None)."""
    from pymavlink import mavutil

    p = str(path)
    t0 = time.perf_counter()
    if p.lower().endswith(".tlog"):
        conn = mavutil.mavlink_connection(p)
    else:
        conn = mavutil.mavlogfile(p)
    while conn.recv_match() is not None:
        pass
    dt = time.perf_counter() - t0
    conn.close()
    return dt
