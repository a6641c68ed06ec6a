"""Fixed-step RK4 integration shared by the plants, and the plants' gravity.

Angles are wrapped and rotated by :mod:`onboard.sitl.frames` (ZYX
Euler angles, NED earth frame, FRD body frame, as in Fossen, *Handbook of Marine Craft
Hydrodynamics and Motion Control*, 2nd ed., 2021).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

__all__ = [
    "rk4_step",
    "rk4_step_list",
    "integrate_rk4",
    "GRAVITY",
]

GRAVITY = 9.81
"""Standard gravity used by every plant (m/s^2); the BlueROV2 paper uses 9.81 too."""

Derivative = Callable[[float, np.ndarray], np.ndarray]


def rk4_step(f: Derivative, t: float, x: np.ndarray, h: float) -> np.ndarray:
    """One classical fourth-order Runge-Kutta step of ``x' = f(t, x)`` of length ``h`` (s).

    Local error O(h^5), global O(h^4). Returns the new state; ``x`` is not modified.
    """
    k1 = f(t, x)
    k2 = f(t + 0.5 * h, x + (0.5 * h) * k1)
    k3 = f(t + 0.5 * h, x + (0.5 * h) * k2)
    k4 = f(t + h, x + h * k3)
    return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def rk4_step_list(
    f: Callable[[float, list[float]], list[float]], t: float, x: list[float], h: float
) -> list[float]:
    """:func:`rk4_step` on plain lists of floats: for the small states of the plants this
    is ~3x faster than numpy, whose per-call overhead dominates 12-element arithmetic."""
    hh = 0.5 * h
    k1 = f(t, x)
    k2 = f(t + hh, [a + hh * b for a, b in zip(x, k1)])
    k3 = f(t + hh, [a + hh * b for a, b in zip(x, k2)])
    k4 = f(t + h, [a + h * b for a, b in zip(x, k3)])
    h6 = h / 6.0
    return [
        a + h6 * (b1 + 2.0 * b2 + 2.0 * b3 + b4) for a, b1, b2, b3, b4 in zip(x, k1, k2, k3, k4)
    ]


def integrate_rk4(
    f: Derivative, t: float, x: np.ndarray, duration: float, max_step: float
) -> np.ndarray:
    """Advance ``x' = f(t, x)`` from ``t`` by ``duration`` (s) with equal RK4 sub-steps.

    The number of sub-steps is ``ceil(duration / max_step)`` so every sub-step is
    ``<= max_step``; a zero ``duration`` returns a copy of ``x``.
    """
    if duration <= 0.0:
        return np.array(x, dtype=float)
    n = max(1, math.ceil(duration / max_step - 1e-9))
    h = duration / n
    for i in range(n):
        x = rk4_step(f, t + i * h, x, h)
    return x
