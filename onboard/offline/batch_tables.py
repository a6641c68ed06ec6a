"""The season's tables of ``onboard batch``: ``runs.parquet`` (a row per log) and
``current.parquet`` (every published current), their columns in docs/batch.md and
architecture.md §4.7, and the season report of ``--diagnose`` (:func:`season_report`).

A log's row is computed where it was replayed, from its summary.json, estimates.csv and
diagnosis.json (:func:`replay_figures`, :func:`diagnosis_figures`), and kept as JSON in
its folder; its current goes into ``current.parquet`` in its folder
(:func:`write_log_current`); :func:`write_tables` gathers them. UTC comes from the log's
clock as the replay recorded it in summary.json's ``utc`` (:func:`clock_of`); a current's
place is the one its record carried (:class:`Places`: the vehicle's best position,
:mod:`onboard.engine.whereabouts`, as the fleet receives it live), a dive's the midpoint
of its fixes about summary.json's ``origin`` (:class:`onboard.core.geo.LocalFrame`).
pyarrow is imported only here (the ``batch`` extra).
"""

from __future__ import annotations

import math
import statistics
from array import array
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from onboard.core.errors import UsageError
from onboard.core.geo import circular_stats
from onboard.offline.plots import dive_rows

LOG_CURRENT = "current.parquet"
"""A log's current in its own folder, gathered into ``DIR/current.parquet``."""
MOVING_MPS = 0.5
"""Speed over ground above which heading minus course is counted (m/s): below it the
course of a GNSS is noise."""
ROW_KEYS = ("log", "name", "status", "error", "format", "vehicle_id", "vehicle_class",
            "config", "utc_start", "utc_source", "duration_s", "samples", "rows",
            "warnings", "n_warnings", "origin_lat_deg", "origin_lon_deg",
            "current_fraction", "current_speed_median_mps", "current_north_median_mps",
            "current_east_median_mps", "current_std_median_mps",
            "heading_minus_course_median_deg", "availability", "diagnosed",
            "diagnose_error", "effects", "effect_params", "holdout_metric",
            "holdout_error_before", "holdout_error_after", "cpu_s", "wall_s")
"""The columns of runs.parquet, in order (docs/batch.md)."""
FITTED_CONFIG = "(its header fits this bundled config)"
"""The end of runs.parquet's ``config`` for a CSV log given no ``--config``, replayed with
the bundled config its header fits (``onboard.offline.batch``)."""
Units = Callable[[str, str], tuple[str, float]]
"""``units(effect, parameter)``: the unit a parameter is shown in and the factor from its
SI value ("" and 1 for a number without one)."""
CIRCULAR_PARAMS = {("compass_deviation", "phase"), ("heading_bias", "bias"),
                   ("wave_oscillation", "direction")}
"""Effect parameters that are angles on the circle: the season report takes their
circular mean and standard deviation (a bias of 179 deg and one of -179 deg average to
180, not 0) and shows each value within (-180, 180] deg."""


def require_pyarrow() -> None:
    """A :class:`UsageError` naming the extra when pyarrow is missing."""
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        raise UsageError("onboard batch writes Parquet with pyarrow: pip install "
                         "'onboard[batch]'") from None


def empty_row(log: str, name: str) -> dict:
    """A row of runs.parquet for ``log`` (its folder ``name``) with nothing known yet."""
    row: dict = dict.fromkeys(ROW_KEYS)
    row.update(log=str(log), name=name, status="ok", warnings={}, availability={},
               diagnosed=False, effects=[], effect_params={}, n_warnings=0)
    return row


def clock_of(summary: dict):
    """The :class:`drivers.logclock.LogClock` the replay recorded in ``summary``
    (summary.json's ``utc``: :func:`onboard.offline.replay.clock_from_summary`), None
    when it recorded none."""
    from onboard.offline.replay import clock_from_summary

    return clock_from_summary(summary)


