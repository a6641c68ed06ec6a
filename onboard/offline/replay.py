"""``onboard replay LOG [--config FILE] [--out DIR] [--force] [--mcap FILE] ...``: run
the pipelines over a log.

Writes ``DIR/estimates.csv`` (architecture.md §4.2), ``DIR/summary.json`` (what was read,
the inputs rejected and the estimates withheld apart, rates, time span, the vehicle
config used and why) and ``DIR/track.png``; with ``--mcap`` also the estimates as MCAP,
on the channels and with the schemas of the live Zenoh records (:mod:`drivers.mcap_out`,
docs/foxglove.md); with ``--geojson``, ``--gpx`` and ``--foxglove-layout`` the tracks,
current arrows and a Foxglove layout of the topics published
(:mod:`onboard.offline.exports`). MCAP and GPX are in UTC where the log has it
(:mod:`drivers.logclock`).
The same engine and pipelines as the live service, so a replay is the live result.

Every output path is checked before the log is read (:mod:`onboard.core.outputs`); each
export is then written on its own, one that fails listed in summary.json's ``failed``
and on the last line printed (exit status 1), and track.png, the slowest, is drawn last,
once summary.json is written and the headline and warnings are printed.
"""

from __future__ import annotations

import itertools
import json
import sys
import time
import traceback
from pathlib import Path
from typing import Callable, Iterable, Iterator, Mapping, Sequence

import msgspec

from onboard.drivers.base import ReadStats, UnreadableLog, shortfall
from onboard.drivers.logclock import LogClock, log_clock
from onboard.drivers.logs import open_log, sniff
from onboard.estimators.noise_learning import ChannelNoise
from onboard.monitor.alerts import Alerts
from onboard.offline import exports
from onboard.offline.autodetect import consistency, detect
from onboard.core import config as configmod
from onboard.core.config import Config
from onboard.core.errors import OutputFailed, UsageError
from onboard.core.outputs import Output, check as check_outputs, existing
from onboard.core.messages import EstimateRecord, Parameter, Sample, VehicleInfo
from onboard.core.wire import LocationFix
from onboard.engine import Engine, run
from onboard.engine.inputs import column_names
from onboard.engine.sources import QUANTITIES
from onboard.engine.timeline import log_time
from onboard.offline.estimates_csv import EstimatesCsv, Runs


class _Progress:
    """Progress on a terminal (stderr), at most twice a second; silent otherwise: the
    samples read and how far into the log (s from its first sample; a log's own stamps
    may be a date or a time since boot)."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.last = 0.0
        self.n = 0
        self.t_first: float | None = None

    def wrap(self, samples: Iterable[Sample]) -> Iterator[Sample]:
        for s in samples:
            self.n += 1
            if self.t_first is None:
                self.t_first = s.t
            if self.enabled and (self.n & 1023) == 0:
                now = time.monotonic()
                if now - self.last > 0.5:
                    self.last = now
                    print(f"\r  {self.n:,} samples, {s.t - self.t_first:,.0f} s into the log",
                          end="", file=sys.stderr, flush=True)
            yield s

    def done(self) -> None:
        if self.enabled and self.last:
            print(file=sys.stderr)


DETECTED_CONFIG = "detected:"
"""The start of the config note (summary.json ``config``) of a config detected from the
log, not given (:func:`choose_config`)."""
SLOCUM_CONFIG = "slocum-glider"
"""The bundled config a Slocum glider's binary log is replayed with (its sensors have the
same names on every Slocum)."""
SURVEY_BOAT_CONFIG = "survey-boat-csv"
"""The bundled config a survey-boat Arduino capture (:class:`drivers.textlog.MixedCaptureReader`)
is replayed with: the capture's rows are that logger's, its RC channels that boat's
throttle and rudder."""


def choose_config(log: str, config_path: str | Sequence[str] | None
                  ) -> tuple[Config, str]:
    """The config to use: the given file, or several applied in order
    (:func:`onboard.core.config.load_all`), or one detected from the log's header."""
    if isinstance(config_path, str):
        config_path = [config_path]
    if config_path:
        cfg = configmod.load_all(config_path)
        _needs_csv_mapping(log, cfg, " + ".join(config_path))
        return cfg, f"from {' + '.join(config_path)}"
    _needs_csv_mapping(log, None, "")
    fmt, reader = open_log(log)
    if fmt == "recording":
        from onboard.service.recorder import recording_config

        cfg = recording_config(log)
        if cfg is not None:
            return cfg, "the configuration the service recorded with"
    if fmt == "tlog":
        from onboard.drivers.tlog import scan_header

        infos, params = scan_header(log)
        cfg, why = detect([*infos, *params])
    elif fmt == "slocum":
        cfg, why = configmod.load(SLOCUM_CONFIG), f"a Slocum glider's log: {SLOCUM_CONFIG}"
        glider = reader.glider  # type: ignore[attr-defined]
        if glider:   # the glider names itself: the vehicle is it, not its class
            vehicle = msgspec.structs.replace(cfg.vehicle, id=glider)
            return (msgspec.structs.replace(cfg, vehicle=vehicle),
                    f"the glider's own name in its log ({glider}) with {SLOCUM_CONFIG}")
    elif fmt in ("dataflash", "recording", "mcap"):
        header = [s for s in reader if isinstance(s, (Parameter, VehicleInfo))]
        cfg, why = detect(header)
    elif type(reader).__name__ == "MixedCaptureReader":
        cfg, why = configmod.load(SURVEY_BOAT_CONFIG), (
            f"the survey boat's Arduino capture (its IMU and RC rows between the GPS's NMEA, "
            f"a logger of that boat alone): {SURVEY_BOAT_CONFIG}")
    else:
        cfg, why = configmod.Config(), "no vehicle evidence in a text log; generic config"
    return cfg, f"{DETECTED_CONFIG} {why}"


