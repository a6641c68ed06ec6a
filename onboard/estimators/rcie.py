"""Retrospective-cost input estimation (RCIE) of one scalar axis: the input-estimation
half of adaptive input estimation (AIE).

Ansari & Bernstein, "Input estimation for nonminimum-phase systems with application to
acceleration estimation for a maneuvering vehicle", IEEE TCST 2019, as used by Faros &
Tanner, "System Identification and Adaptive Input Estimation on the Jaiabot", arXiv
2504.02005 (2025). Equations restated in algorithms.md §2, scalar case ``l_d = l_y = 1``:

* input-estimation subsystem (§2.3), IIR of order ``n_c`` in the innovation ``z``::

      d_hat_k = sum_{i=1..n_c} P_i d_hat_{k-i} + sum_{i=0..n_c} Q_i z_{k-i} = phi_k . theta

* filter ``G_f(q) = sum_{i=1..n_f} H_i q^-i`` (§2.4), the retrospective variable
  ``z_hat(theta) = z_k - d_hat_f,k + phi_f,k . theta`` (§2.5), and the exact RLS
  minimizer (§2.6) with rows ``[phi_f; phi]`` (or ``[phi_f; phi_k - phi_{k-1}]`` with the
  rate penalty) weighted ``diag(R_z, R_d)``::

      Gamma  = lambda R~^-1 + Phi~ P Phi~^T          (2 x 2, LDL^T-factored)
      P+     = (P - P Phi~^T Gamma^-1 Phi~ P) / lambda
      theta+ = theta - P Phi~^T Gamma^-1 (z~ + Phi~ theta)

Signals are normalized before RLS (§2.10): ``z`` by ``z_scale`` and ``d_hat`` by
``u_scale``.

Two forms of the update
-----------------------
:func:`reference_rls_update` is §2.6 in numpy, line for line. :func:`rcie_kernel`, which
:class:`Rcie` runs, is the same update as straight-line float code generated once per
``l_theta`` (the rows built inside it, ``Gamma`` factored ``L D L^T``, the covariance kept
as its packed upper triangle times a scalar, ``P = sc Q``, so that forgetting is one
multiplication). It is the one generated kernel left: an AIE axis step stays within half
of a textbook Kalman filter step (``onboard bench``, ``aie_step_vs_filterpy_kf``) only with
it; docs/performance.md, "Fast paths", has the figures. The tests compare the two forms
on random inputs (tests/test_primitives.py). The compiled build (setup.py) compiles the
same lines ahead of time (:func:`compiled_kernels_source`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from functools import cache
from typing import Any, Callable, Mapping

from mypy_extensions import mypyc_attr
import numpy as np


def reference_rls_update(
    P: np.ndarray, theta: np.ndarray, phi_f: np.ndarray, b: np.ndarray, e1: float,
    r_z: float, r_d: float, lam: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The RLS update of §2.6 in numpy: ``(P+, theta+)`` from the rows ``phi_f`` (weight
    ``r_z``, residual ``e1 = z_k - d_hat_f,k``) and ``b`` (weight ``r_d``, target 0; the
    row drops out when ``r_d = 0``)."""
    if r_d > 0.0:
        Phi = np.vstack([phi_f, b])                       # Phi~ = [phi_f^T; b^T]
        z = np.array([e1, 0.0])                           # z~ = [z_k - d_hat_f,k; 0]
        R = np.diag([r_z, r_d])                           # R~ = diag(R_z, R_d)
    else:
        Phi, z, R = np.atleast_2d(phi_f), np.array([e1]), np.array([[r_z]])
    Gamma = lam * np.linalg.inv(R) + Phi @ P @ Phi.T      # Gamma = lambda R~^-1 + Phi~ P Phi~^T
    theta = theta - P @ Phi.T @ np.linalg.solve(Gamma, z + Phi @ theta)
    #                                        theta+ = theta - P Phi~^T Gamma^-1 (z~ + Phi~ theta)
    P = (P - P @ Phi.T @ np.linalg.solve(Gamma, Phi @ P)) / lam
    #                                        P+ = (P - P Phi~^T Gamma^-1 Phi~ P) / lambda
    return P, theta


