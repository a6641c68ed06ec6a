"""The page's routes, BlueOS's discovery contract and the JSON API.

=============================  ================================================================
``GET /``                      the page (``<title>onboard</title>``)
``GET /page.js``, ``/icon.svg``  its script and icon
``GET /register_service``      BlueOS's service metadata (name, description, icon, company,
                               version, webpage, api, works_in_relative_paths, extras.cockpit)
``GET /cockpit_extras.json``   the Cockpit widget description: the page in an iframe
``GET /api/state``             :meth:`.view.LiveView.state` (``?vehicle=&since=&epoch=``)
``GET /api/fleet``             :meth:`.view.LiveView.fleet`: the newest fleet grid (``?since=``
                               its utc seen), the fleet's vehicles and tracks (``&vehicle=``
                               the one the page shows, left out)
``GET /api/config``            the configuration files and the configuration in use (service)
``POST /api/config/check``     check a new text of the last file: ``{"errors": [...]}``
``POST /api/config``           check and save it (422 with the errors when it fails)
=============================  ================================================================

Every URL the page uses is relative, so it works behind BlueOS's proxy under
``/extensionv2/<name>/`` (the trailing slash matters) as on its own port. BlueOS finds
the service by scanning listening ports for ``GET /`` with a ``<title>`` and asking
``/register_service`` (bluerobotics/BlueOS ``core/services/helper``); Cockpit asks the
path of ``extras.cockpit`` and prefixes every ``iframe_url`` with the service's base
URL (bluerobotics/cockpit ``src/libs/blueos.ts``).
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import threading
from importlib import resources
from importlib.metadata import PackageNotFoundError, version
from typing import Any, Sequence

import msgspec

from onboard.core.errors import UsageError
from onboard.service.web.config_edit import ConfigEditor
from onboard.service.web.http import (
    Handler,
    HttpError,
    HttpServer,
    Request,
    Response,
    parse_listen,
)
from onboard.service.web.view import LiveView

NAME = "onboard"
DESCRIPTION = ("Live map of the track, water current with its uncertainty, speed, heading, "
               "integrity and health")
ICON = "mdi-map-marker-path"
"""A Material Design icon name, as BlueOS expects."""
COMPANY = "onboard"
WEBPAGE_ENV = "ONBOARD_WEBPAGE"
"""The project's web page in ``/register_service`` comes from this environment variable
(the BlueOS image sets it from the repository it is built from; empty otherwise)."""
COCKPIT_EXTRAS = "/cockpit_extras.json"
COCKPIT_API_VERSION = "1.0.0"


PRIME_TIMEOUT_S = 3.0
"""Seconds :class:`PageOnThread` waits for the answers it is primed with."""


def _version() -> str:
    try:
        return version("onboard")
    except PackageNotFoundError:  # a source tree on sys.path, not installed
        return "0+unknown"


VERSION = _version()
STATIC = {"/": ("index.html", "text/html; charset=utf-8"),
          "/page.js": ("page.js", "text/javascript; charset=utf-8"),
          "/icon.svg": ("icon.svg", "image/svg+xml")}
JSON = "application/json"


def static_file(name: str) -> bytes:
    """A file of ``static/`` (the page, its script, its icon)."""
    return resources.files("onboard.service.web").joinpath("static", name).read_bytes()


def register_service() -> dict:
    """BlueOS's ServiceMetadata for this service."""
    return {"name": NAME, "description": DESCRIPTION, "icon": ICON, "company": COMPANY,
            "version": VERSION, "webpage": os.environ.get(WEBPAGE_ENV, ""), "api": "/api/state",
            "route": "/", "new_page": False, "works_in_relative_paths": True,
            "extras": {"cockpit": COCKPIT_EXTRAS}}


def cockpit_extras() -> dict:
    """The Cockpit widget description: the page in an iframe (compact layout)."""
    return {"target_system": "Cockpit", "target_cockpit_api_version": COCKPIT_API_VERSION,
            "widgets": [{"name": "onboard: track and current", "config_iframe_url": None,
                         "iframe_url": "/?widget=1", "iframe_icon": "/icon.svg",
                         "version": VERSION}],
            "actions": []}


def json_response(obj: object, status: int = 200) -> Response:
    """``obj`` as JSON (non-finite numbers as null)."""
    return Response(status, msgspec.json.encode(obj), JSON)