def _needs_csv_mapping(log: str, cfg: Config | None, given: str) -> None:
    """A CSV log read without a ``[csv]`` column mapping (no ``--config``, or ``given``
    configs with none) is :class:`UnreadableLog`, naming the bundled config that fits
    its header (:func:`onboard.drivers.csvlog.fitting_note`); so is a folder whose CSV
    files are not one logger's runs (:func:`onboard.drivers.csvlog.run_files`), with or
    without a mapping."""
    fmt = sniff(log)
    if fmt not in ("csv", "csv-dir"):
        return
    from onboard.drivers.csvlog import csv_header, fitting_note, run_files

    if fmt == "csv-dir":
        run_files(log)   # one logger's runs, or a one-line refusal
    if cfg is not None and (cfg.csv.lat_deg or cfg.csv.north_m):
        return

    lacks = f"{given} has no [csv] column mapping" if given else \
        "a CSV log needs a [csv] column mapping (--config)"
    raise UnreadableLog(f"{log}: {lacks}; {fitting_note(csv_header(log))}")


def replay(log: str, cfg: Config, out_dir: Path, *, config_note: str = "",
           plot: bool = True, progress: bool = False, mcap: Path | None = None,
           geojson: Path | None = None, gpx: Path | None = None,
           foxglove_layout: Path | None = None,
           on_records: Callable[[float, Sequence[EstimateRecord]], None] | None = None
           ) -> dict:
    """Run the pipelines over ``log``; write the outputs into ``out_dir`` (and the
    estimates as MCAP into ``mcap`` when given; with ``geojson`` the tracks and current
    arrows there, with ``gpx`` the tracks, with ``foxglove_layout`` a Foxglove layout of
    the topics published, :mod:`onboard.offline.exports`); ``on_records`` is called with
    each tick's time and records, as estimates.csv gets a row (``onboard batch``'s
    current.parquet takes the records' place from them); return the summary. MCAP and
    GPX are stamped in UTC where the log knows it (:mod:`drivers.logclock`). Each export
    is written on its own: one that fails is listed in the summary's ``failed`` and the
    others, summary.json included, are still written; track.png is drawn last, after
    summary.json (:func:`add_figure`)."""
    wall0 = time.perf_counter()
    fmt, reader = open_log(log, cfg.csv, column_names(cfg.inputs))
    not_read = files_not_read(log, fmt)
    for f in not_read:
        reader.stats.skipped["log_file" if f["log"] else "other_file"] += 1
    out_dir.mkdir(parents=True, exist_ok=True)
    engine = Engine(cfg)
    samples = iter(reader)
    first = next(samples, None)
    if first is None:
        raise UnreadableLog(f"{log}: no usable samples ({reader.stats.as_dict()['rejected']})")
    # ``t`` counts from the first tick: the first stamp the time line kept (the reader's
    # first sample may be an outlier), or a live recording's first tick before its first
    # sample.
    csv = EstimatesCsv(out_dir / "estimates.csv", engine.columns, None,
                       Runs(engine, [r for r in getattr(reader, "runs", ())
                                     if r.t_start == r.t_start]))
    failed: list[dict] = []
    clock = _clock(fmt, reader, log, first.t)
    if clock.utc:
        engine.whereabouts.utc_of = clock.to_utc
    mcap_out = _McapExport(mcap, cfg, clock, failed) if mcap is not None else None
    published = exports.Published() if foxglove_layout is not None else None

    def on_tick(t: float, records: Sequence[EstimateRecord]) -> None:
        csv.write(t, records)
        if on_records is not None:
            on_records(t, records)
        if mcap_out is not None or published is not None:
            fixes = engine.location_fixes(records)
            if mcap_out is not None:
                mcap_out.write(t, records, fixes)
            if published is not None:
                published.add(records, fixes)
    meter = _Progress(progress)

    header: list[Sample] = []   # HEARTBEAT and parameters, checked against cfg at the end

    def stream() -> Iterator[Sample]:
        for s in itertools.chain((first,), samples):
            if isinstance(s, (VehicleInfo, Parameter)):
                header.append(s)
            yield s

    source = meter.wrap(stream()) if progress else stream()
    if fmt == "recording":
        ticks = _replay_recording(log, engine, on_tick, reader)
    else:
        ticks = run(engine, source, on_tick)
    csv.close()
    meter.done()
    summary = _summary(log, fmt, cfg, engine, csv, reader, first.t, ticks, header,
                       config_note, not_read)
    summary["wall_time_s"] = round(time.perf_counter() - wall0, 3)
    summary["utc"] = utc_summary(clock, summary["time_span"]["start"])
    if mcap_out is not None:
        mcap_out.close()
        if mcap_out.writer is not None:
            summary["mcap"] = {"file": str(mcap), "messages": mcap_out.writer.messages}
    if geojson is not None or gpx is not None:
        summary["geojson"] = _write_geojson(out_dir, geojson, gpx, summary, failed, clock,
                                            csv.t0)
    if published is not None:
        summary["foxglove_layout"] = _write_layout(foxglove_layout, cfg, published, failed)
    summary["failed"] = failed
    write_summary(out_dir, summary)
    if plot:
        add_figure(out_dir, summary, Path(log).name, cfg.csv.position_kind)
    return summary


