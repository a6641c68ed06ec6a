"""A water-current field in space and time for a fleet: a tidal channel, eddies, fronts.

Each part is a :class:`FieldPart` whose :meth:`~FieldPart.velocity` gives the horizontal
current ``(north, east)`` (m/s, toward, NED) at local positions ``north``, ``east`` (m, on
the tangent plane of the field's origin), ``depth`` (m, positive down) and ``utc``
(seconds since the Unix epoch). The arguments may be floats or numpy arrays (they
broadcast), so one formula serves the plants (one point per RK4 sub-step) and the truth
grid (every point at once). Parts add: :class:`SeaField` is their sum, evaluated at
``(lat_deg, lon_deg, depth_m, utc)`` (:meth:`SeaField.at`, geodesy by pymap3d through
:class:`onboard.sitl.frames.GeoOrigin`) or on a local position (:meth:`SeaField.local`).

The parts and their published forms:

* :class:`TidalChannel`: a rectilinear tidal stream along a channel, with the lateral
  (cross-channel) shear of plane Poiseuille flow ``U(y) = U_max (1 - (2 y / W)^2)``
  (Batchelor 1967, An Introduction to Fluid Dynamics, eq. 4.2.4) and the vertical profile
  of a tidal stream over a rough bed, Soulsby's one-seventh power law (Soulsby 1997,
  Dynamics of Marine Sands, eq. 40): ``u(z) = (z / (0.32 h))^(1/7) U`` for ``z < h/2`` and
  ``1.07 U`` above, ``z`` the height above the bed, ``h`` the water depth, ``U`` the
  depth-averaged speed; in time ``cos(2 pi (utc - t_ref) / T + phase)`` with ``T`` the M2
  period (12.42 h) or a compressed one for a demonstration. It varies only across the
  channel, so it is divergence-free.
* :class:`LambOseenEddy`: the Lamb-Oseen vortex (Oseen 1912; Lamb 1932, Hydrodynamics,
  art. 334a), azimuthal speed ``v(r) = Gamma / (2 pi r) (1 - exp(-r^2 / r_c^2))``, peak
  ``0.638 Gamma / (2 pi r_c)`` at ``r = 1.1209 r_c``, solid-body rotation near the centre
  and the potential vortex far away; positive ``Gamma`` turns counter-clockwise seen from
  above (cyclonic in the northern hemisphere). Its centre drifts at a constant velocity.
  Divergence-free.
* :class:`TanhFront`: a jump between two currents across a straight line moving along
  its normal, the hyperbolic-tangent shear layer of Michalke 1964 (J. Fluid Mech. 19,
  543-556): ``V = V_a + (V_b - V_a) (1 + tanh(s / L)) / 2`` with ``s`` the signed distance
  to the line (m, positive on the ``b`` side) and ``L`` the half-width. A jump in the
  along-front component is a shear front (divergence-free); a jump in the normal
  component makes it convergent, divergence ``(V_b - V_a) . n sech^2(s / L) / (2 L)``.
* :class:`UniformFlow`: a constant background current.
* :class:`BickleyJet`: the Bickley jet with three travelling waves, the flow of
  del-Castillo-Negrete and Morrison 1993 (Phys. Fluids A 5, 948-965) in the form and
  with the parameters of Rypina et al. 2007 (J. Atmos. Sci. 64, 3595-3610, eqs. 1-2):
  stream function ``psi = -U0 L tanh(y/L) + U0 L sech^2(y/L) sum_n eps_n cos(k_n (x -
  c_n t))``, ``u = -dpsi/dy``, ``v = dpsi/dx`` (``x`` along the jet, ``y`` across it),
  its shape kept and its size scaled (:meth:`BickleyJet.coastal`). Not used by the
  named fleets' seas: a flow whose formula is not ours, to test the fleet's field on.

Nothing here is shared with the estimators.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from onboard.sitl.environment import TIDAL_M2_PERIOD_S, CurrentField
from onboard.sitl.frames import WGS84, GeoOrigin

__all__ = [
    "FieldPart",
    "UniformFlow",
    "TidalChannel",
    "LambOseenEddy",
    "TanhFront",
    "BickleyJet",
    "SeaField",
    "VehicleCurrent",
    "LAMB_OSEEN_PEAK_RADIUS",
    "LAMB_OSEEN_PEAK_FACTOR",
]

SOULSBY_ROUGHNESS_SCALE = 0.32
"""``0.32 h``: the height scale of Soulsby's power law (Soulsby 1997, eq. 40)."""
SOULSBY_UPPER_FACTOR = 1.07
"""Speed over the upper half of the water column, as a multiple of the depth average."""
SEVENTH = 1.0 / 7.0
LAMB_OSEEN_PEAK_RADIUS = 1.1209
"""Radius of the Lamb-Oseen vortex's fastest ring, in core radii (root of
``1 + 2 x^2 = exp(x^2)``)."""
LAMB_OSEEN_PEAK_FACTOR = 0.6382
"""Its peak speed in units of ``Gamma / (2 pi r_c)``."""

