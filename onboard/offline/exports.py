"""A replay's exports: its tracks and current on a map (GeoJSON, RFC 7946), its tracks as
GPX, and a Foxglove layout of the topics it published.

:func:`feature_collection` turns the columns of estimates.csv into one GeoJSON
``FeatureCollection``, every position in WGS-84 longitude, latitude order (RFC 7946 §3.1.1;
7 decimals, about 1 cm):

* a **track** per pipeline with a position and per run: a ``LineString`` of its
  ``north``/``east`` (m about the origin, the first fix) turned into degrees, with
  properties ``kind = "track"``, ``pipeline``, ``run``, ``run_name``, ``t_start``,
  ``t_end`` (s, the ``t`` of estimates.csv), ``points``. A run with fewer than two
  positions (a LineString needs two) has no track.
* a **current arrow** every :data:`ARROW_EVERY_S` where the ``current`` pipeline published
  one and a track gives the vehicle's position: a ``LineString`` from the position toward
  where the water flows, as long as the water moves in :data:`ARROW_SCALE_S`, with
  properties ``kind = "current"``, ``t`` (s), ``run``, ``north_mps``, ``east_mps``,
  ``speed_mps``, ``toward_deg`` (clockwise from true north), ``std_north_mps``,
  ``std_east_mps`` (null when not published) and ``scale_s``.

The position of an arrow is the first track in :data:`ARROW_TRACKS` with a value at that
row. Without an origin (no fix in the log) there is nothing to place: the collection is
empty.

:func:`to_gpx` gives the same tracks as GPX 1.1 for a handheld or a chart plotter: one
``trk`` per pipeline and run (named ``<pipeline> run <n>``), each point with its ``<time>``
in UTC where the log knows UTC (``utc``: the replay's :class:`drivers.logclock.LogClock`
applied to ``t``), and without times where it does not (time since boot and no GPS time);
the metadata's ``<desc>`` says which and why. The current arrows are not in it.

:func:`foxglove_layout` is a Foxglove layout (the JSON of Foxglove's *Layouts* → *Import
from file...*) for the topics a replay published (:class:`Published`), named with its
vehicle id: a Map of every ``fix/`` topic (the raw GNSS ``nav`` hidden when an estimate
has a position), a plot of the speeds (``speed`` of ``nav``, ``aie``, ``kf``; the surge
``u`` of ``eseso``) and one of the water current (``north``, ``east``, ``down`` and their
sigmas), each panel only where its topics exist.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Callable, Sequence
from xml.sax.saxutils import quoteattr, escape

from onboard.core import wire
from onboard.core.geo import LocalFrame
from onboard.core.messages import EstimateRecord
from onboard.core.wire import LocationFix
from onboard.core.pipeline_config import VELOCITY_PIPELINES

ARROW_EVERY_S = 10.0
"""One current arrow per this many seconds of the replay (s)."""
ARROW_SCALE_S = 60.0
"""An arrow is as long as the water moves in this long (s): 0.5 m/s draws 30 m."""
ARROW_TRACKS = ("nav", "kf", "aie", "eseso")
"""Where an arrow starts: the first of these with a position at its row (GNSS first)."""
DECIMALS = 7
"""Decimals of a coordinate in degrees (1e-7 deg is 1.1 cm of latitude)."""
MS_PER_S = 1000


def _finite(x: float) -> bool:
    return x == x and not math.isinf(x)


def _lonlat(frame: LocalFrame, north_m: float, east_m: float) -> list[float]:
    """[lon, lat] (deg, RFC 7946 order) of a point at ``north_m``, ``east_m`` (m)."""
    lat, lon = frame.to_latlon(north_m, east_m)
    lon = (lon + 180.0) % 360.0 - 180.0
    return [round(lon, DECIMALS), round(lat, DECIMALS)]


def _pipelines(cols: dict[str, list[float]]) -> list[str]:
    """The pipelines with a ``north``/``east`` position in ``cols``, in column order."""
    return [c[:-6] for c in cols if c.endswith(".north") and c[:-6] + ".east" in cols
            and c[:-6] not in VELOCITY_PIPELINES]


def _runs(cols: dict[str, list[float]]) -> list[int]:
    """The run of each row (0 for every row of a file without a ``run`` column)."""
    run = cols.get("run")
    return [int(r) for r in run] if run else [0] * len(cols["t"])


def _track_rows(cols: dict[str, list[float]]) -> list[tuple[str, int, list[int]]]:
    """(pipeline, run, its rows with a finite position) of every track: per pipeline with
    a position and per run with at least two positions."""
    runs = _runs(cols)
    out = []
    for p in _pipelines(cols):
        north, east = cols[p + ".north"], cols[p + ".east"]
        per_run: dict[int, list[int]] = {}
        for i, (n, e) in enumerate(zip(north, east)):
            if _finite(n) and _finite(e):
                per_run.setdefault(runs[i], []).append(i)
        out.extend((p, k, rows) for k, rows in per_run.items() if len(rows) >= 2)
    return out


def tracks(cols: dict[str, list[float]], frame: LocalFrame,
           run_names: dict[int, str] | None = None) -> list[dict]:
    """One ``LineString`` feature per pipeline with a position and per run (module
    docstring)."""
    t = cols["t"]
    out = []
    for p, k, rows in _track_rows(cols):
        north, east = cols[p + ".north"], cols[p + ".east"]
        out.append({"type": "Feature", "geometry": {
            "type": "LineString",
            "coordinates": [_lonlat(frame, north[i], east[i]) for i in rows]},
            "properties": {"kind": "track", "pipeline": p, "run": k,
                           "run_name": (run_names or {}).get(k, ""),
                           "t_start": t[rows[0]], "t_end": t[rows[-1]],
                           "points": len(rows)}})
    return out


def current_arrows(cols: dict[str, list[float]], frame: LocalFrame,
                   every_s: float = ARROW_EVERY_S, scale_s: float = ARROW_SCALE_S
                   ) -> list[dict]:
    """A ``LineString`` arrow of the published current every ``every_s`` (module
    docstring)."""
    if "current.north" not in cols or "current.east" not in cols:
        return []
    where = [p for p in ARROW_TRACKS if p + ".north" in cols and p + ".east" in cols]
    t, runs = cols["t"], _runs(cols)
    cn, ce = cols["current.north"], cols["current.east"]
    sn, se = cols.get("current.std_north"), cols.get("current.std_east")
    out: list[dict] = []
    t_next = -math.inf
    for i, (vn, ve) in enumerate(zip(cn, ce)):
        if t[i] < t_next or not (_finite(vn) and _finite(ve)):
            continue
        at = next(((cols[p + ".north"][i], cols[p + ".east"][i]) for p in where
                   if _finite(cols[p + ".north"][i]) and _finite(cols[p + ".east"][i])), None)
        if at is None:
            continue
        t_next = t[i] + every_s
        tip = (at[0] + vn * scale_s, at[1] + ve * scale_s)
        out.append({"type": "Feature", "geometry": {
            "type": "LineString",
            "coordinates": [_lonlat(frame, *at), _lonlat(frame, *tip)]},
            "properties": {
                "kind": "current", "t": t[i], "run": runs[i], "north_mps": vn,
                "east_mps": ve, "speed_mps": math.hypot(vn, ve),
                "toward_deg": math.degrees(math.atan2(ve, vn)) % 360.0,
                "std_north_mps": sn[i] if sn is not None and _finite(sn[i]) else None,
                "std_east_mps": se[i] if se is not None and _finite(se[i]) else None,
                "scale_s": scale_s}})
    return out


def feature_collection(cols: dict[str, list[float]], origin: dict | None,
                       runs: Sequence[dict] = (), title: str = "") -> dict:
    """The GeoJSON ``FeatureCollection`` of a replay: its tracks and current arrows
    (module docstring). ``origin``: summary.json's ``origin`` (``lat_deg``, ``lon_deg``;
    None: no feature); ``runs``: summary.json's ``runs`` (their names); ``title``: the
    log's name (a foreign member ``name``, RFC 7946 §6.1)."""
    fc: dict = {"type": "FeatureCollection", "name": title, "features": []}
    if origin is None:
        return fc
    frame = LocalFrame(origin["lat_deg"], origin["lon_deg"])
    names = {r["run"]: r["name"] for r in runs}
    fc["features"] = tracks(cols, frame, names) + current_arrows(cols, frame)
    return fc