def _clock(fmt: str, reader, log: str, t_first: float) -> LogClock:
    """The log's clock and its UTC (:func:`onboard.drivers.logclock.log_clock`); a log
    whose clock cannot be read has no UTC (the estimates are the same)."""
    try:
        return log_clock(fmt, reader, log, t_first)
    except Exception as err:  # noqa: BLE001 - the records say the UTC is unknown
        return LogClock(f"no UTC: the log's clock could not be read ({type(err).__name__}: "
                        f"{err})")


def utc_summary(clock: LogClock, t_start: float) -> dict:
    """summary.json's ``utc``: whether the log has UTC, from where, its start in ISO 8601
    and in POSIX s (``start_s``), and the log clock's ``offsets`` (``[t_from, offset_s]``
    pairs: UTC is ``t + offset_s``; :class:`onboard.drivers.logclock.LogClock`), so that a
    reader maps any log time to UTC without reading the log again
    (:func:`clock_from_summary`)."""
    return {**clock.summary(t_start), "start_s": clock.to_utc(t_start),
            "offsets": [list(p) for p in clock.offsets]}


def clock_from_summary(summary: Mapping) -> LogClock | None:
    """The :class:`LogClock` a replay recorded in its summary.json (:func:`utc_summary`),
    None for a summary written before it recorded one."""
    utc = summary.get("utc")
    if not isinstance(utc, dict) or "offsets" not in utc:
        return None
    return LogClock(utc.get("source", ""), tuple((float(a), float(b))
                                                 for a, b in utc["offsets"]))


def _replay_recording(log: str, engine: Engine, on_tick, reader) -> int:
    """The service's own recording: every raw chunk re-parsed in the order it arrived,
    through the same intake as live, ticking at the recorded tick times, so the
    estimates are exactly the live ones (onboard.service.recorder.replay_recording);
    ``reader``'s counts become the recording's. Returns the ticks."""
    from onboard.service.recorder import replay_recording

    result = replay_recording(log, engine, on_tick)
    reader.stats = result.stats
    for reason, n in result.rejected.items():
        reader.stats.rejected[reason] += n
    reader.stats.samples = sum(engine.accepted.values()) + sum(engine.rejected.values())
    return result.ticks


def _summary(log: str, fmt: str, cfg: Config, engine: Engine, csv: EstimatesCsv, reader,
             t_first: float, ticks: int, header: Sequence[Sample], config_note: str,
             not_read: Sequence[dict] = ()) -> dict:
    """summary.json's content (architecture.md §4.2) but for the exports and the wall
    time; ``not_read``: the files of a folder log its reader left out
    (:func:`files_not_read`), in ``read.skipped_files``."""
    time_span = _time_span(engine, t_first)
    span = time_span["duration_s"]
    kinds: dict[str, int] = {}
    for (kind, _), n in engine.accepted.items():
        kinds[kind] = kinds.get(kind, 0) + n
    return {
        "log": str(log),
        "format": fmt,
        "config": config_note,
        "vehicle_class": cfg.vehicle.vehicle_class,
        "vehicle_id": cfg.vehicle.id,
        "pipelines": [p.name for p in engine.pipelines],
        "columns": csv.columns,
        "time_span": time_span,
        "origin": _origin(engine),
        "runs": csv.runs,
        "read": {**reader.stats.as_dict(),
                 **({"skipped_files": [{k: f[k] for k in ("file", "why")} for f in not_read]}
                    if not_read else {})},
        "samples_accepted_by_type": dict(sorted(kinds.items())),
        "rates_hz": {k: (n / span if span > 0 else None) for k, n in sorted(kinds.items())},
        "accepted": {f"{k}:{src}": n for (k, src), n in sorted(engine.accepted.items())},
        "rejected": dict(sorted(engine.rejections().items())),
        "withheld": dict(sorted(engine.withheld().items())),
        "withheld_rows": dict(sorted(engine.integrity.withheld_rows.items())),
        "sources": {"active": dict(engine.selector.active),
                    "switches": engine.selector.switches,
                    "events": [e for e in engine.events if e.split(":", 1)[0] in QUANTITIES],
                    "standby": {f"{q}:{src}": n for (q, src), n
                                in sorted(engine.selector.standby.items())}},
        "ticks": ticks,
        "rows": csv.rows,
        "rate_hz": cfg.engine.rate_hz,
        "warnings": msgspec.to_builtins(sorted(run_warnings(   # a log mostly unread first
            engine, kinds, cfg, header, reader.stats.rejected, fmt, reader.stats,
            Path(log).name, not_read), key=lambda a: a.code not in FIRST_WARNINGS)),
        "innovations": msgspec.to_builtins(engine.monitor.snapshot(reset_max=False)),
        "pipeline_health": engine.counters(),
        "noise": {p.name: p.noise.summary() for p in engine.pipelines
                  if isinstance(getattr(p, "noise", None), ChannelNoise)},
        "declination": msgspec.to_builtins(engine.declination.report),
    }


