"""A replay's tracks and current on a map: GeoJSON (RFC 7946).

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
``trk`` per pipeline and run (named ``<pipeline> run <n>``), without times (the log's
clock need not be UTC); the current arrows are not in it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Sequence
from xml.sax.saxutils import quoteattr, escape

from onboard.core.geo import LocalFrame

ARROW_EVERY_S = 10.0
"""One current arrow per this many seconds of the replay (s)."""
ARROW_SCALE_S = 60.0
"""An arrow is as long as the water moves in this long (s): 0.5 m/s draws 30 m."""
ARROW_TRACKS = ("nav", "kf", "aie", "eseso")
"""Where an arrow starts: the first of these with a position at its row (GNSS first)."""
TRACK_EXCLUDED = frozenset({"current"})
"""Pipelines whose ``north``/``east`` are a velocity (m/s), not a position."""
DECIMALS = 7
"""Decimals of a coordinate in degrees (1e-7 deg is 1.1 cm of latitude)."""


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
            and c[:-6] not in TRACK_EXCLUDED]


def _runs(cols: dict[str, list[float]]) -> list[int]:
    """The run of each row (0 for every row of a file without a ``run`` column)."""
    run = cols.get("run")
    return [int(r) for r in run] if run else [0] * len(cols["t"])


def tracks(cols: dict[str, list[float]], frame: LocalFrame,
           run_names: dict[int, str] | None = None) -> list[dict]:
    """One ``LineString`` feature per pipeline with a position and per run (module
    docstring)."""
    t, runs = cols["t"], _runs(cols)
    out = []
    for p in _pipelines(cols):
        north, east = cols[p + ".north"], cols[p + ".east"]
        per_run: dict[int, list[int]] = {}
        for i, (n, e) in enumerate(zip(north, east)):
            if _finite(n) and _finite(e):
                per_run.setdefault(runs[i], []).append(i)
        for k, rows in per_run.items():
            if len(rows) < 2:
                continue
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


def to_gpx(fc: dict) -> str:
    """The tracks of :func:`feature_collection` ``fc`` as a GPX 1.1 document (module
    docstring)."""
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           '<gpx version="1.1" creator="onboard" xmlns="http://www.topografix.com/GPX/1/1">',
           f"  <metadata><name>{escape(fc.get('name', ''))}</name></metadata>"]
    for f in fc["features"]:
        p = f["properties"]
        if p["kind"] != "track":
            continue
        out.append(f"  <trk><name>{escape(p['pipeline'])} run {p['run']}</name><trkseg>")
        out.extend(f"    <trkpt lat={quoteattr(repr(lat))} lon={quoteattr(repr(lon))}/>"
                   for lon, lat in f["geometry"]["coordinates"])
        out.append("  </trkseg></trk>")
    out.append("</gpx>")
    return "\n".join(out) + "\n"


def write(path: Path, cols: dict[str, list[float]], origin: dict | None,
          runs: Sequence[dict] = (), title: str = "", gpx: Path | None = None) -> int:
    """Write :func:`feature_collection` to ``path`` (None: not), and its tracks as GPX
    (:func:`to_gpx`) to ``gpx``; return the number of features."""
    fc = feature_collection(cols, origin, runs, title)
    if path is not None:
        Path(path).write_text(json.dumps(fc, allow_nan=False) + "\n")
    if gpx is not None:
        Path(gpx).write_text(to_gpx(fc))
    return len(fc["features"])
