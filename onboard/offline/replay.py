"""``onboard replay LOG [--config FILE] [--out DIR] [--mcap FILE]``: run the pipelines
over a log.

Writes ``DIR/estimates.csv`` (architecture.md §4.2), ``DIR/summary.json`` (what was read
and rejected, rates, time span, the vehicle config used and why) and ``DIR/track.png``;
with ``--mcap`` also the estimates as MCAP, on the channels and with the schemas of the
live Zenoh records (:mod:`drivers.mcap_out`, docs/foxglove.md).
The same engine and pipelines as the live service, so a replay is the live result.
"""

from __future__ import annotations

import bisect
import itertools
import json
import sys
import time
from pathlib import Path
from typing import Iterable, Iterator, Mapping, Sequence

import msgspec

from onboard.drivers.base import UnreadableLog
from onboard.drivers.logs import open_log
from onboard.monitor.alerts import Alerts
from onboard.offline.autodetect import consistency, detect
from onboard.core import config as configmod
from onboard.core.config import Config
from onboard.core.errors import UsageError
from onboard.core.messages import EstimateRecord, Parameter, Sample, VehicleInfo
from onboard.engine import Engine, run
from onboard.engine.inputs import column_names
from onboard.engine.sources import QUANTITIES


def _fmt(v: float) -> str:
    """Deterministic text for a float: 10 significant digits, empty for NaN."""
    return "" if v != v else f"{v:.10g}"


class EstimatesCsv:
    """Streams ticks into estimates.csv: ``t`` since the first sample, ``run`` (the run
    the tick belongs to, :class:`Runs`), then a column per ``<pipeline>.<quantity>``,
    empty where a pipeline has no estimate.

    Attributes:
        runs: per run, its number, name, first and last ``t`` and rows.
    """

    def __init__(self, path: Path, columns: Sequence[str], t0: float | None,
                 runs: Runs | None = None) -> None:
        """``columns``: ``t`` then the pipelines' columns (:attr:`Engine.columns`);
        ``run`` is written after ``t``. ``runs`` tells each tick's run (default: one)."""
        self.columns = [columns[0], RUN_COLUMN, *columns[1:]]
        self.index = {c: i for i, c in enumerate(self.columns)}
        self.t0 = t0
        self.rows = 0
        self.run_of = runs if runs is not None else Runs()
        self.runs: list[dict] = []
        self._by_pipeline: dict[str, dict[str, int]] = {}
        """Per pipeline: quantity -> column index (the quantities it has written)."""
        self._f = open(path, "w", encoding="utf-8", newline="\n")
        self._f.write(",".join(self.columns) + "\n")

    def _column(self, pipeline: str, quantity: str) -> int | None:
        """Index of ``<pipeline>.<quantity>``, None if that is not a column (cached)."""
        i = self.index.get(pipeline + "." + quantity)
        if i is not None:
            self._by_pipeline.setdefault(pipeline, {})[quantity] = i
        return i

    def write(self, t: float, records: Sequence[EstimateRecord]) -> None:
        """One row at tick time ``t`` (s); values as :func:`_fmt` writes them."""
        if self.t0 is None:
            self.t0 = t
        row = [""] * len(self.columns)
        row[0] = tt = f"{t - self.t0:.6f}"
        row[1] = self._run(t, float(tt))
        by_pipeline = self._by_pipeline
        for rec in records:
            index = by_pipeline.get(rec.pipeline)
            if index is None:
                index = by_pipeline[rec.pipeline] = {}
            for k, v in rec.values.items():
                i = index.get(k)
                if i is None:
                    i = self._column(rec.pipeline, k)
                    if i is None:
                        continue
                row[i] = "" if v != v else f"{v:.10g}"   # _fmt, inline
        self._f.write(",".join(row) + "\n")
        self.rows += 1

    def _run(self, t: float, t_csv: float) -> str:
        """The run of the tick at ``t`` (s, log clock; ``t_csv`` as written), counted in
        :attr:`runs`."""
        k, name = self.run_of.at(t)
        runs = self.runs
        if not runs or runs[-1]["run"] != k:
            runs.append({"run": k, "name": name, "t_start": t_csv, "t_end": t_csv,
                         "rows": 0})
        last = runs[-1]
        last["t_end"] = t_csv
        last["rows"] += 1
        return str(k)

    def close(self) -> None:
        """Close the file (rows already written are complete lines)."""
        self._f.close()


RUN_COLUMN = "run"
"""The column of estimates.csv after ``t``: the run (0, 1, ...) the row belongs to."""


