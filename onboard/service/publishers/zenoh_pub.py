"""Zenoh publisher: estimates and health to shore (architecture.md §4.4).

Keys (``<prefix>`` is ``onboard`` unless configured)::

    <prefix>/<vehicle_id>/est/<pipeline>   EstimateRecord, every tick
    <prefix>/<vehicle_id>/fix/<pipeline>   its position as foxglove.LocationFix, every tick
    <prefix>/<vehicle_id>/health           HealthRecord, 1 Hz
    <prefix>/<vehicle_id>/alive            liveliness token (present while running)
    <prefix>/<vehicle_id>/**               queryable: the latest value of every key above

Payloads are JSON objects: the msgspec structs of :mod:`onboard.core.messages`, each with
its ``schema`` version, and Foxglove's LocationFix; the Zenoh encoding names the schema
(``application/json;onboard.Estimate.v2``, ``application/json;onboard.Health.v3``,
``application/json;foxglove.LocationFix``: :mod:`onboard.core.wire`), so BlueOS's
recorder writes them into its MCAP under that schema name and Foxglove maps the fixes. The vehicle's session is a peer
or client with multicast scouting off: it connects to the endpoints configured (a router
on the vehicle or on shore) and listens where configured. :func:`open_router` starts an
in-process router session for the demo and the tests (no zenohd binary).

A router that goes away (restarted, link down) is reconnected by Zenoh itself: a client or
peer retries its ``connect`` endpoints (zenoh 1.x ``connect/retry``: 1 s doubling to
4 s, the defaults; docs/service.md gives the reconnection times). The publisher
watches the session's routers/peers at every health record and reports the loss and
the return as events (``on_event``); puts while disconnected are dropped by Zenoh, so
the estimator loop never waits for the network (``put`` drops under congestion,
Zenoh's default for data, and never blocks).

Secrets (the CA certificate, a TLS key and certificate, the user and password) come from
``[service.zenoh]`` keys that name files or systemd credentials (:func:`secret_settings`),
so the JSON5 ``config_file`` itself holds none and needs no protection.
"""

from __future__ import annotations

import json
import logging
import threading
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import msgspec

from onboard.core import wire
from onboard.core.config import ZenohOut
from onboard.core.errors import UsageError
from onboard.core.messages import EstimateRecord, HealthRecord

log = logging.getLogger(__name__)

DEFAULT_ROUTER_ENDPOINT = "tcp/127.0.0.1:7447"
JSON_ENCODING = "application/json"
"""The MIME type of every payload; the encoding adds the schema name (``;<schema>``).

Publishers are not declared ``express``: the records of a tick, put one after the other,
leave in the batches Zenoh's transmit thread finds queued when it wakes, instead of one
wake-up of that thread per put (and the main thread's sleeps on the locks they share:
~10 a second fewer in the bench, docs/performance.md). Zenoh
holds a message back for batching only under back-pressure (its
``transport/link/tx/queue/batching``); otherwise each batch leaves at once: the bench's
tick-to-subscriber latency is the same either way (docs/performance.md)."""


def session_config(mode: str = "peer", connect: Iterable[str] = (), listen: Iterable[str] = (),
                   config_file: str = "") -> "zenoh.Config":  # noqa: F821
    """A Zenoh configuration: ``mode`` peer/client/router, multicast scouting off,
    ``connect``/``listen`` endpoints; ``config_file`` (JSON5: TLS, credentials, access
    control) is the base when given."""
    import zenoh

    conf = zenoh.Config.from_file(config_file) if config_file else zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", "false")
    connect, listen = list(connect), list(listen)
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(connect))
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps(listen))
    elif mode != "router":
        conf.insert_json5("listen/endpoints", "[]")  # a vehicle listens only where told
    return conf


KEY_SPECIALS = frozenset("*$?#")
"""Characters a key prefix cannot hold (Zenoh's wildcards and selector marks)."""


def valid_prefix(prefix: str) -> bool:
    """Whether ``prefix`` can start a key: segments joined by ``/``, none empty, no
    wildcard or selector mark (:data:`KEY_SPECIALS`)."""
    return bool(prefix) and all(prefix.split("/")) and not KEY_SPECIALS & set(prefix)


def config_endpoints(config_file: str, what: str = "connect") -> list[str]:
    """The ``<what>/endpoints`` of a Zenoh JSON5 configuration file (``[]`` when it gives
    none, or for no file)."""
    import zenoh

    if not config_file:
        return []
    return list(json.loads(zenoh.Config.from_file(config_file).get_json(f"{what}/endpoints")))


def config_mode(config_file: str) -> str | None:
    """The ``mode`` of a Zenoh JSON5 configuration file (None when it gives none, or for
    no file)."""
    import zenoh

    if not config_file:
        return None
    return json.loads(zenoh.Config.from_file(config_file).get_json("mode") or "null")