Num = Any
"""A float or a numpy array (the formulas broadcast)."""


class FieldPart:
    """One part of a current field: :meth:`velocity` at local positions and times."""

    def velocity(self, north: Num, east: Num, depth: Num, utc: Num) -> tuple[Num, Num]:
        """``(north, east)`` current (m/s) at ``north``, ``east`` (m), ``depth`` (m) and
        ``utc`` (s since the Unix epoch)."""
        raise NotImplementedError

    def velocity_point(self, north: float, east: float, depth: float,
                       utc: float) -> tuple[float, float]:
        """:meth:`velocity` at one point, in plain floats: the plants call it at every
        RK4 sub-step, where numpy's per-call overhead doubled a boat's simulation time
        (docs/sitl.md "A fleet in a current field"); the parts below write it out with
        :mod:`math`, and tests/test_current_field.py checks it against :meth:`velocity`."""
        vn, ve = self.velocity(north, east, depth, utc)
        return float(vn), float(ve)

    def describe(self) -> dict[str, Any]:
        """The part's kind and parameters (JSON-ready), for the truth file."""
        d = {k: v for k, v in self.__dict__.items()}
        return {"kind": type(self).__name__, **d}


@dataclass(frozen=True)
class UniformFlow(FieldPart):
    """A constant current (m/s)."""

    north: float = 0.0
    east: float = 0.0

    def velocity(self, north: Num, east: Num, depth: Num, utc: Num) -> tuple[Num, Num]:
        zero = 0.0 * (north + east + depth + utc)
        return zero + self.north, zero + self.east

    def velocity_point(self, north: float, east: float, depth: float,
                       utc: float) -> tuple[float, float]:
        return self.north, self.east


RYPINA_L_OVER_R0 = 1770.0 / 6371.0
"""Rypina et al. 2007's jet half-width over the radius ``r0`` that sets its wave numbers
(``L`` = 1770 km, ``r0`` = 6371 km)."""
RYPINA_EPS = (0.0075, 0.15, 0.3)
"""Their wave amplitudes ``eps_n``."""
RYPINA_C_OVER_U0 = (0.1446, 0.205, 0.461)
"""Their waves' phase speeds ``c_n / U0``."""


