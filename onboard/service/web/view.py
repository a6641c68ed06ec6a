"""The web page's model: what the page shows of each vehicle, fed from any thread.

The service feeds it its own records (:meth:`LiveView.feed_estimates`,
:meth:`LiveView.feed_health`), the shore feeds it Zenoh samples
(:meth:`LiveView.feed_zenoh`: the key says what the JSON payload is, whatever its
encoding's schema suffix). :meth:`LiveView.state` is the JSON the page polls
(``api/state``): the track since a given time, the newest position, speed, heading and
current with their one-sigma, the integrity flags and the health summary. Units are in the
names: metres, m/s, degrees (angles are shown, not computed with).

The track is one point per :data:`TRACK_PERIOD_S` of vehicle time, north/east metres of
the first pipeline of :data:`TRACK_PIPELINES` whose newest record has a position (an AUV
under water: ``aie``, ``kf`` or ``eseso`` once ``nav`` has none), about the track's
origin; the position shown is that pipeline's newest. Each pipeline counts its metres from
its own origin (its first GNSS fix; a restarted service counts from its new first fix):
the service asks its pipelines for theirs (``origin`` callable); the shore derives each
pipeline's from the LocationFix it publishes on ``<prefix>/<vehicle>/fix/<pipeline>``
paired with that pipeline's estimate of the same time (:func:`frame_origin`), and follows
it when it moves by more than :data:`ORIGIN_MOVED_M`. The track's origin (lat, lon) is
the first one known of the pipeline making the track, and puts the track on map tiles;
positions counted from another origin are moved to it, so the track goes on where the
vehicle is across a service's restart. Without an origin the page draws a metric grid.

The fleet layer: the fleet service's grid (``<prefix>/fleet/current/grid``, JSON
``onboard.FleetGrid.v1``: ``utc``, ``spacing_m``, ``cells`` with ``lat``, ``lon``,
``north``, ``east`` (null where the field knows nothing), ``std_north``, ``std_east``,
``n_obs``; ``vehicles`` with ``vehicle``, ``utc``, ``lat``, ``lon``, ``north``, ``east``
and their sigmas) is kept as it came (:meth:`LiveView.feed_grid`), the newest by ``utc``,
and each vehicle of it leaves a track of (utc, lat, lon), one point per
:data:`FLEET_TRACK_PERIOD_S` (the shore feeds the grid's Zenoh samples; a fleet service
serving the page itself calls :meth:`LiveView.feed_grid` with each grid it makes).
:meth:`LiveView.fleet` is the JSON of ``api/fleet``.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable

import msgspec

from onboard.core.geo import LocalFrame, metres_per_degree
from onboard.core.messages import EstimateRecord, HealthRecord

TRACK_PIPELINES = ("nav", "aie", "kf", "eseso")
"""Pipelines whose ``north``/``east`` make the track, best first."""
TRACK_STALE_S = 2.0
"""A pipeline whose newest position is this much older (vehicle s) than another's no
longer makes the track."""
ORIGIN_MOVED_M = 1.0
"""A pipeline's origin derived again this far (m) from the one held has moved: the
service restarted and counts from a new first fix."""
FIX_PAIR_S = 1e-3
"""A LocationFix and an estimate of one pipeline are of the same tick when their times
are this close (s; the fix's is the record's ``utc``, else ``t``, to the nanosecond)."""
MOTION_PIPELINES = ("aie", "kf", "nav")
"""Pipelines whose ``speed`` and ``heading`` are shown, best first."""
SPEED_STD_FLOOR_MPS = 0.1
"""A speed's one-sigma wider than the speed itself, or than this (m/s), tells nothing at a
glance (:func:`_says_nothing`)."""
HEADING_STD_MAX_RAD = 0.5 * math.pi
"""A heading's one-sigma beyond a quarter turn tells nothing at a glance."""
CURRENT_PIPELINE = "current"
TRACK_PERIOD_S = 1.0
"""Vehicle seconds between two track points."""
TRACK_MAX_POINTS = 7200
"""Track points kept per vehicle (2 h at one a second)."""
EVENTS_KEPT = 20
"""Recent health events kept per vehicle."""
FLEET_GRID_SUFFIX = "/fleet/current/grid"
"""The key of the fleet service's grid ends so: ``<prefix>/fleet/current/grid``."""
FLEET_TRACK_PERIOD_S = 5.0
"""UTC seconds between two points of a vehicle's track on the fleet layer."""
FLEET_TRACK_MAX_POINTS = 1440
"""Fleet track points kept per vehicle (2 h at one every 5 s)."""

