"""``onboard shore``: a live table of a vehicle's estimates and health, from Zenoh.

Runs on any shore machine that reaches the vehicle's Zenoh network::

    onboard shore --connect tcp/192.168.2.2:7447              # all vehicles, live
    onboard shore --connect tcp/192.168.2.2:7447 --vehicle boat1 --once
    onboard shore --connect tcp/192.168.2.2:7447 --web 0.0.0.0:8110   # the map page

On start it asks the vehicles' queryables for their latest values (so ``--once`` prints a
snapshot at once) and the liveliness tokens for who is alive, then follows
``<prefix>/<vehicle>/est/*`` and ``<prefix>/<vehicle>/health`` (``<prefix>`` is
``onboard`` unless ``--prefix``: the vehicles' ``[service.zenoh] key_prefix``). The table
is redrawn every second: one row per pipeline with its newest values (angles in degrees,
everything else in SI units), then the vehicle's mode, input rates, rejections with
reasons, drops and recent events. With ``--web HOST:PORT`` it serves the service's web
page instead (:mod:`onboard.service.web`: live map, current, speed, heading, flags,
health), fed from the same subscription (:func:`serve_web`), with the fleet service's
current field (``<prefix>/fleet/current/grid``) as its fleet layer.
``--foxglove [HOST:]PORT`` also serves the records to Foxglove on a
WebSocket server (:mod:`onboard.apps.foxglove_live`, docs/foxglove.md), beside the table
or the page.

:class:`ShoreView` (the subscriber and the formatting) is reused by ``onboard demo``.
"""

from __future__ import annotations

import argparse
import math
import sys
import threading
import time
from collections import Counter, deque
from pathlib import Path
from typing import Any

import msgspec

from onboard.core.errors import UsageError
from onboard.core.messages import EstimateRecord, HealthRecord
from onboard.core.wire import ESTIMATE_SCHEMAS, HEALTH_SCHEMA, LOCATION_FIX_SCHEMA
from onboard.service.publishers.zenoh_pub import open_shore_session as open_session, valid_prefix
from onboard.service.web.view import key_parts

DEFAULT_PREFIX = "onboard"
FLEET_GRID_SUFFIX = "fleet/current/grid"
"""The fleet service's grid (``onboard fleet``) is on ``<prefix>/fleet/current/grid``,
drawn by ``--web`` as the fleet layer."""
EXPECTED = {"est": ESTIMATE_SCHEMAS, "health": frozenset({HEALTH_SCHEMA}),
            "fix": frozenset({LOCATION_FIX_SCHEMA})}
"""Third key segment -> the schema names this version decodes there (every version of
the estimate record: schema 1 decodes with its ``utc`` and position null)."""
ANGLES = {"heading", "course", "yaw", "roll", "pitch"}
"""Quantities shown in degrees."""
ANGLE_RATES = {"yaw_rate", "rate_p", "rate_q", "rate_r"}
"""Quantities shown in degrees per second."""


def fmt_bearing(deg: float, decimals: int) -> str:
    """A heading or bearing in degrees, rounded to ``decimals`` and then wrapped into
    [0, 360): 359.97 shown with one decimal is 0.0, never 360.0."""
    return f"{round(deg % 360.0, decimals) % 360.0:.{decimals}f}"


def fmt_value(name: str, v: float) -> str:
    """A compact human form of one quantity (degrees for angles)."""
    if not math.isfinite(v):
        return f"{name}=nan"
    if name in ANGLES:
        return f"{name}={fmt_bearing(math.degrees(v), 1)}°"
    if name in ANGLE_RATES:
        return f"{name}={math.degrees(v):+.1f}°/s"
    return f"{name}={v:+.3g}" if abs(v) < 1000 else f"{name}={v:+.0f}"


