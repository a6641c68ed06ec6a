"""``onboard shore --foxglove [HOST:]PORT``: the vehicles' Zenoh records, live in Foxglove.

Foxglove reads live data from a Foxglove WebSocket server, not from Zenoh. The relay
subscribes to ``<prefix>/<vehicle>/**`` (``onboard`` unless ``--prefix``) and logs every
record whose encoding names one of our schemas (``application/json;onboard.Estimate.v2``,
``onboard.Health.v3``, ``foxglove.LocationFix``: :mod:`onboard.core.wire`) on a channel
of the same name as its Zenoh key, JSON messages with that schema name and its JSON
schema, through the ``foxglove-sdk`` package (the ``foxglove`` extra). In Foxglove: *Open
connection* → *Foxglove WebSocket* → ``ws://HOST:PORT``, then import the vehicle's layout
(written by ``onboard replay --foxglove-layout``, docs/foxglove.md).
"""

from __future__ import annotations

import json
import re
import threading
from typing import Any

from onboard.core import wire
from onboard.core.errors import UsageError

DEFAULT_HOST = "127.0.0.1"
MISSING_SDK = "--foxglove needs the foxglove-sdk package: pip install 'onboard[foxglove]'"


def foxglove_module() -> Any:
    """The ``foxglove`` package of foxglove-sdk, or UsageError naming the extra."""
    try:
        import foxglove
    except ImportError:
        raise UsageError(MISSING_SDK) from None
    return foxglove


def parse_listen(text: str) -> tuple[str, int]:
    """``PORT`` or ``HOST:PORT`` -> (host, port); UsageError otherwise."""
    host, _, port = text.rpartition(":")
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise UsageError(f"--foxglove {text!r}: expected PORT or HOST:PORT")
    return host.strip("[]") or DEFAULT_HOST, int(port)


class FoxgloveRelay:
    """Logs Zenoh samples on Foxglove channels (see the module docstring); ``context``: a
    ``foxglove.Context`` (default the SDK's global one, which the server reads)."""

    def __init__(self, context: Any = None) -> None:
        self.foxglove = foxglove_module()
        self.context = context
        self.channels: dict[str, Any] = {}
        self.relayed = 0
        self.skipped = 0
        """Samples not of one of our schemas (another version, another publisher)."""
        self._lock = threading.Lock()

    def _channel(self, key: str, schema: str) -> Any:
        with self._lock:
            ch = self.channels.get(key)
            if ch is None:
                fg = self.foxglove
                data = json.dumps(wire.json_schema(wire.SCHEMAS[schema])).encode()
                ch = self.channels[key] = fg.Channel(
                    key, message_encoding="json", context=self.context,
                    schema=fg.Schema(name=schema, encoding="jsonschema", data=data))
            return ch

    def on_sample(self, sample: Any) -> None:
        """Zenoh subscriber callback: relay one sample."""
        schema = str(sample.encoding).partition(";")[2]
        if schema not in wire.SCHEMAS:
            self.skipped += 1
            return
        self._channel(str(sample.key_expr), schema).log(sample.payload.to_bytes())
        self.relayed += 1


def start_server(fg: Any, host: str, port: int, listen: str) -> Any:
    """The SDK's WebSocket server on ``host:port``; a port that cannot be bound (in use,
    an unknown host) is a UsageError naming ``--foxglove`` and why, as ``--web``'s."""
    try:
        return fg.start_server(name="onboard", host=host, port=port)
    except RuntimeError as err:  # the SDK's FoxgloveError
        text = str(err)
        if "bind" not in text:
            raise
        why = re.sub(r"\s*\(os error \d+\)$", "", text.rpartition("port: ")[2] or text)
        raise UsageError(f"--foxglove {listen}: {why}") from None


def start(session: Any, vehicle: str, listen: str, prefix: str = "onboard"
          ) -> tuple[Any, Any, FoxgloveRelay]:
    """Start the WebSocket server on ``listen`` and relay ``<prefix>/<vehicle>/**`` from
    ``session``; returns (server, subscriber, relay) for the caller to stop."""
    fg = foxglove_module()
    host, port = parse_listen(listen)
    relay = FoxgloveRelay()
    server = start_server(fg, host, port, listen)
    sub = session.declare_subscriber(f"{prefix}/{vehicle}/**", relay.on_sample)
    return server, sub, relay
