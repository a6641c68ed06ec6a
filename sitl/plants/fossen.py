"""6-DOF rigid-body helpers in Fossen's vectorial form, shared by the underwater plants.

    M nu_r' + C(nu_r) nu_r + D(nu_r) nu_r + g(eta) = tau        (Fossen 2021, eq. 10.146)

``M = M_RB + M_A`` symmetric positive definite; ``nu_r = [v; omega]`` the velocity
through the water (body FRD), ``eta = [N, E, D, phi, theta, psi]``.
"""

from __future__ import annotations

import math

import numpy as np

from onboard.sitl.frames import skew

__all__ = [
    "SparseMatrix",
    "rigid_body_mass",
    "coriolis_times_nu",
    "restoring_forces",
    "submerged_fraction",
]


class SparseMatrix:
    """A small constant matrix stored as its non-zero entries per row, for fast
    matrix-vector products on Python floats (6x6 numpy products on tiny arrays cost more
    in call overhead than in arithmetic)."""

    def __init__(self, a: np.ndarray, tol: float = 0.0) -> None:
        self.shape = a.shape
        self.rows = tuple(
            tuple((j, float(a[i, j])) for j in range(a.shape[1]) if abs(a[i, j]) > tol)
            for i in range(a.shape[0])
        )

        terms = [
            " + ".join(f"{v!r} * x[{j}]" for j, v in row) if row else "0.0" for row in self.rows
        ]
        # A straight-line expression of the constant entries: ~10x faster than a loop.
        self.matvec = eval("lambda x: [" + ", ".join(terms) + "]")  # noqa: S307 (numbers only)
        """``A @ x`` for a list of floats, as a list."""


def rigid_body_mass(
    m: float, r_g: tuple[float, float, float], inertia: np.ndarray, *, about_cg: bool = True
) -> np.ndarray:
    """M_RB about the body origin (Fossen eq. 3.44): ``[[m I, -m S(r_g)], [m S(r_g), I_o]]``.

    ``m`` mass (kg), ``r_g`` CG position in body axes (m), ``inertia`` 3x3 (kg m^2) about
    the CG (``about_cg=True``, then ``I_o = I_g - m S(r_g)^2``, parallel-axis theorem) or
    about the origin.
    """
    s = skew(r_g)
    i_o = np.asarray(inertia, dtype=float) - (m * s @ s if about_cg else 0.0)
    mrb = np.zeros((6, 6))
    mrb[0:3, 0:3] = m * np.eye(3)
    mrb[0:3, 3:6] = -m * s
    mrb[3:6, 0:3] = m * s
    mrb[3:6, 3:6] = i_o
    return mrb


def coriolis_times_nu(mass: np.ndarray | SparseMatrix, nu: np.ndarray | list[float]) -> list[float]:
    """C(nu) nu for a symmetric mass matrix (Fossen Theorem 3.2 / eq. 6.43).

    With ``[a; b] = M nu``: ``C(nu) nu = [omega x a; v x a + omega x b]``. Applied to
    ``M_RB + M_A`` and ``nu_r`` this gives the rigid-body and added-mass (Munk) terms.
    """
    if isinstance(mass, SparseMatrix):
        nu = list(nu)
        a1, a2, a3, b1, b2, b3 = mass.matvec(nu)
    else:
        nu = np.asarray(nu, dtype=float)
        a1, a2, a3, b1, b2, b3 = (mass @ nu).tolist()
    u, v, w, p, q, r = (float(n) for n in nu)
    return [
        q * a3 - r * a2,
        r * a1 - p * a3,
        p * a2 - q * a1,
        v * a3 - w * a2 + q * b3 - r * b2,
        w * a1 - u * a3 + r * b1 - p * b3,
        u * a2 - v * a1 + p * b2 - q * b1,
    ]


def restoring_forces(
    weight: float,
    buoyancy: float,
    r_g: tuple[float, float, float],
    r_b: tuple[float, float, float],
    phi: float,
    theta: float,
) -> list[float]:
    """g(eta), the restoring vector on the left-hand side (Fossen eq. 4.6), N and N m.

    ``weight`` W = m g and ``buoyancy`` B (N); ``r_g``, ``r_b`` the centres of gravity and
    buoyancy in body axes (m).
    """
    xg, yg, zg = r_g
    xb, yb, zb = r_b
    sth, cth = math.sin(theta), math.cos(theta)
    sphi, cphi = math.sin(phi), math.cos(phi)
    wb = weight - buoyancy
    return [
        wb * sth,
        -wb * cth * sphi,
        -wb * cth * cphi,
        -(yg * weight - yb * buoyancy) * cth * cphi + (zg * weight - zb * buoyancy) * cth * sphi,
        (zg * weight - zb * buoyancy) * sth + (xg * weight - xb * buoyancy) * cth * cphi,
        -(xg * weight - xb * buoyancy) * cth * sphi - (yg * weight - yb * buoyancy) * sth,
    ]


def submerged_fraction(down: float, height: float) -> float:
    """Crude free surface: the fraction of the hull below the surface, for a body of
    vertical extent ``height`` (m) whose origin is at depth ``down`` (m). Scales the
    buoyancy so that a positively buoyant vehicle floats at the surface instead of
    flying out of the water. 1 when fully submerged.
    """
    return min(1.0, max(0.0, 0.5 + down / height))