def _t0(summary: dict) -> float:
    """The log time (s) of estimates.csv's ``t`` = 0: the first stamp of the time line."""
    segments = summary["time_span"]["segments"]
    return segments[0]["start"] if segments else summary["time_span"]["start"]


def read_estimates(csv_path: Path) -> dict[str, np.ndarray]:
    """estimates.csv as float columns (NaN where empty), read once for the row and the
    current (:func:`onboard.offline.plots.read_columns`)."""
    from onboard.offline.plots import read_columns

    return {k: np.asarray(v, dtype=float) for k, v in read_columns(csv_path).items()}


def _median(x: np.ndarray) -> float | None:
    x = x[np.isfinite(x)]
    return float(np.median(x)) if x.size else None


def replay_figures(summary: dict, cols: dict[str, np.ndarray], clock) -> dict:
    """The row's figures of a replay: what summary.json says, the UTC start, and the key
    figures of its estimates.csv ``cols`` (:func:`read_estimates`,
    :func:`_estimate_figures`)."""
    warnings: dict[str, int] = {}
    for w in summary["warnings"]:
        warnings[w["code"]] = warnings.get(w["code"], 0) + 1
    origin = summary.get("origin") or {}
    utc = clock.summary(_t0(summary)) if clock is not None else None
    row = {"status": "ok", "format": summary["format"], "vehicle_id": summary["vehicle_id"],
           "vehicle_class": summary["vehicle_class"], "config": summary["config"],
           "utc_start": utc["start"] if utc else None,
           "utc_source": utc["source"] if utc else None,
           "duration_s": summary["time_span"]["duration_s"],
           "samples": summary["read"]["samples"], "rows": summary["rows"],
           "warnings": warnings, "n_warnings": len(summary["warnings"]),
           "origin_lat_deg": origin.get("lat_deg"), "origin_lon_deg": origin.get("lon_deg")}
    row.update(_estimate_figures(cols, summary["pipelines"]))
    return row


def _estimate_figures(cols: dict[str, np.ndarray], pipelines: Sequence[str]) -> dict:
    """Key figures of the estimates: the fraction of rows with a current, its median
    speed, north, east and sigma (the root mean square of its north and east sigmas),
    the median of heading minus course while moving (``nav``; a compass offset, or a
    crab angle), and per pipeline the fraction of rows with an estimate."""
    n = len(cols.get("t", ()))
    out: dict = {"availability": {}}
    for p in pipelines:
        mine = [v for k, v in cols.items() if k.startswith(p + ".")]
        have = np.any([np.isfinite(v) for v in mine], axis=0) if mine and n else []
        out["availability"][p] = float(np.mean(have)) if n and mine else 0.0
    velocity = _published_current(cols)
    if velocity is not None and n:
        fraction, cn, ce, sn, se = velocity
        out["current_fraction"] = fraction
        out["current_speed_median_mps"] = _median(np.hypot(cn, ce))
        out["current_north_median_mps"] = _median(cn)
        out["current_east_median_mps"] = _median(ce)
        if sn is not None and se is not None:
            out["current_std_median_mps"] = _median(np.sqrt((sn ** 2 + se ** 2) / 2.0))
    else:
        out["current_fraction"] = 0.0
    hd, co, sp = cols.get("nav.heading"), cols.get("nav.course"), cols.get("nav.speed")
    if hd is not None and co is not None and sp is not None:
        moving = sp > MOVING_MPS
        diff = np.degrees(np.angle(np.exp(1j * (hd[moving] - co[moving]))))
        out["heading_minus_course_median_deg"] = _median(diff)
    return out