@dataclass(frozen=True)
class BickleyJet(FieldPart):
    """The Bickley jet with three waves (module docstring): a jet of peak speed ``u0``
    (m/s) and half-width ``half_width`` (m, ``L``) toward ``direction`` (rad, clockwise
    from north) through ``(north0, east0)`` (m), wave numbers ``k_n = 2 n / r0`` with
    ``r0 = L / RYPINA_L_OVER_R0``, amplitudes ``eps`` and phase speeds ``c_over_u0 *
    u0`` along the jet, ``t`` in s since ``t_ref`` (utc)."""

    u0: float = 0.3
    half_width: float = 120.0
    direction: float = 0.0
    north0: float = 0.0
    east0: float = 0.0
    t_ref: float = 0.0
    eps: tuple[float, float, float] = RYPINA_EPS
    c_over_u0: tuple[float, float, float] = RYPINA_C_OVER_U0

    @classmethod
    def coastal(cls, u0: float, half_width: float, **kw: Any) -> BickleyJet:
        """Rypina et al.'s jet (``U0`` = 62.66 m/s, ``L`` = 1770 km) scaled to a peak speed
        ``u0`` (m/s) and half-width ``half_width`` (m): the same shape (``L / r0``,
        ``eps_n``, ``c_n / U0``), so the same flow in units of ``L`` and ``L / U0``."""
        return cls(u0=u0, half_width=half_width, **kw)

    def velocity(self, north: Num, east: Num, depth: Num, utc: Num) -> tuple[Num, Num]:
        c, s = math.cos(self.direction), math.sin(self.direction)
        dn, de = north - self.north0, east - self.east0
        x = dn * c + de * s                     # along the jet
        y = -dn * s + de * c                    # across it, to its right
        t = utc - self.t_ref
        big_l, u0 = self.half_width, self.u0
        r0 = big_l / RYPINA_L_OVER_R0
        sech2 = 1.0 / np.cosh(y / big_l) ** 2
        wave, dwave = 0.0 * x, 0.0 * x
        for n, (eps, c_n) in enumerate(zip(self.eps, self.c_over_u0), start=1):
            k = 2.0 * n / r0
            phase = k * (x - c_n * u0 * t)
            wave = wave + eps * np.cos(phase)
            dwave = dwave - eps * k * np.sin(phase)
        u = u0 * sech2 + 2.0 * u0 * sech2 * np.tanh(y / big_l) * wave   # -dpsi/dy
        v = u0 * big_l * sech2 * dwave                                    # dpsi/dx
        # (x, y) to (north, east): y points to the jet's right, x along it
        return u * c - v * s, u * s + v * c


@dataclass(frozen=True)
class TidalChannel(FieldPart):
    """A tidal stream along a channel (see the module docstring for the formulas).

    ``direction`` (rad, clockwise from north): the flood direction along the channel axis,
    which passes through the local point ``(centre_north, centre_east)`` (m); ``width``
    (m): bank to bank, no flow outside; ``amplitude`` (m/s): the depth-averaged speed on
    the axis at full flood; ``mean`` (m/s): a residual along-channel flow (with the same
    lateral and vertical shape); ``period`` (s) and ``phase`` (rad) at ``t_ref`` (utc);
    ``water_depth`` (m): ``h`` of the vertical profile (None: depth-uniform).
    """

    amplitude: float = 0.4
    direction: float = 0.0
    width: float = 1000.0
    centre_north: float = 0.0
    centre_east: float = 0.0
    period: float = TIDAL_M2_PERIOD_S
    phase: float = 0.0
    t_ref: float = 0.0
    mean: float = 0.0
    water_depth: float | None = None

    def cross(self, north: Num, east: Num) -> Num:
        """Signed cross-channel distance (m) from the axis, positive to starboard of the
        flood direction."""
        c, s = math.cos(self.direction), math.sin(self.direction)
        return -(north - self.centre_north) * s + (east - self.centre_east) * c

    def lateral(self, north: Num, east: Num) -> Num:
        """The Poiseuille factor ``1 - (2 y / W)^2``, 0 outside the banks."""
        y = self.cross(north, east)
        return np.maximum(0.0, 1.0 - (2.0 * y / self.width) ** 2)

    def vertical(self, depth: Num) -> Num:
        """Soulsby's factor: the speed at ``depth`` over the depth average (1 without
        ``water_depth``)."""
        if self.water_depth is None:
            return 1.0 + 0.0 * depth
        h = self.water_depth
        z = np.clip(h - depth, 1e-3 * h, h)  # height above the bed
        low = (z / (SOULSBY_ROUGHNESS_SCALE * h)) ** SEVENTH
        return np.where(z < 0.5 * h, low, SOULSBY_UPPER_FACTOR)

    def tide(self, utc: Num) -> Num:
        """``mean + amplitude cos(2 pi (utc - t_ref) / period + phase)`` (m/s)."""
        return self.mean + self.amplitude * np.cos(
            2.0 * math.pi * (utc - self.t_ref) / self.period + self.phase)

    def velocity(self, north: Num, east: Num, depth: Num, utc: Num) -> tuple[Num, Num]:
        speed = self.tide(utc) * self.lateral(north, east) * self.vertical(depth)
        return speed * math.cos(self.direction), speed * math.sin(self.direction)

    def velocity_point(self, north: float, east: float, depth: float,
                       utc: float) -> tuple[float, float]:
        c, s = math.cos(self.direction), math.sin(self.direction)
        y = -(north - self.centre_north) * s + (east - self.centre_east) * c
        lateral = max(0.0, 1.0 - (2.0 * y / self.width) ** 2)
        vertical = 1.0
        if self.water_depth is not None:
            h = self.water_depth
            z = min(max(h - depth, 1e-3 * h), h)
            vertical = ((z / (SOULSBY_ROUGHNESS_SCALE * h)) ** SEVENTH if z < 0.5 * h
                        else SOULSBY_UPPER_FACTOR)
        tide = self.mean + self.amplitude * math.cos(
            2.0 * math.pi * (utc - self.t_ref) / self.period + self.phase)
        speed = tide * lateral * vertical
        return speed * c, speed * s