SHORE_CONNECT = "tcp/127.0.0.1:7447"
"""Where a shore session connects when neither its flags nor its config file say: a
router on this machine."""


def open_shore_session(connect: Sequence[str] | None, listen: Sequence[str] | None,
                       mode: str | None, config_file: str = "") -> Any:
    """A shore Zenoh session (``onboard shore``, ``onboard fleet``; multicast scouting
    off): in ``mode``, else ``config_file``'s, else client; to ``connect``, else
    ``config_file``'s endpoints, else :data:`SHORE_CONNECT` (a peer that listens, with none
    of them, dials nobody: the vehicles connect to it). ``config_file`` (JSON5) also
    carries TLS and credentials for a router with access control (docs/security.md). A
    missing file or an unreachable router is a :class:`UsageError` of one line."""
    import zenoh

    if config_file and not Path(config_file).is_file():
        raise UsageError(f"--zenoh-config {config_file}: no such file")
    m = mode or config_mode(config_file) or "client"
    default = [] if listen and m == "peer" else [SHORE_CONNECT]
    endpoints = list(connect or config_endpoints(config_file) or default)
    try:
        return zenoh.open(session_config(m, endpoints, list(listen or []), config_file))
    except Exception as err:  # noqa: BLE001 - zenoh.ZError
        where = ", ".join(endpoints or list(listen or []) or [config_file])
        raise UsageError(f"cannot reach Zenoh at {where}: "
                         f"{str(err).split(' at ')[0]}") from None


def secret_settings(cfg: ZenohOut) -> dict[str, str]:
    """The Zenoh settings (key -> JSON value) that the secrets of ``[service.zenoh]``
    add on top of ``config_file``: the CA certificate, this vehicle's TLS key and
    certificate, the user and password (each a path or ``credential:NAME``, a systemd
    credential: :mod:`onboard.service.credentials`). Raises ConfigError, naming the key,
    for a missing or non-private secret, or a key without its certificate."""
    from onboard.core.config import ConfigError
    from onboard.service.credentials import (
        missing_hint,
        read_secret,
        read_user_password,
        resolve_secret,
    )

    out: dict[str, str] = {}

    def public(value: str, key: str) -> str:
        p = resolve_secret(value, key)
        if not p.is_file():
            raise ConfigError(f"{key}: {p}: no such file{missing_hint(value)}")
        return json.dumps(str(p))

    if cfg.tls_root_ca_certificate:
        out["transport/link/tls/root_ca_certificate"] = public(
            cfg.tls_root_ca_certificate, "service.zenoh.tls_root_ca_certificate")
    if bool(cfg.tls_private_key) != bool(cfg.tls_certificate):
        raise ConfigError("service.zenoh.tls_private_key and tls_certificate go together")
    if cfg.tls_private_key:
        key, _ = read_secret(cfg.tls_private_key, "service.zenoh.tls_private_key")
        cert = public(cfg.tls_certificate, "service.zenoh.tls_certificate")
        for side in ("listen", "connect"):
            out[f"transport/link/tls/{side}_private_key"] = json.dumps(str(key))
            out[f"transport/link/tls/{side}_certificate"] = cert
    if cfg.user_password_file:
        user, password = read_user_password(cfg.user_password_file,
                                            "service.zenoh.user_password_file")
        out["transport/auth/usrpwd/user"] = json.dumps(user)
        out["transport/auth/usrpwd/password"] = json.dumps(password)
    return out


def open_router(listen: str | Sequence[str] = DEFAULT_ROUTER_ENDPOINT) -> "zenoh.Session":  # noqa: F821
    """An in-process Zenoh router listening on ``listen`` (default tcp/127.0.0.1:7447).

    Close it with ``session.close()`` (an open session keeps the interpreter alive).
    """
    import zenoh

    eps = [listen] if isinstance(listen, str) else list(listen)
    return zenoh.open(session_config("router", listen=eps))