def gpx_time(t_utc: float) -> str:
    """A GPX ``<time>`` (xsd:dateTime in UTC, to the millisecond) of a POSIX time (s)."""
    sec, ms = divmod(round(t_utc * MS_PER_S), round(MS_PER_S))
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(sec)) + f".{ms:03d}Z"


def to_gpx(cols: dict[str, list[float]], origin: dict | None, title: str = "",
           utc: Callable[[float], float | None] | None = None, clock: str = "") -> str:
    """The tracks of :func:`feature_collection` as a GPX 1.1 document (module docstring):
    ``utc`` maps a row's ``t`` (s) to UTC (POSIX s; None or absent: no times), ``clock``
    says in words where the times come from or why there are none (the metadata's
    ``<desc>``)."""
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           '<gpx version="1.1" creator="onboard" xmlns="http://www.topografix.com/GPX/1/1">',
           f"  <metadata><name>{escape(title)}</name>"
           f"<desc>{escape(_gpx_desc(utc is not None, clock))}</desc></metadata>"]
    frame = LocalFrame(origin["lat_deg"], origin["lon_deg"]) if origin is not None else None
    t = cols["t"]
    for p, k, rows in _track_rows(cols) if frame is not None else ():
        north, east = cols[p + ".north"], cols[p + ".east"]
        out.append(f"  <trk><name>{escape(p)} run {k}</name><trkseg>")
        for i in rows:
            lon, lat = _lonlat(frame, north[i], east[i])
            at = f"    <trkpt lat={quoteattr(repr(lat))} lon={quoteattr(repr(lon))}"
            t_utc = utc(t[i]) if utc is not None else None
            out.append(f"{at}><time>{gpx_time(t_utc)}</time></trkpt>" if t_utc is not None
                       else f"{at}/>")
        out.append("  </trkseg></trk>")
    out.append("</gpx>")
    return "\n".join(out) + "\n"


