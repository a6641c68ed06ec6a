"""Nonlinear MPC of the BlueROV2 in 4 DOF (surge, sway, heave, yaw), casadi.

Paper §IV (eqs. 27-29) and algorithms.md §5.2, cleaned of the public code's defects:

* the decision variables are the six thruster forces ``T`` (N), the wrench
  ``U = [X, Y, Z, N] = B T`` with the vehicle's allocation matrix ``B`` (4 x 6), so a
  disturbance estimate in N adds to the force balance as it is (no empirical
  ``compensate_coef``) and the input limits are the thrusters' own,
  ``-30 N <= T_i <= 40 N``, instead of a box ``|u_i| <= 50`` in unstated units (the whole
  attainable wrench set, not the smaller one of a fixed pseudo-inverse allocation);
* the reference is sampled at the model's own interval ``dt`` (the public code previews a
  0.05 s-sampled trajectory over an 0.0125 s grid, i.e. 4x fast).

Prediction model (state ``x = [N, E, D, psi, u, v, w, r]``, roll and pitch taken as zero,
the BlueROV2 being passively stable in both), Fossen (2021) eqs. 6.xx in 4 DOF with the
rigid-body and added-mass Coriolis terms that the paper drops (on a 2 m circle at 1.5 m/s
they are worth ~15 N)::

    N' = cos(psi) u - sin(psi) v        E' = sin(psi) u + cos(psi) v
    D' = w                               psi' = r
    (m + A_u) u' = X + (m + A_v) v r - (d_lu + d_nu |u|) u + xi_x
    (m + A_v) v' = Y - (m + A_u) u r - (d_lv + d_nv |v|) v + xi_y
    (m + A_w) w' = Z + (W - B)       - (d_lw + d_nw |w|) w + xi_z
    (I_z + A_r) r' = N + (A_u - A_v) u v - (d_lr + d_nr |r|) r

``xi`` is zero for the plain NMPC; the AMPC (:mod:`sitl.controllers.ampc`) sets it from the
ESESO estimate, as a force fixed in the earth frame over the horizon (body components
turn with the predicted yaw), or fixed in the body frame (the paper) on request.

Optimal control problem (eq. 28), multiple shooting, one RK4 step per interval::

    min sum_k |x_k - r_k|^2_Q + |T_k|^2_R + |T_k - T_{k-1}|^2_Rd  +  |x_N - r_N|^2_QN
    s.t. x_{k+1} = RK4(x_k, B T_k, dt),  t_min <= T_k <= t_max,  x_0 = x_hat

The horizon is N = 20 intervals of 0.05 s (1 s, the paper's preview, sampled at the
control rate instead of 80 x 0.0125 s). Solver: casadi ``sqpmethod`` with the exact
Gauss-Newton Hessian of the least-squares cost and the ``osqp`` QP solver (box input
constraints only; ``proxqp`` gives the same answers, slower), warm
started from the previous solution shifted by one interval, one SQP iteration per
control period (a real-time iteration, as acados' SQP_RTI in the paper).
``solve_time_stats`` measures it for ``onboard bench``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from onboard.core.messages import EstimateRecord
from onboard.sitl.controllers.base import (
    Bluerov2Params,
    CircleReference,
    ControlOutput,
    state_from_record,
)

NX = 8
NT = 6
"""Number of thrusters (decision inputs per interval)."""


@dataclass(frozen=True)
class NmpcTuning:
    """Horizon, weights and solver options [DEFAULT, tuned on ``bluerov2-circle``].

    The paper: N = 80 over 1 s, Q = [300 300 150 | 10 10 150 | 10 10 10 | 10 10 10] on
    [x y z | phi theta psi | u v w | p q r] and R = [1 1 1 0.5] on inputs of unstated
    scale. The state weights are the paper's; the input weights are per thruster newton,
    small (a 40 N thrust costs as much as a 4 cm position error) so that the controller
    does not trade position error for thrust, with a rate penalty for smoothness.
    """

    horizon: int = 20
    dt: float = 0.05
    q_position: tuple[float, float, float] = (300.0, 300.0, 150.0)
    q_yaw: float = 150.0
    q_velocity: tuple[float, float, float] = (10.0, 10.0, 10.0)
    q_yaw_rate: float = 10.0
    terminal_scale: float = 2.0
    r_thrust: float = 3e-4
    r_rate: float = 2e-3
    sqp_iterations: int = 1
    qp_solver: str = "osqp"


def _dynamics(p: Bluerov2Params) -> ca.Function:
    """Continuous-time model ``x' = f(x, U, xi_b)``, ``U = [X, Y, Z, N]`` (module docstring)."""
    x = ca.SX.sym("x", NX)
    U = ca.SX.sym("U", 4)
    xi = ca.SX.sym("xi", 3)
    _, _, _, psi, u, v, w, r = (x[i] for i in range(NX))
    Au, Av, Aw, Ar = p.added_mass
    dl, dn = p.damping_linear, p.damping_quadratic
    m = p.mass
    WB = p.weight - p.buoyancy
    # smooth |.| keeps the Gauss-Newton model differentiable at 0
    sabs = lambda s: ca.sqrt(s * s + 1e-4)  # noqa: E731
    xdot = ca.vertcat(
        ca.cos(psi) * u - ca.sin(psi) * v,
        ca.sin(psi) * u + ca.cos(psi) * v,
        w,
        r,
        (U[0] + (m + Av) * v * r - (dl[0] + dn[0] * sabs(u)) * u + xi[0]) / (m + Au),
        (U[1] - (m + Au) * u * r - (dl[1] + dn[1] * sabs(v)) * v + xi[1]) / (m + Av),
        (U[2] + WB - (dl[2] + dn[2] * sabs(w)) * w + xi[2]) / (m + Aw),
        (U[3] + (Au - Av) * u * v - (dl[3] + dn[3] * sabs(r)) * r) / (p.inertia_z + Ar),
    )
    return ca.Function("f", [x, U, xi], [xdot])


