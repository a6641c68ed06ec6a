"""Protocol registry: a source ``kind`` -> a fresh stream parser for it.

The live service and the replay of the service's own recordings both turn raw chunks
into samples through :func:`parser_for`, so the same bytes give the same samples in both.

=========  ==========================================  ===================================
kind       parser                                      what it reads
=========  ==========================================  ===================================
mavlink    :class:`drivers.mavlink.MavlinkParser`      MAVLink 1/2 frames (autopilot link)
nmea       :class:`drivers.nmea.NmeaParser`            NMEA 0183 GNSS and heading lines
dvl-json   :class:`drivers.dvl_json.DvlJsonParser`     Water Linked DVL TCP JSON lines
pd6        :class:`drivers.pd6.Pd6Parser`              Teledyne RDI PD6 ensembles
gpsd       :class:`drivers.gpsd.GpsdParser`            gpsd's JSON reports (TPV, ATT, SKY)
sample     :class:`SampleParser`                       typed samples as msgpack (simulator)
=========  ==========================================  ===================================

Every parser has ``feed(data, t_rx) -> list[Sample]`` and ``stats`` (a
:class:`drivers.base.ReadStats`); none raises on bad bytes. Parser modules are imported
only when a source of that kind exists.
"""

from __future__ import annotations

import importlib
import math
from typing import TYPE_CHECKING, Callable

import msgspec

from onboard.drivers.base import ReadStats, StreamParser
from onboard.core.messages import AnySample, Sample

if TYPE_CHECKING:
    from onboard.drivers.mavlink_link import AutopilotLink
    from onboard.drivers.mavlink_signing import FrameVerifier

KINDS: tuple[str, ...] = ("mavlink", "nmea", "dvl-json", "pd6", "gpsd", "sample")
"""Protocols a source (or a raw record of a recording) may have."""

_CLASSES: dict[str, tuple[str, str]] = {
    "mavlink": ("onboard.drivers.mavlink", "MavlinkParser"),
    "nmea": ("onboard.drivers.nmea", "NmeaParser"),
    "dvl-json": ("onboard.drivers.dvl_json", "DvlJsonParser"),
    "pd6": ("onboard.drivers.pd6", "Pd6Parser"),
    "gpsd": ("onboard.drivers.gpsd", "GpsdParser"),
}


class UnknownProtocol(KeyError, ValueError):
    """A kind that no parser reads (a KeyError for registry lookups, a ValueError for
    configuration checks)."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "unknown protocol"


def _finite(sample: Sample) -> bool:
    """True if every number of ``sample`` (tuples included) is finite."""
    for v in msgspec.structs.astuple(sample):
        if isinstance(v, float) and not math.isfinite(v):
            return False
        if isinstance(v, tuple) and not all(math.isfinite(x) for x in v if isinstance(x, float)):
            return False
    return True


class SampleParser:
    """Typed samples encoded as msgpack (one sample per chunk), e.g. from the simulator.

    A chunk that does not decode is counted as ``"decode"``, one with a NaN or infinite
    number as ``"nan"``. The sample's own ``t`` is
    kept (the producer stamped it); ``source`` is kept when set, else this parser's.
    """

    def __init__(self, source: str = "sample") -> None:
        self.source = source
        self.stats = ReadStats()
        self._dec = msgspec.msgpack.Decoder(AnySample)

    def feed(self, data: bytes, t_rx: float) -> list[Sample]:
        """The sample encoded in ``data`` (one per chunk), with the parser's ``source`` when it
        has none; nothing for undecodable data (rejection ``decode``) or a non-finite value
        (``nan``). ``t_rx`` is unused: the sample carries its own time."""
        self.stats.records += 1
        try:
            s = self._dec.decode(data)
        except (msgspec.DecodeError, ValueError):
            self.stats.reject("decode")
            return []
        self.stats.by_type[type(s).__name__] += 1
        if not _finite(s):
            self.stats.reject("nan")
            return []
        if not s.source:
            s = msgspec.structs.replace(s, source=self.source)
        self.stats.samples += 1
        return [s]


def encode_sample(sample: Sample) -> bytes:
    """The bytes a :class:`SampleParser` reads back as ``sample``."""
    return msgspec.msgpack.encode(sample)


def parser_for(kind: str, source: str = "", *, verifier: "FrameVerifier | None" = None,
               link: "AutopilotLink | None" = None) -> StreamParser:
    """A new stream parser for ``kind``; ``source`` names its samples where the protocol
    lets the parser choose (MAVLink names sources by system id and message itself).
    ``verifier`` (MAVLink only) makes the parser require signed, fresh frames
    (:mod:`drivers.mavlink_signing`); other protocols have no signatures and ignore it.
    ``link`` (MAVLink only): decode only the autopilot's frames, stamped with its mapped
    boot time (:mod:`drivers.mavlink_link`).

    Raises :class:`UnknownProtocol` for an unknown kind.
    """
    if kind == "sample":
        return SampleParser(source or "sample")
    try:
        module_name, class_name = _CLASSES[kind]
    except KeyError:
        raise UnknownProtocol(f"unknown protocol {kind!r}; known: {', '.join(KINDS)}") from None
    cls: Callable[..., StreamParser] = getattr(importlib.import_module(module_name), class_name)
    if kind == "mavlink":
        return cls(verifier=verifier, link=link)
    return cls(source=source or kind)
