"""``onboard fleet``: the fleet's current field on Zenoh (docs/fleet.md).

Runs on a shore machine that reaches the vehicles' Zenoh network::

    onboard fleet --connect tcp/192.168.2.1:7447
    onboard fleet --connect tcp/192.168.2.1:7447 --mcap field.mcap

It subscribes ``<prefix>/*/est/current`` (every vehicle's current pipeline,
:class:`~onboard.core.messages.EstimateRecord` of schema 2: ``utc``, ``lat_deg``,
``lon_deg``), adds each record to one :class:`~onboard.fleet.field.CurrentField` on its
own ``utc`` (late and out-of-order records too; a schema-1 record, with no time or
position, is counted and skipped), and

* answers queries on ``<prefix>/fleet/current`` (parameters ``lat``, ``lon`` in deg and
  ``utc`` in POSIX s) with one ``FleetCurrent`` (:mod:`onboard.fleet.messages`);
* every ``--period`` seconds refreshes the field and publishes it on
  ``<prefix>/fleet/current/grid`` as a ``FleetGrid``: the area of the vehicles' newest
  positions plus a margin, at most :data:`GRID_CELLS` cells a side, at the newest record's
  time; the hyperparameters are fitted again every ``--refit`` seconds;
* with ``--mcap FILE`` writes each grid into an MCAP file for Foxglove: the ``FleetGrid``
  on ``<prefix>/fleet/current/grid`` and the same field as arrows on
  ``<prefix>/fleet/current/geojson`` (``foxglove.GeoJSON``, for the Map panel);
* with ``--at`` and ``--vdr`` or ``--signalk`` sends the field's current at a place (a
  fixed one, or the own vessel's on a Signal K server) as set and drift to a chart plotter
  once a second (:mod:`onboard.fleet.chartplot`);
* with ``--history FILE`` first adds the currents of an ``onboard batch`` table
  (``current.parquet``, docs/batch.md) as if they had been received
  (:meth:`FleetService.load_history`): yesterday's survey, replayed, served as a field.

The field is fitted on its own thread (:meth:`FleetService.step`); a query reads the
field the last fit left (:class:`onboard.fleet.field.Fitted`) and never waits for the
next.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import threading
import time
from datetime import timezone
from pathlib import Path
from typing import Any, Mapping

import msgspec

from onboard.core.errors import SigtermAsInterrupt, UsageError
from onboard.core.messages import EstimateRecord, HealthRecord
from onboard.core.outputs import Output, existing
from onboard.core.outputs import check as check_outputs
from onboard.core.wire import ESTIMATE_SCHEMAS, HEALTH_SCHEMA, JSON_MIME, encoding, json_schema
from onboard.fleet.chartplot import CHART_PERIOD_S, FieldSetDrift, parse_place, udp_output
from onboard.fleet.field import CurrentField, Plane, one_blas_thread
from onboard.fleet.messages import (
    FLEET_CURRENT_SCHEMA,
    FLEET_GRID_SCHEMA,
    FleetCell,
    FleetGrid,
    QueryError,
    VehicleCurrent,
    current_key,
    grid_key,
)
from onboard.service.publishers.zenoh_pub import open_shore_session as open_session, valid_prefix
from onboard.service.web.http import parse_listen
from onboard.service.web.view import FLEET_TRACK_PERIOD_S

CURRENT_PIPELINE = "current"
"""The vehicles' pipeline whose records the field fuses (``<prefix>/<vehicle>/est/current``)."""
GRID_PERIOD_S = 5.0
"""Seconds between two grids (and two refreshes of the field)."""
REFIT_PERIOD_S = 60.0
"""Seconds between two fits of the hyperparameters."""
GRID_CELLS = 16
"""Cells along the longer side of the grid, at most."""
GRID_MARGIN_M = 500.0
"""Margin (m) about the vehicles' positions the grid covers."""
MIN_SPACING_M = 50.0
"""The grid's cells are at least this large (m)."""
FUTURE_S = 3600.0
"""A record stamped more than this (s) after this machine's clock is left out
(``future``): a vehicle's clock that is wrong, or a time in the wrong unit, would
otherwise make every later record look older than the history the field keeps."""
GRID_CLOCK_SLACK_S = 60.0
"""A vehicle whose newest record is more than this (s) ahead of this machine's clock does
not set the grid's time (:meth:`FleetService.grid`), unless every vehicle is: one fast
clock would put the grid, its predictions and the page ahead of the fleet by as much,
and hold the MCAP's later grids back until the real time caught up."""
UNKNOWN_CURRENT = frozenset({"no_current", "no_std", "not_converged"})
"""Reasons a record makes no observation although its time and place are good: the
vehicle is still shown where it is (:attr:`FleetService.newest`)."""
ARROW_S = 600.0
"""An arrow of the GeoJSON map is as long as the water moves in this time (s)."""
HISTORY_COLUMNS = ["vehicle", "t_s", "utc", "lat", "lon", "north", "east", "std_north",
                   "std_east", "pipeline"]