CONTROL_SHOWN = {c: f"\\x{c:02x}" for c in (*range(32), *range(127, 160))}
"""The control characters a record's text may carry (a vehicle id, an event, a key),
shown as ``\\xNN`` on the terminal rather than acted on (an escape sequence would move
the cursor, retitle or clear the operator's terminal; a newline would forge a line)."""
TABLE_SHOWN = {c: s for c, s in CONTROL_SHOWN.items() if c != 10}
"""The same for a whole table, its own newlines kept."""


class ShoreView:
    """The shore's picture of one or more vehicles, fed by Zenoh samples (any thread).

    Attributes:
        estimates: newest EstimateRecord per (vehicle, pipeline).
        health: newest HealthRecord per vehicle.
        history: every EstimateRecord received when ``keep_history`` (the demo scores it).
        received: number of records received, by kind (and the estimates by schema
            version, ``est.v1``, ``est.v2``).
    """

    def __init__(self, keep_history: bool = False, prefix: str = "") -> None:
        self.prefix = prefix
        """The key prefix of :meth:`feed`'s keys (empty: their first segment)."""
        self.estimates: dict[tuple[str, str], EstimateRecord] = {}
        self.health: dict[str, HealthRecord] = {}
        self.alive: set[str] = set()
        self.history: list[EstimateRecord] = []
        self.keep_history = keep_history
        self.received: Counter[str] = Counter()
        self.bad = 0
        self.vehicle_mismatch = 0
        """Records left out because they name another vehicle than their key's."""
        self.events: deque[tuple[str, str]] = deque(maxlen=20)
        self.lock = threading.Lock()
        self._dec_est = msgspec.json.Decoder(EstimateRecord)
        self._dec_health = msgspec.json.Decoder(HealthRecord)

    def feed(self, key: str, payload: bytes, encoding: str = "") -> None:
        """One Zenoh sample or query reply on ``key``; a schema name in its ``encoding``
        (``application/json;<schema>``) other than the one this version reads for the
        key (another schema version) is counted in ``bad`` and skipped, a record naming
        another vehicle than its key's in ``vehicle_mismatch`` (a router's access control
        vouches for the key, not for the payload: docs/security.md)."""
        parts = key_parts(key, self.prefix)
        if parts is None:
            return
        schema = encoding.partition(";")[2]
        if schema and len(parts) >= 3 and schema not in EXPECTED.get(parts[2], (schema,)):
            self.bad += 1
            return
        try:
            if len(parts) >= 4 and parts[2] == "est":
                rec = self._dec_est.decode(payload)
                with self.lock:
                    if rec.vehicle != parts[1]:
                        self.vehicle_mismatch += 1
                        return
                    self.estimates[(rec.vehicle, rec.pipeline)] = rec
                    if self.keep_history:
                        self.history.append(rec)
                    self.received["est"] += 1
                    self.received[f"est.v{rec.schema}"] += 1
            elif len(parts) >= 3 and parts[2] == "health":
                h = self._dec_health.decode(payload)
                with self.lock:
                    if h.vehicle != parts[1]:
                        self.vehicle_mismatch += 1
                        return
                    self.health[h.vehicle] = h
                    self.received["health"] += 1
                    for e in h.events:
                        self.events.append((h.vehicle, e))
        except msgspec.DecodeError:
            self.bad += 1  # another schema version or a foreign publisher: skip it

    def on_sample(self, sample: Any) -> None:
        """Zenoh subscriber callback."""
        self.feed(str(sample.key_expr), sample.payload.to_bytes(), str(sample.encoding))

    def vehicles(self) -> list[str]:
        """Ids of the vehicles seen so far (estimates, health or liveliness), sorted."""
        with self.lock:
            return sorted({v for v, _ in self.estimates} | set(self.health) | self.alive)

    def line(self, vehicle: str | None = None) -> str:
        """A one-line summary of a vehicle's key estimates (the demo's live line)."""
        with self.lock:
            est = {p: r for (v, p), r in self.estimates.items() if vehicle in (None, v)}
            h = self.health.get(vehicle) if vehicle else next(iter(self.health.values()), None)
        if not est:
            return "waiting for estimates ..."
        t = max(r.t for r in est.values())
        parts = [f"t={t:7.1f}s"]
        picks = (("nav", ("north", "east")), ("aie", ("speed", "heading", "surge_input", "yaw_input")),
                 ("kf", ("speed",)), ("current", ("north", "east")),
                 ("eseso", ("dist_x", "dist_y", "dist_z")))
        for pipe, qs in picks:
            r = est.get(pipe)
            if r is None:
                continue
            vals = " ".join(fmt_value(q, r.values[q]) for q in qs if q in r.values)
            if vals:
                parts.append(f"{pipe}: {vals}")
        if h is not None:
            parts.append(f"rej {sum(h.rejected.values())} drop {sum(h.dropped.values())}"
                         f" {h.mode}")
        return " | ".join(parts)

    def table(self, vehicle: str = "*", now: float | None = None) -> str:
        """The full table for every vehicle matching ``vehicle`` (``*`` = all)."""
        out: list[str] = []
        for v in self.vehicles():
            if vehicle not in ("*", v):
                continue
            with self.lock:
                est = sorted(((p, r) for (vv, p), r in self.estimates.items() if vv == v))
                h = self.health.get(v)
                alive = v in self.alive
            t_ref = max([r.t for _, r in est] + ([h.t] if h else []), default=0.0)
            flag = "alive" if alive else "no liveliness token"
            out.append(f"== {v.translate(CONTROL_SHOWN)} ({flag})"
                       + (f", mode {h.mode}" if h and h.mode else ""))
            for p, r in est:
                vals = "  ".join(fmt_value(q, x) for q, x in r.values.items()
                                 if not q.startswith("std_"))
                age = t_ref - r.t
                out.append(f"  {p:<8} age {age:4.1f}s  {vals}")
            if h is not None:
                rates = "  ".join(f"{k}={x:.1f}" for k, x in sorted(h.rates_hz.items())
                                  if ":" not in k or x > 0)
                out.append(f"  rates Hz   {rates or '-'}")
                rej = "  ".join(f"{k}={n}" for k, n in sorted(h.rejected.items()))
                out.append(f"  rejected   {rej or '-'}")
                if h.dropped:
                    out.append("  dropped    " + "  ".join(f"{k}={n}" for k, n in sorted(h.dropped.items())))
                nis = [f"{p}.{c}={ch.nis_recent:.2f}/{ch.dof}"
                       + (f" ({ch.rejected} rejected)" if ch.rejected else "")
                       for p, chans in h.innovations.items() for c, ch in chans.items()
                       if ch.nis_recent is not None]
                if nis:
                    out.append("  NIS/dof    " + "  ".join(nis))
        with self.lock:
            evs = [f"  {v.translate(CONTROL_SHOWN)}: {e.translate(CONTROL_SHOWN)}"
                   for v, e in self.events if vehicle in ("*", v)]
        if evs:
            out.append("events:")
            out.extend(evs[-8:])
        return "\n".join(out).translate(TABLE_SHOWN) if out else "no vehicle seen yet"