class ZenohPublisher:
    """Publishes one vehicle's records; answers queries with the latest of each.

    Parameters:
        cfg: the ``[service.zenoh]`` table.
        vehicle: the vehicle id (the second key segment).
    """

    def __init__(self, cfg: ZenohOut, vehicle: str,
                 on_event: "Callable[[str], None] | None" = None) -> None:
        self.cfg = cfg
        self.on_event = on_event
        self.connected: bool | None = None
        """Whether the session reaches a router or peer (None: not checked yet, or no
        ``connect`` endpoints to watch)."""
        self.disconnects = 0
        self.vehicle = vehicle
        self.base = f"{cfg.key_prefix}/{vehicle}"
        self.session = None
        self.published = 0
        self.errors = 0
        self.queries = 0
        self._pubs: dict[str, object] = {}
        self._latest: dict[str, tuple[bytes, str]] = {}
        """Key -> (payload, encoding) of the newest put (what the queryable answers)."""
        self._lock = threading.Lock()
        self._token = None
        self._queryable = None
        self._enc = msgspec.json.Encoder()

    def start(self) -> None:
        """Open the session, declare the liveliness token and the queryable."""
        import zenoh

        if self.cfg.config_file and not Path(self.cfg.config_file).exists():
            raise FileNotFoundError(f"zenoh config file {self.cfg.config_file} not found")
        mode = self.cfg.mode if self.cfg.mode in ("peer", "client", "router") else "peer"
        conf = session_config(mode, self.cfg.connect, self.cfg.listen, self.cfg.config_file)
        for key, value in secret_settings(self.cfg).items():
            conf.insert_json5(key, value)
        self.session = zenoh.open(conf)
        self._token = self.session.liveliness().declare_token(f"{self.base}/alive")
        self._queryable = self.session.declare_queryable(f"{self.base}/**", self._on_query)
        self._publisher("health", wire.HEALTH_SCHEMA)

    def _publisher(self, suffix: str, schema: str) -> object:
        pub = self._pubs.get(suffix)
        if pub is None:
            import zenoh

            pub = self._pubs[suffix] = self.session.declare_publisher(  # type: ignore[union-attr]
                f"{self.base}/{suffix}", encoding=zenoh.Encoding(wire.encoding(schema)),
                express=False)
        return pub

    def _put(self, suffix: str, payload: bytes, schema: str) -> None:
        with self._lock:
            self._latest[f"{self.base}/{suffix}"] = (payload, wire.encoding(schema))
        if self.session is None:
            return
        try:
            self._publisher(suffix, schema).put(payload)  # type: ignore[attr-defined]
            self.published += 1
        except Exception as err:  # noqa: BLE001 - a network hiccup never stops the loop
            self.errors += 1
            if self.errors == 1 or self.errors % 1000 == 0:
                log.warning("zenoh put on %s/%s failed (%d): %s", self.base, suffix,
                            self.errors, err)

    def publish_estimates(self, records: Sequence[EstimateRecord],
                          fixes: Sequence[wire.LocationFix] = ()) -> None:
        """Put each record on ``<base>/est/<pipeline>`` and each fix on
        ``<base>/fix/<frame_id>`` (its pipeline)."""
        enc = self._enc.encode
        for rec in records:
            self._put(f"est/{rec.pipeline}", enc(rec), wire.ESTIMATE_SCHEMA)
        for fix in fixes:
            self._put(f"fix/{fix.frame_id}", enc(fix), wire.LOCATION_FIX_SCHEMA)

    def publish_health(self, health: HealthRecord) -> None:
        """Put the health record on ``<base>/health``, then :meth:`check_connection`."""
        self._put("health", self._enc.encode(health), wire.HEALTH_SCHEMA)
        self.check_connection()

    def check_connection(self) -> bool | None:
        """Look whether the session reaches any router or peer (only with ``connect``
        endpoints); report a change as an event. Called at 1 Hz with the health record."""
        if self.session is None or not self.cfg.connect:
            return None
        try:
            info = self.session.info
            up = bool(list(info.routers_zid())) or bool(list(info.peers_zid()))
        except Exception:  # noqa: BLE001 - a closed session
            up = False
        if up != self.connected:
            if self.connected is not None and self.on_event is not None:
                ends = ", ".join(self.cfg.connect)
                self.on_event(f"zenoh: connected again to {ends}" if up else
                              f"zenoh: lost {ends}; reconnecting (estimates not delivered)")
            if not up and self.connected is not None:
                self.disconnects += 1
            self.connected = up
        return up

    def _on_query(self, query: object) -> None:
        """Reply with the latest value of every key the query's selector matches."""
        import zenoh

        self.queries += 1
        try:
            sel = query.key_expr  # type: ignore[attr-defined]
            with self._lock:
                items = list(self._latest.items())
            for key, (payload, enc) in items:
                if sel.intersects(zenoh.KeyExpr(key)):
                    query.reply(key, payload, encoding=zenoh.Encoding(enc))  # type: ignore[attr-defined]
        except Exception as err:  # noqa: BLE001 - never let a query kill the session thread
            self.errors += 1
            log.warning("zenoh query failed: %s", err)

    def close(self) -> None:
        """Undeclare everything and close the session (removes the liveliness token)."""
        for obj in [self._queryable, self._token, *self._pubs.values()]:
            if obj is not None:
                try:
                    obj.undeclare()  # type: ignore[attr-defined]
                except Exception:  # noqa: BLE001
                    pass
        self._pubs.clear()
        self._queryable = self._token = None
        if self.session is not None:
            try:
                self.session.close()
            except Exception:  # noqa: BLE001
                pass
            self.session = None