def packed_index(n: int) -> dict[tuple[int, int], int]:
    """Position of ``P[i][j]`` in the packed upper triangle (row-major) of an ``n x n``
    symmetric matrix (the storage of :attr:`Rcie.P`)."""
    idx: dict[tuple[int, int], int] = {}
    m = 0
    for i in range(n):
        for j in range(i, n):
            idx[(i, j)] = idx[(j, i)] = m
            m += 1
    return idx


def unpack(P: Sequence[float], n: int) -> list[list[float]]:
    """Packed upper triangle (row-major) -> full symmetric matrix (list of rows)."""
    idx = packed_index(n)
    return [[P[idx[(i, j)]] for j in range(n)] for i in range(n)]


def unpack_line(names: str, count: int, value: str) -> str:
    """The kernel line unpacking the sequence ``value`` into ``names0 .. names<count-1>``."""
    return f"    {', '.join(f'{names}{i}' for i in range(count))}, = {value}"


def compile_kernel(lines: Sequence[str], name: str) -> Callable[..., Any]:
    """The function ``kernel`` defined by the generated ``lines`` (its first line is the
    ``def``); ``name`` labels it in tracebacks."""
    ns: dict[str, Any] = {}
    code = compile("\n".join(lines), f"<generated {name}>", "exec")
    exec(code, ns)  # noqa: S102 - source generated here from integers only
    return ns["kernel"]


def two_row_update_lines(n: int) -> list[str]:
    """Kernel lines of the two-row update (algorithms.md §2.6) for ``n`` parameters.

    In scope before them: the packed covariance ``p0 ..``, with ``P = sc * p``; the
    parameters ``t0 ..``; the rows ``a0 ..`` (weight ``R_a``) and ``b0 ..`` (weight
    ``R_b``, target 0); ``e1``, the first row's residual before the parameters;
    ``wa = lam / R_a``, ``wb = lam / R_b``; ``lam``. With ``Phi~ = [a; b]``,
    ``z~ = [e1; 0]``, they compute::

        Gamma  = diag(wa, wb) + Phi~ P Phi~^T                 (LDL^T-factored, 2 x 2)
        theta+ = theta - P Phi~^T Gamma^-1 (z~ + Phi~ theta)   -> n0 ..
        P+     = sn * Q,  sn = sc / lam,
        Q      = p - sc p Phi~^T Gamma^-1 Phi~ p               -> Q (packed list)
        tr     = trace(P+)

    and ``return None`` when a pivot of ``Gamma`` is not positive (impossible in exact
    arithmetic: a divergence). Keeping ``P = sc Q`` makes the forgetting one
    multiplication of ``sc`` rather than one per entry.
    """
    idx = packed_index(n)
    r = range(n)
    p = {(i, j): f"p{idx[(i, j)]}" for i in r for j in r}
    src: list[str] = []
    add = src.append
    for i in r:
        add(f"    pa{i} = " + " + ".join(f"{p[(i, j)]}*a{j}" for j in r))
        add(f"    pb{i} = " + " + ".join(f"{p[(i, j)]}*b{j}" for j in r))
    add("    g11 = wa + sc*(" + " + ".join(f"a{i}*pa{i}" for i in r) + ")")
    add("    g12 = sc*(" + " + ".join(f"a{i}*pb{i}" for i in r) + ")")
    add("    g22 = wb + sc*(" + " + ".join(f"b{i}*pb{i}" for i in r) + ")")
    add("    e1 = e1 + " + " + ".join(f"a{i}*t{i}" for i in r))
    add("    e2 = " + " + ".join(f"b{i}*t{i}" for i in r))
    # Gamma = L D L^T (2 x 2 Cholesky without square roots), pivots must be positive
    add("    if not g11 > 0.0:")
    add("        return None")
    add("    l = g12 / g11")
    add("    d2 = g22 - l * g12")
    add("    if not d2 > 0.0:")
    add("        return None")
    add("    i22 = sc / d2")
    add("    i12 = -l * i22")
    add("    i11 = sc / g11 + l * l * i22")
    add("    w1 = i11 * e1 + i12 * e2")
    add("    w2 = i12 * e1 + i22 * e2")
    for i in r:
        add(f"    ka{i} = i11*pa{i} + i12*pb{i}")
        add(f"    kb{i} = i12*pa{i} + i22*pb{i}")
    for i in r:
        add(f"    n{i} = t{i} - pa{i}*w1 - pb{i}*w2")
    terms = [f"{p[(i, j)]} - ka{i}*pa{j} - kb{i}*pb{j}" for i in r for j in range(i, n)]
    add("    Q = [" + ", ".join(terms) + "]")
    add("    sn = sc / lam")
    add("    tr = sn * (" + " + ".join(f"Q[{idx[(i, i)]}]" for i in r) + ")")
    return src