@dataclass(frozen=True)
class LambOseenEddy(FieldPart):
    """A Lamb-Oseen vortex of circulation ``circulation`` (m^2/s, positive
    counter-clockwise seen from above) and core radius ``core_radius`` (m), centred at
    ``(north0, east0)`` (m) at ``t_ref`` (utc) and drifting at ``(drift_north,
    drift_east)`` (m/s)."""

    circulation: float = 150.0
    core_radius: float = 100.0
    north0: float = 0.0
    east0: float = 0.0
    t_ref: float = 0.0
    drift_north: float = 0.0
    drift_east: float = 0.0

    @classmethod
    def with_peak(cls, peak_speed: float, core_radius: float, **kw: Any) -> LambOseenEddy:
        """The eddy whose fastest ring (at 1.1209 core radii) turns at ``peak_speed``
        (m/s; negative: clockwise)."""
        gamma = peak_speed * 2.0 * math.pi * core_radius / LAMB_OSEEN_PEAK_FACTOR
        return cls(circulation=gamma, core_radius=core_radius, **kw)

    def centre(self, utc: Num) -> tuple[Num, Num]:
        """The centre (m) at ``utc``."""
        dt = utc - self.t_ref
        return self.north0 + self.drift_north * dt, self.east0 + self.drift_east * dt

    def azimuthal(self, r: Num) -> Num:
        """``v(r) = Gamma / (2 pi r) (1 - exp(-r^2 / r_c^2))`` (m/s), 0 at the centre."""
        r = np.asarray(r, dtype=float)
        r2 = r * r
        return self.circulation / (2.0 * math.pi) * _one_minus_exp_over(r2, self.core_radius) * r

    def velocity(self, north: Num, east: Num, depth: Num, utc: Num) -> tuple[Num, Num]:
        cn, ce = self.centre(utc)
        dn, de = north - cn, east - ce
        # v(r) / r: the velocity is (v/r) times the radius vector turned 90 deg
        k = self.circulation / (2.0 * math.pi) * _one_minus_exp_over(dn * dn + de * de,
                                                                    self.core_radius)
        # counter-clockwise seen from above, in (north, east): (dn, de) -> (de, -dn)
        return k * de, -k * dn

    def velocity_point(self, north: float, east: float, depth: float,
                       utc: float) -> tuple[float, float]:
        dt = utc - self.t_ref
        dn = north - (self.north0 + self.drift_north * dt)
        de = east - (self.east0 + self.drift_east * dt)
        r2 = dn * dn + de * de
        rc2 = self.core_radius * self.core_radius
        x = r2 / rc2
        f = 1.0 / rc2 if x < 1e-8 else -math.expm1(-x) / r2
        k = self.circulation / (2.0 * math.pi) * f
        return k * de, -k * dn