def _published_current(cols: dict[str, np.ndarray]) -> tuple | None:
    """The current a log published, for its key figures: (the fraction of rows with
    one, and on those rows north, east, std north, std east) of pipeline ``current``'s
    rows (a row whose current is withheld as unknown keeps its sigma, which is not the
    published current's), or, where it
    published none and a glider's ``dac`` did, of its dives (each once: its rows repeat
    the newest dive); None where neither has columns."""
    cn, ce = cols.get("current.north"), cols.get("current.east")
    end = cols.get("dac.dive_end")
    if end is not None and np.isfinite(end).any() and \
            (cn is None or ce is None or not np.isfinite(cn).any()):
        rows = dive_rows(end)
        return (float(np.mean(np.isfinite(end))),) + tuple(
            cols[f"dac.{k}"][rows] for k in ("north", "east", "std_north", "std_east"))
    if cn is None or ce is None:
        return None
    known = np.isfinite(cn) & np.isfinite(ce)   # a withheld row's sigma is not the current's
    sn, se = cols.get("current.std_north"), cols.get("current.std_east")
    return (float(np.mean(known)), cn[known], ce[known],
            None if sn is None else sn[known], None if se is None else se[known])


def diagnosis_figures(doc: dict) -> dict:
    """The row's figures of a diagnosis: the effects found, their parameters
    (``<effect>.<param>``, a list's items as ``<param>[k]``) and the test-part error
    before and after."""
    found = [e for e in doc["effects"] if e.get("detected")]
    params: dict[str, float] = {}
    for e in found:
        for k, v in (e.get("params") or {}).items():
            for key, x in _flat(f"{e['name']}.{k}", v):
                params[key] = x
    return {"diagnosed": True, "effects": [e["name"] for e in found],
            "effect_params": params, "holdout_metric": doc.get("holdout_metric"),
            "holdout_error_before": doc.get("holdout_error_before"),
            "holdout_error_after": doc.get("holdout_error_after")}


def _flat(key: str, v) -> list[tuple[str, float]]:
    """``(key, number)`` of a parameter: a number, or each item of a list of numbers."""
    if isinstance(v, bool) or v is None:
        return []
    if isinstance(v, (int, float)):
        return [(key, float(v))] if math.isfinite(v) else []
    if isinstance(v, (list, tuple)):
        return [kv for i, x in enumerate(v) for kv in _flat(f"{key}[{i}]", x)]
    return []


class Places:
    """Where each tick's records (:class:`~onboard.core.messages.EstimateRecord`) put the
    vehicle, a row per tick as estimates.csv has (every record of a tick carries the same
    place; NaN where unknown): called with each tick's records (``replay``'s
    ``on_records``). Three floats a tick: a vehicle-day at 10 Hz is 7 MB."""

    def __init__(self) -> None:
        self.lat, self.lon, self.std = array("d"), array("d"), array("d")

    def __call__(self, t: float, records: Sequence) -> None:
        lat = lon = std = None
        if records:
            lat, lon, std = records[0].lat_deg, records[0].lon_deg, records[0].position_std_m
        for column, value in ((self.lat, lat), (self.lon, lon), (self.std, std)):
            column.append(math.nan if value is None else value)

    def __getitem__(self, i: int) -> tuple[float | None, float | None, float | None]:
        """Row ``i``'s ``(lat_deg, lon_deg, position_std_m)``, None where unknown."""
        return _num(self.lat[i]), _num(self.lon[i]), _num(self.std[i])


def current_rows(cols: dict[str, np.ndarray], summary: dict, clock,
                 places: Places | Sequence) -> dict[str, list]:
    """The current.parquet columns of one log: a row per row of estimates.csv with a
    published current (module docstring of docs/batch.md), at ``places[i]``, the place
    the records of row ``i`` carried (:class:`Places`)."""
    from onboard.core.geo import LocalFrame

    cn, ce = cols.get("current.north"), cols.get("current.east")
    keys = ("t_s", "utc", "lat", "lon", "north", "east", "std_north", "std_east", "flags",
            "pipeline", "position_std_m", "down", "std_down")
    out: dict[str, list] = {k: [] for k in keys}
    origin = summary.get("origin")
    frame = LocalFrame(origin["lat_deg"], origin["lon_deg"]) if origin else None
    _dive_rows(cols, summary, clock, frame, out)
    if cn is None or ce is None:
        return out
    nan = np.full_like(cn, np.nan)
    sn, se = cols.get("current.std_north", nan), cols.get("current.std_east", nan)
    down, sd = cols.get("current.down", nan), cols.get("current.std_down", nan)
    t0 = _t0(summary)
    spans = _flag_spans(summary["warnings"])
    for i in np.flatnonzero(np.isfinite(cn) & np.isfinite(ce)):
        t = float(cols["t"][i])
        lat, lon, position_std = places[i]
        for k, v in zip(keys, (t, _utc_ms(clock, t0 + t), lat, lon, float(cn[i]),
                               float(ce[i]), _num(sn[i]), _num(se[i]),
                               sorted({c for c, a, b in spans if a <= t0 + t <= b}),
                               "current", position_std, _num(down[i]), _num(sd[i]))):
            out[k].append(v)
    return out


