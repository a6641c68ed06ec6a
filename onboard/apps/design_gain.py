"""``onboard design-gain --config FILE [--out FILE]``: the high-gain observer's LMI, offline.

Solves (algorithms.md §3.1-§3.2; Kim, Fan & Bose 2018, eq. 15-16)

    find P = P^T > 0, Y, lambda > 0:   A^T P + P A - C^T Y^T - Y C + lambda I <= 0
    K = P^-1 Y

for the chain of the current observer (per earth axis ``z1 = V_g``, ``z2 = V_g'``: ``n_c = 2``
states, ``p = nd`` channels). The LMI is homogeneous, so it is normalized with ``lambda = 1``
and ``P >= I``, and ``||P||_2`` is minimized (``P <= t I``, minimize ``t``), which minimizes
``||P|| / lambda`` and hence ``gamma*``. ``||Y||_F <= y_max`` keeps ``K`` finite: without it
the optimum drives ``P`` towards singular and ``K`` towards 1e6 (as with a trace
normalization and maximized ``lambda``). It then computes the Lipschitz
constant of the model nonlinearity ``L_f = ||J_e||`` (largest damping rate of the
configured or default model over a range of speeds) and

    gamma* = max(1, 2 ||P||_2 L_f / lambda)          (algorithms.md §3.1)

and writes a JSON file read by :class:`onboard.estimators.hgo.GainDesign`. cvxpy is imported
here only; the service and the pipelines never import it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from onboard.core.config import CONFIG_DIR, Config, load, resolve
from onboard.core.errors import OutputFailed, UsageError
from onboard.core.outputs import Output, check as check_outputs
from onboard.core.vehicles import traits
from onboard.estimators.hgo import LIPSCHITZ_SPEEDS, chain_matrices, gamma_star
from onboard.estimators.hgo import model_lipschitz as hgo_lipschitz
from onboard.estimators.vehicle_models import RegressionModel
from onboard.pipelines.current import GAIN_DIR, model_kind


def solve_lmi(n_c: int = 2, p: int = 1, y_max: float = 10.0, eps: float = 1e-6,
              solver: str | None = None) -> dict[str, Any]:
    """Solve the LMI of Kim eq. (16) for a ``p``-channel chain of length ``n_c``.

    Returns ``{"K", "P", "lambda", "status", "solver", "max_eig_closed_loop",
    "lyapunov_max_eig"}`` with numpy-verified results. Raises RuntimeError if infeasible.
    """
    import cvxpy as cp  # offline only

    A, C = chain_matrices(n_c, p)
    n = n_c * p
    P = cp.Variable((n, n), symmetric=True)
    Y = cp.Variable((n, p))
    t = cp.Variable()
    lam = 1.0
    M = A.T @ P + P @ A - C.T @ Y.T - Y @ C + lam * np.eye(n)
    Msym = 0.5 * (M + M.T)
    cons = [P >> np.eye(n), P << t * np.eye(n), Msym << -eps * np.eye(n),
            cp.norm(Y, "fro") <= y_max * np.sqrt(p)]
    prob = cp.Problem(cp.Minimize(t), cons)
    tried = [solver] if solver else ["CLARABEL", "SCS"]
    status, used = "not solved", ""
    for s in tried:
        if s not in cp.installed_solvers():
            continue
        try:
            kw = {"eps_abs": 1e-9, "eps_rel": 1e-9} if s == "SCS" else {}
            prob.solve(solver=s, **kw)
        except cp.error.SolverError:
            continue
        status, used = prob.status, s
        if status == "optimal":
            break
    if status not in ("optimal", "optimal_inaccurate"):
        raise RuntimeError(f"LMI not solved: status {status}")
    Pv = 0.5 * (P.value + P.value.T)
    K = np.linalg.solve(Pv, Y.value)
    Acl = A - K @ C
    lyap = Acl.T @ Pv + Pv @ Acl
    out = {
        "K": K, "P": Pv, "lambda": lam, "status": status, "solver": used,
        "max_eig_closed_loop": float(np.max(np.linalg.eigvals(Acl).real)),
        "lyapunov_max_eig": float(np.max(np.linalg.eigvalsh(0.5 * (lyap + lyap.T)))),
    }
    if out["max_eig_closed_loop"] >= 0 or out["lyapunov_max_eig"] > -0.9 * out["lambda"]:
        raise RuntimeError(f"LMI solution fails verification: {out}")
    return out


def model_lipschitz(cfg: Config, speeds: tuple[float, ...] = LIPSCHITZ_SPEEDS) -> float:
    """``max ||d nu_r'/d nu_r||_2`` of the configured (or default) model over ``speeds``
    (m/s, surge) with small sway/heave and the nominal rates of a turn (0.1 rad/s);
    :func:`onboard.estimators.hgo.model_lipschitz` of the configured coefficients."""
    ccfg = cfg.pipelines.current
    model = RegressionModel(model_kind(cfg, ccfg))
    return hgo_lipschitz(model, model.thetas_from_mapping(ccfg.model), speeds)


def design(cfg: Config, margin: float = 1.0) -> dict[str, Any]:
    """The gain file's content for ``cfg`` (a JSON-serializable dict): the LMI gain ``K``,
    ``gamma* = max(1, 2 ||P|| L_f / lambda)`` and the gain the observer runs at, ``gamma =
    margin * gamma*`` (fixed: ``gamma_0 = gamma_max = gamma``, ``rho = 0``; anti-peaking by
    saturating the injected innovation, :class:`.CurrentHighGainObserver`)."""
    ccfg = cfg.pipelines.current
    nd = RegressionModel(model_kind(cfg, ccfg)).nd
    sol = solve_lmi(2, nd)
    lf = model_lipschitz(cfg)
    gs = gamma_star(sol["P"], sol["lambda"], lf)
    rate = (cfg.sensors.dvl.rate_hz if traits(cfg.vehicle.vehicle_class).underwater
            else cfg.sensors.gnss.rate_hz)
    gamma = margin * gs
    return {
        "comment": "HGO gain for the current observer (onboard design-gain); chain z1 = V_g, "
                   "z2 = V_g' per earth axis; K = P^-1 Y from Kim et al. (2018) eq. 16",
        "vehicle_class": cfg.vehicle.vehicle_class,
        "n_c": 2, "p": nd,
        "K": sol["K"].tolist(), "P": sol["P"].tolist(), "lambda": sol["lambda"],
        "solver": sol["solver"], "status": sol["status"],
        "max_eig_closed_loop": sol["max_eig_closed_loop"],
        "lyapunov_max_eig": sol["lyapunov_max_eig"],
        "lipschitz": lf, "gamma_star": gs, "gamma": gamma,
        # the observer runs at gamma >= gamma* (fixed); the injection is integrated with
        # sub-steps between samples (held output), so no discrete-time cap applies
        "gamma_0": gamma, "rho": 0.0, "gamma_max": gamma,
        "velocity_rate_hz": rate, "time_scale_s": 1.0,
    }


def default_out(config_arg: str, cfg: Config) -> Path:
    """For a bundled config, its class's file among the bundled gains (:data:`GAIN_DIR`:
    ``config/gains/<class>.json`` of a checkout, inside the package when installed),
    where the current pipeline loads it; else ``<config>.gain.json`` beside the file."""
    p = resolve(config_arg)
    if p.resolve().parent == CONFIG_DIR.resolve():
        return GAIN_DIR / f"{cfg.vehicle.vehicle_class}.json"
    return p.with_suffix(".gain.json")


def main(args: argparse.Namespace) -> int:
    """Entry point of ``onboard design-gain``."""
    cfg = load(args.config)
    given = getattr(args, "out", None)
    out = Path(given) if given else default_out(args.config, cfg)
    check_outputs([Output("--out" if given else "the default --out", out, replace=not given)],
                  force=bool(getattr(args, "force", False)))
    try:
        import cvxpy  # noqa: F401
    except ImportError:
        raise UsageError("design-gain needs cvxpy: pip install 'onboard[design]'") from None
    try:
        data = design(cfg)
    except RuntimeError as err:
        print(f"onboard design-gain: {err}", file=sys.stderr)
        return 1
    try:
        out.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    except OSError as err:  # checked before the solve: a full disk, a removed folder
        raise OutputFailed(f"{out}: cannot write: {err.strerror or err}") from None
    k = np.asarray(data["K"])
    print(f"{out}: K chain = [{k[0, 0]:.4f}, {k[1, 0]:.4f}], lambda = {data['lambda']:.4f}, "
          f"||P|| = {np.linalg.norm(np.asarray(data['P']), 2):.3f}, "
          f"L_f = {data['lipschitz']:.3f} 1/s, "
          f"gamma* = {data['gamma_star']:.3f}, gamma = {data['gamma']:.3f}, "
          f"increasing gain {data['gamma_0']:.2f} -> {data['gamma_max']:.3f}")
    if out.parent.resolve() != GAIN_DIR.resolve():
        print(f"set [pipelines.current.hgo] gain_file = \"{out}\" and [pipelines.current] "
              "observer = \"hgo\"")
    return 0


__all__ = ["design", "main", "model_lipschitz", "solve_lmi"]
