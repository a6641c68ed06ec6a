"""Generic CSV log reader driven by the ``[csv]`` mapping (:class:`onboard.core.config.CsvFormat`).

Input: one CSV file with a header row, or a directory of such files (one *run* per file,
read in file-name order). A single file can also hold several runs told apart by
``run_column``.

Per row, one sample of each type whose columns are mapped and numeric:

==================  ==========================================================  ==========
sample              columns                                                     notes
==================  ==========================================================  ==========
GnssFix             ``lat_deg``, ``lon_deg`` (+ ``alt_m``, ``sog_mps``)         decimal deg
GnssFix             ``north_m``, ``east_m`` when lat/lon are not mapped         WGS-84
                                                                                tangent
                                                                                plane at
                                                                                ``origin_*``
Heading             ``heading`` (``heading_unit``, ``heading_reference``)       rad
Attitude            ``heading`` + ``yaw_rate`` + (``roll``, ``pitch`` or         rad, rad/s
                    ``assume_level = true``)
VelocityOverGround  ``surge_mps``, ``sway_mps`` + ``heading``                    rotated to
                                                                                NED
VelocityOverGround  ``north_mps``, ``east_mps``                                earth axes
Depth               ``depth_m``                                                 m, down +
ActuatorOutputs     ``pwm_columns`` (channel 1 first)                           us
ActuatorColumn      each of ``actuator_columns`` (the ``[inputs]`` roles with    the log's
                    ``source = "column"``), one sample per column               units
==================  ==========================================================  ==========

Surge and sway are taken as velocity *over ground* in body axes (as in the BlueBoat NTNU
runs, where they were derived from GNSS) and rotated by the heading of the same row into
an earth-frame VelocityOverGround: ``vn = u cos(psi) - v sin(psi)``,
``ve = u sin(psi) + v cos(psi)``. ``v_down_mps`` is None.

Time: ``t = time * time_scale``. Runs are joined on one time line so that the reader yields
samples in time order: the first run keeps its own time; every later run is shifted to
start ``run_gap_s`` after the previous run's last row. :attr:`CsvReader.runs` lists each
run (name, source, first/last ``t`` after the shift, the shift, rows) before iteration,
so model-closure code can split train/test by run; each sample's ``source`` is
``"csv:<run>"`` (e.g. ``"csv:fixed_00000216"``).

With ``heading_spike_deg``, each row is held until the next one is read, and a row whose
heading is a spike loses its Heading and Attitude (``"heading_spike"``, :class:`_HeadingSpikes`).

Rejections (per row): ``"malformed"`` (wrong number of cells), ``"bad_time"`` (time not
numeric or not finite), ``"time_backwards"`` (time earlier than the previous row of the
run), ``"time_outlier"`` (one row stamped more than :data:`TIME_JUMP_S` away from the rows
before and after it, the rows after it kept; or a row outside the group of the run's
first stamps that agree, where the run starts; :class:`_RowClock`). Per sample type of a row: ``"nan"`` (empty or NaN cell), ``"non_numeric"``. A
mapped column missing from a file's header raises :class:`UnreadableLog`.
"""

from __future__ import annotations

import csv
import functools
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator, Sequence

from onboard.drivers.base import TIME_JUMP_S, ReadStats, UnreadableLog
from onboard.core.config import CsvFormat
from onboard.core.geo import LocalFrame, wrap_2pi
from onboard.core.stamps import Anchor
from onboard.core.messages import (
    ActuatorColumn,
    ActuatorOutputs,
    Attitude,
    Depth,
    GnssFix,
    Heading,
    Sample,
    VelocityOverGround,
)


@dataclass
class RunInfo:
    """One run of a CSV log. Times in s on the reader's joined time line."""

    name: str
    source: str
    path: Path
    t_start: float
    t_end: float
    t_offset: float
    """Added to ``time * time_scale`` to place the run on the joined time line."""
    rows: int