"""The columns of ``current.parquet`` (docs/batch.md) ``--history`` reads; also those of
:data:`HISTORY_COLUMNS_ADDED` where the table has them."""
HISTORY_COLUMNS_ADDED = ["position_std_m", "down", "std_down"]
"""Columns of ``current.parquet`` added on 2026-11-30: a table written before has none."""


class FleetService:
    """The fleet's field on a Zenoh session (module docstring); without a session (None)
    it is fed by :meth:`feed` and stepped by :meth:`step` (the tests, the benchmark).

    Attributes:
        field: the :class:`CurrentField`.
        newest: each vehicle's newest record (:class:`VehicleCurrent`); a vehicle not
            heard within the field's history (6 h before the newest record) is
            forgotten at the next :meth:`step`, as its records are: it no longer
            stretches the grid's box nor is listed in it.
        received: records received, by schema (``est.v1``, ``est.v2``) and ``bad`` (not
            an ``application/json`` Estimate of a schema this version reads, or not
            decodable), and ``history`` (rows of :meth:`load_history`); a record decoded
            but left out is counted by its reason in the field's ``rejected``
            (``vehicle_mismatch``, ``future`` and :meth:`.CurrentField.take`'s).
        grids: grids published.
        tracks: each vehicle's track in the rows :meth:`load_history` added, ``(utc,
            lat, lon)``, a point per ``FLEET_TRACK_PERIOD_S`` (for the page's fleet
            layer, which draws the live ones from the grids).
        doubted: each vehicle's integrity flags on its ``current`` pipeline in the newest
            health record heard from it (``<prefix>/<vehicle>/health``) that say its
            sigma claims too much (:func:`overconfident_flags`): while it has any, its
            records are left out (``doubted``). A sigma larger than its errors (the NIS
            below its band) is no reason: the field weighs such records less, and
            calibrates its own sigma on the fleet's misses.
    """

    def __init__(self, session: Any = None, prefix: str = "onboard",
                 field: CurrentField | None = None, mcap: str | Path | None = None,
                 refit_s: float = REFIT_PERIOD_S, clock: Any = time.time) -> None:
        self.session, self.prefix, self.refit_s = session, prefix, refit_s
        self.clock = clock
        self._one_thread = one_blas_thread()   # queries' small Cholesky on one thread
        self.field = field if field is not None else CurrentField()
        self.newest: dict[str, VehicleCurrent] = {}
        self.received: dict[str, int] = {}
        self.grids = 0
        self.tracks: dict[str, list[tuple[float, float, float]]] = {}
        self.doubted: dict[str, list[str]] = {}
        self.lock = threading.Lock()
        self._dec = msgspec.json.Decoder(EstimateRecord)
        self._dec_health = msgspec.json.Decoder(HealthRecord)
        self._enc = msgspec.json.Encoder()
        self._refit_due = 0.0
        self.mcap = _McapGrid(mcap, prefix) if mcap is not None else None
        self._declared: list[Any] = []
        if session is not None:
            self._declare(session)

    def _declare(self, session: Any) -> None:
        self._grid_pub = session.declare_publisher(grid_key(self.prefix),
                                                   encoding=encoding(FLEET_GRID_SCHEMA))
        self._declared = [
            session.declare_subscriber(f"{self.prefix}/*/est/{CURRENT_PIPELINE}",
                                       self.on_sample),
            session.declare_subscriber(f"{self.prefix}/*/health", self.on_health),
            session.declare_queryable(current_key(self.prefix), self.on_query),
            self._grid_pub]

    def close(self) -> None:
        """Undeclare the subscriber, the queryable and the grid's publisher; finish the
        MCAP file."""
        for d in self._declared:
            d.undeclare()
        self._declared = []
        if self.mcap is not None:
            self.mcap.close()

    # ----------------------------------------------------------------- records in
    def on_sample(self, sample: Any) -> None:
        """Zenoh subscriber callback."""
        self.feed(sample.payload.to_bytes(), str(sample.encoding), str(sample.key_expr))

    def feed(self, payload: bytes, enc: str | None = None, key: str | None = None) -> bool:
        """One ``est/current`` record; False when it is not one this version reads or
        makes no observation (counted in :attr:`received` and the field's ``rejected``).

        ``enc``: its Zenoh encoding, which must be ``application/json;<an Estimate schema
        this version reads>`` (None: not checked, a caller that decoded nothing from the
        network). ``key``: the key it was put on, ``<prefix>/<vehicle>/est/current``,
        whose vehicle the record must name (a router's access control vouches for the
        key, not for the payload: docs/security.md). A record stamped more than
        :data:`FUTURE_S` after :attr:`clock` is left out."""
        mime, _, schema = (enc or "").partition(";")
        if enc is not None and (mime != JSON_MIME or schema not in ESTIMATE_SCHEMAS):
            self._count("bad")
            return False
        try:
            rec = self._dec.decode(payload)
        except msgspec.DecodeError:
            self._count("bad")
            return False
        if f"onboard.Estimate.v{rec.schema}" not in ESTIMATE_SCHEMAS:
            self._count("bad")
            return False
        self._count(f"est.v{rec.schema}")
        with self.lock:
            if key is not None and key_vehicle(key, self.prefix) != rec.vehicle:
                self.field.reject("vehicle_mismatch")
                return False
            if rec.utc is not None and rec.utc > self.clock() + FUTURE_S:
                self.field.reject("future")
                return False
            if self.doubted.get(rec.vehicle):
                self.field.reject("doubted")
                return False
            return not self._take(rec)

    def on_health(self, sample: Any) -> None:
        """Zenoh subscriber callback of the vehicles' health records."""
        self.feed_health(sample.payload.to_bytes(), str(sample.encoding), str(sample.key_expr))

    def feed_health(self, payload: bytes, enc: str | None = None, key: str | None = None
                    ) -> bool:
        """One vehicle's health record: its ``current`` pipeline's flags become
        :attr:`doubted`. False (and nothing changed) for one that is not an
        ``application/json`` Health of this version's schema, or names another vehicle
        than its ``key``."""
        if enc is not None and enc != encoding(HEALTH_SCHEMA):
            return False
        try:
            h = self._dec_health.decode(payload)
        except msgspec.DecodeError:
            return False
        if key is not None and key_vehicle(key, self.prefix, ("health",)) != h.vehicle:
            return False
        with self.lock:
            self.doubted[h.vehicle] = overconfident_flags(h)
        return True

    def _count(self, what: str) -> None:
        self.received[what] = self.received.get(what, 0) + 1

    def _take(self, rec: EstimateRecord) -> str:
        """``rec`` into the field (:meth:`.CurrentField.take`: ``""`` when added, else why
        not) and, when its time and place are good (added, or its current not known
        yet), as its vehicle's newest."""
        why = self.field.take(rec)
        if why in ("", *UNKNOWN_CURRENT):
            self._note(rec)
        return why

    def _note(self, rec: EstimateRecord) -> None:
        """Keep ``rec``, of a good time and place, as its vehicle's newest (by ``utc``)."""
        old = self.newest.get(rec.vehicle)
        if old is not None and old.utc is not None and old.utc > rec.utc:
            return
        v, sd = rec.values, rec.std
        self.newest[rec.vehicle] = VehicleCurrent(
            vehicle=rec.vehicle, utc=rec.utc, lat=rec.lat_deg, lon=rec.lon_deg,
            north=v.get("north"), east=v.get("east"), std_north=sd.get("north"),
            std_east=sd.get("east"), down=v.get("down"), std_down=sd.get("down"))

    def load_history(self, path: str | Path) -> dict[str, int]:
        """Add the currents of an ``onboard batch`` table ``path`` (``current.parquet``,
        docs/batch.md; a folder: the one in it) as the records they were published as.

        A row of the ``current`` pipeline is its vehicle's record at its ``utc``, ``lat``,
        ``lon`` and ``position_std_m``, with its current (``down`` where given; a table
        written before :data:`HISTORY_COLUMNS_ADDED` has none of them), added by the same
        :meth:`.CurrentField.add_record` as a live record (rejected for the same reasons)
        in the order of their time, as they were received. A row older than the field's
        history before the file's newest is counted ``too_old``, as a record that late
        is; a glider's dive (pipeline ``dac``), an average over kilometres and hours and
        not the water at a place and time, ``dive_average``. Returns the rows read, added
        and left out by reason (this file's). Raises :class:`UsageError` for a file that
        is not such a table, or without pyarrow (the ``batch`` extra)."""
        try:
            import pyarrow.parquet as pq
        except ImportError:
            raise UsageError("--history reads Parquet with pyarrow: pip install "
                             "'onboard[batch]'") from None
        if Path(path).is_dir():
            path = Path(path) / "current.parquet"
        try:
            names = pq.read_schema(path).names
            table = pq.read_table(path, columns=HISTORY_COLUMNS + [
                c for c in HISTORY_COLUMNS_ADDED if c in names])
        except (OSError, ValueError, KeyError) as err:   # pyarrow's errors derive from these
            raise UsageError(f"--history {path}: not a current.parquet of onboard batch "
                             f"({str(err).splitlines()[0]})") from None
        rows = table.to_pydict()
        for c in HISTORY_COLUMNS_ADDED:
            rows.setdefault(c, [None] * table.num_rows)
        # a time without a zone (a table another tool wrote) is UTC, not this machine's
        utc_s = [None if u is None else u.replace(tzinfo=u.tzinfo or timezone.utc).timestamp()
                 for u in rows["utc"]]
        order = sorted(range(table.num_rows), key=lambda i: (utc_s[i] is None, utc_s[i] or 0.0))
        field = self.field
        oldest = max((u for u in utc_s if u is not None), default=0.0) - field.history_s
        before, added = dict(field.rejected), 0
        for i in order:
            if rows["pipeline"][i] != CURRENT_PIPELINE:
                field.reject("dive_average")
                continue
            if utc_s[i] is not None and utc_s[i] < oldest:
                field.reject("too_old")
                continue
            values = {k: v for k in ("north", "east", "down") if (v := rows[k][i]) is not None}
            std = {k: v for k in ("north", "east", "down")
                   if (v := rows[f"std_{k}"][i]) is not None}
            rec = EstimateRecord(vehicle=rows["vehicle"][i], pipeline=CURRENT_PIPELINE,
                                 t=rows["t_s"][i], values=values, std=std, utc=utc_s[i],
                                 lat_deg=rows["lat"][i], lon_deg=rows["lon"][i],
                                 position_std_m=rows["position_std_m"][i])
            self._count("history")
            with self.lock:
                if not self._take(rec):
                    added += 1
                    self._track_point(rec)
        left = {k: n - before.get(k, 0) for k, n in field.rejected.items()
                if n > before.get(k, 0)}
        return {"rows": table.num_rows, "added": added, **left}

    def _track_point(self, rec: EstimateRecord) -> None:
        """Extend :attr:`tracks` with ``rec``'s place (an added record: it has a time and
        a position), a point per ``FLEET_TRACK_PERIOD_S``."""
        track = self.tracks.setdefault(rec.vehicle, [])
        if not track or rec.utc - track[-1][0] >= FLEET_TRACK_PERIOD_S:
            track.append((rec.utc, rec.lat_deg, rec.lon_deg))

    # ----------------------------------------------------------------- the field
    def step(self, refit: bool | None = None) -> FleetGrid | None:
        """Refresh the field (the hyperparameters too when ``refit``, by default every
        ``refit_s``), then publish the grid (and write it to the MCAP);
        return it (None before a vehicle with a position). A refresh without any observation
        fits nothing: the first fit of the hyperparameters is the first refresh's with
        observations, not ``refit_s`` after the service started."""
        now = time.monotonic()
        with self.lock:
            obs = self.field.gather()
            oldest = self.field.newest_utc - self.field.history_s
            for gone in [k for k, v in self.newest.items() if v.utc < oldest]:
                del self.newest[gone]   # not heard within the field's history
            vehicles = list(self.newest.values())
        if refit is None:
            refit = now >= self._refit_due
        if refit and obs is not None:
            self._refit_due = now + self.refit_s
        self.field.update(obs, hyperparameters=refit)
        grid = self.grid(vehicles)
        if grid is not None:
            self._publish(grid)
        return grid

    def grid(self, vehicles: list[VehicleCurrent]) -> FleetGrid | None:
        """The field on the grid about ``vehicles`` (module docstring) at their newest
        record's time (of those not :data:`GRID_CLOCK_SLACK_S` ahead of this machine's
        clock, while there are any), None without a vehicle with a position. Before the
        field has an observation (the vehicles' currents not known yet) the grid still
        lists them, its cells unknown."""
        placed = [v for v in vehicles if v.lat is not None and v.lon is not None]
        if not placed:
            return None
        lat, lon = ([v.lat for v in placed], [v.lon for v in placed])
        plane = self.field.plane or Plane(lat[0], lon[0])
        times = [v.utc for v in placed if v.utc is not None]
        latest = self.clock() + GRID_CLOCK_SLACK_S
        utc = max([u for u in times if u <= latest] or times)
        lats, lons, spacing = grid_points(plane, lat, lon)
        cells = [self.answer(la, lo, utc) for la in lats for lo in lons]
        return FleetGrid(utc=utc, spacing_m=spacing, cells=cells,
                         vehicles=sorted(vehicles, key=lambda v: v.vehicle))

    def answer(self, lat: float, lon: float, utc: float) -> FleetCell:
        """The field at ``lat``, ``lon`` (deg) and ``utc`` (s) as a :class:`FleetCell`
        (a query's reply is its :meth:`.FleetCell.reply`)."""
        p = self.field.predict(lat, lon, utc)
        return FleetCell(lat=lat, lon=lon, utc=utc, north=p.north, east=p.east,
                         std_north=p.std_north, std_east=p.std_east, n_obs=p.n_obs,
                         down=p.down, std_down=p.std_down)

    def left_out(self) -> dict[str, int]:
        """Records left out so far, by reason: ``bad`` (:attr:`received`) and the
        field's ``rejected``."""
        bad = self.received.get("bad", 0)
        return ({"bad": bad} if bad else {}) | dict(self.field.rejected)

    def _publish(self, grid: FleetGrid) -> None:
        payload = self._enc.encode(grid)
        if self._declared:
            self._grid_pub.put(payload)
        if self.mcap is not None:
            self.mcap.write(grid, payload)
        self.grids += 1

    # ----------------------------------------------------------------- queries
    def on_query(self, query: Any) -> None:
        """Zenoh queryable callback: one :class:`FleetCurrent`, or a :class:`QueryError`
        naming the bad parameter."""
        payload, ok = self.reply(dict(query.parameters))
        schema = FLEET_CURRENT_SCHEMA if ok else "onboard.FleetQueryError.v1"
        if ok:
            query.reply(current_key(self.prefix), payload, encoding=encoding(schema))
        else:
            query.reply_err(payload, encoding=encoding(schema))

    def reply(self, params: Mapping[str, str]) -> tuple[bytes, bool]:
        """The reply to a query's ``params``: (JSON, True) with the field there, or
        (JSON of a :class:`QueryError`, False)."""
        try:
            lat, lon, utc = parse_query(params)
        except ValueError as err:
            return self._enc.encode(QueryError(str(err))), False
        return self._enc.encode(self.answer(lat, lon, utc).reply()), True


NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")
"""A query parameter's number: decimal digits, a point, an exponent (no spaces,
underscores, ``inf`` or ``nan``, which Python's ``float`` would also read)."""


def parse_query(params: Mapping[str, str]) -> tuple[float, float, float]:
    """``(lat, lon, utc)`` of a query's parameters; ValueError saying which is missing or
    bad (a latitude within +-90 deg, a longitude within +-180, a finite time). The
    parameters may be separated by ``&`` as well as by Zenoh's ``;``
    (:func:`selector_parameters`)."""
    params = selector_parameters(params)
    out = []
    for name, limit in (("lat", 90.0), ("lon", 180.0), ("utc", math.inf)):
        text = params.get(name)
        if text is None:
            raise ValueError(f"parameter {name} is missing: ask "
                             f"fleet/current?lat=<deg>;lon=<deg>;utc=<POSIX s>")
        if not NUMBER.fullmatch(text):
            raise ValueError(f"parameter {name}={text!r} is not a number")
        value = float(text)
        if not math.isfinite(value) or abs(value) > limit:
            raise ValueError(f"parameter {name}={text!r} is out of range")
        out.append(value)
    return out[0], out[1], out[2]


def selector_parameters(params: Mapping[str, str]) -> dict[str, str]:
    """A selector's parameters as Zenoh parsed them (separated by ``;``), each ``&`` in
    them read as a separator too: ``lat=43.1&lon=5.9&utc=..``, as a URL's query and Zenoh
    before 1.0 write it, gives the same ``lat``, ``lon`` and ``utc`` as
    ``lat=43.1;lon=5.9;utc=..``. A name given twice has its last value."""
    out: dict[str, str] = {}
    for key, value in params.items():
        for part in f"{key}={value}".split("&"):
            name, _, text = part.partition("=")
            if name:
                out[name] = text
    return out