def key_parts(key: str, prefix: str = "") -> list[str] | None:
    """A Zenoh key ``<prefix>/<vehicle>/...`` split as ``[prefix, vehicle, ...]`` (the
    prefix may have several segments); None for a key outside ``prefix``. Without a
    prefix, the key's first segment is taken for it."""
    if not prefix:
        return key.split("/")
    if not key.startswith(prefix + "/"):
        return None
    return [prefix, *key[len(prefix) + 1:].split("/")]


OriginFn = Callable[[str], "tuple[float, float] | None"]
"""(lat, lon) in degrees of the local origin of a pipeline's positions, or None."""


@dataclass
class _Vehicle:
    """What the page knows of one vehicle."""

    estimates: dict[str, EstimateRecord] = field(default_factory=dict)
    health: HealthRecord | None = None
    track: deque[tuple[float, float, float]] = field(
        default_factory=lambda: deque(maxlen=TRACK_MAX_POINTS))
    track_pipeline: str = ""
    """The pipeline of the newest track point."""
    epoch: int = 0
    """Incremented when the track starts again (time went back) or a point is moved."""
    origin: tuple[float, float] | None = None
    """The track's origin (lat, lon): its points are metres from it."""
    origins: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Each pipeline's own origin, as known."""
    fixes: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    """Each pipeline's newest LocationFix (time, lat, lon) not yet paired with its estimate."""
    events: deque[str] = field(default_factory=lambda: deque(maxlen=EVENTS_KEPT))
    wall_rx: float | None = None
    """time.monotonic() of the newest record."""