def _dive_rows(cols: dict[str, np.ndarray], summary: dict, clock, frame,
               out: dict[str, list]) -> None:
    """A row per dive of a glider's ``dac`` pipeline (algorithms.md §3.7) into ``out``:
    at the dive's middle in time (``t_s``, ``utc``) and place (``lat``, ``lon``: the
    midpoint of its two fixes), pipeline ``dac``, no flags."""
    end = cols.get("dac.dive_end")
    if end is None:
        return
    t0 = _t0(summary)
    for i in dive_rows(end):
        mid = 0.5 * (float(cols["dac.dive_start"][i]) + float(end[i]))
        lat = lon = None
        if frame is not None:
            lat, lon = frame.to_latlon(float(cols["dac.place_north"][i]),
                                       float(cols["dac.place_east"][i]))
        row = (mid - t0, _utc_ms(clock, mid), lat, lon,
               float(cols["dac.north"][i]), float(cols["dac.east"][i]),
               _num(cols["dac.std_north"][i]), _num(cols["dac.std_east"][i]), [], "dac",
               None, None, None)
        for k, v in zip(out, row):
            out[k].append(v)


def _utc_ms(clock, t: float) -> int | None:
    """The UTC (ms) of log time ``t`` (s) on ``clock``; None without one, or where the log
    has no UTC."""
    utc_s = clock.to_utc(t) if clock is not None else None
    return round(1000.0 * utc_s) if utc_s is not None else None


def _num(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def _flag_spans(warnings: Sequence[dict]) -> list[tuple[str, float, float]]:
    """(code, start, end) of the warnings that flag the current: those of the ``current``
    pipeline (over the whole log when they have no time) and those of no pipeline with a
    time (a clock jump, a source switch)."""
    spans = []
    for w in warnings:
        timed = w.get("t_start") is not None
        if w.get("pipeline") == "current" or (not w.get("pipeline") and timed):
            spans.append((w["code"], w["t_start"] if timed else -math.inf,
                          w["t_end"] if timed else math.inf))
    return spans


def write_log_current(out: Path, summary: dict, est: dict[str, np.ndarray], clock,
                      places: Places) -> None:
    """``out/current.parquet``: the log's current rows (:func:`current_rows` of its
    estimates.csv ``est`` and its rows' ``places``), with its vehicle and folder name."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    cols = current_rows(est, summary, clock, places)
    n = len(cols["t_s"])
    table = pa.table({"name": [out.name] * n, "vehicle": [summary["vehicle_id"]] * n,
                      **{k: v for k, v in cols.items()}}, schema=current_schema())
    pq.write_table(table, out / LOG_CURRENT)


def current_schema():
    """current.parquet's schema (docs/batch.md); built when asked (pyarrow is imported
    only by a batch)."""
    import pyarrow as pa

    f64 = pa.float64()
    return pa.schema([("name", pa.string()), ("vehicle", pa.string()), ("t_s", f64),
                      ("utc", pa.timestamp("ms", tz="UTC")), ("lat", f64), ("lon", f64),
                      ("north", f64), ("east", f64), ("std_north", f64),
                      ("std_east", f64), ("flags", pa.list_(pa.string())),
                      ("pipeline", pa.string()), ("position_std_m", f64), ("down", f64),
                      ("std_down", f64)])


def runs_schema():
    """runs.parquet's schema (docs/batch.md), its columns in :data:`ROW_KEYS` order."""
    import pyarrow as pa

    f64, s, i64 = pa.float64(), pa.string(), pa.int64()
    types = {"log": s, "name": s, "status": s, "error": s, "format": s, "vehicle_id": s,
             "vehicle_class": s, "config": s, "utc_start": pa.timestamp("ms", tz="UTC"),
             "utc_source": s, "samples": i64, "rows": i64,
             "warnings": pa.map_(s, i64), "n_warnings": i64,
             "availability": pa.map_(s, f64), "diagnosed": pa.bool_(),
             "diagnose_error": s, "effects": pa.list_(s), "effect_params": pa.map_(s, f64),
             "holdout_metric": s}
    return pa.schema([(k, types.get(k, f64)) for k in ROW_KEYS])