def overconfident_flags(h: HealthRecord) -> list[str]:
    """The integrity flags of ``h``'s ``current`` pipeline that doubt its values or say
    its sigma is too small: every flag but ``nis_out_of_band`` while the current's
    channels' recent NIS is at most their dimension (the innovations smaller than the
    filter expects: its sigma too large, its values not in doubt)."""
    flags = list(h.flags.get(CURRENT_PIPELINE, ()))
    if "nis_out_of_band" in flags:
        channels = h.innovations.get(CURRENT_PIPELINE, {}).values()
        if not any(c.nis_recent is not None and c.nis_recent > c.dof for c in channels):
            flags.remove("nis_out_of_band")
    return flags


def key_vehicle(key: str, prefix: str, tail: tuple[str, ...] = ("est", CURRENT_PIPELINE)
                ) -> str | None:
    """The vehicle of a key ``<prefix>/<vehicle>/<tail>`` (a current's record by default;
    None for a key of another form)."""
    head, _, rest = key.partition(f"{prefix}/")
    parts = rest.split("/")
    if head or len(parts) != 1 + len(tail) or tuple(parts[1:]) != tail:
        return None
    return parts[0]


def grid_points(plane: Plane, lats: list[float], lons: list[float]
                ) -> tuple[list[float], list[float], float]:
    """The latitudes and longitudes (deg) of the grid's rows and columns over the box
    of ``lats``, ``lons`` plus :data:`GRID_MARGIN_M`, and its spacing (m): at most
    :data:`GRID_CELLS` cells along the longer side, cells at least :data:`MIN_SPACING_M`."""
    north, east = plane.to_ne(lats, lons)
    n0, n1 = float(min(north)) - GRID_MARGIN_M, float(max(north)) + GRID_MARGIN_M
    e0, e1 = float(min(east)) - GRID_MARGIN_M, float(max(east)) + GRID_MARGIN_M
    spacing = max(max(n1 - n0, e1 - e0) / GRID_CELLS, MIN_SPACING_M)
    rows, cols = _centres(n0, n1, spacing), _centres(e0, e1, spacing)
    lat_rows = [float(plane.to_latlon(n, 0.0)[0]) for n in rows]
    lon_cols = [float(plane.to_latlon(0.0, e)[1]) for e in cols]
    return lat_rows, lon_cols, spacing