class LiveView:
    """The vehicles' picture for the page, thread-safe.

    Parameters:
        origin: the service's callable giving a pipeline's origin (None on the shore).
        vehicle: the vehicle :meth:`state` shows by default (empty: the first seen).
        prefix: the Zenoh key prefix of :meth:`feed_zenoh`'s keys (empty: their first
            segment, whatever it is).
    """

    def __init__(self, origin: OriginFn | None = None, vehicle: str = "",
                 prefix: str = "") -> None:
        self.origin_fn = origin
        self.default_vehicle = vehicle
        self.prefix = prefix
        self.lock = threading.Lock()
        self.vehicles: dict[str, _Vehicle] = {}
        self.bad = 0
        """Zenoh payloads that could not be decoded (another schema, a foreign publisher)."""
        self.vehicle_mismatch = 0
        """Zenoh records left out because they name another vehicle than their key's."""
        self._dec_est = msgspec.json.Decoder(EstimateRecord)
        self._dec_health = msgspec.json.Decoder(HealthRecord)
        self._fixes: dict[tuple[str, str], tuple[float, float, float]] = {}
        """(vehicle, pipeline) -> a LocationFix heard before any record of its vehicle."""
        self.grid: dict | None = None
        """The newest fleet grid, as published."""
        self.fleet_tracks: dict[str, deque[tuple[float, float, float]]] = {}
        """Vehicle -> (utc, lat, lon) from the grids' ``vehicles``."""

    # ------------------------------------------------------------------ feeding

    def feed_estimates(self, records: list[EstimateRecord]) -> None:
        """One tick's records (the service calls this on its loop; cheap)."""
        with self.lock:
            for rec in records:
                self._estimate(rec)

    def feed_health(self, h: HealthRecord) -> None:
        """One health record."""
        with self.lock:
            v = self._vehicle(h.vehicle)
            v.health = h
            v.events.extend(h.events)
            v.wall_rx = time.monotonic()

    def feed_zenoh(self, key: str, payload: bytes) -> None:
        """One Zenoh sample on ``<prefix>/<vehicle>/...``: ``est/<pipeline>`` is an
        EstimateRecord, ``health`` a HealthRecord, ``fix/<pipeline>`` that pipeline's
        position as a LocationFix, which gives the pipeline's origin (see the module's
        docstring).
        A record that names another vehicle than its key's is left out (counted in
        :attr:`vehicle_mismatch`): a router's access control vouches for the key, not
        for the payload (docs/security.md), as ``onboard fleet`` takes them."""
        if key.endswith(FLEET_GRID_SUFFIX):
            try:
                self.feed_grid(msgspec.json.decode(payload))
            except (msgspec.DecodeError, ValueError):
                self.bad += 1
            return
        parts = key_parts(key, self.prefix)
        if parts is None or len(parts) < 3:
            return
        try:
            if parts[2] == "est" and len(parts) == 4:
                rec = self._dec_est.decode(payload)
                if self._named(rec.vehicle, parts[1]):
                    self.feed_estimates([rec])
            elif parts[2] == "health" and len(parts) == 3:
                h = self._dec_health.decode(payload)
                if self._named(h.vehicle, parts[1]):
                    self.feed_health(h)
            elif parts[2] == "fix" and len(parts) == 4:
                self._location(parts[1], parts[3], msgspec.json.decode(payload))
        except (msgspec.DecodeError, msgspec.ValidationError):
            self.bad += 1

    def _named(self, vehicle: str, key_vehicle: str) -> bool:
        """Whether a record naming ``vehicle`` came on its own key; counted when not."""
        if vehicle == key_vehicle:
            return True
        with self.lock:
            self.vehicle_mismatch += 1
        return False

    def feed_grid(self, grid: Any) -> None:
        """One fleet grid (the decoded JSON): kept when it is newer than the one held (a
        grid heard twice, or late, changes nothing); its vehicles extend their tracks.
        Raises ValueError when it is not a grid."""
        if not (isinstance(grid, dict) and isinstance(grid.get("cells"), list)
                and _finite(grid.get("utc"))):
            raise ValueError("not a fleet grid")
        with self.lock:
            if self.grid is not None and grid["utc"] <= self.grid["utc"]:
                return
            self.grid = grid
            for v in grid.get("vehicles") or []:
                self._fleet_point(v)

    def feed_fleet_track(self, vehicle: str, points: list[tuple[float, float, float]]
                         ) -> None:
        """Earlier points ``(utc, lat, lon)`` of ``vehicle``'s track on the fleet layer,
        oldest first (a fleet service started from a history: ``onboard fleet
        --history``), kept as a grid's vehicles are."""
        with self.lock:
            for utc, lat, lon in points:
                self._fleet_point({"vehicle": vehicle, "utc": utc, "lat": lat, "lon": lon})

    def _fleet_point(self, v: Any) -> None:
        if not isinstance(v, dict) or not all(_finite(v.get(k)) for k in ("utc", "lat", "lon")):
            return
        track = self.fleet_tracks.setdefault(str(v.get("vehicle")),
                                             deque(maxlen=FLEET_TRACK_MAX_POINTS))
        if not track or v["utc"] - track[-1][0] >= FLEET_TRACK_PERIOD_S:
            track.append((v["utc"], v["lat"], v["lon"]))

    def on_sample(self, sample: Any) -> None:
        """Zenoh subscriber callback."""
        self.feed_zenoh(str(sample.key_expr), sample.payload.to_bytes())

    def _vehicle(self, vid: str) -> _Vehicle:
        v = self.vehicles.get(vid)
        if v is None:
            v = self.vehicles[vid] = _Vehicle()
        return v

    def _estimate(self, rec: EstimateRecord) -> None:
        v = self._vehicle(rec.vehicle)
        v.estimates[rec.pipeline] = rec
        v.wall_rx = time.monotonic()
        p = rec.pipeline
        if p not in TRACK_PIPELINES:
            return
        n, e = rec.values.get("north"), rec.values.get("east")
        if n is None or e is None:
            return
        if v.track and rec.t < v.track[-1][0] and _track_source(v, rec.t) == p:
            v.track.clear()  # time went back: the vehicle's computer started again
            v.epoch += 1
            v.origin = None
            v.origins.clear()
        if p not in v.origins and self.origin_fn is not None:
            o = self.origin_fn(p)
            if o is not None:
                v.origins[p] = o
        pending = self._fixes.pop((rec.vehicle, p), None)
        if pending is not None:
            v.fixes[p] = pending
        self._pair(v, p)
        if _track_source(v, rec.t) != p:
            return  # a better pipeline makes the track
        if v.origin is None and not v.track:
            v.origin = v.origins.get(p)
        v.track_pipeline = p
        if not v.track or rec.t - v.track[-1][0] >= TRACK_PERIOD_S:
            v.track.append((rec.t, *_on_track(v, p, n, e)))

    def _location(self, vid: str, pipeline: str, obj: Any) -> None:
        """A LocationFix of ``pipeline``: kept until it pairs with the pipeline's estimate
        of the same time (:meth:`_pair`)."""
        if not isinstance(obj, dict) or pipeline not in TRACK_PIPELINES:
            return
        lat, lon, stamp = obj.get("latitude"), obj.get("longitude"), obj.get("timestamp")
        if not (_finite(lat) and _finite(lon) and isinstance(stamp, dict)
                and _finite(stamp.get("sec")) and _finite(stamp.get("nsec"))):
            return
        fix = (stamp["sec"] + stamp["nsec"] * 1e-9, float(lat), float(lon))
        with self.lock:
            v = self.vehicles.get(vid)
            if v is None:
                self._fixes[(vid, pipeline)] = fix  # its estimate comes later
                return
            v.fixes[pipeline] = fix
            self._pair(v, pipeline)

    def _pair(self, v: _Vehicle, p: str) -> None:
        """The origin of ``p`` from its waiting LocationFix and its newest estimate, when
        they are of the same tick; a moved origin (the service restarted) replaces the
        one held, and the newest track point, placed from the old one, is placed again."""
        fix, rec = v.fixes.get(p), v.estimates.get(p)
        if fix is None or rec is None:
            return
        n, e = rec.values.get("north"), rec.values.get("east")
        if n is None or e is None:
            return
        if abs(fix[0] - (rec.t if rec.utc is None else rec.utc)) > FIX_PAIR_S:
            return
        del v.fixes[p]
        o = frame_origin(fix[1], fix[2], n, e)
        old = v.origins.get(p)
        if old is not None and _metres_apart(old, o) <= ORIGIN_MOVED_M:
            return
        v.origins[p] = o
        if v.origin is None and v.track_pipeline in ("", p):
            v.origin = o
        elif old is not None and v.track and v.track_pipeline == p and v.track[-1][0] == rec.t:
            v.track[-1] = (rec.t, *_on_track(v, p, n, e))
            v.epoch += 1  # the page fetches the whole track again

    # ------------------------------------------------------------------ reading

    def state(self, vehicle: str = "", since: float = -math.inf, epoch: int = -1) -> dict:
        """The page's JSON: ``vehicle`` (default: the configured one, else the first
        seen); track points newer than ``since`` unless ``epoch`` differs from the
        track's (then the whole track)."""
        with self.lock:
            ids = sorted(self.vehicles)
            vid = vehicle or self.default_vehicle or (ids[0] if ids else "")
            v = self.vehicles.get(vid)
            if v is None:
                return {"vehicle": vid, "vehicles": ids, "t": None}
            whole = epoch != v.epoch
            points = [list(p) for p in v.track if whole or p[0] > since]
            out = {"vehicle": vid, "vehicles": ids, "epoch": v.epoch,
                   "t": max((r.t for r in v.estimates.values()), default=None),
                   "age_s": None if v.wall_rx is None else time.monotonic() - v.wall_rx,
                   "origin": None if v.origin is None else
                   {"lat_deg": v.origin[0], "lon_deg": v.origin[1]},
                   "track": {"pipeline": v.track_pipeline, "points": points},
                   "position": _position(v), "speed": _motion(v, "speed", 1.0),
                   "heading": _motion(v, "heading", math.degrees),
                   "current": _current(v.estimates.get(CURRENT_PIPELINE)),
                   "health": _health(v), "estimates": _estimates(v)}
        return out

    def fleet(self, since: float = -math.inf, shown: str = "") -> dict:
        """The fleet layer's JSON: ``grid`` (the newest grid as published, null when
        there is none or it is not newer than ``since``, its ``utc``), ``vehicles`` (each
        vehicle's newest place and current estimate: the grid's ``vehicles``, then every
        vehicle this view follows itself that the grid does not list, with ``t`` its
        vehicle time) and ``tracks`` (vehicle -> [[time, lat, lon], ...]: from the grids,
        else one point per :data:`FLEET_TRACK_PERIOD_S` of the vehicle's own track). The
        vehicle ``shown`` (the page's own layer draws it) is left out of those this view
        follows, so the service's page, whose only vehicle is its own, costs nothing here;
        without ``shown``, the vehicle :meth:`state` shows by default is left out."""
        with self.lock:
            shown = shown or self.default_vehicle or min(self.vehicles, default="")
            grid = self.grid if self.grid is not None and self.grid["utc"] > since else None
            tracks = {vid: [list(p) for p in tr] for vid, tr in self.fleet_tracks.items()}
            vehicles = [dict(v) for v in (self.grid or {}).get("vehicles") or []
                        if isinstance(v, dict)]
            listed = {str(v.get("vehicle")) for v in vehicles}
            for vid, v in sorted(self.vehicles.items()):
                if vid not in listed and vid != shown and v.origin is not None and v.track:
                    vehicles.append(_own_place(vid, v))
                    tracks.setdefault(vid, _own_track(v))
        return {"grid": grid, "vehicles": vehicles, "tracks": dict(sorted(tracks.items()))}