class Runs:
    """The run of each tick: a new one at each time segment of the engine's time line
    (a clock jump, :mod:`onboard.engine.timeline`) and at each run of a CSV log (a file of a
    directory, or a ``run_column`` value; :attr:`CsvReader.runs`). Runs are numbered
    from 0 in the order they start; a name says which it is (the CSV run's name, or
    ``segment <n>``; empty for a log of one run)."""

    def __init__(self, engine: Engine | None = None, csv_runs: Sequence = ()) -> None:
        """``engine``: its time line's segments; ``csv_runs``: the reader's runs (each
        with ``name`` and ``t_start`` on the log clock), in order."""
        self.engine = engine
        self.starts = [r.t_start for r in csv_runs]
        self.names = [r.name for r in csv_runs]
        self._key: tuple[int, int] | None = None
        self._k = -1

    def at(self, t: float) -> tuple[int, str]:
        """(run number, name) of the tick at ``t`` (s, log clock)."""
        seg = _segment_of(self.engine.timeline.segments, t) if self.engine else 0
        part = bisect.bisect_right(self.starts, t) - 1
        key = (seg, max(part, 0))
        if key != self._key:
            self._key = key
            self._k += 1
        if self.names:
            return self._k, self.names[key[1]]
        return self._k, f"segment {seg + 1}" if seg > 0 else ""


def _segment_of(segments: Sequence, t: float) -> int:
    """The index of the segment the tick at ``t`` (s) belongs to: the newest that spans
    ``t``, else the newest that started before it (a tick past its newest sample, or in a
    gap), else 0. The time line adds a segment when its jump is confirmed, which is before
    the last ticks of the old one (``onboard.engine.run``)."""
    for k in range(len(segments) - 1, -1, -1):
        if segments[k].start <= t <= segments[k].end:
            return k
    for k in range(len(segments) - 1, -1, -1):
        if segments[k].start <= t:
            return k
    return 0

class _Progress:
    """Progress on a terminal (stderr), at most twice a second; silent otherwise."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.last = 0.0
        self.n = 0

    def wrap(self, samples: Iterable[Sample]) -> Iterator[Sample]:
        for s in samples:
            self.n += 1
            if self.enabled and (self.n & 1023) == 0:
                now = time.monotonic()
                if now - self.last > 0.5:
                    self.last = now
                    print(f"\r  {self.n:,} samples, log time {s.t:.1f} s", end="",
                          file=sys.stderr, flush=True)
            yield s

    def done(self) -> None:
        if self.enabled and self.last:
            print(file=sys.stderr)


def choose_config(log: str, config_path: str | Sequence[str] | None
                  ) -> tuple[Config, str]:
    """The config to use: the given file, or several applied in order
    (:func:`onboard.core.config.load_all`), or one detected from the log's header."""
    if isinstance(config_path, str):
        config_path = [config_path]
    if config_path:
        return configmod.load_all(config_path), f"from {' + '.join(config_path)}"
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
    elif fmt in ("dataflash", "recording", "mcap"):
        header = [s for s in reader if isinstance(s, (Parameter, VehicleInfo))]
        cfg, why = detect(header)
    else:
        cfg, why = configmod.Config(), "no vehicle evidence in a text log; generic config"
    return cfg, f"detected: {why}"