def _rk4(f: ca.Function, x: ca.SX, U: ca.SX, xi: ca.SX, h: float) -> ca.SX:
    k1 = f(x, U, xi)
    k2 = f(x + 0.5 * h * k1, U, xi)
    k3 = f(x + 0.5 * h * k2, U, xi)
    k4 = f(x + h * k3, U, xi)
    return x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


class Nmpc:
    """The NMPC (``nmpc``); the AMPC subclasses it and only supplies a disturbance."""

    name = "nmpc"

    def __init__(self, params: Bluerov2Params | None = None, tuning: NmpcTuning | None = None,
                 disturbance_frame: str = "earth") -> None:
        if disturbance_frame not in ("earth", "body"):
            raise ValueError("disturbance_frame must be 'earth' or 'body'")
        self.p = params or Bluerov2Params()
        self.tn = tuning or NmpcTuning()
        self.disturbance_frame = disturbance_frame
        self._build()
        self._w0: np.ndarray | None = None
        self._lam_g: np.ndarray | None = None
        self._lam_x: np.ndarray | None = None
        self._t_prev = np.zeros(NT)
        self.solve_times: list[float] = []
        """Wall-clock time of each solve (s)."""
        self.cpu_times: list[float] = []
        """Process CPU time of each solve (s): unaffected by other load on the machine."""
        self.failures = 0

    # ------------------------------------------------------------------ problem
    def _build(self) -> None:
        """The OCP as an NLP; variables ordered stage-wise ``[x_0, T_0, x_1, T_1, ...,
        x_N]`` and the initial state fixed through the variable bounds."""
        tn, p = self.tn, self.p
        N, h = tn.horizon, tn.dt
        f = _dynamics(p)
        B = ca.DM(p.B)
        Xs = [ca.SX.sym(f"x{k}", NX) for k in range(N + 1)]
        Ts = [ca.SX.sym(f"t{k}", NT) for k in range(N)]
        # parameters: reference (8 x (N+1)), disturbance (3), previous thrusts (6)
        P = ca.SX.sym("P", NX * (N + 1) + 3 + NT)
        ref = ca.reshape(P[0:NX * (N + 1)], NX, N + 1)
        off = NX * (N + 1)
        xi_p = P[off:off + 3]
        t_prev = P[off + 3:off + 3 + NT]
        sq = np.sqrt(np.array([*tn.q_position, tn.q_yaw, *tn.q_velocity, tn.q_yaw_rate]))
        w: list[ca.SX] = []
        g: list[ca.SX] = []
        res: list[ca.SX] = []
        psi0 = Xs[0][3]
        for k in range(N):
            if self.disturbance_frame == "earth":
                # xi_p is the disturbance in body axes at x_0; it is fixed in the earth
                # frame, so in body axes it turns by the predicted yaw change (level ROV)
                d = Xs[k][3] - psi0
                c, s = ca.cos(d), ca.sin(d)
                xi_b = ca.vertcat(c * xi_p[0] + s * xi_p[1], -s * xi_p[0] + c * xi_p[1], xi_p[2])
            else:
                xi_b = xi_p
            w += [Xs[k], Ts[k]]
            g.append(_rk4(f, Xs[k], ca.mtimes(B, Ts[k]), xi_b, h) - Xs[k + 1])
            dT = Ts[k] - (t_prev if k == 0 else Ts[k - 1])
            res += [sq * (Xs[k] - ref[:, k]), math.sqrt(tn.r_thrust) * Ts[k],
                    math.sqrt(tn.r_rate) * dT]
        w.append(Xs[N])
        res.append(math.sqrt(tn.terminal_scale) * sq * (Xs[N] - ref[:, N]))
        wv = ca.vertcat(*w)
        r = ca.vertcat(*res)
        gv = ca.vertcat(*g)
        nlp = {"x": wv, "p": P, "f": 0.5 * ca.dot(r, r), "g": gv}
        J = ca.jacobian(r, wv)
        sigma = ca.SX.sym("sigma")
        lam = ca.SX.sym("lam", int(gv.shape[0]))
        hess_fn = ca.Function("nlp_hess_l", [wv, P, sigma, lam], [sigma * ca.mtimes(J.T, J)],
                              ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
        qp = tn.qp_solver if ca.has_conic(tn.qp_solver) else "qrqp"
        qp_opts: dict = {"error_on_fail": False}
        if qp == "osqp":
            qp_opts["osqp"] = {"verbose": False, "eps_abs": 1e-4, "eps_rel": 1e-4}
        elif qp == "qrqp":
            qp_opts.update(print_iter=False, print_header=False)
        opts: dict = {
            "qpsol": qp,
            "qpsol_options": qp_opts,
            "max_iter": tn.sqp_iterations,
            "print_header": False,
            "print_iteration": False,
            "print_status": False,
            "print_time": False,
            "error_on_fail": False,
            "hess_lag": hess_fn,
        }
        self.solver = ca.nlpsol("nmpc", "sqpmethod", nlp, opts)
        self._nw = int(wv.shape[0])
        self._ng = int(gv.shape[0])
        stage = NX + NT
        lbx = np.full(self._nw, -np.inf)
        ubx = np.full(self._nw, np.inf)
        for k in range(N):
            lbx[k * stage + NX:(k + 1) * stage] = p.thrust_min_n
            ubx[k * stage + NX:(k + 1) * stage] = p.thrust_max_n
        self._lbx, self._ubx = lbx, ubx

    # ------------------------------------------------------------------ use
    def disturbance(self, estimate: EstimateRecord) -> np.ndarray:
        """The disturbance the prediction model carries (N, body); none for the NMPC."""
        return np.zeros(3)

    def reference_matrix(self, t: float, reference: CircleReference, yaw_now: float) -> np.ndarray:
        """Reference states at ``t + k dt``, k = 0..N (8 x (N+1)), the yaw unwrapped near
        ``yaw_now`` so that the yaw error never jumps by 2 pi."""
        N, h = self.tn.horizon, self.tn.dt
        out = np.empty((NX, N + 1))
        prev = yaw_now
        for k in range(N + 1):
            rp = reference(t + k * h)
            yaw = prev + math.remainder(rp.yaw - prev, 2 * math.pi)
            prev = yaw
            out[:, k] = [*rp.position, yaw, *rp.velocity_body, rp.yaw_rate]
        return out

    def solve(self, x0: np.ndarray, ref: np.ndarray,
              xi: np.ndarray) -> tuple[np.ndarray, float, bool]:
        """Solve the OCP from state ``x0`` (8); returns (first thrusts N (6), solve time s,
        ok)."""
        N = self.tn.horizon
        stage = NX + NT
        P = np.concatenate([ref.T.reshape(-1), xi, self._t_prev])
        if self._w0 is None:
            w0 = np.zeros(self._nw)
            for k in range(N + 1):
                w0[k * stage:k * stage + NX] = ref[:, k]
        else:
            w0 = self._w0
            # the estimate's yaw is wrapped to (-pi, pi]: move the warm start's yaw onto the
            # same branch, or the single SQP iteration starts 2 pi away
            turns = round((x0[3] - w0[3]) / (2 * math.pi))
            if turns:
                w0[3::stage] += 2 * math.pi * turns
        w0[0:NX] = x0
        lbx, ubx = self._lbx.copy(), self._ubx.copy()
        lbx[0:NX] = x0
        ubx[0:NX] = x0
        t0 = time.perf_counter()
        c0 = time.process_time()
        sol = self.solver(x0=w0, p=P, lbx=lbx, ubx=ubx, lbg=0.0, ubg=0.0,
                          lam_g0=self._lam_g if self._lam_g is not None else 0.0,
                          lam_x0=self._lam_x if self._lam_x is not None else 0.0)
        dt = time.perf_counter() - t0
        self.cpu_times.append(time.process_time() - c0)
        w = np.asarray(sol["x"]).ravel()
        if not np.all(np.isfinite(w)):
            self.failures += 1
            self._w0 = self._lam_g = self._lam_x = None
            return self._t_prev.copy(), dt, False
        T0 = np.clip(w[NX:NX + NT], self.p.thrust_min_n, self.p.thrust_max_n)
        # warm start for the next call: shift by one interval
        nxt = np.empty_like(w)
        nxt[: self._nw - stage] = w[stage:]
        nxt[self._nw - stage:self._nw - NX] = w[self._nw - NX - NT:self._nw - NX]  # T_{N-1}
        nxt[self._nw - NX:] = w[self._nw - NX:]  # x_N
        self._w0 = nxt
        self._lam_g = np.asarray(sol["lam_g"]).ravel()
        self._lam_x = None
        return T0, dt, True

    def update(self, t: float, estimate: EstimateRecord,
               reference: CircleReference) -> ControlOutput:
        """Command for time ``t`` (s): solve from the estimated state, apply the first
        interval's thrusts."""
        x0 = state_from_record(estimate)
        ref = self.reference_matrix(t, reference, float(x0[3]))
        xi = self.disturbance(estimate)
        T, dt, ok = self.solve(x0, ref, xi)
        self.solve_times.append(dt)
        self._t_prev = T
        return ControlOutput(wrench=self.p.B @ T, thrusters=self.p.commands_from_forces(T),
                             solve_time_s=dt, status="ok" if ok else "failed")


class OffsetFreeNmpc(Nmpc):
    """The offset-free NMPC (``nmpc-of``): the NMPC with a constant input-disturbance model
    estimated from its own prediction error, the standard offset-free construction
    (Pannocchia & Rawlings 2003; Maeder, Borrelli & Morari 2009) and the fair baseline for
    the AMPC: both then carry a disturbance force, one from the ESESO, one from the
    controller's own model residual.

    At each update the state of the previous update is propagated through the prediction
    model (one RK4 step over the elapsed time, with the thrusts that were applied and the
    disturbance then estimated); the velocity residual ``e = nu - nu_pred`` (body, m/s)
    becomes a force ``M e / h`` (N, body, ``M = diag(m + A_u, m + A_v, m + A_w)``),
    turned into the earth frame with the current yaw, and the earth-frame disturbance
    integrates it::

        d_e <- d_e + L R(psi) M (nu - nu_pred) / h

    ``L`` = ``gain`` (0.1: at 20 Hz a time constant of 0.5 s, about the ESESO's
    disturbance settling, within 4 N after ~1 s), ``|d_e|`` clamped per axis to
    ``limit_n``. The disturbance is held fixed in the earth frame over the horizon as the
    AMPC's is. Everything the model gets wrong (mass, damping, thrust curve, lag, the
    push) lands in ``d_e``; with a constant push and a constant reference it removes the
    steady-state offset, as integral action does.
    """

    name = "nmpc-of"

    def __init__(self, params: Bluerov2Params | None = None, tuning: NmpcTuning | None = None,
                 disturbance_frame: str = "earth", gain: float = 0.1,
                 limit_n: float = 150.0) -> None:
        super().__init__(params, tuning, disturbance_frame)
        if not 0.0 < gain <= 1.0:
            raise ValueError("gain must be in (0, 1]")
        self.gain = gain
        self.limit_n = limit_n
        x = ca.SX.sym("x", NX)
        U = ca.SX.sym("U", 4)
        xi = ca.SX.sym("xi", 3)
        h = ca.SX.sym("h")
        self._predict = ca.Function("predict", [x, U, xi, h],
                                    [_rk4(_dynamics(self.p), x, U, xi, h)])
        p = self.p
        self._m3 = np.array([p.mass + p.added_mass[0], p.mass + p.added_mass[1],
                             p.mass + p.added_mass[2]])
        self.d_earth = np.zeros(3)
        """The estimated disturbance (N, north/east/down)."""
        self._prev: tuple[float, np.ndarray, np.ndarray, np.ndarray] | None = None

    def disturbance(self, estimate: EstimateRecord) -> np.ndarray:
        """The earth-frame disturbance after this update's residual, in body axes (N)."""
        x0 = state_from_record(estimate)
        t = float(estimate.t)
        if self._prev is not None:
            t_prev, x_prev, T_prev, xi_prev = self._prev
            h = t - t_prev
            if 0.0 < h <= 0.5:
                xp = np.asarray(self._predict(x_prev, self.p.B @ T_prev, xi_prev, h)).ravel()
                f_b = self._m3 * (x0[4:7] - xp[4:7]) / h
                c, s = math.cos(x0[3]), math.sin(x0[3])
                f_e = np.array([c * f_b[0] - s * f_b[1], s * f_b[0] + c * f_b[1], f_b[2]])
                if np.all(np.isfinite(f_e)):
                    self.d_earth = np.clip(self.d_earth + self.gain * f_e,
                                           -self.limit_n, self.limit_n)
        c, s = math.cos(x0[3]), math.sin(x0[3])
        de = self.d_earth
        xi = np.array([c * de[0] + s * de[1], -s * de[0] + c * de[1], de[2]])
        self._pending = (t, x0, xi)
        return xi

    def update(self, t: float, estimate: EstimateRecord,
               reference: CircleReference) -> ControlOutput:
        """As :meth:`Nmpc.update`, remembering the state, applied thrusts and disturbance
        for the next update's prediction residual."""
        out = super().update(t, estimate, reference)
        t0, x0, xi = self._pending
        self._prev = (t0, x0, self._t_prev.copy(), xi)
        return out


def solve_time_stats(n: int = 200, horizon: int | None = None,
                     disturbance: bool = True) -> dict[str, float]:
    """Bench (``onboard bench``): ``n`` solves of the AMPC problem along the circle, the
    state advanced by the prediction model itself under the [40, 40, 10] N push so that
    warm starts behave as in flight. Returns wall-clock p50/p99/max and CPU p50/p99 in
    ms, the horizon and the interval (s)."""
    tn = NmpcTuning() if horizon is None else NmpcTuning(horizon=horizon)
    ctl = Nmpc(tuning=tn)
    ref = CircleReference(speed=0.5)
    f = _dynamics(ctl.p)
    rp = ref(0.0)
    x = np.array([*rp.position, rp.yaw, 0.0, 0.0, 0.0, 0.0])
    x[0] += 0.3
    push = np.array([40.0, 40.0, 10.0])
    times = []
    for k in range(n):
        t = k * tn.dt
        c, s = math.cos(x[3]), math.sin(x[3])
        xi = np.array([c * push[0] + s * push[1], -s * push[0] + c * push[1], push[2]])
        r = ctl.reference_matrix(t, ref, float(x[3]))
        T, dt, _ = ctl.solve(x, r, xi if disturbance else np.zeros(3))
        ctl._t_prev = T
        times.append(dt)
        U = ctl.p.B @ T
        xd = ca.DM(x)
        for _ in range(5):
            xd = xd + 0.01 * f(xd, ca.DM(U), ca.DM(xi))
        x = np.asarray(xd).ravel()
    ms = np.array(times) * 1e3
    cpu = np.array(ctl.cpu_times) * 1e3
    return {"p50_ms": float(np.percentile(ms, 50)), "p99_ms": float(np.percentile(ms, 99)),
            "max_ms": float(ms.max()), "cpu_p50_ms": float(np.percentile(cpu, 50)),
            "cpu_p99_ms": float(np.percentile(cpu, 99)), "horizon": float(tn.horizon),
            "dt_s": tn.dt, "n": float(n)}