def _utc(text: str | None):
    """A datetime of summary.json's ISO 8601 UTC, None for None."""
    from datetime import datetime

    return None if text is None else datetime.fromisoformat(text.replace("Z", "+00:00"))


def write_tables(out: Path, rows: Sequence[dict]) -> list[str]:
    """``out/runs.parquet`` (one row per log) and ``out/current.parquet`` (every log's
    current, in the order of ``rows``); the paths written."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    data = {k: [r.get(k) for r in rows] for k in ROW_KEYS}
    data["utc_start"] = [_utc(x) for x in data["utc_start"]]
    for k in ("warnings", "availability", "effect_params"):
        data[k] = [list((x or {}).items()) for x in data[k]]
    pq.write_table(pa.table(data, schema=runs_schema()), out / "runs.parquet")
    parts = [pq.read_table(out / r["name"] / LOG_CURRENT, schema=current_schema())
             for r in rows if r["status"] == "ok" and (out / r["name"] / LOG_CURRENT).exists()]
    current = pa.concat_tables(parts) if parts else current_schema().empty_table()
    pq.write_table(current, out / "current.parquet")
    return [str(out / "runs.parquet"), str(out / "current.parquet")]


def _cut(name: str, width: int = 32) -> str:
    """``name`` in ``width`` characters: its start and its end about a ``~`` when
    longer (folder names differ at either end: ``a__run.tlog``, ``a__run.tlog-2``)."""
    if len(name) <= width:
        return name
    head = (width - 1) // 2
    return f"{name[:head]}~{name[-(width - 1 - head):]}"


def table_text(rows: Sequence[dict]) -> str:
    """The table printed at the end of a batch: a line per log (status, vehicle, log
    time, rows, warnings, current, effects found; the reason of a failed one)."""
    lines = [f"{'log':<32} {'status':<7} {'vehicle':<16} {'log s':>8} {'rows':>8} "
             f"{'warn':>4} {'current':>8}  effects / error"]
    for r in rows:
        if r["status"] != "ok":
            lines.append(f"{_cut(r['name']):<32} {'failed':<7} {'':<16} {'':>8} {'':>8} "
                         f"{'':>4} {'':>8}  {r['error']}")
            continue
        cur = r.get("current_speed_median_mps")
        effects = ", ".join(r.get("effects") or []) if r.get("diagnosed") else \
            (f"not diagnosed: {r['diagnose_error']}" if r.get("diagnose_error") else "")
        lines.append(f"{_cut(r['name']):<32} {'ok':<7} {str(r['vehicle_id'])[:16]:<16} "
                     f"{r['duration_s']:>8.0f} {r['rows']:>8,} {r['n_warnings']:>4} "
                     f"{(f'{cur:.2f}m/s' if cur is not None else '-'):>8}  {effects}")
    return "\n".join(lines)


def season_report(rows: Sequence[dict], units: Units) -> str:
    """The season report of a ``--diagnose`` batch (Markdown): per vehicle and effect, in
    how many of its diagnosed logs it was found, and per parameter its mean, standard
    deviation, range and its first and last value in UTC order (a compass deviation that
    drifts, a thruster that weakens), in the unit ``units(effect, parameter)`` gives with
    its factor from SI (diagnose's report's: ``closure.report.unit_of``)."""
    lines = ["# Season report", "",
             "| vehicle | effect | found in | parameter | mean | std | min | max | "
             "first -> last |", "|---|---|---|---|---|---|---|---|---|"]
    by_vehicle: dict[str, list[dict]] = {}
    for r in rows:
        if r["status"] == "ok" and r.get("diagnosed"):
            by_vehicle.setdefault(season_vehicle(r), []).append(r)
    for vehicle, logs in sorted(by_vehicle.items()):
        logs = sorted(logs, key=lambda r: (r.get("utc_start") is None,
                                           r.get("utc_start") or "", r["name"]))
        effects = sorted({e for r in logs for e in r["effects"]})
        if not effects:
            lines.append(f"| {vehicle} | none | 0 of {len(logs)} | | | | | | |")
        for effect in effects:
            found = [r for r in logs if effect in r["effects"]]
            lines.extend(_effect_lines(vehicle, effect, found, len(logs), units))
    if not by_vehicle:
        lines.append("| | no log diagnosed | | | | | | | |")
    return "\n".join(lines) + "\n"


def season_vehicle(row: dict) -> str:
    """The vehicle a log counts for in the season report: the id of the configuration it
    was replayed with, when that names the vehicle (a ``--config``, or the service's own
    recording); for a config detected from the log or fitted to its CSV header, whose id
    is its class's or the generic ``vehicle`` (every BlueROV2 or every unknown boat
    alike), that id and the log's folder (the log itself when it is a folder, CSV runs
    or a recording), ``bluerov2 (rov-a)``: a season's logs are usually kept a folder per
    vehicle, and two boats' compasses are not one compass."""
    from onboard.offline.replay import DETECTED_CONFIG

    note = row.get("config") or ""
    if note.startswith(DETECTED_CONFIG) or note.endswith(FITTED_CONFIG):
        log = Path(row["log"])
        return f"{row['vehicle_id']} ({(log if log.is_dir() else log.parent).name})"
    return str(row["vehicle_id"])