def _one_minus_exp_over(r2: Num, rc: float) -> Num:
    """``(1 - exp(-r2 / rc^2)) / r2``, ``1 / rc^2`` at ``r2 = 0`` (its limit)."""
    r2 = np.asarray(r2, dtype=float)
    x = r2 / (rc * rc)
    small = x < 1e-8
    safe = np.where(small, 1.0, r2)
    return np.where(small, 1.0 / (rc * rc), -np.expm1(-x) / safe)


@dataclass(frozen=True)
class TanhFront(FieldPart):
    """A front: the current is ``(a_north, a_east)`` on one side and ``(b_north, b_east)``
    on the other (m/s), with a tanh transition of half-width ``half_width`` (m) across a
    straight line through ``(north0, east0)`` (m) at ``t_ref``, whose normal points
    toward ``normal`` (rad, clockwise from north; the ``b`` side) and which moves along
    it at ``speed`` (m/s)."""

    a_north: float = 0.0
    a_east: float = 0.0
    b_north: float = 0.0
    b_east: float = 0.2
    normal: float = 0.0
    half_width: float = 20.0
    north0: float = 0.0
    east0: float = 0.0
    t_ref: float = 0.0
    speed: float = 0.0

    def distance(self, north: Num, east: Num, utc: Num) -> Num:
        """Signed distance (m) from the front line at ``utc``, positive on the ``b`` side."""
        s = ((north - self.north0) * math.cos(self.normal)
             + (east - self.east0) * math.sin(self.normal))
        return s - self.speed * (utc - self.t_ref)

    def share(self, north: Num, east: Num, utc: Num) -> Num:
        """``(1 + tanh(s / L)) / 2``: 0 deep on the ``a`` side, 1 on the ``b`` side."""
        return 0.5 * (1.0 + np.tanh(self.distance(north, east, utc) / self.half_width))

    def velocity(self, north: Num, east: Num, depth: Num, utc: Num) -> tuple[Num, Num]:
        w = self.share(north, east, utc) + 0.0 * depth
        return (self.a_north + (self.b_north - self.a_north) * w,
                self.a_east + (self.b_east - self.a_east) * w)

    def velocity_point(self, north: float, east: float, depth: float,
                       utc: float) -> tuple[float, float]:
        d = ((north - self.north0) * math.cos(self.normal)
             + (east - self.east0) * math.sin(self.normal) - self.speed * (utc - self.t_ref))
        w = 0.5 * (1.0 + math.tanh(d / self.half_width))
        return (self.a_north + (self.b_north - self.a_north) * w,
                self.a_east + (self.b_east - self.a_east) * w)