class _RowClock:
    """The time order of one run's rows, proof against bad stamps.

    The run starts where its first rows agree (:class:`onboard.core.stamps.Anchor`: the
    largest group of the first :data:`~onboard.core.stamps.ANCHOR_STAMPS` distinct
    stamps; the rows outside it are ``time_outlier``), so a bad first row costs itself
    only. Then a row up to :data:`TIME_JUMP_S` before the newest used one is ``time_backwards``. A row
    further ahead is held: the next row decides whether it was a jump (the next row agrees
    with it: both are used) or a ``time_outlier`` (the next row continues the old times).
    A row further back is rejected; the next row decides the count: ``time_outlier`` when
    it continues the old times, ``time_backwards`` when it agrees with the rejected row
    (a clock stepped back: rows are lost until it catches up, as in a tlog). A row held
    or rejected last in its run is a ``time_outlier``. Rows come out in time order.
    """

    def __init__(self, stats: ReadStats | None) -> None:
        """Count rejections in ``stats`` (None: count nothing, for the pre-scan)."""
        self.stats = stats
        self.last: float | None = None
        """The newest time used (s)."""
        self._held: tuple[float, object] | None = None
        self._back: float | None = None
        self._anchor: Anchor[object] = Anchor(TIME_JUMP_S)

    def admit(self, t: float, item: object) -> list:
        """The items to use, in order, after a row at ``t`` (s) carrying ``item``."""
        if not self._anchor.decided:
            return self._start(*self._anchor.push(t, item))
        return self._order(t, item)

    def _start(self, kept: list[tuple[float, object]],
               outliers: list[tuple[float, object]]) -> list:
        """The run's first rows, once the anchor chose its start: ``outliers`` counted,
        ``kept`` put in order."""
        for _ in outliers:
            self._count("time_outlier")
        return [used for t, item in kept for used in self._order(t, item)]

    def _order(self, t: float, item: object) -> list:
        """The items to use after a row at ``t`` (s), the run's start known."""
        last = self.last
        if self._back is not None:
            agrees = abs(t - self._back) <= TIME_JUMP_S and (
                last is None or t < last - TIME_JUMP_S)
            self._count("time_backwards" if agrees else "time_outlier")
            self._back = None
        if self._held is not None:
            ht, hitem = self._held
            self._held = None
            near_old = last is not None and abs(t - last) <= TIME_JUMP_S
            if abs(t - ht) <= TIME_JUMP_S and not near_old:
                self.last = max(t, ht)
                if t < ht:
                    self._count("time_backwards")
                    return [hitem]
                return [hitem, item]
            self._count("time_outlier")
        if last is None or last <= t <= last + TIME_JUMP_S:
            self.last = t
            return [item]
        if t > last:
            self._held = (t, item)
        elif t >= last - TIME_JUMP_S:
            self._count("time_backwards")
        else:
            self._back = t
        return []

    def end(self) -> list:
        """The run ended: return the items it releases (a run shorter than the anchor's
        stamps: its start is chosen now); a row still held, or rejected far back, was an
        outlier."""
        out = [] if self._anchor.decided else self._start(*self._anchor.decide())
        if self._held is not None or self._back is not None:
            self._count("time_outlier")
        self._held = self._back = None
        return out

    def _count(self, reason: str) -> None:
        if self.stats is not None:
            self.stats.reject(reason)


class _HeadingSpikes:
    """A one-row delay that drops a row's Heading and Attitude when its heading is a spike
    (``heading_spike_deg``): more than the threshold from both the last accepted heading
    and the next row's, while those two agree within it."""

    def __init__(self, threshold_deg: float, stats: ReadStats) -> None:
        self.thr = math.radians(threshold_deg)
        self.stats = stats
        self._held: list[Sample] | None = None
        self._last: float | None = None  # the last accepted heading (rad)

    @staticmethod
    def _heading(row: list[Sample]) -> float | None:
        return next((s.heading_rad for s in row if isinstance(s, Heading)), None)

    def _far(self, a: float, b: float) -> bool:
        return abs(math.remainder(a - b, 2 * math.pi)) > self.thr

    def push(self, row: list[Sample] | None) -> list[Sample]:
        """Hold ``row`` (None: the run ended) and return the held row before it, its
        Heading and Attitude removed if they were a spike."""
        held, self._held = self._held, row
        if held is None:
            return []
        h = self._heading(held)
        nxt = self._heading(row) if row is not None else None
        if h is None:
            return held
        last = self._last
        if (last is not None and nxt is not None and not self._far(last, nxt)
                and self._far(h, last) and self._far(h, nxt)):
            self.stats.reject("heading_spike")
            return [s for s in held if not isinstance(s, (Heading, Attitude))]
        self._last = h
        return held


@functools.lru_cache(maxsize=8)
def _frame(lat0_deg: float, lon0_deg: float) -> LocalFrame:
    """The local frame of the ``north_m``/``east_m`` columns (one per origin)."""
    return LocalFrame(lat0_deg, lon0_deg)