def _centres(lo: float, hi: float, spacing: float) -> list[float]:
    """The centres of the fewest cells of ``spacing`` that cover ``[lo, hi]``, centred on
    it."""
    n = max(1, math.ceil((hi - lo) / spacing - 1e-9))
    start = 0.5 * (lo + hi) - 0.5 * n * spacing
    return [start + spacing * (k + 0.5) for k in range(n)]


def geojson_arrows(grid: FleetGrid) -> dict:
    """The grid as Foxglove's ``foxglove.GeoJSON`` message: an arrow (a LineString from
    the cell toward where the water flows in :data:`ARROW_S`) per known cell, properties
    the cell's object."""
    features = []
    for c in grid.cells:
        if c.north is None or c.east is None:
            continue
        m_lat = 111_132.0
        m_lon = m_lat * math.cos(math.radians(c.lat))
        end = [c.lon + c.east * ARROW_S / m_lon, c.lat + c.north * ARROW_S / m_lat]
        features.append({"type": "Feature", "properties": msgspec.to_builtins(c),
                         "geometry": {"type": "LineString",
                                      "coordinates": [[c.lon, c.lat], end]}})
    return {"geojson": json.dumps({"type": "FeatureCollection", "features": features})}


GEOJSON_SCHEMA = {"type": "object", "properties": {"geojson": {"type": "string"}}}
"""Foxglove's ``foxglove.GeoJSON`` as a JSON schema."""


