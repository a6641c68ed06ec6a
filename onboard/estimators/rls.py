"""Recursive least squares with forgetting and a bounded covariance (algorithms.md §3.4).

One regression ``a_k = phi_k^T theta + e_k`` per instance; the current pipeline runs one
per degree of freedom of its vehicle model (:mod:`onboard.estimators.vehicle_models`), and
any other pipeline may reuse it.

Update (algorithms.md §3.4)::

    e_k     = a_k - phi_k^T theta_{k-1}                      (a priori residual)
    S_k     = lambda_k + phi_k^T P_{k-1} phi_k
    K_k     = P_{k-1} phi_k / S_k
    theta_k = theta_{k-1} + K_k e_k
    P_k     = (P_{k-1} - K_k phi_k^T P_{k-1}) / lambda_k

Plain exponential forgetting (``lambda_k = lambda``) makes ``P`` grow without bound when the
regressor is not exciting (a vehicle on a straight line): "covariance wind-up", after which
one noisy sample throws the parameters away. Two guards keep ``P`` bounded:

* variable-rate forgetting: ``lambda_k = 1 - (1 - lambda) * (1 - tr(P)/tr_max)``, i.e. full
  forgetting when the covariance is small and none as its trace approaches ``tr_max``
  (Fortescue-type, in trace form);
* exponential resetting (EFRA, Salgado, Goodwin & Middleton 1988): after the update
  ``P <- P + beta I - delta P^2``, which keeps ``P`` between about ``p_min`` and ``p_max``
  without any excitation assumption. The defaults scale with ``p0``:
  ``delta = (1/lambda - 1) / p_max`` (the equilibrium of an unexcited direction is then
  ``p_max``) and ``beta = (1 - lambda) p_min``. A fixed ``delta`` ignores the scale: with
  ``p0 = 1e6`` (needed when regressors are ~0.01), ``delta = 1e-6`` pulls ``P`` to ~1 and
  freezes the parameters at their initial values (the spheroid's yaw channel).

The residual variance ``sigma2`` is tracked with the same forgetting, so that the caller can
use the model error as process noise (the current pipeline does, for honest uncertainty).

Generated kernels
-----------------
This module is the one generator of straight-line RLS updates: Python source written per
number of parameters, on local floats and the packed upper triangle of ``P``
(:func:`packed_index`), compiled once and cached. At the 4-9 parameters of the pipelines
that is ~5x faster than numpy, whose per-call overhead dominates at this size. It makes

* :func:`rls_kernel`: the update above, one regression row (:class:`RecursiveLeastSquares`);
* :func:`two_row_rls_kernel`: the exact minimizer of a two-row weighted cost with
  forgetting (algorithms.md §2.6, the RLS of retrospective-cost input estimation); its
  lines (:func:`two_row_update_lines`) also make the kernel of
  :mod:`onboard.estimators.rcie`, which builds its rows inside the kernel.

``P`` is symmetric by construction (both updates are written in the symmetric form
``P - P Phi^T Gamma^-1 Phi P``, upper triangle only), so no symmetrization is needed.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from functools import cache
from typing import Any

import numpy as np

RlsKernel = Callable[..., "tuple[list[float], list[float], float, float, float]"]
"""``kernel(P, theta, phi, a, weight, forgetting, tr_max, beta, delta) -> (P+, theta+, e,
lam, s)``: see :func:`rls_kernel`."""
TwoRowKernel = Callable[..., "tuple[list[float], list[float], float] | None"]
"""``kernel(P, theta, a, b, e1, w_a, w_b, lam) -> (P+, theta+, trace(P+))`` or None: see
:func:`two_row_rls_kernel`."""


def packed_index(n: int) -> dict[tuple[int, int], int]:
    """Position of ``P[i][j]`` in the packed upper triangle (row-major) of an ``n x n``
    symmetric matrix (the storage of the generated float kernels)."""
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


@cache
def rls_kernel(n: int) -> RlsKernel:
    """The update of :class:`RecursiveLeastSquares` for ``n`` parameters, as straight-line
    float code (the module docstring's equations, then EFRA):

    ``kernel(P, theta, phi, a, weight, forgetting, tr_max, beta, delta)
    -> (P+, theta+, e, lam, s)`` with ``P`` the packed upper triangle (``n (n+1)/2``
    floats), ``e`` the a priori residual, ``lam`` the variable forgetting factor and
    ``s = lam / weight + phi^T P phi``. With ``beta = delta = 0`` the EFRA step adds zero.
    """
    idx = packed_index(n)
    r = range(n)
    p = {(i, j): f"p{idx[(i, j)]}" for i in r for j in r}
    q = {(i, j): f"q{idx[(i, j)]}" for i in r for j in r}
    src = ["def kernel(P, th, phi, a, weight, forgetting, tr_max, beta, delta):",
           unpack_line("p", n * (n + 1) // 2, "P"), unpack_line("t", n, "th"),
           unpack_line("f", n, "phi")]
    add = src.append
    for i in r:  # P phi
        add(f"    g{i} = " + " + ".join(f"{p[(i, j)]}*f{j}" for j in r))
    add("    e = a - (" + " + ".join(f"f{i}*t{i}" for i in r) + ")")
    add("    tr = " + " + ".join(p[(i, i)] for i in r))
    add("    lam = 1.0 - (1.0 - forgetting) * max(0.0, 1.0 - tr / tr_max)")
    add("    s = lam / weight + (" + " + ".join(f"f{i}*g{i}" for i in r) + ")")
    for i in r:
        add(f"    k{i} = g{i} / s")
    for i in r:  # (P - K (P phi)^T) / lam, upper triangle
        for j in range(i, n):
            add(f"    {q[(i, j)]} = ({p[(i, j)]} - k{i}*g{j}) / lam")
    terms = []
    for i in r:  # + beta I - delta P^2 (EFRA)
        for j in range(i, n):
            pp = " + ".join(f"{q[(i, k)]}*{q[(k, j)]}" for k in r)
            terms.append(f"{q[(i, j)]}" + (" + beta" if i == j else "") + f" - delta*({pp})")
    add("    return [" + ", ".join(terms) + "], [" + ", ".join(
        f"t{i} + k{i}*e" for i in r) + "], e, lam, s")
    return compile_kernel(src, f"rls_kernel({n})")


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


@cache
def two_row_rls_kernel(n: int) -> TwoRowKernel:
    """The two-row RLS update (algorithms.md §2.6, :func:`two_row_update_lines`) for ``n``
    parameters, as straight-line float code.

    ``kernel(P, theta, a, b, e1, w_a, w_b, lam) -> (P+, theta+, trace(P+))``, or None when
    ``Gamma`` is not positive definite:

    * ``P``: packed upper triangle of the covariance (``n (n+1)/2`` floats);
    * ``a``: first row (weight ``R_a``), ``e1`` its residual ``z~_1``;
    * ``b``: second row (weight ``R_b``, target 0);
    * ``w_a = lambda / R_a``, ``w_b = lambda / R_b``: the diagonal of ``lambda R~^-1``;
    * ``lam``: forgetting factor lambda.
    """
    src = ["def kernel(P, th, a, b, e1, wa, wb, lam):",
           "    sc = 1.0",
           unpack_line("p", n * (n + 1) // 2, "P"), unpack_line("t", n, "th"),
           unpack_line("a", n, "a"), unpack_line("b", n, "b")]
    src += two_row_update_lines(n)
    src.append("    return [x * sn for x in Q], [" + ", ".join(f"n{i}" for i in range(n))
               + "], tr")
    return compile_kernel(src, f"two_row_rls_kernel({n})")


class RecursiveLeastSquares:
    """RLS with forgetting, bounded covariance and a residual-variance estimate.

    Attributes (read them, do not assign, except ``P`` to set a prior):
        theta: parameter estimate, shape (n,) (a new array on each read).
        P: parameter covariance (in units of ``sigma2``), shape (n, n) (a new array on
            each read; kept as a packed upper triangle of floats).
        e: last a priori residual ``a - phi^T theta`` (units of ``a``).
        S: last residual variance predicted from ``P`` and ``sigma2``.
        nis: last normalized residual ``e^2 / S`` (about 1 when consistent).
        sigma2: forgetting-weighted residual variance (units of ``a`` squared).
        n_updates: number of updates applied.
    """

    def __init__(
        self,
        n: int,
        *,
        forgetting: float = 0.995,
        p0: float = 1e3,
        tr_max: float | None = None,
        p_min: float | None = None,
        p_max: float | None = None,
        beta: float | None = None,
        delta: float | None = None,
        sigma2_0: float = 1e-2,
        theta0: Sequence[float] | None = None,
        names: Sequence[str] | None = None,
    ) -> None:
        """Args:
            n: number of parameters.
            forgetting: lambda in (0, 1]; 0.995 at 10 Hz is a 20 s memory.
            p0: initial covariance ``p0 * I`` (regressors should be normalized to O(1)).
            tr_max: covariance trace at which forgetting stops (default ``n * p0``).
            p_min, p_max: EFRA bounds (default ``1e-6 p0`` and ``p0``).
            beta, delta: explicit EFRA terms (override p_min / p_max; 0 disables).
            sigma2_0: initial residual variance.
            theta0: initial parameters (zeros by default).
            names: optional parameter names, for :meth:`as_dict` and the saved state.
        """
        if not 0.0 < forgetting <= 1.0:
            raise ValueError("forgetting must be in (0, 1]")
        self.n = n
        self.forgetting = forgetting
        self.p0 = p0
        self.tr_max = tr_max if tr_max is not None else n * p0
        p_min = p0 * 1e-6 if p_min is None else p_min
        p_max = p0 if p_max is None else p_max
        self.beta = (1.0 - forgetting) * p_min if beta is None else beta
        self.delta = (1.0 / forgetting - 1.0) / p_max if delta is None else delta
        self.names = tuple(names) if names is not None else tuple(f"p{i}" for i in range(n))
        self._kernel = rls_kernel(n)
        self._theta: list[float] = [0.0] * n if theta0 is None else [
            float(v) for v in theta0]
        self._P: list[float] = []
        self.P = np.eye(n) * p0
        self.sigma2 = sigma2_0
        self.e = 0.0
        self.S = sigma2_0
        self.nis = 0.0
        self.n_updates = 0

    @property
    def theta(self) -> np.ndarray:
        """The parameter estimate, shape (n,) (a new array)."""
        return np.array(self._theta)

    @property
    def P(self) -> np.ndarray:
        """The parameter covariance in units of ``sigma2``, shape (n, n) (a new array)."""
        return np.array(unpack(self._P, self.n))

    @P.setter
    def P(self, P: np.ndarray) -> None:
        """Set the covariance (its symmetric part)."""
        P = np.asarray(P, float)
        self._P = [0.5 * (float(P[i, j]) + float(P[j, i]))
                   for i in range(self.n) for j in range(i, self.n)]

    def predict(self, phi: Sequence[float]) -> float:
        """Model output ``phi^T theta``."""
        return float(np.asarray(phi, float) @ self.theta)

    def prediction_variance(self, phi: Sequence[float]) -> float:
        """Variance of ``a`` about ``phi^T theta``: ``sigma2 (1 + phi^T P phi)``."""
        phi = np.asarray(phi, float)
        return float(self.sigma2 * (1.0 + phi @ self.P @ phi))

    def update(self, phi: Sequence[float], a: float, weight: float = 1.0) -> float:
        """Fold in one sample ``a = phi^T theta + e``; returns the a priori residual.

        ``weight`` in (0, 1] scales the sample's information (1 / relative variance), so a
        sample taken while the inputs are uncertain counts less.
        """
        self._P, self._theta, e, lam, s = self._kernel(
            self._P, self._theta, [float(v) for v in phi], float(a),
            max(weight, 1e-9), self.forgetting, self.tr_max, self.beta, self.delta)
        self.S = self.sigma2 * s / lam
        self.e = e
        self.nis = e * e / self.S if self.S > 0 else 0.0
        # a posteriori residual variance, forgetting-weighted (innovation / s is the
        # a posteriori residual of the standard RLS identity).
        self.sigma2 = self.forgetting * self.sigma2 + (1.0 - self.forgetting) * e * e * lam / s
        self.n_updates += 1
        return e

    def as_dict(self) -> dict[str, float]:
        """Parameters by name."""
        return {k: float(v) for k, v in zip(self.names, self.theta)}

    def get_state(self) -> dict[str, Any]:
        """JSON-serializable state (parameters, covariance, residual variance)."""
        return {
            "names": list(self.names),
            "theta": self.theta.tolist(),
            "P": self.P.tolist(),
            "sigma2": self.sigma2,
            "n_updates": self.n_updates,
        }

    def set_state(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`get_state`; ignored if the parameter names do not match."""
        try:
            if tuple(state["names"]) != self.names:
                return
            theta = np.asarray(state["theta"], float)
            P = np.asarray(state["P"], float)
            if theta.shape != (self.n,) or P.shape != (self.n, self.n):
                return
            if not (np.all(np.isfinite(theta)) and np.all(np.isfinite(P))):
                return
            self._theta = theta.tolist()
            self.P = P
            self.sigma2 = float(state.get("sigma2", self.sigma2))
            self.n_updates = int(state.get("n_updates", 0))
        except (KeyError, TypeError, ValueError):
            return