def mapped_columns(fmt: CsvFormat, actuator_columns: Sequence[str] = ()) -> list[str]:
    """The columns a ``[csv]`` mapping reads (and ``actuator_columns``, the ``[inputs]``
    roles with ``source = "column"``): a log's header must have each."""
    cols = [fmt.time, fmt.lat_deg, fmt.lon_deg, fmt.alt_m, fmt.north_m, fmt.east_m,
            fmt.heading, fmt.yaw_rate, fmt.surge_mps, fmt.sway_mps, fmt.sog_mps, fmt.depth_m,
            fmt.roll, fmt.pitch, fmt.north_mps, fmt.east_mps, fmt.run_column,
            *fmt.pwm_columns, *actuator_columns]
    return [c for c in cols if c]


def run_files(folder: str | Path) -> list[Path]:
    """The CSV files of a folder of runs, in name order; :class:`UnreadableLog` when there
    are none, or when their headers differ (the folder is not one logger's runs: a
    vehicle log beside a table of another kind, each its own log)."""
    folder = Path(folder)
    files = sorted(folder.glob("*.csv"))
    if not files:
        raise UnreadableLog(f"{folder}: a directory with no .csv files")
    headers: dict[tuple[str, ...], Path] = {}
    for f in files:
        headers.setdefault(tuple(csv_header(f)), f)
    if len(headers) > 1:
        (a, fa), (b, fb) = list(headers.items())[:2]
        raise UnreadableLog(
            f"{folder}: its .csv files are not runs of one log, their headers differ "
            f"({fa.name}: {', '.join(a[:6])}{', ...' if len(a) > 6 else ''}; {fb.name}: "
            f"{', '.join(b[:6])}{', ...' if len(b) > 6 else ''}): replay each file, or keep "
            "one logger's runs in a folder of their own")
    return files


def csv_header(path: str | Path) -> list[str]:
    """The header of a CSV log (of its first file, for a directory of runs); empty when
    there is none to read."""
    p = Path(path)
    first = min(p.glob("*.csv"), default=None) if p.is_dir() else p
    try:
        with open(first, newline="", encoding="utf-8", errors="replace") as fh:  # type: ignore[arg-type]
            return [h.strip() for h in next(csv.reader(fh), [])]
    except (OSError, TypeError, csv.Error):
        return []


TABLE_ROWS = 20
"""Rows after the header that :func:`looks_like_table` compares with it."""
TABLE_SHARE_MIN = 0.8
"""Share of those rows that must have the header's number of cells."""
NOT_A_HEADER = ("{", "[", "$", "!", ":")
"""First characters of a line that is a record, not a CSV header: JSON, an NMEA sentence,
a PD6 line."""


def looks_like_table(head: bytes) -> bool:
    """Whether the first bytes of a file, ``head``, are a CSV table: a header row of two or
    more names (none a number; a pandas index column's empty name is one) over rows of
    which most (:data:`TABLE_SHARE_MIN` of the first :data:`TABLE_ROWS`) have as many
    cells, a number among them. An NMEA sentence, a JSON line or a PD6 line is no header,
    and lines of prose with commas are no table (no row holds a number)."""
    text = head.decode("utf-8", "replace").splitlines()
    lines = [ln for ln in (text[:-1] if len(text) > 1 else text) if ln.strip()]
    if not lines or lines[0].lstrip()[:1] in NOT_A_HEADER:
        return False
    try:
        rows = list(csv.reader(lines[:TABLE_ROWS + 1]))
    except csv.Error:
        return False
    if len(rows) < 2 or len(rows[0]) < 2:
        return False
    names = [c.strip() for c in rows[0]]
    if any(_number(c) for c in names) or not any(c[:1].isalpha() for c in names):
        return False
    fit = sum(len(r) == len(names) and any(_number(c) for c in r) for r in rows[1:])
    return fit >= TABLE_SHARE_MIN * (len(rows) - 1)


def _number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def fitting_configs(header: Sequence[str]) -> list[str]:
    """The bundled configs (``onboard.core.config.bundled``) with a ``[csv]`` mapping whose
    every column, and every column its ``[inputs]`` read, is in ``header``; the one
    that maps the most columns first."""
    from onboard.core import config as configmod

    have, fits = set(header), []
    for name in configmod.bundled():
        try:
            cfg = configmod.load(name)
        except Exception:  # noqa: BLE001 - a config that does not load fits nothing
            continue
        if not (cfg.csv.lat_deg or cfg.csv.north_m):
            continue
        cols = mapped_columns(cfg.csv, _column_inputs(cfg.inputs))
        if set(cols) <= have:
            fits.append((-len(cols), name))
    return [name for _, name in sorted(fits)]