class _McapGrid:
    """``--mcap``: every grid as a ``FleetGrid`` and as ``foxglove.GeoJSON`` arrows, at
    the grid's UTC; a grid no newer than the last one written (no record came since: an
    idle fleet, a field served from its history) is not written again."""

    def __init__(self, path: str | Path, prefix: str) -> None:
        from onboard.drivers.mcap_log import mcap_module

        mcap_module()
        from mcap.writer import Writer

        self._f = open(path, "wb")
        self.writer = Writer(self._f)
        self.writer.start(profile="", library="onboard fleet")
        grid_schema = self.writer.register_schema(
            FLEET_GRID_SCHEMA, "jsonschema", json.dumps(json_schema(FleetGrid)).encode())
        geo_schema = self.writer.register_schema("foxglove.GeoJSON", "jsonschema",
                                                 json.dumps(GEOJSON_SCHEMA).encode())
        self.grid_channel = self.writer.register_channel(grid_key(prefix), "json", grid_schema)
        self.geo_channel = self.writer.register_channel(f"{current_key(prefix)}/geojson",
                                                        "json", geo_schema)
        self.messages = 0
        self._utc = -math.inf

    def write(self, grid: FleetGrid, payload: bytes) -> None:
        if grid.utc <= self._utc:
            return
        self._utc = grid.utc
        t_ns = max(0, round(grid.utc * 1e9))
        self.writer.add_message(self.grid_channel, log_time=t_ns, publish_time=t_ns,
                                data=payload)
        self.writer.add_message(self.geo_channel, log_time=t_ns, publish_time=t_ns,
                                data=json.dumps(geojson_arrows(grid)).encode())
        self.messages += 2

    def close(self) -> None:
        try:
            self.writer.finish()
        finally:
            self._f.close()