def _gpx_desc(timed: bool, clock: str) -> str:
    """The GPX metadata's description: the estimates' tracks, with or without times."""
    head = "Tracks of the onboard replay estimates, one per pipeline and run; "
    if timed:
        return head + f"point times in {clock or 'UTC'}."
    return head + f"no point times ({clock or 'no UTC: no clock given'})."


# ------------------------------------------------------------------ the Foxglove layout


class Published:
    """What a replay published, as the live service would: per pipeline the fields its
    ``est/`` records had a finite value for, and the pipelines with a ``fix/``
    LocationFix, in the order they first appeared.

    Attributes:
        values: pipeline -> the ``values`` keys with a finite value in some record.
        std: pipeline -> the ``std`` keys with a finite value in some record.
        fixes: the pipelines that published a position.
    """

    def __init__(self) -> None:
        self.values: dict[str, set[str]] = {}
        self.std: dict[str, set[str]] = {}
        self.fixes: list[str] = []

    def add(self, records: Sequence[EstimateRecord], fixes: Sequence[LocationFix] = ()) -> None:
        """One tick's records and fixes."""
        for rec in records:
            self.values.setdefault(rec.pipeline, set()).update(
                k for k, v in rec.values.items() if _finite(v))
            self.std.setdefault(rec.pipeline, set()).update(
                k for k, v in rec.std.items() if _finite(v))
        for fix in fixes:
            if fix.frame_id not in self.fixes:
                self.fixes.append(fix.frame_id)


MAP_FOLLOW = ("kf", "aie", "eseso", "nav")
"""The fix the map follows: the first of these that was published."""
MAP_HIDDEN = ("nav",)
"""Fixes drawn but hidden (the raw GNSS) when another pipeline has a position."""
TOPIC_COLORS = {"kf": "#1f77b4", "aie": "#ff7f0e", "eseso": "#2ca02c", "nav": "#7f7f7f"}
"""Map colour of each pipeline's fixes."""
MAP_ZOOM = 16
"""The map's zoom level (Web Mercator; 16 shows about 600 m across)."""
SPEED_SERIES = (("nav", "speed", "nav (GNSS)"), ("aie", "speed", "aie"),
                ("kf", "speed", "kf"), ("eseso", "u", "eseso (surge u)"))
"""The speed plot: (pipeline, its value, label)."""
CURRENT_AXES = ("north", "east", "down")
"""The current plot: these values and their sigmas, where published."""
PANEL_TITLE = "foxglovePanelTitle"
"""The key of a panel's title in the config of an exported Foxglove layout."""
PLOT_STYLE = {"showLegend": True, "legendDisplay": "floating", "showXAxisLabels": True,
              "showYAxisLabels": True, "isSynced": True, "xAxisVal": "timestamp"}