def write_summary(out_dir: Path, summary: dict) -> None:
    """``out_dir/summary.json``; a failure to write it is :class:`OutputFailed`."""
    path = out_dir / "summary.json"
    try:
        path.write_text(json.dumps(summary, indent=2) + "\n")
    except OSError as err:
        raise OutputFailed(f"{path}: cannot write: {err.strerror or err}") from None


def export_failed(failed: list[dict], output: str, path: Path | str,
                  err: BaseException) -> None:
    """Record in ``failed`` that ``output`` (its flag, or its name in the output
    directory) could not be written to ``path``, and why: a file system error in its
    words; any other error is a bug, whose traceback goes to stderr."""
    if isinstance(err, OSError):
        why = f"cannot write: {err.strerror or err}"
    else:
        traceback.print_exception(err, file=sys.stderr)
        why = f"internal error: {type(err).__name__}: {err}"
    failed.append({"output": output, "path": str(path), "error": why})


class _McapExport:
    """``--mcap``: the estimates as MCAP, written tick by tick beside estimates.csv. A
    failure (opening, a write, closing) stops this export only; it is listed in
    ``failed`` and the replay carries on.

    Attributes:
        writer: the MCAP writer (None once failed).
    """

    def __init__(self, path: Path, cfg: Config, clock: LogClock | None,
                 failed: list[dict]) -> None:
        from onboard.drivers.mcap_out import McapRecordWriter

        self.path, self.failed = path, failed
        try:
            self.writer = McapRecordWriter(path, cfg.service.zenoh.key_prefix,
                                           cfg.vehicle.id, clock)
        except Exception as err:  # noqa: BLE001 - one export fails, not the replay
            self._fail(err)

    def write(self, t: float, records: Sequence[EstimateRecord],
              fixes: Sequence[LocationFix]) -> None:
        """One tick's records and the positions they carry."""
        if self.writer is not None:
            try:
                self.writer.write(t, records, fixes)
            except Exception as err:  # noqa: BLE001
                self._fail(err)

    def close(self) -> None:
        if self.writer is not None:
            try:
                self.writer.close()
            except Exception as err:  # noqa: BLE001
                self._fail(err)

    def _fail(self, err: BaseException) -> None:
        self.writer = None
        export_failed(self.failed, "--mcap", self.path, err)


def add_figure(out_dir: Path, summary: dict, title: str, position_kind: str = "") -> None:
    """Draw ``out_dir/track.png`` from estimates.csv, the last and slowest output, once
    summary.json is written (its measured track labelled by the log's format and, for a
    CSV, ``position_kind``, its ``[csv] position_kind``); then record it in the summary
    (``figure``: its path, or None and ``figure_skipped`` saying why; a failure in
    ``failed``) and write summary.json again."""
    try:
        summary["figure"] = _plot_track(out_dir, title, summary["format"], position_kind)
        if summary["figure"] is None:
            summary["figure_skipped"] = "no pipeline gave a position to draw"
    except ImportError:
        summary["figure"] = None
        summary["figure_skipped"] = "matplotlib is missing (pip install 'onboard[plot]')"
    except Exception as err:  # noqa: BLE001 - the other outputs are written already
        summary["figure"] = None
        export_failed(summary.setdefault("failed", []), "track.png", out_dir / "track.png",
                      err)
    write_summary(out_dir, summary)


def _write_layout(path: Path, cfg: Config, published: exports.Published,
                  failed: list[dict]) -> dict | None:
    """``--foxglove-layout``: the layout of what the replay published, for its vehicle
    (:func:`onboard.offline.exports.write_foxglove_layout`); None, listed in ``failed``,
    when it could not be written."""
    try:
        return exports.write_foxglove_layout(path, cfg.service.zenoh.key_prefix,
                                             cfg.vehicle.id, published)
    except Exception as err:  # noqa: BLE001 - one export fails, not the replay
        export_failed(failed, "--foxglove-layout", path, err)
        return None