def check_prefix(prefix: str) -> str:
    """``prefix`` when it can start a key (segments joined by ``/``, none empty, no
    wildcard), else UsageError naming ``--prefix``."""
    if not valid_prefix(prefix):
        raise UsageError(f"--prefix {prefix!r}: a key prefix such as onboard or "
                         "region/north (no empty segment, no * $ ? #)")
    return prefix


def _token_vehicle(view: ShoreView, key: str) -> str | None:
    parts = key_parts(key, view.prefix)
    return parts[1] if parts and len(parts) > 2 else None


def snapshot(session: Any, view: ShoreView, vehicle: str = "*", timeout_s: float = 3.0) -> None:
    """Fill ``view`` from the vehicles' queryables and liveliness tokens (under the
    view's prefix, ``onboard`` when it has none)."""
    prefix = view.prefix or DEFAULT_PREFIX
    for rep in session.liveliness().get(f"{prefix}/{vehicle}/alive", timeout=timeout_s):
        if rep.ok is not None and (v := _token_vehicle(view, str(rep.ok.key_expr))):
            with view.lock:
                view.alive.add(v)
    for rep in session.get(f"{prefix}/{vehicle}/**", timeout=timeout_s):
        if rep.ok is not None:
            view.feed(str(rep.ok.key_expr), rep.ok.payload.to_bytes(), str(rep.ok.encoding))


