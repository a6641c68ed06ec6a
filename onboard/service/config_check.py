"""What ``onboard run`` requires of a configuration beyond its schema.

:func:`check_config` is the deployment check the service runs on its configuration
before it starts anything (:mod:`onboard.service.daemon`), and the one the web page runs
on a new text of the configuration file before saving it
(:mod:`onboard.service.web.config_edit`): both reject the same files with the same
dotted-key errors.
"""

from __future__ import annotations

from onboard.core.config import Config, ConfigError
from onboard.drivers.transports import TransportUrlError, parse_url
from onboard.service.web.http import parse_listen


def check_zenoh_url(cfg: Config, url: str, where: str, kind: str) -> None:
    """A ``zenoh:`` URL (MAVLink over Zenoh, on the session of ``[service.zenoh]``) needs
    that session enabled and carries MAVLink only; ConfigError naming ``where``."""
    if not url.startswith("zenoh:"):
        return
    if kind != "mavlink":
        raise ConfigError(f"{where}: {url!r}: a zenoh: url carries MAVLink (kind \"mavlink\")")
    if not cfg.service.zenoh.enabled:
        raise ConfigError(f"{where}: {url!r} uses the Zenoh session of [service.zenoh], "
                          "which is disabled (service.zenoh.enabled = false)")


def check_config(cfg: Config, origin: str) -> None:
    """What ``onboard run`` requires of a configuration beyond its schema (at least one
    source, parseable source URLs, gpsd URLs with kind gpsd only, a ``HOST:PORT`` web
    listen address); ConfigError naming ``origin`` and the key otherwise."""
    if not cfg.service.sources:
        raise ConfigError(f"{origin}: service.sources is empty: nothing to read")
    for i, src in enumerate(cfg.service.sources):
        try:
            spec = parse_url(src.url)
        except TransportUrlError as err:
            raise ConfigError(f"{origin}: service.sources[{i}].url: {err}") from None
        if (spec.scheme == "gpsd") != (src.kind == "gpsd"):
            raise ConfigError(f"{origin}: service.sources[{i}]: kind \"gpsd\" goes with "
                              f"a gpsd://HOST:PORT url and only with it")
        check_zenoh_url(cfg, src.url, f"{origin}: service.sources[{i}].url", src.kind)
    check_zenoh_url(cfg, cfg.service.mavlink.url, f"{origin}: service.mavlink.url", "mavlink")
    if cfg.service.web.listen:
        try:
            parse_listen(cfg.service.web.listen)
        except ValueError as err:
            raise ConfigError(f"{origin}: service.web.listen: {err}") from None