@dataclass(frozen=True)
class SeaField:
    """A current field: the sum of ``parts`` on the tangent plane at ``origin`` (lat,
    lon in degrees)."""

    origin: tuple[float, float]
    parts: tuple[FieldPart, ...] = ()
    geo: GeoOrigin = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "geo", GeoOrigin(*self.origin))

    def local(self, north: Num, east: Num, depth: Num, utc: Num) -> tuple[Num, Num]:
        """``(north, east)`` current (m/s) at local positions (m) and times (s, utc)."""
        vn: Num = 0.0
        ve: Num = 0.0
        for p in self.parts:
            a, b = p.velocity(north, east, depth, utc)
            vn = vn + a
            ve = ve + b
        return vn, ve

    def local_point(self, north: float, east: float, depth: float,
                    utc: float) -> tuple[float, float]:
        """:meth:`local` at one point in plain floats (:meth:`FieldPart.velocity_point`)."""
        vn = ve = 0.0
        for p in self.parts:
            a, b = p.velocity_point(north, east, depth, utc)
            vn += a
            ve += b
        return vn, ve

    def to_local(self, lat_deg: Num, lon_deg: Num) -> tuple[np.ndarray, np.ndarray]:
        """Local ``(north, east)`` (m) of geodetic points (pymap3d, WGS-84)."""
        import pymap3d

        e, n, _ = pymap3d.geodetic2enu(np.asarray(lat_deg, dtype=float),
                                       np.asarray(lon_deg, dtype=float), 0.0,
                                       self.origin[0], self.origin[1], 0.0,
                                       ell=WGS84)
        return np.asarray(n), np.asarray(e)

    def at(self, lat_deg: Num, lon_deg: Num, depth_m: Num, utc: Num) -> tuple[Num, Num]:
        """``(north, east)`` current (m/s) at latitude, longitude (deg), depth (m) and
        ``utc`` (s since the Unix epoch)."""
        n, e = self.to_local(lat_deg, lon_deg)
        return self.local(n, e, np.asarray(depth_m, dtype=float), np.asarray(utc, dtype=float))

    def describe(self) -> list[dict[str, Any]]:
        """The parts with their parameters (JSON-ready)."""
        return [p.describe() for p in self.parts]

    @classmethod
    def from_description(cls, origin: Sequence[float],
                         parts: Sequence[dict[str, Any]]) -> SeaField:
        """The field :meth:`describe` described (``fleet.json``'s ``field``)."""
        kinds = {k.__name__: k for k in (UniformFlow, TidalChannel, LambOseenEddy, TanhFront,
                                         BickleyJet)}
        built = []
        for d in parts:
            params = {k: v for k, v in d.items() if k != "kind"}
            built.append(kinds[d["kind"]](**params))
        return cls((float(origin[0]), float(origin[1])), tuple(built))

    def grid(self, lat_deg: Sequence[float], lon_deg: Sequence[float],
             depth_m: Sequence[float], utc: Sequence[float]) -> dict[str, Any]:
        """The field on a grid: ``north``/``east`` (m/s) indexed ``[utc][depth][lat][lon]``
        as nested lists, beside the axes (docs/sitl.md "The fleet's truth")."""
        lat = np.asarray(lat_deg, dtype=float)
        lon = np.asarray(lon_deg, dtype=float)
        la, lo = np.meshgrid(lat, lon, indexing="ij")
        n, e = self.to_local(la, lo)
        t4 = np.asarray(utc, dtype=float)[:, None, None, None]
        d4 = np.asarray(depth_m, dtype=float)[None, :, None, None]
        vn, ve = self.local(n[None, None], e[None, None], d4, t4)
        shape = (len(utc), len(depth_m), len(lat), len(lon))
        return {"lat_deg": lat.tolist(), "lon_deg": lon.tolist(),
                "depth_m": [float(d) for d in depth_m], "utc": [float(t) for t in utc],
                "north": np.round(np.broadcast_to(vn, shape), 6).tolist(),
                "east": np.round(np.broadcast_to(ve, shape), 6).tolist()}


@dataclass(frozen=True)
class VehicleCurrent(CurrentField):
    """The field as one vehicle's plant sees it (:class:`sitl.environment.CurrentField`):
    the plant's position ``p`` (m, NED about the vehicle's own origin) is the field's
    local ``(offset_north + p_N, offset_east + p_E)`` at depth ``p_D``, and the plant's
    time ``t`` (s since the vehicle's start) is ``utc0 + t``. No vertical current."""

    sea: SeaField
    offset_north: float = 0.0
    offset_east: float = 0.0
    utc0: float = 0.0

    def velocity_ned(self, t: float, position_ned: np.ndarray) -> np.ndarray:
        vn, ve = self.sea.local_point(self.offset_north + float(position_ned[0]),
                                      self.offset_east + float(position_ned[1]),
                                      float(position_ned[2]), self.utc0 + t)
        return np.array([vn, ve, 0.0])