def set_drift_flags(args: argparse.Namespace) -> dict[str, Any] | None:
    """The arguments of a :class:`FieldSetDrift` but its ``predict``: the place of
    ``--at``, the outputs of ``--vdr`` and ``--signalk`` and ``--max-std``; None without
    them; UsageError for a bad or incomplete set of flags."""
    at, vdr, signalk = (getattr(args, k, None) for k in ("at", "vdr", "signalk"))
    max_std = getattr(args, "max_std", 0.0)
    if not at and not vdr and not signalk:
        return None
    if not at or not (vdr or signalk):
        raise UsageError("--at and one of --vdr, --signalk go together: where the current "
                         "is wanted and where its set and drift are sent")
    if not max_std >= 0.0:
        raise UsageError("--max-std is a sigma in m/s, 0 or more")
    try:
        outputs = [udp_output(url, flag) if url else None
                   for url, flag in ((vdr, "--vdr"), (signalk, "--signalk"))]
        place = parse_place(at)
    except ValueError as err:
        raise UsageError(f"--at, --vdr, --signalk: {err}") from None
    return {"place": place, "vdr": outputs[0], "signalk": outputs[1], "max_std_mps": max_std}


def main(args: argparse.Namespace) -> int:
    """``onboard fleet [--connect E] [--listen E] [--mode M] [--zenoh-config FILE]
    [--prefix P] [--period S] [--refit S] [--mcap FILE [--force]] [--web HOST:PORT]
    [--history FILE]... [--at PLACE (--vdr URL | --signalk URL)... [--max-std M/S]]``;
    SIGTERM stops it as Ctrl-C does (the MCAP file finished)."""
    if not (0 < args.period < math.inf and 0 < args.refit < math.inf):
        raise UsageError("--period and --refit are positive seconds")
    if not valid_prefix(args.prefix):
        raise UsageError(f"--prefix {args.prefix!r}: a key prefix such as onboard or "
                         "region/north (no empty segment, no * $ ? #)")
    history = getattr(args, "history", None) or []
    if args.mcap:
        check_outputs([Output("--mcap", Path(args.mcap))], force=args.force,
                      inputs=existing(history))
    if getattr(args, "web", ""):
        try:
            parse_listen(args.web)
        except ValueError as err:
            raise UsageError(f"--web {err}") from None
    chart_flags = set_drift_flags(args)
    session = open_session(args.connect, args.listen, args.mode,
                           getattr(args, "zenoh_config", "") or "")
    service = FleetService(session, args.prefix, mcap=args.mcap, refit_s=args.refit)
    chart = None if chart_flags is None else FieldSetDrift(service.answer, **chart_flags)
    page = None
    stop = threading.Event()
    terminate = SigtermAsInterrupt()
    try:
        for path in history:
            counts = service.load_history(path)
            left = ", ".join(f"{k} {n:,}" for k, n in counts.items()
                             if k not in ("rows", "added"))
            print(f"onboard fleet: {path}: {counts['added']:,} of {counts['rows']:,} "
                  f"currents added" + (f" (left out: {left})" if left else ""), flush=True)
        print(f"onboard fleet: fusing {args.prefix}/*/est/current; ask "
              f"{current_key(args.prefix)}?lat=..;lon=..;utc=..; grid on "
              f"{grid_key(args.prefix)} every {args.period:g} s", flush=True)
        if getattr(args, "web", ""):
            from onboard.service.web.app import PageOnThread

            page = PageOnThread(session, [f"{args.prefix}/**"], args.web, prefix=args.prefix)
            for vehicle, points in service.tracks.items():
                page.view.feed_fleet_track(vehicle, points)
            print(f"onboard fleet: the page is on {page.url}", flush=True)
        if chart is not None:
            chart.start()
            print(f"onboard fleet: set and drift at {chart.place} to "
                  + " and ".join(f"{name} {url}" for name, url in
                                 (("VDR", args.vdr), ("Signal K", args.signalk)) if url),
                  flush=True)
        now = time.monotonic()
        grid_due = now if history else now + args.period   # a history is a field at once
        chart_due = now
        while True:
            due = grid_due if chart is None else min(grid_due, chart_due)
            if stop.wait(max(0.0, due - time.monotonic())):
                break
            now = time.monotonic()
            if chart is not None and now >= chart_due:
                chart.send()
                chart_due = max(chart_due + CHART_PERIOD_S, now)
            if now < grid_due:
                continue
            grid_due = now + args.period
            grid = service.step()
            if grid is not None and page is not None:
                page.view.feed_grid(msgspec.to_builtins(grid))
            known = sum(c.north is not None for c in grid.cells) if grid else 0
            learned = service.field.learned()
            left = ", ".join(f"{k} {n:,}" for k, n in sorted(service.left_out().items()))
            print(f"{time.strftime('%H:%M:%S')} {len(service.newest)} vehicles, "
                  f"{service.field.added:,} records, {known} cells known"
                  + (f"; left out: {left}" if left else "")
                  + (f"; {learned}" if learned else "")
                  + (f"; {chart.summary()}" if chart is not None else ""), flush=True)
    except KeyboardInterrupt:
        return 0
    finally:
        if chart is not None:
            chart.close()
        if page is not None:
            page.close()
        service.close()
        session.close()
        terminate.restore()
    return 0