def _column_inputs(inputs) -> list[str]:
    """The columns the ``[inputs]`` roles with ``source = "column"`` read."""
    maps = []
    for name in inputs.__struct_fields__:
        v = getattr(inputs, name)
        maps.extend(v if isinstance(v, list) else [v])
    return [m.column for m in maps if getattr(m, "source", "") == "column"]


def fitting_note(header: Sequence[str]) -> str:
    """What to pass for a CSV log with ``header``: the bundled config that fits it, or
    how to write a mapping."""
    fits = fitting_configs(header)
    if fits:
        return f"its header fits the bundled config {fits[0]}: --config {fits[0]}"
    shown = (", ".join(h if h.isprintable() else repr(h) for h in header[:8])
             + (", ..." if len(header) > 8 else ""))  # a control character quoted, not printed
    return (f"no bundled config fits its header ({shown or 'none'}): write a [csv] table "
            "(docs/formats-text.md)")


class _Lines:
    """The lines of an open text file for :func:`csv.reader`, counting their characters:
    ``n`` so far, ``counted`` up to the previous call of :meth:`row` (a CSV row may span
    lines)."""

    def __init__(self, fh) -> None:  # type: ignore[no-untyped-def]
        self.fh = fh
        self.n = 0
        self.counted = 0

    def __iter__(self) -> "_Lines":
        return self

    def __next__(self) -> str:
        line = next(self.fh)
        self.n += len(line)
        return line

    def row(self) -> int:
        """Characters of the lines read since the previous call (the last row's)."""
        k, self.counted = self.n - self.counted, self.n
        return k

    def rest(self) -> int:
        """Characters of the whole file: those read and the rest, read now (what a CSV
        error left unread)."""
        for _ in self:
            pass
        return self.n

    def close(self) -> None:
        """Close the file."""
        self.fh.close()


class _Bad(Exception):
    def __init__(self, reason: str) -> None:
        self.reason = reason


