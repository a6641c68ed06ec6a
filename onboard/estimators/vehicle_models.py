"""Vehicle models in regression form: through-water acceleration = phi^T theta per DOF.

Each degree of freedom ``i`` of the body-frame velocity through water ``nu_r`` obeys

    nu_r_i' = phi_i(nu_r, omega, attitude, inputs)^T theta_i            (algorithms.md §3.3)

where ``theta_i`` are the hydrodynamic coefficients divided by the DOF's mass term
(``(m - X_udot)`` for surge, ...). The equations are those of the Gavia 3-DOF model of
Kim, Fan & Bose (2018) eq. (3)-(5) for torpedo AUVs (roll, pitch and yaw motion fed in as
measured inputs) and a surge/sway(/yaw) manoeuvring model for surface boats.

No regressor is a constant (except the heave net-weight term, which is physics): a constant
would soak up the water current, which the current pipeline estimates as a separate,
slowly varying state. The current is thus never absorbed into the parameters. The
gravity/buoyancy terms are nearly constant when the attitude is (a steady propeller-torque
roll makes ``cos(theta)sin(phi)`` one): with an unknown net weight (mode (b)) they trade
against the current on a straight line until a turn separates them, within the net-weight
prior of the surge and sway terms (:data:`NET_WEIGHT_REGRESSORS`, docs/current.md).

Symbols: ``u, v, w`` (m/s) through-water velocity, ``p, q, r`` (rad/s) body rates,
``phi, theta`` (rad) roll and pitch, ``n`` normalized propulsion (propeller rpm divided by
``rpm_scale``, or throttle in [-1, 1]), ``dr, ds`` rudder and stern-plane angles (rad),
``left, right`` normalized thruster commands, ``T1..T6`` BlueROV2 thruster commands.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import NamedTuple

from mypy_extensions import mypyc_attr
import numpy as np

from onboard.core.vehicles import traits


@mypyc_attr(allow_interpreted_subclasses=True)
class ModelInputs:
    """Everything a regressor needs besides ``nu_r``; units in the module docstring.

    ``roll`` and ``pitch`` are ZYX Euler angles (rad, NED/FRD: pitch positive nose up, roll
    positive starboard side down), the signs of Kim et al. eq. (3)-(5) and of the SITL
    plants' restoring forces; the current pipeline sets them from its attitude samples.
    """

    __slots__ = ("p", "q", "r", "roll", "pitch", "n", "dr", "ds", "left", "right", "thrusters")

    def __init__(self) -> None:
        self.p = 0.0
        self.q = 0.0
        self.r = 0.0
        self.roll = 0.0
        self.pitch = 0.0
        self.n = 0.0
        self.dr = 0.0
        self.ds = 0.0
        self.left = 0.0
        self.right = 0.0
        self.thrusters: tuple[float, ...] = (0.0,) * 6


def _sq(x: float) -> float:
    """Signed square ``x |x|``."""
    return x * abs(x)


def _dot(a: Sequence[float], b: Sequence[float] | np.ndarray) -> float:
    """``a . b`` summed left to right in plain floats from 0 (``sum``'s order up to
    Python 3.11; an indexed loop, on which the compiled build adds unboxed floats)."""
    total = 0.0
    for i in range(min(len(a), len(b))):
        total += a[i] * b[i]
    return total


NET_WEIGHT_REGRESSORS = ("sin(theta)", "cos(theta)sin(phi)")
"""Regressors whose coefficient is the net weight ``W - B`` over the DOF's mass term
(Kim et al. eq. (3)-(4)) and nothing else: physics with a known scale, their prior is
``CurrentConfig.net_weight_std``. Not the heave term ``cos(theta)cos(phi)`` (eq. (5), the
ROV's heave): near level flight it is ~1, the heave equation's constant, whose coefficient
carries every steady vertical force a generic (mode (b)) model lacks, not only the net
weight (vertical thrust against a push or a tether, lift at a trim angle); a net-weight
prior on it makes the unidentified spheroid and BlueROV2 runs worse (docs/current.md,
"Net-weight prior")."""


TURN_LOSS_REGRESSORS = ("u|u|dr^2", "u|r|")
"""Surge regressors of the speed lost in turns (surface boats), coefficients ``<= 0``:

* ``u|u|dr^2``: rudder drag, ``X_dd u^2 delta^2 / (m - X_udot)`` (the drag of a rudder
  grows with the square of its angle), where the rudder angle is an
  input (``surface-rudder``);
* ``u|r|``: the hull's drag in a turn, ``X_ur u|r| / (m - X_udot)``: the first term of
  the drag's growth with the non-dimensional turn rate ``r L / U`` (a hull crabbing
  through a turn meets the water at a drift angle), for a skid-steered boat, whose turn
  leaves no rudder angle to regress on (``surface-twin``).