def _origin(engine: Engine) -> dict | None:
    """The latitude and longitude (deg) of the first fix handed to the pipelines: the
    origin of the published ``north``/``east`` (m); None without a fix."""
    frame = engine.integrity.frame
    if frame is None:
        return None
    return {"lat_deg": frame.lat0, "lon_deg": frame.lon0}


def _time_span(engine: Engine, t_first: float) -> dict:
    """``start`` and ``end`` (s, log clock): the earliest and the latest stamp of the
    run's time line (after a clock that went back, not those of its first and last
    segment), ``duration_s`` the sum of its
    segments' durations (the time between segments is not counted), and ``segments``:
    each segment's start, end and duration (:mod:`onboard.engine.timeline`). A recording replayed
    at its recorded ticks has one segment, from the first sample to the newest."""
    segments = [(s.start, s.end) for s in engine.timeline.segments] or \
        [(t_first, max(engine.t_newest, t_first))]
    return {"start": min(a for a, _ in segments), "end": max(b for _, b in segments),
            "duration_s": sum(b - a for a, b in segments),
            "segments": [{"start": a, "end": b, "duration_s": b - a} for a, b in segments]}


POSITION_KINDS = {"gnss", "dvl_position"}
"""Sample kinds that measure a position."""
NEEDS: dict[str, tuple[str, tuple[frozenset[str], ...]]] = {
    "nav": ("a GNSS fix, a heading, a velocity over ground or a depth",
            (frozenset({"gnss", "heading", "attitude", "vog", "depth"}),)),
    "aie": ("a heading (compass or AHRS yaw) or a GNSS fix",
            (frozenset({"heading", "attitude", "gnss"}),)),
    "kf": ("a heading (compass or AHRS yaw) or a GNSS fix",
           (frozenset({"heading", "attitude", "gnss"}),)),
    "current": ("a heading (compass or AHRS yaw) to put velocities in the earth frame, and a "
                "velocity over ground (GNSS speed and course, INS velocity, DVL bottom track)",
                (frozenset({"heading", "attitude"}), frozenset({"gnss", "vog", "dvl"}))),
    "dac": ("GNSS fixes at the surface, depth, and the heading and pitch under water",
            (frozenset({"gnss"}), frozenset({"depth"}), frozenset({"heading", "attitude"}))),
    "eseso": ("the IMU and the attitude", (frozenset({"imu"}), frozenset({"attitude"}))),
}
"""Per pipeline: what it needs to give any estimate, in words, and as groups of sample
kinds of which the log must have one each."""


def run_warnings(engine: Engine, kinds: dict[str, int], cfg: Config,
                 header: Sequence[Sample] = (),
                 read_rejected: Mapping[str, int] | None = None, fmt: str = "",
                 read: ReadStats | None = None, log_name: str = "log",
                 not_read: Sequence[dict] = ()) -> Alerts:
    """The engine's warnings and those of the whole run: a log of which little could be
    used (``read``: the reader's counts, :func:`onboard.drivers.base.shortfall`), the logs
    of a folder log that its reader left out (``not_read``, :func:`files_not_read`), the
    log's HEARTBEAT and servo
    functions against ``cfg`` (:func:`onboard.offline.autodetect.consistency`), records the
    reader dropped as time outliers and MCAP messages it could not read
    (``read_rejected``: its rejections by reason), no position source, and every pipeline
    that gave no estimate with what it lacked (``kinds``: accepted samples by kind);
    ``fmt``: the log's format (a CSV log's columns are mapped in ``[csv]``)."""
    alerts = engine.alerts
    little = read and shortfall(read, log_name, engine.time_outliers())
    if little:
        alerts.warn("log_mostly_unread", little)
    _not_read_warning(alerts, log_name, fmt, not_read)
    for code, message in consistency(cfg, header):
        alerts.warn(code, message)
    _reader_warnings(alerts, read_rejected or {})
    have = {k for k, n in kinds.items() if n > 0}
    csv = fmt in ("csv", "csv-dir")
    listed = "summary.json samples_accepted_by_type lists what the log has"
    if not have & POSITION_KINDS:
        alerts.warn("no_position_source", "no position in the log (no GNSS fix, no DVL "
                    "position): positions are dead reckoned from velocities, or absent; "
                    + ("map its position columns in [csv]" if csv else listed),
                    details="position samples: " + ", ".join(sorted(POSITION_KINDS))
                    + ("" if csv else "; normal for a vehicle under water without them"))
    log_has = ", ".join(f"{k} ({kinds[k]})" for k in sorted(have)) or "no usable sample"
    for p in engine.pipelines:
        if p.name in engine.latest:
            continue
        needs, groups = NEEDS.get(p.name, ("inputs this log lacks", ()))
        missing = [g for g in groups if not g & have]
        lacks = p.lacks()
        why = (f"it needs {needs}" if missing or not groups
               else f"it needs {lacks}" if lacks else "its inputs never lined up")
        alerts.warn("no_estimate", f"{p.name} gave no estimate: {why}; the log has "
                    f"{log_has}; [pipelines.{p.name}] enabled = false leaves it out",
                    pipeline=p.name, details=(
                        "a CSV log maps its columns to samples in [csv] (docs/formats-text.md)"
                        if csv else ""))
    return alerts