def replay(log: str, cfg: Config, out_dir: Path, *, config_note: str = "",
           plot: bool = True, progress: bool = False, mcap: Path | None = None,
           geojson: Path | None = None, gpx: Path | None = None) -> dict:
    """Run the pipelines over ``log``; write the outputs into ``out_dir`` (and the
    estimates as MCAP into ``mcap`` when given; with ``geojson`` the tracks and current
    arrows there, with ``gpx`` the tracks, :mod:`onboard.offline.exports`); return the summary."""
    out_dir.mkdir(parents=True, exist_ok=True)
    wall0 = time.perf_counter()
    fmt, reader = open_log(log, cfg.csv, column_names(cfg.inputs))
    engine = Engine(cfg)
    samples = iter(reader)
    first = next(samples, None)
    if first is None:
        raise UnreadableLog(f"{log}: no usable samples ({reader.stats.as_dict()['rejected']})")
    # A live recording starts ticking before its first sample: count from the first tick.
    csv = EstimatesCsv(out_dir / "estimates.csv", engine.columns,
                       None if fmt == "recording" else first.t,
                       Runs(engine, [r for r in getattr(reader, "runs", ())
                                     if r.t_start == r.t_start]))
    on_tick = csv.write
    mcap_out = None
    if mcap is not None:
        from onboard.drivers.mcap_out import McapRecordWriter

        mcap_out = McapRecordWriter(mcap, cfg.service.zenoh.key_prefix, cfg.vehicle.id)

        def on_tick(t: float, records: Sequence[EstimateRecord]) -> None:
            csv.write(t, records)
            mcap_out.write(t, records, engine.location_fixes(records))
    meter = _Progress(progress)

    header: list[Sample] = []   # HEARTBEAT and parameters, checked against cfg at the end

    def stream() -> Iterator[Sample]:
        for s in itertools.chain((first,), samples):
            if isinstance(s, (VehicleInfo, Parameter)):
                header.append(s)
            yield s

    source = meter.wrap(stream()) if progress else stream()
    if fmt == "recording":
        # The service's own recording: re-parse every raw chunk in the order it arrived,
        # through the same intake as live, ticking at the recorded tick times, so the
        # estimates are exactly the live ones (onboard.service.recorder.replay_recording).
        from onboard.service.recorder import replay_recording

        result = replay_recording(log, engine, on_tick)
        ticks = result.ticks
        reader.stats = result.stats
        for reason, n in result.rejected.items():
            reader.stats.rejected[reason] += n
        reader.stats.samples = sum(engine.accepted.values()) + sum(engine.rejected.values())
    else:
        ticks = run(engine, source, on_tick)
    csv.close()
    if mcap_out is not None:
        mcap_out.close()
    meter.done()
    time_span = _time_span(engine, first.t)
    span = time_span["duration_s"]
    kinds: dict[str, int] = {}
    for (kind, _), n in engine.accepted.items():
        kinds[kind] = kinds.get(kind, 0) + n
    summary = {
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
        "read": reader.stats.as_dict(),
        "samples_accepted_by_type": dict(sorted(kinds.items())),
        "rates_hz": {k: (n / span if span > 0 else None) for k, n in sorted(kinds.items())},
        "accepted": {f"{k}:{src}": n for (k, src), n in sorted(engine.accepted.items())},
        "rejected": dict(sorted(engine.rejections().items())),
        "sources": {"active": dict(engine.selector.active),
                    "switches": engine.selector.switches,
                    "events": [e for e in engine.events if e.split(":", 1)[0] in QUANTITIES],
                    "standby": {f"{q}:{src}": n for (q, src), n
                                in sorted(engine.selector.standby.items())}},
        "ticks": ticks,
        "rows": csv.rows,
        "rate_hz": cfg.engine.rate_hz,
        "warnings": msgspec.to_builtins(list(run_warnings(
            engine, kinds, cfg, header, reader.stats.rejected))),
        "innovations": msgspec.to_builtins(engine.monitor.snapshot(reset_max=False)),
        "pipeline_health": engine.counters(),
        "declination": msgspec.to_builtins(engine.declination.report),
        "wall_time_s": round(time.perf_counter() - wall0, 3),
    }
    if mcap_out is not None:
        summary["mcap"] = {"file": str(mcap), "messages": mcap_out.messages}
    if geojson is not None or gpx is not None:
        summary["geojson"] = _write_geojson(out_dir, geojson, gpx, summary)
    if plot:
        summary["figure"] = _plot_track(out_dir, Path(log).name, fmt, cfg.csv.position_kind)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def _origin(engine: Engine) -> dict | None:
    """The latitude and longitude (deg) of the first fix handed to the pipelines: the
    origin of the published ``north``/``east`` (m); None without a fix."""
    frame = engine.integrity.frame
    if frame is None:
        return None
    return {"lat_deg": frame.lat0, "lon_deg": frame.lon0}


def _time_span(engine: Engine, t_first: float) -> dict:
    """``start`` and ``end`` (s, log clock) of the run, ``duration_s`` the sum of its
    segments' durations (the time between segments is not counted), and ``segments``:
    each segment's start, end and duration (:mod:`onboard.engine.timeline`). A recording replayed
    at its recorded ticks has one segment, from the first sample to the newest."""
    segments = [(s.start, s.end) for s in engine.timeline.segments] or \
        [(t_first, max(engine.t_newest, t_first))]
    return {"start": segments[0][0], "end": segments[-1][1],
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
    "eseso": ("the IMU and the attitude", (frozenset({"imu"}), frozenset({"attitude"}))),
}
"""Per pipeline: what it needs to give any estimate, in words, and as groups of sample
kinds of which the log must have one each."""