class CsvReader:
    """Read a CSV file or a directory of CSV runs with a ``[csv]`` column mapping.

    Raises :class:`UnreadableLog` when the path is missing, holds no CSV, has no header,
    or lacks a mapped column. Iterating yields samples in time order; ``stats`` counts.
    """

    def __init__(self, path: str | Path, fmt: CsvFormat, source_prefix: str = "csv",
                 actuator_columns: Sequence[str] = ()) -> None:
        self.path = Path(path)
        self.fmt = fmt
        self.actuator_columns = tuple(dict.fromkeys(actuator_columns))
        """Columns read as :class:`ActuatorColumn` samples (each once)."""
        self.prefix = source_prefix
        self.stats = ReadStats(time_source=f'[csv] time = "{fmt.time}" with time_scale = '
                               f"{fmt.time_scale:g}")
        if self.path.is_dir():
            files = run_files(self.path)
        elif self.path.is_file():
            files = [self.path]
        else:
            raise UnreadableLog(f"{self.path}: no such file or directory")
        self.files = files
        self.runs: list[RunInfo] = []
        """The runs in order, known before iteration (see the module docstring)."""
        self._scan()

    # -- helpers

    def _open(self, path: Path) -> tuple[list[str], Iterator[list[str]], _Lines]:
        try:
            fh = _Lines(open(path, newline="", encoding="utf-8", errors="replace"))
        except OSError as err:
            raise UnreadableLog(f"{path}: {err.strerror or err}") from None
        rd = csv.reader(fh)
        try:
            header = next(rd)
        except StopIteration:
            fh.close()
            raise UnreadableLog(f"{path}: empty file") from None
        except csv.Error as err:
            fh.close()
            raise UnreadableLog(f"{path}: not CSV: {err}") from None
        return [h.strip() for h in header], rd, fh

    def _columns(self) -> list[str]:
        return mapped_columns(self.fmt, self.actuator_columns)

    def _index(self, header: list[str], path: Path) -> dict[str, int]:
        idx = {name: i for i, name in enumerate(header)}
        missing = [c for c in self._columns() if c not in idx]
        if missing:
            raise UnreadableLog(f"{path}: the [csv] mapping's column(s) "
                                f"{', '.join(map(repr, missing))} not in its header; "
                                f"{fitting_note(header)}")
        return idx

    @staticmethod
    def _time(row: list[str], i: int, scale: float) -> float | None:
        try:
            v = float(row[i]) * scale
        except (ValueError, IndexError):
            return None
        return v if math.isfinite(v) else None

    def _run_name(self, path: Path, row: list[str], idx: dict[str, int]) -> str:
        if self.fmt.run_column:
            i = idx[self.fmt.run_column]
            return row[i].strip() if i < len(row) and row[i].strip() else path.stem
        return path.stem

    # -- pre-scan: run boundaries and time offsets

    def _scan(self) -> None:
        prev_end: float | None = None
        for path in self.files:
            header, rd, fh = self._open(path)
            try:
                idx = self._index(header, path)
                try:
                    for name, times, rows in self._scan_runs(rd, idx, len(header), path):
                        first = times[0] if times else None
                        last = max(times) if times else None
                        prev_end = self._add_run(name, path, first, last, rows, prev_end)
                except csv.Error as err:
                    raise UnreadableLog(f"{path}: not CSV: {err}") from None
            finally:
                fh.close()

    def _scan_runs(self, rd: Iterator[list[str]], idx: dict[str, int], ncol: int,
                   path: Path) -> Iterator[tuple[str, list[float], int]]:
        """Per run of one file: its name, the times its rows will be used at (in order:
        the run's clock applied as in :meth:`__iter__`) and its rows."""
        f = self.fmt
        cur: str | None = None
        times: list[float] = []
        rows = 0
        clock = _RowClock(None)
        for row in rd:
            if not row or not any(c.strip() for c in row):
                continue
            name = self._run_name(path, row, idx)
            if cur is not None and name != cur:
                yield cur, times + clock.end(), rows
                times, rows, clock = [], 0, _RowClock(None)
            cur = name
            rows += 1
            t = self._time(row, idx[f.time], f.time_scale) if len(row) == ncol else None
            if t is not None:
                times += clock.admit(t, t)
        if cur is not None:
            yield cur, times + clock.end(), rows

    def _add_run(self, name: str, path: Path, first: float | None, last: float | None,
                 rows: int, prev_end: float | None) -> float | None:
        if first is None or last is None:
            self.runs.append(RunInfo(name, f"{self.prefix}:{name}", path, math.nan, math.nan,
                                     0.0, rows))
            return prev_end
        offset = 0.0 if prev_end is None else prev_end + self.fmt.run_gap_s - first
        self.runs.append(RunInfo(name, f"{self.prefix}:{name}", path, first + offset,
                                 last + offset, offset, rows))
        return last + offset

    # -- iteration

    def __iter__(self) -> Iterator[Sample]:
        f = self.fmt
        runs = {(r.path, r.name): r for r in self.runs}
        st = self.stats
        st.size_bytes = st.used_bytes = 0
        for path in self.files:
            header, rd, fh = self._open(path)
            try:
                idx = self._index(header, path)
                ncol = len(header)
                st.used_bytes += fh.row()  # the header
                clock = _RowClock(st)
                spikes = _HeadingSpikes(f.heading_spike_deg, st) if f.heading_spike_deg else None
                cur = None
                for row in rd:
                    chars = fh.row()
                    if not row or not any(c.strip() for c in row):
                        st.used_bytes += chars
                        if row:  # cells, all empty: a spreadsheet's empty row
                            st.skipped["empty_row"] += 1
                        continue
                    st.records += 1
                    name = self._run_name(path, row, idx)
                    run = runs.get((path, name))
                    if run is None:
                        st.reject("malformed")
                        continue
                    if run is not cur:
                        yield from self._rows(clock.end(), idx, cur, spikes)
                        cur, clock = run, _RowClock(st)
                        if spikes is not None:  # the previous run's last row
                            yield from self._count(spikes.push(None))
                            spikes = _HeadingSpikes(f.heading_spike_deg, st)
                    if len(row) != ncol:
                        st.reject("malformed")
                        continue
                    t = self._time(row, idx[f.time], f.time_scale)
                    if t is None:
                        st.reject("bad_time")
                        continue
                    st.used_bytes += chars
                    t += run.t_offset
                    yield from self._rows(clock.admit(t, (t, row)), idx, run, spikes)
                yield from self._rows(clock.end(), idx, cur, spikes)
                if spikes is not None:
                    yield from self._count(spikes.push(None))
            except csv.Error:
                st.reject("malformed")
            finally:
                st.size_bytes += fh.rest()
                fh.close()

    def _rows(self, rows: list[tuple[float, list[str]]], idx: dict[str, int],
              run: RunInfo | None, spikes: _HeadingSpikes | None) -> Iterator[Sample]:
        """The samples of the rows the clock released, ``(t, cells)`` of ``run``."""
        for row_t, cells in rows:
            self.stats.by_type["row"] += 1
            out = self._samples(cells, idx, row_t, run.source)  # type: ignore[union-attr]
            yield from self._count(spikes.push(out) if spikes is not None else out)

    def _count(self, samples: list[Sample]) -> Iterator[Sample]:
        """Yield ``samples``, counting them."""
        for s in samples:
            self.stats.samples += 1
            yield s

    def _samples(self, row: list[str], idx: dict[str, int], t: float, src: str) -> list[Sample]:
        f = self.fmt
        st = self.stats
        out: list[Sample] = []

        def num(col: str) -> float:
            s = row[idx[col]].strip()
            if not s:
                raise _Bad("nan")
            try:
                v = float(s)
            except ValueError:
                raise _Bad("non_numeric") from None
            if not math.isfinite(v):
                raise _Bad("nan")
            return v

        def opt(col: str) -> float | None:
            if not col:
                return None
            try:
                return num(col)
            except _Bad:
                return None

        ang = math.radians if f.heading_unit == "deg" else float
        rate = math.radians if f.yaw_rate_unit == "deg/s" else float

        # position
        try:
            if f.lat_deg and f.lon_deg:
                lat, lon = num(f.lat_deg), num(f.lon_deg)
                if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
                    raise _Bad("out_of_range")
            elif f.north_m and f.east_m:
                n, e = num(f.north_m), num(f.east_m)
                lat, lon = _frame(f.origin_lat_deg, f.origin_lon_deg).to_latlon(n, e)
            else:
                lat = lon = None
            if lat is not None:
                out.append(GnssFix(t=t, source=src, lat_deg=lat, lon_deg=lon,  # type: ignore[arg-type]
                                   alt_m=opt(f.alt_m), sog_mps=opt(f.sog_mps)))
        except _Bad as b:
            st.reject(b.reason)

        heading: float | None = None
        if f.heading:
            try:
                heading = wrap_2pi(ang(num(f.heading)))
                out.append(Heading(t=t, source=src, heading_rad=heading,
                                   reference=f.heading_reference))
            except _Bad as b:
                st.reject(b.reason)

        if f.yaw_rate and heading is not None and ((f.roll and f.pitch) or f.assume_level):
            try:
                r = rate(num(f.yaw_rate))
                roll = ang(num(f.roll)) if f.roll else 0.0
                pitch = ang(num(f.pitch)) if f.pitch else 0.0
                out.append(Attitude(t=t, source=src, roll_rad=roll, pitch_rad=pitch,
                                    yaw_rad=heading, yaw_rate_rps=r))
            except _Bad as b:
                st.reject(b.reason)

        if f.surge_mps and f.sway_mps and heading is not None:
            try:
                u, v = num(f.surge_mps), num(f.sway_mps)
                c, s = math.cos(heading), math.sin(heading)
                out.append(VelocityOverGround(t=t, source=src, v_north_mps=u * c - v * s,
                                              v_east_mps=u * s + v * c))
            except _Bad as b:
                st.reject(b.reason)

        if f.north_mps and f.east_mps:
            try:
                out.append(VelocityOverGround(t=t, source=src, v_north_mps=num(f.north_mps),
                                              v_east_mps=num(f.east_mps)))
            except _Bad as b:
                st.reject(b.reason)

        if f.depth_m:
            try:
                out.append(Depth(t=t, source=src, depth_m=num(f.depth_m)))
            except _Bad as b:
                st.reject(b.reason)

        if f.pwm_columns:
            try:
                out.append(ActuatorOutputs(t=t, source=src,
                                           pwm_us=tuple(num(c) for c in f.pwm_columns)))
            except _Bad as b:
                st.reject(b.reason)

        for col in self.actuator_columns:
            try:
                out.append(ActuatorColumn(t=t, source=src, column=col, value=num(col)))
            except _Bad as b:
                st.reject(b.reason)
        return out