"""The settings every plot shares (Foxglove's Plot panel config)."""


def _series(topic: str, field: str, label: str) -> dict:
    """One plot series: a field of a topic (quoted: the topic has no leading slash)."""
    return {"value": f'"{topic}".{field}', "enabled": True, "timestampMethod": "receiveTime",
            "label": label}


def _map_panel(prefix: str, vehicle: str, pub: Published) -> dict | None:
    """The Map panel of every published fix, or None without any."""
    if not pub.fixes:
        return None
    topic = {p: wire.fix_key(prefix, vehicle, p) for p in pub.fixes}
    follow = next((p for p in MAP_FOLLOW if p in topic), pub.fixes[0])
    hidden = [topic[p] for p in MAP_HIDDEN if p in topic and len(topic) > 1]
    return {"layer": "map", "zoomLevel": MAP_ZOOM, "disabledTopics": hidden,
            "followTopic": topic[follow],
            "topicColors": {topic[p]: TOPIC_COLORS[p] for p in pub.fixes
                            if p in TOPIC_COLORS and topic[p] not in hidden}}


def _speed_panel(prefix: str, vehicle: str, pub: Published) -> dict | None:
    """The plot of every published speed, or None without any."""
    paths = [_series(wire.estimate_key(prefix, vehicle, p), "values." + q, label)
             for p, q, label in SPEED_SERIES if q in pub.values.get(p, ())]
    return {PANEL_TITLE: "Speed (m/s)", "paths": paths, **PLOT_STYLE} if paths else None


def _current_panel(prefix: str, vehicle: str, pub: Published) -> dict | None:
    """The plot of the published water current and its sigmas, or None without it."""
    topic = wire.estimate_key(prefix, vehicle, "current")
    paths = [_series(topic, "values." + a, a) for a in CURRENT_AXES
             if a in pub.values.get("current", ())]
    paths += [_series(topic, "std." + a, "sigma " + a) for a in CURRENT_AXES
              if a in pub.std.get("current", ())]
    return {PANEL_TITLE: "Water current (m/s, NED, the direction it flows to)",
            "paths": paths, **PLOT_STYLE} if paths else None


def foxglove_layout(prefix: str, vehicle: str, pub: Published) -> dict:
    """The Foxglove layout of what ``pub`` saw published under ``<prefix>/<vehicle>``
    (module docstring): the map on the left, the plots in a column on the right."""
    panels = {"Map!onboard": _map_panel(prefix, vehicle, pub),
              "Plot!speed": _speed_panel(prefix, vehicle, pub),
              "Plot!current": _current_panel(prefix, vehicle, pub)}
    panels = {k: v for k, v in panels.items() if v is not None}
    plots = [k for k in panels if k.startswith("Plot!")]
    column: str | dict | None = plots[0] if len(plots) == 1 else (
        {"direction": "column", "first": plots[0], "second": plots[1],
         "splitPercentage": 50} if plots else None)
    if "Map!onboard" in panels and column is not None:
        mosaic: str | dict | None = {"direction": "row", "first": "Map!onboard",
                                     "second": column, "splitPercentage": 55}
    else:
        mosaic = "Map!onboard" if "Map!onboard" in panels else column
    return {"configById": panels, "globalVariables": {}, "userNodes": {},
            "playbackConfig": {"speed": 1}, "layout": mosaic}


def layout_topics(layout: dict) -> list[str]:
    """Every topic a layout of :func:`foxglove_layout` names, in order, once."""
    out: list[str] = []
    for cfg in layout["configById"].values():
        named = [s["value"][1:].partition('"')[0] for s in cfg.get("paths", [])]
        named += [cfg["followTopic"]] if "followTopic" in cfg else []
        named += [*cfg.get("disabledTopics", []), *cfg.get("topicColors", {})]
        out.extend(t for t in named if t not in out)
    return out


def write_foxglove_layout(path: Path, prefix: str, vehicle: str, pub: Published) -> dict:
    """Write :func:`foxglove_layout` to ``path`` (JSON, indented); return what was
    written: ``file``, ``vehicle_id`` and the ``topics`` it names."""
    layout = foxglove_layout(prefix, vehicle, pub)
    Path(path).write_text(json.dumps(layout, indent=2) + "\n")
    return {"file": str(path), "vehicle_id": vehicle, "topics": layout_topics(layout)}
