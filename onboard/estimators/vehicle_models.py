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
import operator
from collections.abc import Mapping, Sequence

import numpy as np


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


def _dot(a: Sequence[float], b: Sequence[float]) -> float:
    """``a . b`` summed left to right in plain floats."""
    return sum(map(operator.mul, a, b))


NET_WEIGHT_REGRESSORS = ("sin(theta)", "cos(theta)sin(phi)")
"""Regressors whose coefficient is the net weight ``W - B`` over the DOF's mass term
(Kim et al. eq. (3)-(4)) and nothing else: physics with a known scale, their prior is
``CurrentConfig.net_weight_std``. Not the heave term ``cos(theta)cos(phi)`` (eq. (5), the
ROV's heave): near level flight it is ~1, the heave equation's constant, whose coefficient
carries every steady vertical force a generic (mode (b)) model lacks, not only the net
weight (vertical thrust against a push or a tether, lift at a trim angle); a net-weight
prior on it makes the unidentified spheroid and BlueROV2 runs worse (docs/current.md,
"Net-weight prior")."""


class RegressionModel:
    """A per-DOF linear-in-parameters model.

    Attributes:
        kind: ``"torpedo"``, ``"surface-rudder"``, ``"surface-twin"`` or ``"rov"``.
        dofs: the state channels, in order (``"surge", "sway"[, "heave"]``).
        aux: channels identified but not part of the velocity state (``"yaw"``).
        terms: regressor names per channel.
        net_weight_terms: per channel, the terms among ``terms`` whose coefficient is the
            net weight over the DOF's mass term (:data:`NET_WEIGHT_REGRESSORS`).
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
            self.terms = {
                "surge": ("u|u|", "u", "vr", "tau_u"),
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
            out = [(uu, u, v * r, tau), (v, v * abs(v), u * r, r)]
            if not dofs_only:
                out.append((r, r * abs(r), u * v, uu * x.dr, tau * x.dr))
            return out
        if self.kind == "surface-twin":
            tl, tr = _sq(x.left), _sq(x.right)
            out = [(u * abs(u), u, v * r, tl + tr), (v, v * abs(v), u * r, r)]
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
    """The regression-model kind for a config's ``vehicle.class``."""
    if vehicle_class in ("torpedo-auv", "spheroid"):
        return "torpedo"
    if vehicle_class == "bluerov2":
        return "rov"
    if vehicle_class == "twin-thruster-boat" or has_twin:
        return "surface-twin"
    return "surface-rudder"
