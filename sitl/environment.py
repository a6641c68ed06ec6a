"""The simulated sea: water currents and first-order wave-induced motion.

Everything is in the NED earth frame, SI units, angles in rad. A current *direction* is
the direction the water flows **toward**, clockwise from north (oceanographic
convention); a wave direction is the direction the waves travel toward.

Currents enter the plants through the flow-relative velocity
``nu_r = nu - [R^T V_c; 0]`` (Fossen 2021, section 10.3). Each plant integrates ``nu_r``
and the position with ``p' = R nu_r[0:3] + V_c(t, p)``.

Waves: first-order (linear, wave-frequency) motion is an oscillatory displacement
superposed on the low-frequency (manoeuvring) motion that the plant integrates (the usual
separation of Fossen 2021, section 10.2: total motion = low-frequency + wave-frequency).
A small vehicle compared with the wavelength rides the water particles: its
wave-frequency displacement is the Airy particle displacement at its mean position,
and its roll and pitch follow the local surface slope. Both decay with depth as
``exp(-k d)``. The plants add :meth:`WaveField.motion` to their truth and to the ideal
IMU quantities; the low-frequency state itself is not disturbed, so the waves add no
drift. Second-order drift forces are not modelled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from onboard.sitl.frames import GeoOrigin
from onboard.sitl.integrate import GRAVITY

__all__ = [
    "TIDAL_M2_PERIOD_S",
    "CurrentField",
    "UniformCurrent",
    "NonuniformCurrent",
    "TidalCurrent",
    "CombinedCurrent",
    "WaveMotion",
    "WaveField",
    "Environment",
]

TIDAL_M2_PERIOD_S = 12.4206012 * 3600.0
"""Period of the principal lunar semidiurnal tide M2 (s), 12.42 h."""


class CurrentField:
    """A water-current field ``V_c(t, p)`` in NED (m/s).

    Subclasses implement :meth:`velocity_ned`. Fields add: ``UniformCurrent(...) +
    TidalCurrent(...)`` is a :class:`CombinedCurrent`.
    """

    def velocity_ned(self, t: float, position_ned: np.ndarray) -> np.ndarray:
        """Water velocity (m/s, NED) at time ``t`` (s) and position ``position_ned`` (m)."""
        raise NotImplementedError

    def __call__(self, t: float, position_ned: np.ndarray) -> np.ndarray:
        return self.velocity_ned(t, position_ned)

    def __add__(self, other: CurrentField) -> CombinedCurrent:
        return CombinedCurrent(self, other)


@dataclass(frozen=True)
class UniformCurrent(CurrentField):
    """A steady, uniform current (m/s, NED components)."""

    north: float = 0.0
    east: float = 0.0
    down: float = 0.0

    def velocity_ned(self, t: float, position_ned: np.ndarray) -> np.ndarray:
        return np.array([self.north, self.east, self.down])


@dataclass(frozen=True)
class NonuniformCurrent(CurrentField):
    """The steady nonuniform flow of Fan et al. (algorithms.md section 4.1):

        V_f(X) = [0, -a sqrt((L + xi) / L), 0] m/s,   xi = north position (m)

    with ``a = amplitude = 0.3`` m/s and ``L = length = 500`` m. The flow runs toward the
    west, faster further north; for ``xi < -L`` (outside the paper's domain) it is 0.
    Its gradient ``dV_east/dxi = -a / (2 L sqrt((L + xi)/L))`` is ~3e-4 1/s at xi = 0.
    """

    amplitude: float = 0.3
    length: float = 500.0

    def velocity_ned(self, t: float, position_ned: np.ndarray) -> np.ndarray:
        xi = float(position_ned[0])
        s = max(0.0, (self.length + xi) / self.length)
        return np.array([0.0, -self.amplitude * math.sqrt(s), 0.0])


@dataclass(frozen=True)
class TidalCurrent(CurrentField):
    """A rectilinear tidal stream (m/s):

        speed(t) = mean + amplitude * cos(2 pi t / period + phase)
        V_c(t)   = speed(t) * [cos(direction), sin(direction), 0]

    ``direction`` (rad, clockwise from north) is the flood direction; a negative speed
    is the ebb. ``period`` defaults to the M2 tide, 12.42 h; use a short period (e.g.
    600 s) to see a full cycle in a short scenario.
    """

    amplitude: float = 0.2
    direction: float = 0.0
    period: float = TIDAL_M2_PERIOD_S
    phase: float = 0.0
    mean: float = 0.0

    def speed(self, t: float) -> float:
        """Signed speed along ``direction`` (m/s) at time ``t`` (s)."""
        return self.mean + self.amplitude * math.cos(2.0 * math.pi * t / self.period + self.phase)

    def velocity_ned(self, t: float, position_ned: np.ndarray) -> np.ndarray:
        s = self.speed(t)
        return np.array([s * math.cos(self.direction), s * math.sin(self.direction), 0.0])


class CombinedCurrent(CurrentField):
    """The sum of several current fields (e.g. a tidal stream plus a river outflow)."""

    def __init__(self, *fields: CurrentField) -> None:
        flat: list[CurrentField] = []
        for f in fields:
            flat.extend(f.fields if isinstance(f, CombinedCurrent) else [f])
        self.fields: tuple[CurrentField, ...] = tuple(flat)

    def velocity_ned(self, t: float, position_ned: np.ndarray) -> np.ndarray:
        v = np.zeros(3)
        for f in self.fields:
            v = v + f.velocity_ned(t, position_ned)
        return v

    def __repr__(self) -> str:
        return f"CombinedCurrent{self.fields!r}"


@dataclass(frozen=True)
class WaveMotion:
    """First-order wave-induced motion of a vehicle at one instant.

    ``displacement``, ``velocity``, ``acceleration``: NED (m, m/s, m/s^2), the total time
    derivatives along the vehicle's low-frequency path (so they include the encounter
    frequency). ``roll``, ``pitch`` (rad) and ``p``, ``q`` (rad/s): small-angle
    wave-following attitude and its rate, to be added to the low-frequency attitude.
    """

    displacement: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    roll: float = 0.0
    pitch: float = 0.0
    p: float = 0.0
    q: float = 0.0

    @staticmethod
    def zero() -> WaveMotion:
        """No wave motion."""
        z = np.zeros(3)
        return WaveMotion(z, z, z)


class WaveField:
    """Long-crested or short-crested linear (Airy) deep-water waves: a sum of sinusoids.

    Component i has amplitude ``a_i`` (m), angular frequency ``w_i`` (rad/s), wave number
    ``k_i = w_i^2 / g`` (deep water), travel direction ``beta_i`` (rad) and phase ``eps_i``.
    With ``chi_i = k_i (N cos beta_i + E sin beta_i) - w_i t + eps_i``, the surface
    elevation (up) is ``zeta = sum a_i cos chi_i`` and the particle displacement at depth d

        xi_N = -sum a_i e^{-k_i d} sin chi_i cos beta_i
        xi_E = -sum a_i e^{-k_i d} sin chi_i sin beta_i
        xi_D = -sum a_i e^{-k_i d} cos chi_i

    (circular orbits, radius a_i e^{-k_i d}). Velocity and acceleration are the time
    derivatives along the vehicle's path, ``chi_i' = k_i . V_h - w_i``. Wave-following
    attitude: pitch = slope along the body x axis, roll = minus slope along body y.

    Build with :meth:`regular` (one sinusoid) or :meth:`from_spectrum` (JONSWAP,
    significant height ``hs`` and peak period ``tp``, random phases from ``seed``).
    """

    def __init__(
        self,
        amplitudes: np.ndarray,
        omegas: np.ndarray,
        directions: np.ndarray,
        phases: np.ndarray,
        gravity: float = GRAVITY,
    ) -> None:
        self.amplitudes = np.asarray(amplitudes, dtype=float)
        self.omegas = np.asarray(omegas, dtype=float)
        self.directions = np.asarray(directions, dtype=float)
        self.phases = np.asarray(phases, dtype=float)
        self.wavenumbers = self.omegas**2 / gravity
        self._kn = self.wavenumbers * np.cos(self.directions)
        self._ke = self.wavenumbers * np.sin(self.directions)

    @classmethod
    def regular(
        cls, height: float, period: float, direction: float = 0.0, phase: float = 0.0
    ) -> WaveField:
        """One regular wave of crest-to-trough ``height`` (m) and ``period`` (s)."""
        return cls(
            np.array([height / 2.0]),
            np.array([2.0 * math.pi / period]),
            np.array([direction]),
            np.array([phase]),
        )

    @classmethod
    def from_spectrum(
        cls,
        hs: float,
        tp: float,
        direction: float = 0.0,
        *,
        n_components: int = 24,
        spreading: float = 0.0,
        gamma: float = 3.3,
        seed: int = 0,
    ) -> WaveField:
        """Irregular sea with significant height ``hs`` (m) and peak period ``tp`` (s).

        JONSWAP shape ``S(w) ~ w^-5 exp(-1.25 (wp/w)^4) gamma^r`` (DNV-RP-C205 3.5.5),
        ``n_components`` frequencies between 0.6 wp and 3 wp, jittered by ``seed`` to avoid
        periodicity; amplitudes ``a_i = sqrt(2 S(w_i) dw)`` rescaled so that
        ``4 sqrt(sum a_i^2 / 2) = hs`` exactly. ``spreading`` (rad) is the standard
        deviation of a normal spread of component directions around ``direction``
        (0 = long-crested). Deterministic for a given ``seed``.
        """
        rng = np.random.default_rng(seed)
        wp = 2.0 * math.pi / tp
        edges = np.linspace(0.6 * wp, 3.0 * wp, n_components + 1)
        dw = np.diff(edges)
        w = edges[:-1] + dw * rng.uniform(0.2, 0.8, n_components)
        sigma = np.where(w <= wp, 0.07, 0.09)
        r = np.exp(-((w - wp) ** 2) / (2.0 * sigma**2 * wp**2))
        s = w**-5.0 * np.exp(-1.25 * (wp / w) ** 4) * gamma**r
        a = np.sqrt(2.0 * s * dw)
        a *= (hs / 4.0) / math.sqrt(float(np.sum(a**2)) / 2.0)
        dirs = direction + spreading * rng.standard_normal(n_components)
        phases = rng.uniform(0.0, 2.0 * math.pi, n_components)
        return cls(a, w, dirs, phases)

    @property
    def significant_height(self) -> float:
        """4 sqrt(m0) (m), from the component variances."""
        return 4.0 * math.sqrt(float(np.sum(self.amplitudes**2)) / 2.0)

    def elevation(self, t: float, north: float, east: float) -> float:
        """Surface elevation (m, positive up) at time ``t`` and horizontal position."""
        chi = self._kn * north + self._ke * east - self.omegas * t + self.phases
        return float(np.sum(self.amplitudes * np.cos(chi)))

    def motion(
        self,
        t: float,
        position_ned: np.ndarray,
        velocity_ned: np.ndarray | None = None,
        yaw: float = 0.0,
    ) -> WaveMotion:
        """First-order motion of a body whose low-frequency position is ``position_ned``
        (m) moving at ``velocity_ned`` (m/s, for the encounter frequency) with heading
        ``yaw`` (rad). Depth ``d = max(position_ned[2], 0)`` attenuates as ``exp(-k d)``.
        """
        n, e, d = float(position_ned[0]), float(position_ned[1]), float(position_ned[2])
        vn, ve = (0.0, 0.0) if velocity_ned is None else (velocity_ned[0], velocity_ned[1])
        chi = self._kn * n + self._ke * e - self.omegas * t + self.phases
        chidot = self._kn * vn + self._ke * ve - self.omegas
        amp = self.amplitudes * np.exp(-self.wavenumbers * max(d, 0.0))
        s, c = np.sin(chi), np.cos(chi)
        cb, sb = np.cos(self.directions), np.sin(self.directions)
        h = -amp * s  # horizontal displacement along beta
        hd = -amp * c * chidot
        hdd = amp * s * chidot**2
        disp = np.array([np.sum(h * cb), np.sum(h * sb), -np.sum(amp * c)])
        vel = np.array([np.sum(hd * cb), np.sum(hd * sb), np.sum(amp * s * chidot)])
        acc = np.array([np.sum(hdd * cb), np.sum(hdd * sb), np.sum(amp * c * chidot**2)])
        # slope of the (attenuated) surface: grad zeta = -sum a k (cb, sb) sin chi
        g = -amp * self.wavenumbers * s
        gd = -amp * self.wavenumbers * c * chidot
        cy, sy = math.cos(yaw), math.sin(yaw)
        proj_x = cb * cy + sb * sy  # beta direction . body x
        proj_y = -cb * sy + sb * cy  # beta direction . body y
        pitch = float(np.sum(g * proj_x))
        roll = -float(np.sum(g * proj_y))
        q = float(np.sum(gd * proj_x))
        p = -float(np.sum(gd * proj_y))
        return WaveMotion(disp, vel, acc, roll=roll, pitch=pitch, p=p, q=q)


@dataclass
class Environment:
    """The sea a plant moves in: a current field, optional waves, constants, geo origin.

    ``current_ned(t, p)`` is the water velocity (m/s, NED); :meth:`current_rate_ned` its
    material derivative along a moving point. ``origin_lat_deg``/``origin_lon_deg``, when
    set, let plants report latitude/longitude (:class:`onboard.sitl.frames.GeoOrigin`:
    pymap3d on the WGS-84 tangent plane at the origin).
    """

    current: CurrentField = field(default_factory=UniformCurrent)
    waves: WaveField | None = None
    rho: float = 1025.0
    gravity: float = GRAVITY
    origin_lat_deg: float | None = None
    origin_lon_deg: float | None = None

    def current_ned(self, t: float, position_ned: np.ndarray) -> np.ndarray:
        """Water current (m/s, NED) at time ``t`` (s) and position ``position_ned`` (m)."""
        return self.current.velocity_ned(t, position_ned)

    def current_rate_ned(
        self,
        t: float,
        position_ned: np.ndarray,
        velocity_ned: np.ndarray | None = None,
        h: float = 0.05,
    ) -> np.ndarray:
        """dV_c/dt along a point moving at ``velocity_ned`` (m/s^2, NED):
        ``dV_c/dt = dV_c/dt|_p + (grad V_c) v``, by a central difference of step ``h`` (s).
        """
        p = np.asarray(position_ned, dtype=float)
        v = np.zeros(3) if velocity_ned is None else np.asarray(velocity_ned, dtype=float)
        vp = self.current.velocity_ned(t + h, p + h * v)
        vm = self.current.velocity_ned(t - h, p - h * v)
        return (vp - vm) / (2.0 * h)

    def wave_motion(
        self,
        t: float,
        position_ned: np.ndarray,
        velocity_ned: np.ndarray | None = None,
        yaw: float = 0.0,
    ) -> WaveMotion:
        """First-order wave motion at the vehicle (zero without waves); see :class:`WaveField`."""
        if self.waves is None:
            return WaveMotion.zero()
        return self.waves.motion(t, position_ned, velocity_ned, yaw)

    def latlon(self, north: float, east: float) -> tuple[float, float] | None:
        """(lat_deg, lon_deg) of a local NED position, or None without a geo origin."""
        if self.origin_lat_deg is None or self.origin_lon_deg is None:
            return None
        return GeoOrigin(self.origin_lat_deg, self.origin_lon_deg).to_latlon(north, east)