def _latlon(origin: tuple[float, float], north_m: float, east_m: float) -> tuple[float, float]:
    m_lat, m_lon = metres_per_degree(origin[0])
    return origin[0] + north_m / m_lat, origin[1] + east_m / m_lon


def _own_place(vid: str, v: _Vehicle) -> dict:
    """A vehicle this view follows, as the grid lists its vehicles: its newest track
    point and current estimate (null where unknown)."""
    t, n, e = v.track[-1]
    lat, lon = _latlon(v.origin, n, e)
    cur = v.estimates.get(CURRENT_PIPELINE)
    values, std = (cur.values, cur.std) if cur is not None else ({}, {})
    return {"vehicle": vid, "t": t, "lat": lat, "lon": lon, "north": values.get("north"),
            "east": values.get("east"), "std_north": std.get("north"), "std_east": std.get("east")}


def _own_track(v: _Vehicle) -> list[list[float]]:
    out: list[list[float]] = []
    for t, n, e in v.track:
        if not out or t - out[-1][0] >= FLEET_TRACK_PERIOD_S:
            out.append([t, *_latlon(v.origin, n, e)])
    return out


def _finite(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def frame_origin(lat: float, lon: float, north_m: float, east_m: float
                 ) -> tuple[float, float]:
    """The origin (lat, lon) of the local frame (:class:`onboard.core.geo.LocalFrame`) in
    which the point at (``lat``, ``lon``) is ``north_m``, ``east_m``: a pipeline's
    origin from its LocationFix and its estimate of the same tick (to a millimetre
    within kilometres)."""
    m_lat, m_lon = metres_per_degree(lat)
    o = (lat - north_m / m_lat, lon - east_m / m_lon)
    for _ in range(2):
        la, lo = LocalFrame(*o).to_latlon(north_m, east_m)
        o = (o[0] + lat - la, o[1] + lon - lo)
    return o


def _metres_apart(a: tuple[float, float], b: tuple[float, float]) -> float:
    m_lat, m_lon = metres_per_degree(a[0])
    return math.hypot((b[0] - a[0]) * m_lat, (b[1] - a[1]) * m_lon)


def _on_track(v: _Vehicle, p: str, north_m: float, east_m: float) -> tuple[float, float]:
    """``p``'s position (m from its own origin) in metres from the track's origin."""
    o = v.origins.get(p)
    if o is None or v.origin is None or o == v.origin:
        return north_m, east_m
    m_lat, m_lon = metres_per_degree(v.origin[0])
    return (north_m + (o[0] - v.origin[0]) * m_lat, east_m + (o[1] - v.origin[1]) * m_lon)


def _track_source(v: _Vehicle, t: float) -> str | None:
    """The first of :data:`TRACK_PIPELINES` whose newest record has a position no more
    than :data:`TRACK_STALE_S` older than ``t``."""
    for p in TRACK_PIPELINES:
        rec = v.estimates.get(p)
        if (rec is not None and "north" in rec.values and "east" in rec.values
                and t - rec.t <= TRACK_STALE_S):
            return p
    return None


def _position(v: _Vehicle) -> dict | None:
    """The newest position of the pipeline that makes the track now, in metres from the
    track's origin."""
    t = max((r.t for p in TRACK_PIPELINES if (r := v.estimates.get(p)) is not None),
            default=None)
    p = None if t is None else _track_source(v, t)
    if p is None:
        return None
    rec = v.estimates[p]
    north, east = _on_track(v, p, rec.values["north"], rec.values["east"])
    return {"north_m": north, "east_m": east, "pipeline": p,
            "std_north_m": rec.std.get("north"), "std_east_m": rec.std.get("east")}


def _says_nothing(q: str, value: float, std: float | None) -> bool:
    """Whether the one-sigma ``std`` of ``q`` (speed m/s, heading rad) tells nothing at a
    glance: the next pipeline's value is shown instead (an AUV's dead-reckoned kf speed
    of 1.25 +- 10.62 m/s under water, where the measured speed is 1.5)."""
    if std is None:
        return False
    if q == "speed":
        return std > max(abs(value), SPEED_STD_FLOOR_MPS)
    return std > HEADING_STD_MAX_RAD


def _motion(v: _Vehicle, q: str, scale: float | Callable[[float], float]) -> dict | None:
    """The newest ``q`` (speed m/s, heading deg) of the best motion pipeline whose sigma
    says something (:func:`_says_nothing`; the best one with a value when none does)."""
    conv = scale if callable(scale) else (lambda x: x * scale)
    shown = [(p, rec) for p in MOTION_PIPELINES
             if (rec := v.estimates.get(p)) is not None and q in rec.values]
    if not shown:
        return None
    p, rec = next(((p, r) for p, r in shown
                   if not _says_nothing(q, r.values[q], r.std.get(q))), shown[0])
    value, std = conv(rec.values[q]), rec.std.get(q)
    if q == "heading":
        value %= 360.0
    return {"value": value, "std": None if std is None else conv(std), "pipeline": p}


def _current(rec: EstimateRecord | None) -> dict | None:
    """The current (m/s, the direction it flows to); a component the data do not
    determine is absent from the record: null here, with its sigma."""
    if rec is None:
        return None
    n, e = rec.values.get("north"), rec.values.get("east")
    out: dict[str, Any] = {"north_mps": n, "east_mps": e,
                           "std_north_mps": rec.std.get("north"),
                           "std_east_mps": rec.std.get("east"),
                           "known": n is not None and e is not None}
    if out["known"]:
        out["speed_mps"] = math.hypot(n, e)
        out["towards_deg"] = math.degrees(math.atan2(e, n)) % 360.0
    return out


def _health(v: _Vehicle) -> dict | None:
    h = v.health
    if h is None:
        return None
    nis = {f"{p}.{c}": [ch.nis_recent, ch.dof] for p, chans in h.innovations.items()
           for c, ch in chans.items() if ch.nis_recent is not None}
    return {"t": h.t, "mode": h.mode, "flags": {p: list(f) for p, f in h.flags.items() if f},
            "rates_hz": h.rates_hz, "rejected": sum(h.rejected.values()),
            "dropped": sum(h.dropped.values()), "nis": nis, "events": list(v.events)}


def _estimates(v: _Vehicle) -> dict:
    return {p: {"t": r.t, "values": r.values, "std": r.std}
            for p, r in sorted(v.estimates.items())}