def _effect_lines(vehicle: str, effect: str, found: list[dict], n_logs: int,
                  units: Units) -> list[str]:
    """The report's lines of one vehicle's effect: one per parameter (one without), in
    the unit ``units`` gives (``amplitude (deg)``; diagnosis.json and runs.parquet keep
    SI, docs/diagnose.md "Parameters and units")."""
    keys = sorted({k for r in found for k in r["effect_params"]
                   if k.startswith(effect + ".")})
    head = f"| {vehicle} | {effect} | {len(found)} of {n_logs} |"
    if not keys:
        return [head + " | | | | | |"]
    out = []
    for k in keys:
        param = k[len(effect) + 1:]
        unit, scale = units(effect, param)
        x = [r["effect_params"][k] for r in found if k in r["effect_params"]]
        if (effect, param) in CIRCULAR_PARAMS:   # the sample's n / (n - 1) on the variance
            mean, std = circular_stats(x)
            std = std * math.sqrt(len(x) / (len(x) - 1)) if len(x) > 1 else 0.0
            x = [math.remainder(a, 2.0 * math.pi) for a in x]
        else:
            mean, std = statistics.fmean(x), statistics.stdev(x) if len(x) > 1 else 0.0
        x = [a * scale for a in x]
        name = f"{param} ({unit})" if unit else param
        out.append(f"{head} {name} | {mean * scale:.4g} | {std * scale:.3g} | "
                   f"{min(x):.4g} | {max(x):.4g} | {x[0]:.4g} -> {x[-1]:.4g} |")
    return out