The skid-steered boat's surge row carries ``tau_astern`` too, the astern part of its
thrust regressor (``sum min(T, 0)`` over the thrusters' signed squares ``T``): a turn on
the spot runs one thruster astern, and a propeller's astern thrust is not its ahead
thrust reversed, so a single ``tau_u`` coefficient reads the difference as speed change.

Without them the centripetal term ``vr`` is the only speed loss in a turn, and the joint
filter's surge model error had to stand in for the rest (docs/current.md, "Surface boats:
the speed lost in turns")."""

DRAG_REGRESSORS = ("u|u|", "v|v|", "w|w|") + TURN_LOSS_REGRESSORS
"""Regressors whose coefficient is a drag over the DOF's mass term and cannot be
positive (quadratic damping, the turn losses): an identified positive value would make
the model's speed grow without bound (``v' = a v|v|`` with ``a > 0`` reaches infinity in
finite time). The joint filter projects their estimates onto ``<= 0``
(:meth:`.current_kf.CurrentKalmanFilter._project_drag`)."""


@mypyc_attr(allow_interpreted_subclasses=True)
class RegressionModel:
    """A per-DOF linear-in-parameters model.

    Attributes:
        kind: ``"torpedo"``, ``"surface-rudder"``, ``"surface-twin"`` or ``"rov"``.
        dofs: the state channels, in order (``"surge", "sway"[, "heave"]``).
        aux: channels identified but not part of the velocity state (``"yaw"``).
        terms: regressor names per channel.
        net_weight_terms: per channel, the terms among ``terms`` whose coefficient is the
            net weight over the DOF's mass term (:data:`NET_WEIGHT_REGRESSORS`).
        drag_terms: per velocity DOF, the indices in ``terms`` of its drag coefficients
            (:data:`DRAG_REGRESSORS`, never positive; surface boats only, empty otherwise).
    """

    KINDS = ("torpedo", "surface-rudder", "surface-twin", "rov")

    def __init__(self, kind: str) -> None:
        if kind not in self.KINDS:
            raise ValueError(f"unknown model kind {kind!r}")
        self.kind = kind
        if kind == "torpedo":
            self.dofs: tuple[str, ...] = ("surge", "sway", "heave")
            self.aux: tuple[str, ...] = ("yaw",)
            self.terms: dict[str, tuple[str, ...]] = {
                # Kim et al. (2018) eq. (3): X_uu, X_wq - m, X_qq + m x_g, X_vr + m,
                # X_rr + m x_g, -(W - B), X_n (all / (m - X_udot)).
                "surge": ("u|u|", "wq", "q^2", "vr", "r^2", "sin(theta)", "n|n|"),
                # eq. (4): Y_vv, Y_rr, Y_uv, Y_ur - m, Y_wp + m, Y_pq - m x_g, W - B, fin.
                "sway": ("v|v|", "r|r|", "uv", "ur", "wp", "pq", "cos(theta)sin(phi)",
                         "u|u|dr"),
                # eq. (5): Z_ww, Z_qq, Z_uw, Z_uq + m, Z_vp - m, Z_rp - m x_g, W - B, fin.
                "heave": ("w|w|", "q|q|", "uw", "uq", "vp", "rp", "cos(theta)cos(phi)",
                          "u|u|ds"),
                # yaw (for the flow observer): N_r, N_rr, N_uv (Munk), N_uu_dr.
                "yaw": ("r", "r|r|", "uv", "u|u|dr"),
            }
        elif kind in ("surface-rudder", "surface-twin"):
            self.dofs = ("surge", "sway")
            self.aux = ("yaw",)
            tau_r = ("u|u|dr", "n|n|dr") if kind == "surface-rudder" else ("l|l|-r|r|",)
            # the speed lost in turns (TURN_LOSS_REGRESSORS): rudder drag where the rudder
            # angle is known; on a skid-steered boat the hull's drag in a turn and the
            # astern thrust a turn uses (weaker than ahead: T200 ~30 N against ~40 N),
            # "tau_astern", the astern part of tau_u
            surge_extra = (("u|u|dr^2",) if kind == "surface-rudder"
                           else ("tau_astern", "u|r|"))
            self.terms = {
                "surge": ("u|u|", "u", "vr", "tau_u") + surge_extra,
                "sway": ("v", "v|v|", "ur", "r"),
                "yaw": ("r", "r|r|", "uv") + tau_r,
            }
        else:  # rov: BlueROV2-class, per-thruster signed squares, allocation learned
            self.dofs = ("surge", "sway", "heave")
            self.aux = ()
            thr = tuple(f"T{i}|T{i}|" for i in range(1, 7))
            self.terms = {
                "surge": ("u", "u|u|", "vr") + thr,
                "sway": ("v", "v|v|", "ur") + thr,
                "heave": ("w", "w|w|", "cos(theta)cos(phi)") + thr,
            }
        self.channels: tuple[str, ...] = self.dofs + self.aux
        self.nd = len(self.dofs)
        # the attitude-borne net-weight terms: coefficient +-(W - B) / (m - X_idot) of the
        # DOF, bounded by g |W - B| / W because the DOF's mass term is at least m
        self.net_weight_terms: dict[str, tuple[str, ...]] = {
            ch: tuple(k for k in self.terms[ch] if k in NET_WEIGHT_REGRESSORS)
            for ch in self.channels}
        # per velocity DOF, the indices of its drag coefficients (DRAG_REGRESSORS), on the
        # surface boats: projecting the torpedo's made the Kolumbo glider's east current
        # worse (RMS 0.071 -> 0.15 m/s, docs/current.md), so its stay free
        surface = kind.startswith("surface")
        self.drag_terms: list[tuple[int, ...]] = [
            tuple(j for j, k in enumerate(self.terms[ch]) if surface and k in DRAG_REGRESSORS)
            for ch in self.dofs]

    # ------------------------------------------------------------------ regressors
    def regressor_rows(self, nu: Sequence[float], x: ModelInputs,
                       dofs_only: bool = False) -> list[tuple[float, ...]]:
        """phi_i for every channel (``dofs`` then ``aux``) as tuples of plain floats, at
        through-water velocity ``nu`` (m/s); with ``dofs_only`` the state DOFs only.

        The filter evaluates these several times per tick (the Jacobian's forward
        differences): at 4-9 terms per channel, float arithmetic is several times cheaper
        than building numpy arrays (numpy's per-call overhead dominates at this size).
        """
        u = nu[0]
        v = nu[1]
        w = nu[2] if len(nu) > 2 else 0.0
        p, q, r = x.p, x.q, x.r
        if self.kind == "torpedo":
            ct, st = math.cos(x.pitch), math.sin(x.pitch)
            cp, sp = math.cos(x.roll), math.sin(x.roll)
            uu = u * abs(u)
            rr = r * abs(r)
            out = [
                (uu, w * q, q * q, v * r, r * r, st, x.n * abs(x.n)),
                (v * abs(v), rr, u * v, u * r, w * p, p * q, ct * sp, uu * x.dr),
                (w * abs(w), q * abs(q), u * w, u * q, v * p, r * p, ct * cp, uu * x.ds),
            ]
            if not dofs_only:
                out.append((r, rr, u * v, uu * x.dr))
            return out
        if self.kind == "surface-rudder":
            tau = _sq(x.n)
            uu = u * abs(u)
            out = [(uu, u, v * r, tau, uu * x.dr * x.dr), (v, v * abs(v), u * r, r)]
            if not dofs_only:
                out.append((r, r * abs(r), u * v, uu * x.dr, tau * x.dr))
            return out
        if self.kind == "surface-twin":
            tl, tr = _sq(x.left), _sq(x.right)
            out = [(u * abs(u), u, v * r, tl + tr, min(tl, 0.0) + min(tr, 0.0), u * abs(r)),
                   (v, v * abs(v), u * r, r)]
            if not dofs_only:
                out.append((r, r * abs(r), u * v, tl - tr))
            return out
        thr = tuple(_sq(t) for t in (tuple(x.thrusters) + (0.0,) * 6)[:6])
        ct, cp = math.cos(x.pitch), math.cos(x.roll)
        return [
            (u, _sq(u), v * r) + thr,
            (v, _sq(v), u * r) + thr,
            (w, _sq(w), ct * cp) + thr,
        ]

    def regressors(self, nu: Sequence[float], x: ModelInputs,
                   dofs_only: bool = False) -> list[np.ndarray]:
        """:meth:`regressor_rows` as numpy arrays."""
        return [np.array(row) for row in self.regressor_rows(nu, x, dofs_only)]

    def linearize(self, nu: Sequence[float], x: ModelInputs,
                  thetas: Sequence[Sequence[float]], h: float = 1e-4,
                  ) -> tuple[list[tuple[float, ...]], list[float], list[list[float]]]:
        """Regressors, acceleration and Jacobian of the state DOFs at ``nu``, in floats.

        Returns ``(phis, f, J)``: ``phis[i]`` the regressor of DOF ``i``, ``f[i] =
        phi_i^T theta_i`` the through-water acceleration ``nu_r'`` (m/s^2) and ``J[i][j] =
        d nu_r'_i / d nu_r_j`` (1/s) by forward differences with step ``h`` (m/s), the
        same numbers as :meth:`accel` and :meth:`jacobian` (up to rounding). ``thetas``
        are best given as lists of floats (indexing numpy arrays element-wise is slow).
        """
        nd = self.nd
        phis = self.regressor_rows(nu, x, dofs_only=True)
        f = [_dot(phis[i], thetas[i]) for i in range(nd)]
        J = [[0.0] * nd for _ in range(nd)]
        for j in range(nd):
            nu2 = list(nu[:nd])
            nu2[j] += h
            phis2 = self.regressor_rows(nu2, x, dofs_only=True)
            for i in range(nd):
                J[i][j] = (_dot(phis2[i], thetas[i]) - f[i]) / h
        return phis, f, J

    def accel(self, nu: Sequence[float], x: ModelInputs,
              thetas: Sequence[np.ndarray]) -> np.ndarray:
        """Through-water acceleration of the state DOFs, ``nu_r'`` (m/s^2)."""
        phis = self.regressor_rows(nu, x, dofs_only=True)
        return np.array([_dot(phis[i], thetas[i]) for i in range(self.nd)])

    def jacobian(self, nu: Sequence[float], x: ModelInputs, thetas: Sequence[np.ndarray],
                 h: float = 1e-4) -> np.ndarray:
        """``d nu_r' / d nu_r`` (1/s) by forward differences (:meth:`linearize`), shape
        (nd, nd)."""
        _, _, J = self.linearize([float(a) for a in nu],
                                 x, [np.asarray(t, float).tolist() for t in thetas], h)
        return np.array(J)

    # ------------------------------------------------------------------ parameters
    def default_thetas(self) -> list[np.ndarray]:
        """A weak generic prior: a streamlined hull that does not crab through water.

        Used when no model is configured; the online identification refines it. Only the
        cross-flow damping is assumed (sway and heave relative velocity decay in ~1-2 s):
        surge is left uninformative (zero coefficients: a random walk), because drag
        without a thrust gain would pull the through-water speed to zero and push the
        whole over-ground velocity into the current.
        """
        th = {c: np.zeros(len(self.terms[c])) for c in self.channels}
        if self.kind == "torpedo":
            th["sway"][2] = -0.8
            th["heave"][2] = -0.8
            th["yaw"][0] = -0.5
        elif self.kind.startswith("surface"):
            th["sway"][0] = -1.0
            th["yaw"][0] = -1.0
        else:
            th["sway"][0] = -0.3
            th["heave"][0] = -0.3
        return [th[c] for c in self.channels]

    def thetas_from_mapping(self, coeffs: Mapping[str, Mapping[str, float]],
                            base: Sequence[np.ndarray] | None = None) -> list[np.ndarray]:
        """Coefficients given by channel and term name (as in ``[pipelines.current.model]``).

        Raises ValueError naming an unknown channel or term.
        """
        out = [np.array(t, float) for t in (base or self.default_thetas())]
        for ch, terms in coeffs.items():
            if ch not in self.channels:
                raise ValueError(f"model: unknown channel {ch!r} (have {', '.join(self.channels)})")
            i = self.channels.index(ch)
            for name, val in terms.items():
                if name not in self.terms[ch]:
                    raise ValueError(f"model.{ch}: unknown term {name!r} "
                                     f"(have {', '.join(self.terms[ch])})")
                out[i][self.terms[ch].index(name)] = float(val)
        return out

    def thetas_to_mapping(self, thetas: Sequence[np.ndarray]) -> dict[str, dict[str, float]]:
        """Inverse of :meth:`thetas_from_mapping`."""
        return {ch: {k: float(v) for k, v in zip(self.terms[ch], th)}
                for ch, th in zip(self.channels, thetas)}


def kind_for_class(vehicle_class: str, has_twin: bool = False) -> str:
    """The regression-model kind for a config's ``vehicle.class`` (its traits'
    ``model_kind``); a rudder boat's becomes the twin thrusters' with ``has_twin``."""
    kind = traits(vehicle_class).model_kind
    return "surface-twin" if has_twin and kind == "surface-rudder" else kind


# ---------------------------------------------------------------------------- glider
# A buoyancy-driven glider does not fit the regression family above: it is driven by its
# net buoyancy (the pump's ballast volume) and trimmed in pitch by a moving battery, and
# its wings turn the vertical motion into horizontal speed. What it offers instead is a
# steady-glide relation between what the log carries (pitch, depth rate, pump volume) and
# the velocity through water (docs/current.md, "Glider model").

GRAVITY_MPS2 = 9.81
"""Gravitational acceleration (m/s^2)."""
SEAWATER_DENSITY_KGM3 = 1027.0
"""Nominal sea-water density (kg/m^3); a configuration sets its area's (the Aegean below
the thermocline: ~1029)."""
SLOCUM_WING_AREA_M2 = 0.10
"""Reference (wing) area ``S`` of the Slocum (m^2); Merckelbach et al. (2019) and their
``gliderflight`` package's default."""
SLOCUM_HULL_LIFT_PER_RAD = 3.8
"""Hull lift slope ``a_h`` (1/rad); Merckelbach et al. (2019), calibrated against a
profiling DVL on a Slocum."""
SLOCUM_WING_ASPECT_RATIO = 7.0
"""Wing aspect ratio (-); Merckelbach et al. (2019)."""
SLOCUM_WING_SWEEP_RAD = math.radians(43.0)
"""Wing sweep angle (rad, 43 deg); Merckelbach et al. (2019)."""
SLOCUM_OSWALD_EFFICIENCY = 0.8
"""Oswald span efficiency of the wings (-); Merckelbach et al. (2019)."""
SLOCUM_HULL_INDUCED_DRAG_PER_RAD2 = 9.7
"""Hull induced-drag coefficient ``C_D1,hull`` (1/rad^2); Merckelbach et al. (2019)."""
SLOCUM_PARASITE_DRAG_CD0 = 0.15
"""Parasite drag coefficient ``C_D0`` (-); Merckelbach et al. (2010), 0.1-0.2 by
deployment."""
SLOCUM_MOVING_MASS_KG = 9.0
"""Mass of the Slocum's moving battery pack (kg); Graver (2005), Slocum (``m_bar``)."""
GLIDE_ITERATIONS = 8
"""Fixed-point iterations of the angle of attack (converges to < 1e-6 rad in 4-5 at
glide angles above 10 deg)."""
MIN_SPEED_MPS = 0.05
"""Speed (m/s) below which the lift cannot carry the net buoyancy: the angle of attack is
bounded there (:data:`MAX_ALPHA_RAD`)."""
MAX_ALPHA_RAD = 0.2
"""Largest angle of attack the steady-glide solution returns (rad, ~11 deg: beyond it the
linear lift model, and the steady glide, no longer hold)."""


def merckelbach_coefficients(density: float = SEAWATER_DENSITY_KGM3,
                              ) -> tuple[float, float, float]:
    """``(K_L, K_D0, K_D)`` (kg/(m rad), kg/m, kg/(m rad^2)) of the Slocum from the
    non-dimensional coefficients of Merckelbach et al. (2019) at ``density`` (kg/m^3):
    ``K = 0.5 rho S C``, with the wing lift slope ``a_w = 2 pi A / (2 + sqrt(A^2 (1 +
    tan^2 Lambda) + 4))`` (A aspect ratio, Lambda sweep) and the wing's induced drag
    ``a_w^2 / (pi e A)``. At 1029 kg/m^3: 387.6, 7.72, 539.8."""
    ar = SLOCUM_WING_ASPECT_RATIO
    a_w = 2.0 * math.pi * ar / (
        2.0 + math.sqrt(ar * ar * (1.0 + math.tan(SLOCUM_WING_SWEEP_RAD) ** 2) + 4.0))
    cd1 = a_w * a_w / (math.pi * SLOCUM_OSWALD_EFFICIENCY * ar) + SLOCUM_HULL_INDUCED_DRAG_PER_RAD2
    q = 0.5 * density * SLOCUM_WING_AREA_M2
    return q * (SLOCUM_HULL_LIFT_PER_RAD + a_w), q * SLOCUM_PARASITE_DRAG_CD0, q * cd1


SLOCUM_LIFT_KL, SLOCUM_DRAG_KD0, SLOCUM_DRAG_KD = merckelbach_coefficients()
"""The Slocum's lift ``K_L`` (kg/(m rad)), parasite drag ``K_D0`` (kg/m) and induced drag
``K_D`` (kg/(m rad^2)) at :data:`SEAWATER_DENSITY_KGM3`: 386.9, 7.70, 538.8, Merckelbach et
al.'s (2019), calibrated against a profiling DVL on a Slocum; lift ``L = (K_L0 + K_L
alpha) U^2``, drag ``D = (K_D0 + K_D alpha^2) U^2`` (N). Graver's (2005) Slocum set, 132.5,
2.15 and 25, puts the angle of attack three times higher: on the Kolumbo glider its
through-water speed was 0.08 m/s slower than the DVL's (0.04 with these), and on three
real dives its depth-averaged current 0.013-0.060 m/s from the gliders' own against
0.004-0.021 with these (docs/current.md, "Glider model")."""


class GlideState(NamedTuple):
    """A steady glide: through-water velocity in the vertical plane of the heading.

    Attributes:
        u_h: horizontal speed through water along the heading (m/s).
        w: vertical speed through water, down positive (m/s).
        speed: speed through water along the flight path ``U`` (m/s).
        gamma: flight-path angle (rad, positive climbing, NED: ``w = -U sin(gamma)``).
        alpha: angle of attack (rad, ``gamma = pitch + alpha``; it steepens the path).
        std_u_h: one-sigma of ``u_h`` (m/s) from the vertical-water and glide-angle
            uncertainties (:meth:`GliderModel.glide_from_depth_rate`).
        thrust: the along-path force the glide needs beyond the buoyancy's (N): drag
            minus the net buoyancy's along-path share; ~0 for a pure glider, the
            thruster's push on a hybrid one.
    """

    u_h: float
    w: float
    speed: float
    gamma: float
    alpha: float
    std_u_h: float
    thrust: float

    def body_velocity(self, pitch: float) -> tuple[float, float, float]:
        """The through-water velocity in body axes (FRD, m/s; no sideslip) at ``pitch``
        (rad): the path is ``pitch - gamma`` below the body's x axis."""
        a = pitch - self.gamma
        return (self.speed * math.cos(a), 0.0, self.speed * math.sin(a))


@mypyc_attr(allow_interpreted_subclasses=True)
class GliderModel:
    """Steady wings-level glide of a buoyancy-driven glider (Graver 2005;
    Fan & Woolsey 2014; Merckelbach et al. 2010, 2019).

    Forces on the glider in the vertical plane, with ``U`` the speed through water,
    ``gamma`` the flight-path angle and ``alpha = gamma - pitch`` (signed so that the path
    is steeper than the hull, as it is in a steady glide):

    * net buoyancy ``B = rho g (V_pump - V_neutral)`` (N; upward positive), from the pump
      volume ``V_pump`` (cm^3, the log's ``pump_vol``) about the neutral volume;
    * lift ``L = (K_L0 + K_L |alpha|) U^2`` perpendicular to the path, drag
      ``D = (K_D0 + K_D alpha^2) U^2`` along it;
    * (hybrid gliders) a thrust ``T`` along the hull.

    Steady flight balances them: across the path ``L = |B| cos(gamma)``; along it
    ``D = |B| |sin(gamma)| + T``. A pure glider (``T = 0``) glides at an angle fixed by
    the pitch (:meth:`glide_from_buoyancy`); with a thruster, or whatever the push, the
    measured depth rate fixes the speed instead (:meth:`glide_from_depth_rate`): with no
    vertical water velocity, ``U = dz/dt / sin|gamma|`` and ``u_h = dz/dt / tan|gamma|``,
    and the lift balance gives ``alpha = |B| cos(gamma) / (K_L U^2)``, iterated.

    The pitch itself follows from the battery position by the static moment balance
    (:meth:`pitch_from_battery`): ``tan(pitch) = (k_pump (V_pump - V_neutral) -
    k_batt (x_batt - x_batt0))``, the pump's buoyancy at the nose and the battery's
    weight against the hull's righting moment (Graver 2005).

    Attributes (SI unless stated): ``k_l``, ``k_l0``, ``k_d0``, ``k_d`` (lift and drag,
    above), ``density`` (kg/m^3), ``neutral_pump_cc`` (cm^3), ``vertical_water_std``
    (m/s: the vertical water velocity the depth rate cannot tell from the glider's),
    ``gamma_std`` (rad: glide-angle uncertainty, pitch sensor and angle of attack),
    ``min_glide`` (rad: below this pitch the depth rate says nothing usable about
    the horizontal speed), ``k_pump`` (1/cm^3), ``k_batt`` (1/m), ``batt0`` (m).
    """

    def __init__(self, *, k_l: float = SLOCUM_LIFT_KL, k_l0: float = 0.0,
                 k_d0: float = SLOCUM_DRAG_KD0, k_d: float = SLOCUM_DRAG_KD,
                 density: float = SEAWATER_DENSITY_KGM3, neutral_pump_cc: float = 0.0,
                 vertical_water_std: float = 0.02, gamma_std: float = math.radians(2.0),
                 min_glide: float = math.radians(12.0), k_pump: float = 0.0,
                 k_batt: float = 0.0, batt0: float = 0.0) -> None:
        self.k_l, self.k_l0, self.k_d0, self.k_d = k_l, k_l0, k_d0, k_d
        self.density = density
        self.neutral_pump_cc = neutral_pump_cc
        self.vertical_water_std = vertical_water_std
        self.gamma_std = gamma_std
        self.min_glide = min_glide
        self.k_pump, self.k_batt, self.batt0 = k_pump, k_batt, batt0

    def net_buoyancy(self, pump_cc: float) -> float:
        """Net buoyancy (N, upward positive) at pump volume ``pump_cc`` (cm^3)."""
        return self.density * GRAVITY_MPS2 * (pump_cc - self.neutral_pump_cc) * 1e-6

    def lift(self, alpha: float, speed: float) -> float:
        """Lift (N) at angle of attack ``alpha`` (rad) and speed ``speed`` (m/s)."""
        return (self.k_l0 + self.k_l * alpha) * speed * speed

    def drag(self, alpha: float, speed: float) -> float:
        """Drag (N) at angle of attack ``alpha`` (rad) and speed ``speed`` (m/s)."""
        return (self.k_d0 + self.k_d * alpha * alpha) * speed * speed

    def pitch_from_battery(self, battery_m: float, pump_cc: float) -> float:
        """Static trim pitch (rad, nose up positive) at battery position ``battery_m``
        (m, forward positive) and pump volume ``pump_cc`` (cm^3): the moment balance of
        the class docstring."""
        return math.atan(self.k_pump * (pump_cc - self.neutral_pump_cc)
                         - self.k_batt * (battery_m - self.batt0))

    def glide_from_depth_rate(self, pitch: float, depth_rate: float,
                              pump_cc: float) -> GlideState | None:
        """The steady glide at ``pitch`` (rad) that descends at ``depth_rate`` (m/s, down
        positive) with the pump at ``pump_cc`` (cm^3), or None where the depth rate cannot
        give the horizontal speed: a flight-path angle below ``min_glide``, or a pitch
        and a depth rate of opposite senses (an inflection, a stall).

        ``std_u_h`` propagates ``vertical_water_std`` and ``gamma_std``:
        ``(sigma_w / tan|gamma|)^2 + (u_h sigma_gamma / (sin|gamma| cos gamma))^2``.
        """
        if not (math.isfinite(pitch) and math.isfinite(depth_rate)
                and math.isfinite(pump_cc)):
            return None
        if abs(pitch) < self.min_glide or depth_rate * pitch >= 0.0:
            return None  # nose down while rising, or nose up while sinking
        b = abs(self.net_buoyancy(pump_cc))
        sgn = -1.0 if pitch < 0.0 else 1.0  # the path is steeper than the hull
        gamma = pitch
        speed = alpha = 0.0
        for _ in range(GLIDE_ITERATIONS):
            speed = abs(depth_rate) / math.sin(abs(gamma))
            q = max(speed, MIN_SPEED_MPS) ** 2
            a = (b * math.cos(gamma) / q - self.k_l0) / self.k_l
            alpha = sgn * min(max(a, 0.0), MAX_ALPHA_RAD)
            gamma = pitch + alpha
        g = abs(gamma)
        u_h = abs(depth_rate) / math.tan(g)
        std = math.hypot(self.vertical_water_std / math.tan(g),
                         u_h * self.gamma_std / (math.sin(g) * math.cos(g)))
        thrust = self.drag(alpha, speed) - b * math.sin(g)
        return GlideState(u_h=u_h, w=depth_rate, speed=speed, gamma=gamma, alpha=alpha,
                          std_u_h=std, thrust=thrust)

    def glide_from_buoyancy(self, pitch: float, pump_cc: float) -> GlideState | None:
        """The unpowered steady glide at ``pitch`` (rad) with the pump at ``pump_cc``
        (cm^3): the angle of attack from ``tan|gamma| = D / L`` (Merckelbach et al. 2010),
        then the speed from the drag balance ``D = |B| sin|gamma|``. None when
        the buoyancy and the pitch disagree (nose down while buoyant) or the pitch is
        below ``min_glide``."""
        b = self.net_buoyancy(pump_cc)
        if abs(pitch) < self.min_glide or b * pitch <= 0.0:
            return None
        sgn = 1.0 if pitch > 0.0 else -1.0
        a = 0.0
        for _ in range(GLIDE_ITERATIONS * 2):
            a = (self.k_d0 + self.k_d * a * a) / (self.k_l * math.tan(abs(pitch) + a))
            a = min(a, MAX_ALPHA_RAD)
        gamma = pitch + sgn * a
        g = abs(gamma)
        speed = math.sqrt(abs(b) * math.sin(g) / (self.k_d0 + self.k_d * a * a))
        u_h = speed * math.cos(g)
        return GlideState(u_h=u_h, w=-speed * math.sin(gamma), speed=speed, gamma=gamma,
                          alpha=sgn * a, std_u_h=math.nan, thrust=0.0)