FIRST_WARNINGS = frozenset({"log_mostly_unread", "logs_not_read"})
"""Warnings listed before the others: much of what was given was not read."""
FORMAT_WORDS = {"tlog": "MAVLink telemetry log (tlog)", "dataflash": "DataFlash log",
                "mcap": "MCAP recording", "slocum": "Slocum glider log", "csv": "CSV log",
                "recording": "service recording", "text": "text capture"}
"""Each format of :func:`drivers.logs.sniff` in words."""
FOLDER_READS = {"csv-dir": (".csv", "CSV runs"), "recording": (".onbrec", "recording files")}
"""Per format of a folder log: the files its reader reads (by name ending) and what they
are, in words."""


def files_not_read(log: str, fmt: str) -> list[dict]:
    """The files of the folder ``log`` (of format ``fmt``) that its reader leaves out, in
    name order (hidden files and sub-folders aside): each ``file`` (its name), ``why``
    (in words), ``log`` (whether the readers recognise it as a log, as ``onboard batch``
    judges it: :func:`onboard.drivers.logs.is_log`) and ``bytes``; empty for a file log."""
    p = Path(log)
    if not p.is_dir() or fmt not in FOLDER_READS:
        return []
    from onboard.drivers.logs import is_log

    suffix, runs = FOLDER_READS[fmt]
    out = []
    for f in sorted(p.iterdir()):
        if not f.is_file() or f.name.startswith(".") or f.suffix.lower() == suffix:
            continue
        not_a_log = is_log(f)
        if not_a_log:
            why = f"not a log ({not_a_log})"
        else:
            try:
                kind = FORMAT_WORDS.get(sniff(f), "log")
            except UnreadableLog:
                kind = "log"
            why = f"a {kind}, not one of the folder's {runs}"
        out.append({"file": f.name, "why": why, "log": not not_a_log,
                    "bytes": f.stat().st_size})
    return out


def _not_read_warning(alerts: Alerts, log_name: str, fmt: str,
                      not_read: Sequence[dict]) -> None:
    """``logs_not_read``: the logs in a folder log that its reader left out, named, with
    what reads them."""
    logs = [f for f in not_read if f["log"]]
    if not logs:
        return
    _, runs = FOLDER_READS[fmt]
    names = ", ".join(f["file"] for f in logs[:NAMED_FILES]) + (
        f" and {len(logs) - NAMED_FILES} more" if len(logs) > NAMED_FILES else "")
    alerts.warn("logs_not_read", f"{len(logs)} log(s) in {log_name} not read: {names}; "
                f"a folder replays as its {runs} alone: replay each other log on its own, "
                f"or onboard batch {log_name} for every log in it",
                details="; ".join(f"{f['file']}: {f['why']} ({f['bytes']:,} bytes)"
                                  for f in logs) + "; summary.json read.skipped_files")


NAMED_FILES = 5
"""Files a ``logs_not_read`` warning names in its line (its details name them all)."""


def _reader_warnings(alerts: Alerts, read_rejected: Mapping[str, int]) -> None:
    """The warnings of what the reader refused: records stamped far from the others, and
    an MCAP's messages or fields this version does not read."""
    n_out = read_rejected.get("time_outlier", 0)
    if n_out:
        alerts.warn("time_outlier", f"the reader dropped {n_out} record(s) stamped far from "
                    "the records around them; counted in summary.json read.rejected",
                    details="a corrupted or mistyped time; the records after them were kept")
    unread = {k.split(":", 1)[1]: n for k, n in read_rejected.items()
              if k.startswith("mcap:")}
    if unread:
        alerts.warn("mcap_unread", "the MCAP's MAVLink JSON had what this version does not "
                    "read (counts: " + ", ".join(f"{k} {n}" for k, n in sorted(unread.items()))
                    + "): those messages skipped; a newer onboard may read them",
                    details="unknown fields ignored, missing ones taken as 0 (summary.json "
                    "read.rejected)")


def print_warnings(warnings: list[dict], t0: float,
                   segments: Sequence[Mapping] = ()) -> None:
    """The warnings, one line each, times from the start of the log (s): along the time
    line's ``segments`` (summary.json ``time_span.segments``; the time between them not
    counted, :func:`onboard.engine.timeline.log_time`), else from ``t0``. Where that
    differs from estimates.csv's ``t`` (after a gap or a clock that went back: ``t``
    counts from the first segment's start), the span in ``t`` follows, so that it finds
    its rows."""
    if not warnings:
        return
    spans = [(g["start"], g["end"]) for g in segments]
    origin = spans[0][0] if spans else t0

    def at(t: float) -> float:
        return log_time(spans, t) if spans else t - t0

    print(f"{len(warnings)} warning{'s' if len(warnings) > 1 else ''}:")
    for w in warnings:
        span = ""
        if w["t_start"] is not None:
            a, b = at(w["t_start"]), at(w["t_end"])
            ta, tb = w["t_start"] - origin, w["t_end"] - origin
            span = f" [{a:.1f}-{b:.1f} s" + (
                f"; estimates.csv t {ta:.1f} to {tb:.1f}]"
                if max(abs(ta - a), abs(tb - b)) >= 0.05 else "]")
        print(f"  {w['code']}{span}: {w['message']}")
        if w.get("details"):
            print(f"      {w['details']}")