def _float(q: dict[str, str], key: str, default: float) -> float:
    try:
        return float(q[key]) if key in q else default
    except ValueError:
        raise HttpError(400, f"{key}: not a number") from None


def routes(view: LiveView, editor: ConfigEditor | None = None) -> dict[tuple[str, str], Handler]:
    """The routes serving ``view`` (and ``editor``'s configuration when given)."""
    table: dict[tuple[str, str], Handler] = {}
    for path, (name, ctype) in STATIC.items():
        table[("GET", path)] = _static(name, ctype)
    table[("GET", "/register_service")] = lambda _r: json_response(register_service())
    table[("GET", COCKPIT_EXTRAS)] = lambda _r: json_response(cockpit_extras())

    def state(req: Request) -> Response:
        q = req.query
        return json_response(view.state(q.get("vehicle", ""), _float(q, "since", -math.inf),
                                         int(_float(q, "epoch", -1))))

    table[("GET", "/api/state")] = state
    table[("GET", "/api/fleet")] = lambda req: json_response(
        view.fleet(_float(req.query, "since", -math.inf), req.query.get("vehicle", "")))
    if editor is not None:
        table.update(_config_routes(editor))
    return table


def _static(name: str, ctype: str) -> Handler:
    body = static_file(name)
    return lambda _r: Response(200, body, ctype)


def _config_routes(editor: ConfigEditor) -> dict[tuple[str, str], Handler]:
    def text_of(req: Request) -> str:
        try:
            obj = json.loads(req.body)
            return str(obj["text"])
        except (ValueError, KeyError, TypeError):
            raise HttpError(400, 'expected JSON {"text": "..."}') from None

    def check(req: Request) -> Response:
        return json_response({"errors": editor.check(text_of(req))})

    def save(req: Request) -> Response:
        errors = editor.save(text_of(req))
        return json_response({"errors": errors, "saved": not errors,
                              "target": str(editor.target)}, 422 if errors else 200)

    return {("GET", "/api/config"): lambda _r: json_response(editor.show()),
            ("POST", "/api/config/check"): check, ("POST", "/api/config"): save}


def make_server(listen: str, view: LiveView, editor: ConfigEditor | None = None) -> HttpServer:
    """The server of the page on ``listen`` (``HOST:PORT``), not started."""
    host, port = parse_listen(listen)
    return HttpServer(routes(view, editor), host, port)


class PageOnThread:
    """The page served on ``listen`` (``HOST:PORT``) from a :class:`LiveView` fed by Zenoh
    subscriptions to ``keys``, its server on an event loop of its own thread (so that the
    caller's work, a fleet fit or a wait for Ctrl-C, never holds a page request back).

    A bad ``listen`` or a port that cannot be bound is a :class:`UsageError` naming
    ``--web``. ``prime``: answers of a Zenoh ``get`` on these key expressions fed first
    (a shore's queryables' latest values). ``prefix``: the key prefix the vehicles
    publish under (:class:`.view.LiveView`)."""

    def __init__(self, session: Any, keys: Sequence[str], listen: str, *, vehicle: str = "",
                 prime: Sequence[str] = (), prefix: str = "") -> None:
        try:
            parse_listen(listen)
        except ValueError as err:
            raise UsageError(f"--web {err}") from None
        self.view = LiveView(vehicle=vehicle, prefix=prefix)
        for key in prime:
            for rep in session.get(key, timeout=PRIME_TIMEOUT_S):
                if rep.ok is not None:
                    self.view.feed_zenoh(str(rep.ok.key_expr), rep.ok.payload.to_bytes())
        self.server = make_server(listen, self.view)
        self._loop = asyncio.new_event_loop()
        try:
            self._loop.run_until_complete(self.server.start())
        except OSError as err:
            self._loop.close()
            raise UsageError(f"--web {listen}: {err.strerror}") from None
        self._subs = [session.declare_subscriber(k, self.view.on_sample) for k in keys]
        self._thread = threading.Thread(target=self._loop.run_forever, name="web", daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        """Where the page is."""
        return f"http://{self.server.host}:{self.server.port}/"

    def close(self) -> None:
        """Stop serving the page."""
        for sub in self._subs:
            sub.undeclare()
        asyncio.run_coroutine_threadsafe(self.server.close(), self._loop).result(10.0)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(10.0)
        self._loop.close()
