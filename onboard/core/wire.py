"""The published records on the wire: schema names, JSON schemas, Foxglove's LocationFix.

Every record the service publishes over Zenoh, and ``onboard replay --mcap`` writes, is a
JSON object whose Zenoh encoding (and MCAP schema name) names its schema and version
(architecture.md §4.4)::

    application/json;onboard.Estimate.v2   EstimateRecord (SCHEMA_VERSION)
    application/json;onboard.Health.v3     HealthRecord (HEALTH_SCHEMA_VERSION)
    application/json;foxglove.LocationFix  a position as Foxglove's LocationFix

BlueOS's recorder (bluerobotics/blueos-recorder ``src/channel_descriptor.rs``) records
every sample whose encoding is ``application/json[;<schema>]`` and whose payload is a JSON
object into its MCAP, with ``<schema>`` as the MCAP schema name; Foxglove draws a
``foxglove.LocationFix`` channel on its Map panel.

:func:`location_fix` turns an estimate's local position (north, east in m from the
pipeline's first fix, :class:`~onboard.core.geo.LocalFrame`) into latitude and longitude.
Foxglove's LocationFix (foxglove/foxglove-sdk ``schemas/jsonschema/LocationFix.json``):
``timestamp`` {sec, nsec}, ``frame_id``, ``latitude``/``longitude`` (deg), ``altitude``
(m), ``position_covariance`` (m^2, 3x3 row-major, East-North-Up),
``position_covariance_type`` (0 unknown, 2 diagonal known), ``heading`` (rad, clockwise
from north; optional).
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import msgspec

from onboard.core.geo import LocalFrame
from onboard.core.messages import (
    HEALTH_SCHEMA_VERSION,
    SCHEMA_VERSION,
    EstimateRecord,
    HealthRecord,
)

JSON_MIME = "application/json"
ESTIMATE_SCHEMA = f"onboard.Estimate.v{SCHEMA_VERSION}"
"""Schema name of an :class:`EstimateRecord`."""
ESTIMATE_SCHEMAS = frozenset(f"onboard.Estimate.v{v}" for v in range(1, SCHEMA_VERSION + 1))
"""Every schema name an :class:`EstimateRecord` decodes (each version only added fields:
an older record decodes with the newer fields at their defaults)."""
HEALTH_SCHEMA = f"onboard.Health.v{HEALTH_SCHEMA_VERSION}"
"""Schema name of a :class:`HealthRecord`."""
LOCATION_FIX_SCHEMA = "foxglove.LocationFix"
"""Schema name of Foxglove's LocationFix."""
COVARIANCE_UNKNOWN = 0
COVARIANCE_DIAGONAL_KNOWN = 2
"""``position_covariance_type`` values of Foxglove's PositionCovarianceType."""
NS_PER_S = 1_000_000_000


def encoding(schema: str) -> str:
    """The Zenoh encoding of a JSON record of ``schema``: ``application/json;<schema>``."""
    return f"{JSON_MIME};{schema}"


def estimate_key(prefix: str, vehicle: str, pipeline: str) -> str:
    """``<prefix>/<vehicle>/est/<pipeline>``: where a pipeline's estimates go."""
    return f"{prefix}/{vehicle}/est/{pipeline}"


def health_key(prefix: str, vehicle: str) -> str:
    """``<prefix>/<vehicle>/health``."""
    return f"{prefix}/{vehicle}/health"


def fix_key(prefix: str, vehicle: str, pipeline: str) -> str:
    """``<prefix>/<vehicle>/fix/<pipeline>``: a pipeline's position as a LocationFix."""
    return f"{prefix}/{vehicle}/fix/{pipeline}"


class Time(msgspec.Struct, frozen=True):
    """Foxglove's time: whole seconds and nanoseconds (0..999999999)."""

    sec: int
    nsec: int


class LocationFix(msgspec.Struct, frozen=True, kw_only=True, omit_defaults=True):
    """Foxglove's ``foxglove.LocationFix`` (see the module docstring); ``heading`` is left
    out when unknown."""

    timestamp: Time
    frame_id: str
    latitude: float
    longitude: float
    altitude: float
    position_covariance: list[float]
    position_covariance_type: int
    heading: float | None = None


def foxglove_time(t: float) -> Time:
    """``t`` (s, >= 0) as Foxglove's {sec, nsec}, the fraction rounded to the nearest
    nanosecond; a negative time is clipped to 0."""
    if not t > 0.0:
        return Time(0, 0)
    sec = math.floor(t)
    nsec = round((t - sec) * NS_PER_S)
    if nsec >= NS_PER_S:
        sec, nsec = sec + 1, nsec - NS_PER_S
    return Time(int(sec), int(nsec))