def serve_web(session: Any, vehicle: str, listen: str, prefix: str = DEFAULT_PREFIX) -> int:
    """Serve the web page on ``listen`` (``HOST:PORT``) from the vehicles' samples under
    ``prefix`` until Ctrl-C: the queryables' latest values first, then every sample, and
    the fleet service's grids (the fleet layer)."""
    from onboard.service.web.app import PageOnThread

    key = f"{prefix}/{vehicle}/**"
    page = PageOnThread(session, [key, f"{prefix}/{FLEET_GRID_SUFFIX}"], listen,
                        vehicle="" if vehicle == "*" else vehicle, prime=[key], prefix=prefix)
    print(f"onboard shore: the page is on {page.url}", flush=True)
    try:
        threading.Event().wait()
    except KeyboardInterrupt:
        pass
    finally:
        page.close()
    return 0


def main(args: argparse.Namespace) -> int:
    """``onboard shore [--connect E] [--listen E] [--mode M] [--zenoh-config FILE]
    [--prefix P] [--vehicle ID] [--once] [--web HOST:PORT] [--foxglove [HOST:]PORT]``."""
    vehicle = args.vehicle or "*"
    if "/" in vehicle:
        raise UsageError(f"--vehicle {vehicle!r}: a vehicle id has no '/'")
    prefix = check_prefix(getattr(args, "prefix", None) or DEFAULT_PREFIX)
    if getattr(args, "foxglove", None):
        from onboard.apps.foxglove_live import foxglove_module, parse_listen

        parse_listen(args.foxglove)
        foxglove_module()
    session = open_session(args.connect, args.listen, args.mode,
                           getattr(args, "zenoh_config", "") or "")
    view = ShoreView(prefix=prefix)
    sub = None
    token_sub = None
    extra: tuple[Any, ...] = ()
    try:
        if args.once:
            snapshot(session, view, vehicle)
            print(view.table(vehicle))
            return 0 if view.vehicles() else 1
        if getattr(args, "foxglove", None):
            from onboard.apps.foxglove_live import parse_listen, start

            server, relay_sub, _ = start(session, vehicle, args.foxglove, prefix)
            extra = (relay_sub, server)
            host, port = parse_listen(args.foxglove)
            print(f"Foxglove: open connection ws://{host}:{port}", flush=True)
        if getattr(args, "web", ""):
            return serve_web(session, vehicle, args.web, prefix)

        def on_token(sample: Any) -> None:
            v = _token_vehicle(view, str(sample.key_expr))
            if v is None:
                return
            with view.lock:
                if str(sample.kind).endswith("DELETE"):
                    view.alive.discard(v)
                    view.events.append((v, "liveliness token withdrawn"))
                else:
                    view.alive.add(v)

        token_sub = session.liveliness().declare_subscriber(f"{prefix}/{vehicle}/alive", on_token)
        sub = session.declare_subscriber(f"{prefix}/{vehicle}/**", view.on_sample)
        snapshot(session, view, vehicle)
        tty = sys.stdout.isatty()
        while True:
            text = view.table(vehicle)
            if tty:
                sys.stdout.write("\x1b[H\x1b[2J" + time.strftime("%H:%M:%S ") + "onboard shore\n"
                                 + text + "\n")
            else:
                sys.stdout.write(text + "\n\n")
            sys.stdout.flush()
            time.sleep(1.0)
    except KeyboardInterrupt:
        return 0
    finally:
        for obj in (sub, token_sub, *extra[:1]):
            if obj is not None:
                obj.undeclare()
        for server in extra[1:]:
            server.stop()
        session.close()