RcieKernel = Callable[..., "tuple[list[float], float, list[float], float, float] | None"]
"""``kernel(Q, sc, theta, s, h, f, g, e1, w_a, w_b, lam) -> (Q+, sc+, theta+, trace(P+),
g . theta+)`` or None: see :func:`rcie_kernel`."""


COMPILED_KERNEL_ORDERS = tuple(2 * n_c + 1 for n_c in range(6))
"""The ``l_theta`` (``n_c`` 0-5) whose kernels the compiled build compiles ahead of time
(:func:`compiled_kernels_source`); another order's is generated at run time."""


def kernel_name(n: int, rate_penalty: bool) -> str:
    """The name of the kernel for ``l_theta = n`` in :func:`compiled_kernels_source`."""
    return f"kernel_{n}_{'rate' if rate_penalty else 'size'}"


def rcie_kernel_lines(n: int, rate_penalty: bool, name: str = "kernel",
                      typed: bool = False) -> list[str]:
    """The source of :func:`rcie_kernel`'s function, named ``name``; ``typed``: with the
    argument and result types, for the compiled build."""
    r = range(n)
    if typed:
        src = [f"def {name}(P: list[float], sc: float, th: list[float], s: list[float], "
               "h: float, f: list[float], g: list[float], e1: float, wa: float, wb: float, "
               "lam: float) -> tuple[list[float], float, list[float], float, float] | None:"]
    else:
        src = [f"def {name}(P, sc, th, s, h, f, g, e1, wa, wb, lam):"]
    src += [unpack_line("p", n * (n + 1) // 2, "P"), unpack_line("t", n, "th"),
            unpack_line("s", n, "s"), unpack_line("g", n, "g")]
    src += [f"    a{i} = h*s{i}" for i in r]
    if rate_penalty:
        src.append(unpack_line("f", n, "f"))
        src += [f"    b{i} = g{i} - f{i}" for i in r]
    else:
        src += [f"    b{i} = g{i}" for i in r]
    src += two_row_update_lines(n)
    src.append("    d = " + " + ".join(f"g{i}*n{i}" for i in r))
    src.append("    return Q, sn, [" + ", ".join(f"n{i}" for i in r) + "], tr, d")
    return src


def compiled_kernels_source() -> str:
    """The module of the kernels of :data:`COMPILED_KERNEL_ORDERS`, both penalties, typed:
    the compiled build compiles it as ``onboard.estimators.rcie_kernels`` (setup.py), the
    same lines :func:`rcie_kernel` runs, ahead of time."""
    lines = ['"""The RCIE kernels compiled ahead of time (onboard.estimators.rcie)."""',
             "", "from __future__ import annotations"]
    for n in COMPILED_KERNEL_ORDERS:
        for rate_penalty in (False, True):
            lines += ["", ""] + rcie_kernel_lines(n, rate_penalty,
                                                  kernel_name(n, rate_penalty), typed=True)
    return "\n".join(lines) + "\n"


@cache
def rcie_kernel(n: int, rate_penalty: bool) -> RcieKernel:
    """The RCIE update (§2.6-§2.7 step 5) for ``l_theta = n``, as straight-line float code:
    the two-row RLS of :func:`two_row_update_lines` with its rows
    built inside (fewer Python list operations) and the covariance scaled, ``P = sc Q``.

    ``kernel(Q, sc, theta, s, h, f, g, e1, w_a, w_b, lam) -> (Q+, sc+, theta+,
    trace(P+), g . theta+)``, or None when ``Gamma`` is not positive definite, with the
    rows ``a = h s`` (``phi_f``, weight ``R_z``; ``e1 = z_k - d_hat_f,k``) and ``b = g - f``
    (rate penalty) or ``b = g`` (size penalty; weight ``R_d``), ``g = phi_k`` and
    ``f = phi_{k-1}``; ``w_a = lambda / R_z``, ``w_b = lambda / R_d``.

    The compiled build has the kernels of :data:`COMPILED_KERNEL_ORDERS` compiled (the
    module ``rcie_kernels``, :func:`compiled_kernels_source`); otherwise, and for another
    order, the lines are compiled here into Python.
    """
    kernel = _compiled_kernel(n, rate_penalty)
    if kernel is not None:
        return kernel
    return compile_kernel(rcie_kernel_lines(n, rate_penalty),
                          f"rcie_kernel({n}, {rate_penalty})")


def _compiled_kernel(n: int, rate_penalty: bool) -> RcieKernel | None:
    """The compiled build's kernel for ``l_theta = n``, None in the pure build or for an
    order it has not compiled."""
    try:
        import onboard.estimators.rcie_kernels as kernels
    except ImportError:  # the pure build
        return None
    return getattr(kernels, kernel_name(n, rate_penalty), None)


@mypyc_attr(allow_interpreted_subclasses=True)
class Rcie:
    """RCIE input estimator of one scalar axis (§2.7 steps 2-5 and 8).

    Attributes:
        theta: coefficients ``[P_1..P_nc, Q_0..Q_nc]`` (normalized units, §2.3).
        P: packed RLS covariance (§2.6).
        d_hat: last input estimate after saturation (unit of the input);
        d_hat_raw: the same before saturation.
        steps: RLS updates since the last reset.
    """

    def __init__(self, n_c: int, n_f: int, r_z: float, r_d: float, r_theta: float,
                 lam: float, u_scale: float, z_scale: float, u_max: float,
                 trace_max: float | None = None, rate_penalty: bool = False) -> None:
        """Args:
            n_c: order of the input-estimation subsystem (§2.3); ``l_theta = 2 n_c + 1``.
            n_f: number of taps of the filter ``G_f`` (§2.4).
            r_z: weight of the retrospective variable (§2.5).
            r_d: weight of the input penalty (§2.5); 0 drops its row.
            r_theta: regularization, ``P_0 = I / r_theta``.
            lam: forgetting factor in (0, 1].
            u_scale: normalization of the input estimate (§2.10, unit of the input).
            z_scale: normalization of the innovation (§2.10, unit of y).
            u_max: saturation of the input estimate (unit of the input).
            trace_max: bound of ``trace(P)``, the wind-up guard (default
                ``10 l_theta / r_theta``).
            rate_penalty: penalize the change of the estimate between steps rather than
                its size (§2.5).
        """
        if n_c < 0 or n_f < 1:
            raise ValueError("need n_c >= 0 and n_f >= 1")
        if not (0.0 < lam <= 1.0 and r_z > 0.0 and r_theta > 0.0 and r_d >= 0.0):
            raise ValueError("need 0 < lam <= 1, r_z > 0, r_theta > 0, r_d >= 0")
        self.n_c, self.n_f = n_c, n_f
        self.n = 2 * n_c + 1
        self.lam = lam
        self.wa = lam / r_z
        self.set_input_penalty(r_d)
        self.r_theta = r_theta
        self.rate_penalty = rate_penalty
        self.u_scale, self.z_scale, self.u_max = u_scale, z_scale, u_max
        self.trace_max = trace_max if trace_max is not None else 10.0 * self.n / r_theta
        self._kernel = rcie_kernel(self.n, rate_penalty)
        self.reset()

    def set_input_penalty(self, r_d: float) -> None:
        """Use the input penalty ``r_d`` (§2.5; 0 drops its row) from the next step on;
        what RLS has learned is kept."""
        if not r_d >= 0.0:
            raise ValueError(f"need r_d >= 0, got {r_d}")
        self.wb = self.lam / r_d if r_d > 0.0 else 1e300   # R_d = 0: the row drops out

    def reset(self) -> None:
        """theta <- 0, P <- I / R_theta, buffers <- 0 (the start-up of §2.7)."""
        n = self.n
        p0 = 1.0 / self.r_theta
        self.theta = [0.0] * n
        self._Q = [p0 if i == j else 0.0 for i in range(n) for j in range(i, n)]
        self._sc = 1.0
        self._dh = [0.0] * self.n_c                   # d_hat_{k-1..k-nc}, normalized
        self._z = [0.0] * (self.n_c + 1)              # z_{k..k-nc}, normalized
        self._phis = [[0.0] * n for _ in range(self.n_f)]   # phi_{k-1..k-nf}
        self._dhf = [0.0] * self.n_f                  # d_hat_{k-1..k-nf}, normalized
        self.d_hat = 0.0
        self.d_hat_raw = 0.0
        self.steps = 0

    def step(self, z: float, H: list[float]) -> float | None:
        """One RCIE step for innovation ``z`` (unit of y) and ``H = [H_1..H_nf]``
        (unit of y per unit input). Returns ``d_hat_k`` saturated to ``+-u_max``, or None
        when the update failed (the caller resets)."""
        zs, us = self.z_scale, self.u_scale
        zn = z / zs
        zb = self._z = [zn] + self._z[:-1]
        phi = self._dh + zb                                        # §2.3 phi_k
        phis, dhf = self._phis, self._dhf
        g = us / zs                                                # H in normalized units
        h = H[0] * g
        prev = phis[0]
        e1 = zn - h * dhf[0]                                       # z_k - d_hat_f,k
        if self.n_f == 1:                                          # §2.4 phi_f = h phi_k-1
            src = prev
        else:
            src = list(prev)
            for i in range(1, self.n_f):
                c = H[i] * g
                src = [x + (c / h) * y for x, y in zip(src, phis[i])]
                e1 -= c * dhf[i]
        res = self._kernel(self._Q, self._sc, self.theta, src, h, prev, phi, e1, self.wa,
                           self.wb, self.lam)
        if res is None:
            return None
        Q, sc, theta, tr, dn = res
        if not (tr < self.trace_max):                              # windup guard (§2.6)
            if not math.isfinite(tr):
                return None
            sc *= self.trace_max / tr
        if not 1e-3 < sc < 1e3:                                    # keep Q well scaled
            Q = [x * sc for x in Q]
            sc = 1.0
        self._Q, self._sc, self.theta = Q, sc, theta
        raw = dn * us                                              # §2.7 step 5
        if not math.isfinite(raw):
            return None
        m = self.u_max
        d = m if raw > m else -m if raw < -m else raw
        self.d_hat_raw, self.d_hat = raw, d
        dn = d / us
        if self.n_c:                                               # §2.7 step 8
            self._dh = [dn] + self._dh[:-1]
        if self.n_f == 1:
            phis[0] = phi
            dhf[0] = dn
        else:
            phis.insert(0, phi)
            phis.pop()
            dhf.insert(0, dn)
            dhf.pop()
        self.steps += 1
        return d

    @property
    def P(self) -> list[float]:
        """The RLS covariance, packed upper triangle (a copy)."""
        return [x * self._sc for x in self._Q]

    @P.setter
    def P(self, value: list[float]) -> None:
        if len(value) != len(self._Q):
            raise ValueError(f"P needs {len(self._Q)} packed entries")
        self._Q = [float(x) for x in value]
        self._sc = 1.0

    def get_state(self) -> dict[str, list[float]]:
        """theta and the packed covariance, JSON-serializable (:meth:`set_state`)."""
        return {"theta": list(self.theta), "P": self.P}

    def set_state(self, state: Mapping[str, Any]) -> bool:
        """Restore theta and P if they fit this estimator; True when restored."""
        th, P = state.get("theta"), state.get("P")
        if not (isinstance(th, list) and isinstance(P, list)):
            return False
        if len(th) != self.n or len(P) != len(self.P):
            return False
        try:
            th_f = [float(x) for x in th]
            P_f = [float(x) for x in P]
        except (TypeError, ValueError):
            return False
        if not all(math.isfinite(x) for x in th_f + P_f):
            return False
        self.theta, self.P = th_f, P_f
        return True