def location_fix(rec: EstimateRecord, frame: LocalFrame,
                 offset: tuple[float, float] = (0.0, 0.0)) -> LocationFix | None:
    """The position of ``rec`` as a LocationFix, or None when it has no finite north and
    east; stamped with the record's ``utc`` where known (Foxglove expects epoch time), else
    its engine time ``t``. ``frame`` is the pipeline's local frame (its first fix) and ``offset`` the
    published position (north, east; m) of the frame's origin (the ESESO's; (0, 0) for
    the others). Altitude is ``-down`` where the pipeline estimates depth, else 0; the
    covariance is diagonal (East, North, Up) from the ``std`` of north, east and down
    when north's and east's are known, else unknown (zeros)."""
    v, sd = rec.values, rec.std
    n, e = v.get("north"), v.get("east")
    if n is None or e is None or not (math.isfinite(n) and math.isfinite(e)):
        return None
    lat, lon = frame.to_latlon(n - offset[0], e - offset[1])
    down = v.get("down")
    alt = -down if down is not None and math.isfinite(down) else 0.0
    cov = [0.0] * 9
    kind = COVARIANCE_UNKNOWN
    s_n, s_e = sd.get("north"), sd.get("east")
    if s_n is not None and s_e is not None:
        s_d = sd.get("down", 0.0)
        cov[0], cov[4], cov[8] = s_e * s_e, s_n * s_n, s_d * s_d
        kind = COVARIANCE_DIAGONAL_KNOWN
    heading = v.get("heading", v.get("yaw"))
    return LocationFix(timestamp=foxglove_time(rec.t if rec.utc is None else rec.utc),
                       frame_id=rec.pipeline, latitude=lat, longitude=lon, altitude=alt,
                       position_covariance=cov, position_covariance_type=kind,
                       heading=heading if heading is not None and math.isfinite(heading) else None)


def _inline(node: Any, defs: Mapping[str, Any], within: frozenset[str] = frozenset()) -> Any:
    """``node`` with every ``{"$ref": "#/$defs/X"}`` replaced by ``defs[X]`` (inlined); a
    reference to a definition it is already inside (a recursive type, e.g. a channel's
    ``by_source`` summaries) becomes ``{"type": "object"}``, one level down."""
    if isinstance(node, dict):
        ref = node.get("$ref")
        if isinstance(ref, str) and ref.startswith("#/$defs/"):
            name = ref.rsplit("/", 1)[1]
            if name in within:
                return {"type": "object"}
            return _inline(defs[name], defs, within | {name})
        return {k: _inline(x, defs, within) for k, x in node.items() if k != "$defs"}
    if isinstance(node, list):
        return [_inline(x, defs, within) for x in node]
    return node


def _one_type(node: Any) -> Any:
    """``node`` with each nullable field (``anyOf`` a type and ``null``) of its one type,
    described as null where unknown, each enumeration of strings typed ``string``, and
    each map (an object with no properties of its own) given an empty ``properties``."""
    if isinstance(node, list):
        return [_one_type(x) for x in node]
    if not isinstance(node, dict):
        return node
    alts = node.get("anyOf")
    if isinstance(alts, list) and len(alts) == 2 and {"type": "null"} in alts:
        (kept,) = [a for a in alts if a != {"type": "null"}]
        node = {k: v for k, v in node.items() if k != "anyOf"} | kept
        node.setdefault("description", "null where unknown")
    values = node.get("enum")
    if isinstance(values, list) and "type" not in node and all(isinstance(v, str) for v in values):
        node = {**node, "type": "string"}
    if node.get("type") == "object" and "properties" not in node:
        node = {**node, "properties": {}}   # a map: its keys are the messages' own
    return {k: _one_type(v) for k, v in node.items()}


def json_schema(kind: type) -> dict[str, Any]:
    """The JSON schema of one of the records above as Foxglove's MCAP reader takes a
    ``jsonschema`` channel's (``parseJsonSchema`` of @foxglove/mcap-support, which
    Foxglove and Lichtblick run): draft 2020-12 with its references inlined (the root an
    object) and each field of exactly one type, which the reader needs (a nullable one
    described as null where unknown, not an ``anyOf``; an enumeration of strings a
    ``string``) and every object with its ``properties``, empty for a map (the reader
    walks them; a map's keys are then the messages' own)."""
    raw = msgspec.json.schema(kind)
    out = _one_type(_inline(raw, raw.get("$defs", {})))
    out.pop("$schema", None)
    return out


SCHEMAS: dict[str, type] = {ESTIMATE_SCHEMA: EstimateRecord, HEALTH_SCHEMA: HealthRecord,
                            LOCATION_FIX_SCHEMA: LocationFix}
"""Schema name -> the msgspec struct that is its single definition."""
