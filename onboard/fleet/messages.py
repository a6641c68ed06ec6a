"""What ``onboard fleet`` answers and publishes (architecture.md §4.4).

=================================  =========================================  ==============
key                                encoding                                   payload
=================================  =========================================  ==============
``<prefix>/fleet/current``         ``application/json;onboard.FleetCurrent.v1``  :class:`FleetCurrent` (a query's reply)
``<prefix>/fleet/current/grid``    ``application/json;onboard.FleetGrid.v1``     :class:`FleetGrid`, every few seconds
=================================  =========================================  ==============

A query of ``<prefix>/fleet/current?lat=<deg>;lon=<deg>;utc=<s>`` (or with ``&`` between
the parameters) gets ONE
:class:`FleetCurrent` (exactly its eight fields; the grid's cells add the down); one
with a missing or bad parameter gets an error reply (a JSON object ``{"error": ...}``
saying which parameter and why).

A current's set and drift, as NMEA VDR and Signal K's ``environment.current`` carry them,
come from :func:`onboard.service.publishers.set_drift.set_drift`.
"""

from __future__ import annotations

import msgspec

FLEET_CURRENT_SCHEMA = "onboard.FleetCurrent.v1"
"""Schema name of a :class:`FleetCurrent`."""
FLEET_GRID_SCHEMA = "onboard.FleetGrid.v1"
"""Schema name of a :class:`FleetGrid`."""
GRID_SCHEMA_VERSION = 1
"""The ``schema`` field of a :class:`FleetGrid`."""


def current_key(prefix: str) -> str:
    """``<prefix>/fleet/current``: the field's queryable."""
    return f"{prefix}/fleet/current"


def grid_key(prefix: str) -> str:
    """``<prefix>/fleet/current/grid``: the field on a grid."""
    return f"{prefix}/fleet/current/grid"


class FleetCurrent(msgspec.Struct, frozen=True, kw_only=True):
    """The reply to a query, exactly these fields: ``lat``, ``lon`` (deg), ``utc`` (POSIX
    s), the current ``north``, ``east`` (m/s, the direction the water flows toward; null
    where the field knows nothing there), their one-sigma ``std_north``, ``std_east``
    (m/s; null there too) and ``n_obs``, the super-observations the answer rests on (0:
    none)."""

    lat: float
    lon: float
    utc: float
    north: float | None
    east: float | None
    std_north: float | None
    std_east: float | None
    n_obs: int


class FleetCell(FleetCurrent, frozen=True, kw_only=True):
    """A cell of the grid: a :class:`FleetCurrent` and the vertical current ``down``
    (m/s, positive down) with its one-sigma ``std_down``, null where no vehicle that
    gives one (an underwater vehicle) was near."""

    down: float | None = None
    std_down: float | None = None

    def reply(self) -> FleetCurrent:
        """The query's reply at this place: the cell without its down."""
        return FleetCurrent(**{f: getattr(self, f) for f in FleetCurrent.__struct_fields__})


class VehicleCurrent(msgspec.Struct, frozen=True, kw_only=True):
    """A vehicle's newest current estimate as the fleet received it: ``vehicle`` id,
    ``utc`` (POSIX s), ``lat``, ``lon`` (deg), ``north``, ``east`` and their one-sigma,
    ``down`` and its one-sigma (m/s; null where the record had none: a boat has no
    down)."""

    vehicle: str
    utc: float | None
    lat: float | None
    lon: float | None
    north: float | None
    east: float | None
    std_north: float | None
    std_east: float | None
    down: float | None = None
    std_down: float | None = None


class FleetGrid(msgspec.Struct, frozen=True, kw_only=True):
    """The field on a grid at one time: ``schema`` (:data:`GRID_SCHEMA_VERSION`), ``utc``
    (POSIX s, the grid's time: the newest record's), ``spacing_m`` (the cells' size, m),
    ``cells`` (one :class:`FleetCell` per cell centre, row by row from the south-west)
    and ``vehicles`` (each vehicle's newest record, :class:`VehicleCurrent`)."""

    schema: int = GRID_SCHEMA_VERSION
    utc: float
    spacing_m: float
    cells: list[FleetCell]
    vehicles: list[VehicleCurrent]


class QueryError(msgspec.Struct, frozen=True):
    """The reply to a query with a bad parameter."""

    error: str