def _write_geojson(out_dir: Path, path: Path | None, gpx: Path | None,
                   summary: dict, failed: list[dict], clock: LogClock | None = None,
                   t0: float = 0.0) -> dict:
    """The replay's tracks and current arrows as GeoJSON in ``path``, its tracks as GPX in
    ``gpx`` (either may be None; :mod:`onboard.offline.exports`; the GPX's times in UTC
    where ``clock`` has it, ``t0`` the log time of ``t`` = 0), each written on its own (a
    failure listed in ``failed``); what was written."""
    from onboard.offline.plots import read_columns

    try:
        cols = read_columns(out_dir / "estimates.csv")
        fc = exports.feature_collection(cols, summary["origin"], summary["runs"],
                                        Path(summary["log"]).name)
    except Exception as err:  # noqa: BLE001 - both exports fail, not the replay
        for flag, p in (("--geojson", path), ("--gpx", gpx)):
            if p is not None:
                export_failed(failed, flag, p, err)
        return {"path": None, "gpx": None, "features": 0}
    utc = (lambda t: clock.to_utc(t0 + t)) if clock is not None and clock.utc else None
    written = {"--geojson": None, "--gpx": None}
    for flag, p, text in (
            ("--geojson", path, lambda: json.dumps(fc, allow_nan=False) + "\n"),
            ("--gpx", gpx, lambda: exports.to_gpx(cols, summary["origin"],
                                                  Path(summary["log"]).name, utc,
                                                  clock.source if clock else ""))):
        if p is None:
            continue
        try:
            Path(p).write_text(text())
            written[flag] = str(p)
        except Exception as err:  # noqa: BLE001
            export_failed(failed, flag, p, err)
    return {"path": written["--geojson"], "gpx": written["--gpx"],
            "features": len(fc["features"])}


def _plot_track(out_dir: Path, title: str, fmt: str, position_kind: str) -> str | None:
    """track.png: the measured track (labelled by the log's format ``fmt`` and, for a
    CSV, its ``[csv] position_kind``) and every reconstructed one, the current along them
    and in a panel of its own, titled ``title``; None when no pipeline has a position.
    Raises ImportError without matplotlib."""
    from onboard.offline.plots import plot_track, position_label

    return plot_track(out_dir / "estimates.csv", out_dir / "track.png", title,
                      position_label(fmt, position_kind))


REPLAY_WRITES = ("estimates.csv", "summary.json", "track.png")
"""What ``onboard replay`` writes in ``--out DIR``: a DIR holding one of them is a previous
replay's, reused only with ``--force``."""
EXPORT_FLAGS = (("--mcap", "mcap"), ("--geojson", "geojson"), ("--gpx", "gpx"),
                ("--foxglove-layout", "foxglove_layout"))
"""The file exports: flag and argument name."""


def planned_outputs(args) -> list[Output]:
    """Every path ``onboard replay`` will write, per its arguments
    (:func:`onboard.core.outputs.check`)."""
    outs = [Output("--out", Path(args.out), "dir", REPLAY_WRITES)]
    for flag, attr in EXPORT_FLAGS:
        value = getattr(args, attr, None)
        if value:
            outs.append(Output(flag, Path(value)))
    return outs


def only_pipelines(cfg: Config, names: str) -> Config:
    """``cfg`` with only the pipelines named in ``names`` (comma-separated) enabled: the
    ``--pipelines`` of ``onboard replay``. A name that is no pipeline, or a list of which
    none applies to the vehicle, is a :class:`UsageError`."""
    from onboard.pipelines import MODULES, build

    wanted = {n.strip() for n in names.split(",") if n.strip()}
    unknown = sorted(wanted - set(MODULES))
    if unknown or not wanted:
        raise UsageError(f"--pipelines {names}: {', '.join(unknown) or 'no name'} is not a "
                         f"pipeline (one or more of {', '.join(MODULES)})")
    tables = {name: msgspec.structs.replace(getattr(cfg.pipelines, name), enabled=False)
              for name in MODULES if name not in wanted}
    cut = msgspec.structs.replace(cfg, pipelines=msgspec.structs.replace(cfg.pipelines,
                                                                         **tables))
    if not build(cut):
        on = [p.name for p in build(cfg)]
        raise UsageError(f"--pipelines {names}: none of them runs on {cfg.vehicle.id} "
                         f"(class {cfg.vehicle.vehicle_class}; its pipelines: {', '.join(on)})")
    return cut