def run_warnings(engine: Engine, kinds: dict[str, int], cfg: Config,
                 header: Sequence[Sample] = (),
                 read_rejected: Mapping[str, int] | None = None) -> Alerts:
    """The engine's warnings and those of the whole run: the log's HEARTBEAT and servo
    functions against ``cfg`` (:func:`onboard.offline.autodetect.consistency`), records the
    reader dropped as time outliers and MCAP messages it could not read
    (``read_rejected``: its rejections by reason), no position source, and every pipeline that gave no estimate with what it lacked
    (``kinds``: accepted samples by kind)."""
    alerts = engine.alerts
    for code, message in consistency(cfg, header):
        alerts.warn(code, message)
    n_out = (read_rejected or {}).get("time_outlier", 0)
    if n_out:
        alerts.warn("time_outlier", f"the reader dropped {n_out} record(s) stamped far from "
                    "the records around them (a corrupted or mistyped time); the records "
                    "after them were kept")
    unread = {k.split(":", 1)[1]: n for k, n in (read_rejected or {}).items()
              if k.startswith("mcap:")}
    if unread:
        alerts.warn("mcap_unread", "the MCAP's MAVLink JSON had what this version does not "
                    "read (counts: " + ", ".join(f"{k} {n}" for k, n in sorted(unread.items()))
                    + "): those messages were skipped, unknown fields ignored, missing ones "
                    "taken as 0 (summary.json read.rejected)")
    have = {k for k, n in kinds.items() if n > 0}
    if not have & POSITION_KINDS:
        alerts.warn("no_position_source", "no position source in the log (no GNSS fix, no "
                    "DVL position): positions are dead reckoned from velocities, or absent")
    log_has = ", ".join(f"{k} ({kinds[k]})" for k in sorted(have)) or "no usable sample"
    for p in engine.pipelines:
        if p.name in engine.latest:
            continue
        needs, groups = NEEDS.get(p.name, ("inputs this log lacks", ()))
        missing = [g for g in groups if not g & have]
        why = f"it needs {needs}" if missing or not groups else "its inputs never lined up"
        alerts.warn("no_estimate", f"{p.name} gave no estimate: {why}; the log has {log_has}",
                    pipeline=p.name)
    return alerts


def print_warnings(warnings: list[dict], t0: float) -> None:
    """The warnings, one line each, times from the start of the log (s)."""
    if not warnings:
        return
    print(f"{len(warnings)} warning{'s' if len(warnings) > 1 else ''}:")
    for w in warnings:
        span = ""
        if w["t_start"] is not None:
            span = f" [{w['t_start'] - t0:.1f}-{w['t_end'] - t0:.1f} s]"
        print(f"  {w['code']}{span}: {w['message']}")


def _write_geojson(out_dir: Path, path: Path | None, gpx: Path | None,
                   summary: dict) -> dict:
    """The replay's tracks and current arrows as GeoJSON in ``path``, its tracks as GPX in
    ``gpx`` (either may be None); what was written."""
    from onboard.offline import exports as geojson
    from onboard.offline.plots import read_columns

    cols = read_columns(out_dir / "estimates.csv")
    n = geojson.write(path, cols, summary["origin"], summary["runs"],
                      Path(summary["log"]).name, gpx)
    return {"path": str(path) if path else None, "gpx": str(gpx) if gpx else None,
            "features": n}


def _plot_track(out_dir: Path, title: str, fmt: str, position_kind: str) -> str | None:
    """track.png: the measured track (labelled by the log's format ``fmt`` and, for a
    CSV, its ``[csv] position_kind``) and every reconstructed one, the current along them
    and in a panel of its own, titled ``title``; None without matplotlib."""
    from onboard.offline.plots import plot_track, position_label

    try:
        return plot_track(out_dir / "estimates.csv", out_dir / "track.png", title,
                          position_label(fmt, position_kind))
    except ImportError:
        return None


def main(args) -> int:
    """``onboard replay``: choose the configuration, replay, print a one-line summary;
    a missing or unreadable log is a :class:`UsageError` (exit status 2)."""
    log = args.log
    if not Path(log).exists():
        raise UsageError(f"{log}: no such file or directory")
    mcap = getattr(args, "mcap", None)
    try:
        if mcap:
            from onboard.drivers.mcap_log import mcap_module

            mcap_module()  # a missing package is said before the replay, not after
        cfg, note = choose_config(log, args.config)
        summary = replay(log, cfg, Path(args.out), config_note=note,
                         plot=not args.no_plot, progress=sys.stderr.isatty(),
                         mcap=Path(mcap) if mcap else None,
                         geojson=getattr(args, "geojson", None),
                         gpx=getattr(args, "gpx", None))
    except UnreadableLog as err:
        raise UsageError(str(err)) from None
    read = summary["read"]
    rejected = sum(read["rejected"].values()) + sum(summary["rejected"].values())
    print(f"{summary['format']} log, {summary['time_span']['duration_s']:.1f} s, "
          f"{read['samples']:,} samples, {rejected:,} rejected; {summary['rows']:,} rows "
          f"-> {Path(args.out) / 'estimates.csv'} ({summary['config']})")
    if mcap:
        print(f"  {summary['mcap']['messages']:,} records -> {mcap} (MCAP; docs/foxglove.md)")
    print_warnings(summary["warnings"], summary["time_span"]["start"])
    return 0