def main(args) -> int:
    """``onboard replay``: check every output path, choose the configuration, replay,
    print the headline, the warnings and, after the figure, one last line saying what
    was written (and what failed). A missing or unreadable log, or an output path that
    cannot be written, is a :class:`UsageError` (exit status 2) before any work; an
    export that failed gives exit status 1, the others written."""
    log = args.log
    if not Path(log).exists():
        raise UsageError(f"{log}: no such file or directory")
    force = bool(getattr(args, "force", False))
    check_outputs(planned_outputs(args), force=force, inputs=[log, *existing(args.config)])
    mcap = getattr(args, "mcap", None)
    out_dir = Path(args.out)
    try:
        if mcap:
            from onboard.drivers.mcap_log import mcap_module

            mcap_module()  # a missing package is said before the replay, not after
        cfg, note = choose_config(log, args.config)
        if getattr(args, "pipelines", None):
            cfg = only_pipelines(cfg, args.pipelines)
        summary = replay(log, cfg, out_dir, config_note=note, plot=False,
                         progress=sys.stderr.isatty(), mcap=Path(mcap) if mcap else None,
                         geojson=getattr(args, "geojson", None),
                         gpx=getattr(args, "gpx", None),
                         foxglove_layout=getattr(args, "foxglove_layout", None))
    except UnreadableLog as err:
        raise UsageError(str(err)) from None
    print(headline(summary, out_dir / "estimates.csv"))
    if "mcap" in summary:
        print(f"  {summary['mcap']['messages']:,} records -> {mcap} (MCAP; docs/foxglove.md)")
    if mcap or getattr(args, "gpx", None):   # the exports stamped in UTC
        print(f"  export times: {summary['utc']['source']}")
    if summary.get("foxglove_layout"):
        lay = summary["foxglove_layout"]
        print(f"  Foxglove layout of {len(lay['topics'])} topics of {lay['vehicle_id']} -> "
              f"{lay['file']}")
    print_warnings(summary["warnings"], summary["time_span"]["start"],
                   summary["time_span"]["segments"])
    if not args.no_plot:
        add_figure(out_dir, summary, Path(log).name, cfg.csv.position_kind)
    elif force:
        (out_dir / "track.png").unlink(missing_ok=True)  # not a previous run's figure
    print(last_line(summary, out_dir, plot=not args.no_plot))
    return 1 if summary["failed"] else 0


def inputs_rejected(summary: dict) -> int:
    """Inputs refused: the records the reader could not use and the samples the engine
    rejected (not the pipelines' failures, not the estimates withheld)."""
    return sum(summary["read"]["rejected"].values()) + sum(
        n for k, n in summary["rejected"].items() if not k.startswith("pipeline:"))


def headline(summary: dict, csv_path: Path) -> str:
    """The first line of ``onboard replay``: the log read, its inputs rejected, the rows
    written and the estimates withheld on them, apart."""
    return (f"{summary['format']} log, {summary['time_span']['duration_s']:.1f} s, "
            f"{summary['read']['samples']:,} samples, {inputs_rejected(summary):,} "
            f"rejected; {summary['rows']:,} rows{_withheld_note(summary)} -> {csv_path} "
            f"({summary['config']})")


def _withheld_note(summary: dict) -> str:
    """`` (current withheld on 3,217)``: per pipeline, the rows on which the integrity
    monitor withheld estimates, the rows on which the current was unknown (its sigma
    above ``unknown_above_std_mps``: what the log cannot resolve), and the values left
    out as not finite; empty without."""
    parts = [f"{p} withheld on {n:,}" for p, n in summary.get("withheld_rows", {}).items()
             if n]
    parts += [f"{p} unknown on {int(h['unknown']):,}"
              for p, h in summary.get("pipeline_health", {}).items()
              if isinstance(h, dict) and h.get("unknown")]
    parts += [f"{n:,} {k.split(':')[1]} values not finite"
              for k, n in summary.get("withheld", {}).items() if k.endswith(":nonfinite") and n]
    return f" ({'; '.join(parts)})" if parts else ""


def last_line(summary: dict, out_dir: Path, plot: bool) -> str:
    """The last line of ``onboard replay``: what was written, and first what failed and
    why (exit status 1)."""
    names = ["estimates.csv", "summary.json"] + (["track.png"] if summary.get("figure")
                                                 else [])
    extra = [p for p in (summary.get("mcap", {}).get("file"),
                         summary.get("geojson", {}).get("path"),
                         summary.get("geojson", {}).get("gpx"),
                         (summary.get("foxglove_layout") or {}).get("file")) if p]
    wrote = f"wrote {', '.join(names)} in {out_dir}" + (f", and {', '.join(extra)}"
                                                        if extra else "")
    if plot and summary.get("figure_skipped"):
        wrote += f"; no track.png: {summary['figure_skipped']}"
    failed = [f"{f['output'] + ' ' if f['output'].startswith('--') else ''}{f['path']}: "
              f"{f['error']}" for f in summary["failed"]]
    if failed:
        return f"failed: {'; '.join(failed)}; {wrote}"
    n = len(summary["warnings"])
    return wrote + (f" ({n} warning{'s' if n > 1 else ''} above)" if n else "")
