"""The ESESO's compiled kernels against their numpy reference.

:mod:`onboard.estimators.eseso_kernel` (numba, the ``fast`` extra) computes the ESESO's
propagation, its Joseph update, the injection and reset, the thrust model, the products
around them and the pipeline's published values; :mod:`onboard.estimators.eseso_filter`
and :mod:`onboard.pipelines.eseso` are the readable reference. They must agree to
rounding: on random states and covariances, and on the real states of a replay (every
propagation, update and thrust update of the committed BlueROV2 log, the kernel run from
the reference's own state beside it). Agreement is measured per entry against the
entry's scale: a vector's largest component, and for a covariance ``sqrt(P_ii P_jj)``
(its entries span 1e-12 to 1e3 in their own units).
"""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
from pathlib import Path

import msgspec
import numpy as np
import pytest

pytest.importorskip("numba", reason="the ESESO kernels need numba: pip install 'onboard[fast]'")

from onboard.cli import main as cli_main  # noqa: E402
from onboard.core.pipeline_config import EsesoConfig  # noqa: E402
from onboard.core.so3 import exp_so3, log_so3  # noqa: E402
from onboard.estimators import eseso_filter, eseso_kernel, kalman  # noqa: E402
from onboard.estimators.eseso_filter import (  # noqa: E402
    KERNEL_ENV,
    N_ERR,
    TH,
    XI,
    EsesoFilter,
    Outcome,
    reset_covariance,
)
from onboard.pipelines.eseso import Eseso, filter_params  # noqa: E402
from tests.helpers.imports import REPO  # noqa: E402

TOL = 1e-12
"""Largest difference allowed, relative to the entry's scale (module docstring). Measured
at worst: 6.5e-16 (propagation), 1.2e-15 (gain, Joseph update and reset), 2.3e-15 (the
whole update), 3.4e-16 (thrust model), 3.4e-13 (the whole thrust update: its noise
scale's mean, whose sample ``y^T y - tr(H P H^T)`` cancels, the two ``H P H^T``
associated differently; the state 2.6e-15), 4.7e-15 (attitude update), 1.9e-16
(injection), 4.3e-16 (``y^T S^-1 y``) and 5.7e-17 (the published values) on the random
states below, 7.3e-15 on the replay's."""
GOLDEN_ROV = Path(__file__).resolve().parent / "data" / "replay" / "bluerov2-circle.tlog"
NOMINAL = ("p", "v", "R", "b_a", "b_g", "g", "xi", "b_ins")


def _gap(got: np.ndarray, want: np.ndarray) -> float:
    """The largest difference of ``got`` from ``want`` relative to its scale: for a square
    matrix with a positive diagonal (a covariance) ``sqrt(P_ii P_jj)``, else the largest
    entry."""
    got, want = np.asarray(got, float), np.asarray(want, float)
    if want.ndim == 2 and want.shape[0] == want.shape[1] > 3 and np.all(np.diag(want) > 0):
        d = np.sqrt(np.diag(want))
        scale = np.outer(d, d)
    else:
        scale = np.full(want.shape, max(float(np.max(np.abs(want))), 1e-300))
    return float(np.max(np.abs(got - want) / scale))


def _filters(model: str = "earth_fixed") -> tuple[EsesoFilter, EsesoFilter]:
    """A reference filter and a compiled one with the same parameters."""
    c = EsesoConfig()
    c = msgspec.structs.replace(c, process=msgspec.structs.replace(
        c.process, disturbance_model=model))
    ref, fast = EsesoFilter(filter_params(c)), EsesoFilter(filter_params(c))
    ref.compiled = False
    assert fast.compiled, "numba imports, so the kernels are used by default"
    return ref, fast


def _random_state(f: EsesoFilter, rng: np.random.Generator) -> None:
    """A random nominal state and a random covariance spanning the filter's scales."""
    f.initialize(exp_so3(rng.normal(size=3)), rng.normal(0.0, 50.0, size=3))
    f.v, f.b_a = rng.normal(0.0, 1.0, 3), rng.normal(0.0, 0.05, 3)
    f.b_g, f.xi = rng.normal(0.0, 0.01, 3), rng.normal(0.0, 30.0, 3)
    f.b_ins = rng.normal(0.0, 0.05, 2)
    sd = np.sqrt(np.diag(f.P)) * rng.uniform(0.1, 10.0, N_ERR)
    C = rng.normal(size=(N_ERR, N_ERR))
    C = C @ C.T / N_ERR + np.eye(N_ERR)
    C /= np.sqrt(np.outer(np.diag(C), np.diag(C)))
    f.P = C * np.outer(sd, sd)


def _same_state(ref: EsesoFilter, fast: EsesoFilter) -> None:
    """Everything of ``ref`` (the nominal state, ``P``, the adaptation's means) into
    ``fast``, which keeps its kernels."""
    for name, value in vars(ref).items():
        if name != "compiled":
            setattr(fast, name, copy.deepcopy(value))


ADAPTED = ("disturbance_excess", "_excess_ratio", "_excess_ratio_slow", "_excess_lag",
           "_last_thrust_u", "R_tau")
"""What an update adapts besides the state (the thrust's noise and published excess)."""


def _agreement(ref: EsesoFilter, fast: EsesoFilter) -> float:
    return max(_gap(getattr(fast, n), getattr(ref, n)) for n in NOMINAL + ("P",))


def _update_agreement(ref: EsesoFilter, fast: EsesoFilter) -> float:
    """:func:`_agreement` and what an update leaves besides the state: its innovation,
    ``S`` and NIS, the adaptation's means and scales, the thrust's noise, published
    excess and model terms; the flags and the keys of the means exactly."""
    assert fast.downweighted == ref.downweighted
    assert fast._consecutive == ref._consecutive
    assert fast._noise_mean.keys() == ref._noise_mean.keys()
    assert fast.noise_scale.keys() == ref.noise_scale.keys()
    gaps = [_agreement(ref, fast), _gap(fast.y, ref.y), _gap(fast.S, ref.S),
            abs(fast.nis - ref.nis) / max(ref.nis, 1e-300),
            _gap(fast.process_scale, ref.process_scale)]
    gaps += [_gap(getattr(fast, n), getattr(ref, n)) for n in ADAPTED]
    gaps += [_gap(fast._noise_mean[k], v) for k, v in ref._noise_mean.items()]
    gaps += [_gap(fast.noise_scale[k], v) for k, v in ref.noise_scale.items()]
    if ref._model_terms is not None:
        gaps.append(_gap(fast._model_terms, ref._model_terms))
    return max(gaps)


@pytest.mark.parametrize("model", ["earth_fixed", "body_fixed"])
def test_compiled_propagation_agrees_with_the_reference_on_random_states(model: str) -> None:
    rng = np.random.default_rng(29)
    ref, fast = _filters(model)
    for _ in range(200):
        _random_state(ref, rng)
        _same_state(ref, fast)
        f_m = np.array([0.0, 0.0, -9.81]) + rng.normal(0.0, 2.0, 3)
        w_m = rng.normal(0.0, 1.0, 3) * rng.choice([1e-9, 1.0])  # the small-angle series too
        dt = float(rng.uniform(0.005, 0.2))
        ref.propagate(f_m, w_m, dt)
        fast.propagate(f_m, w_m, dt)
        assert _agreement(ref, fast) <= TOL
        assert _gap(fast.F, ref.F) <= TOL  # the transition it exposes, built when read


@pytest.mark.parametrize("rows, only", [(1, None), (2, None), (3, None), (3, XI)])
def test_compiled_update_agrees_with_kalman_update(rows: int, only: slice | None) -> None:
    """The Kalman gain and the Joseph update (all states, and Schmidt-Kalman on ``xi``
    alone) and the reset, the blocks of :func:`.eseso_kernel.fuse`."""
    rng = np.random.default_rng(rows)
    ref, _ = _filters()
    for _ in range(200):
        _random_state(ref, rng)
        # sparse, each state's share of S of order one (a badly conditioned S would
        # amplify any rounding by its condition number, in both)
        H = rng.normal(size=(rows, N_ERR)) * (rng.uniform(size=(rows, N_ERR)) < 0.3)
        H /= np.sqrt(np.diag(ref.P))
        A = rng.normal(0.0, 0.3, size=(rows, rows))
        Rm = A @ A.T + np.diag(rng.uniform(0.5, 2.0, rows))  # correlated, well conditioned
        y = rng.normal(size=rows) * 3.0
        want = kalman.update(np.zeros(N_ERR), ref.P, y, Rm, H, keep=only, symmetric=True,
                             inverse=np.linalg.inv)
        lo, hi = (0, N_ERR) if only is None else (only.start, only.stop)
        PHt = eseso_kernel._mmt(ref.P, H)
        S, nis, K, ok = eseso_kernel._gain(PHt, eseso_kernel._mm(H, PHt), y, Rm, lo, hi)
        assert ok
        P = np.empty_like(ref.P)
        eseso_kernel._joseph_into(ref.P, H, K, Rm, P)
        assert _gap(K @ y, want.x) <= TOL and _gap(P, want.P) <= TOL
        assert _gap(S, want.S) <= TOL and abs(nis - want.nis) <= TOL * want.nis
        in_place = ref.P.copy()
        eseso_kernel._joseph_into(in_place, H, K, Rm, in_place)
        assert np.array_equal(in_place, P)
        dtheta = rng.normal(0.0, 0.05, 3)
        eseso_kernel._reset_into(P, dtheta)
        assert _gap(P, reset_covariance(want.P, dtheta)) <= TOL


@pytest.mark.parametrize("with_wdot", [False, True])
def test_compiled_thrust_model_agrees_with_the_reference(with_wdot: bool) -> None:
    """:meth:`EsesoFilter.h_tau` (the force and its Jacobian) on random states."""
    rng = np.random.default_rng(14)
    ref, fast = _filters()
    for _ in range(200):
        _random_state(ref, rng)
        _same_state(ref, fast)
        f_m = np.array([0.0, 0.0, -9.81]) + rng.normal(0.0, 2.0, 3)
        w_m = rng.normal(0.0, 1.0, 3)
        wdot = rng.normal(0.0, 3.0, 3) if with_wdot else None
        (h_ref, H_ref), (h, H) = ref.h_tau(f_m, w_m, wdot), fast.h_tau(f_m, w_m, wdot)
        assert H.shape == H_ref.shape
        assert _gap(h, h_ref) <= TOL and _gap(H, H_ref) <= TOL


@pytest.mark.parametrize("channel, dvl_own_noise", [("depth", False), ("dvl", False),
                                                    ("dvl", True), ("zupt", False)])
def test_compiled_update_agrees_with_the_reference(channel: str, dvl_own_noise: bool) -> None:
    """:meth:`EsesoFilter.update` whole (:func:`.eseso_kernel.fuse`): the noise
    adaptation of a sensor channel (``depth``), of the IMU (``dvl``; with
    ``dvl_own_noise``, the IMU's scale relaxing instead) and none (``zupt``), the gate's
    three outcomes (fused, gated, recovered after the rejections in a row)."""
    rng = np.random.default_rng(len(channel))
    ref, fast = _filters()
    outcomes = set()
    for _ in range(300):
        _random_state(ref, rng)
        ref._noise_mean = {ch: float(rng.uniform(0.5, 5.0)) for ch in ("depth", "process")}
        ref.process_scale = float(rng.uniform(1.0, 3.0))
        ref.dvl_own_noise = dvl_own_noise
        ref._consecutive = {channel: int(rng.integers(0, 6))}
        _same_state(ref, fast)
        rows = 1 if channel == "depth" else 3
        H = rng.normal(size=(rows, N_ERR)) * (rng.uniform(size=(rows, N_ERR)) < 0.3)
        H /= np.sqrt(np.diag(ref.P))
        Rm = np.diag(rng.uniform(0.5, 2.0, rows))
        y = rng.normal(size=rows) * rng.choice([1.0, 10.0])  # beyond the gate at times
        want = ref.update(channel, y, H, Rm, t=1.0, source="s")
        got = fast.update(channel, y, H, Rm, t=1.0, source="s")
        assert got is want
        outcomes.add(want)
        assert _update_agreement(ref, fast) <= TOL
        assert fast.innovations[-1].accepted == ref.innovations[-1].accepted
    assert outcomes == set(Outcome)


@pytest.mark.parametrize("states", ["disturbance", "all"])
def test_compiled_thrust_update_agrees_with_the_reference(states: str) -> None:
    """:meth:`EsesoFilter.update_thrust` whole (:func:`.eseso_kernel.thrust_update`) on
    random states, the model terms and the excess's means too, down-weighted or not."""
    rng = np.random.default_rng(len(states))
    c = EsesoConfig()
    c = msgspec.structs.replace(c, thrust_states=states)
    ref, fast = EsesoFilter(filter_params(c)), EsesoFilter(filter_params(c))
    ref.compiled = False
    weights = set()
    for i in range(300):
        _random_state(ref, rng)
        ref._model_terms = None if i % 10 == 0 else rng.normal(0.0, 20.0, (2, 3))
        ref._excess_ratio = rng.uniform(0.2, 5.0, 3)
        ref._excess_ratio_slow = rng.uniform(0.2, 5.0, 3)
        ref._excess_lag = rng.uniform(-1.0, 3.0, 3)
        ref._last_thrust_u = rng.normal(0.0, 2.0, 3)
        ref._noise_mean = {"thrust": float(rng.uniform(0.5, 5.0))}
        ref.process_scale = float(rng.uniform(1.0, 3.0))
        _same_state(ref, fast)
        f_m = np.array([0.0, 0.0, -9.81]) + rng.normal(0.0, 2.0, 3)
        w_m, wdot = rng.normal(0.0, 1.0, 3), rng.normal(0.0, 3.0, 3)
        tau = rng.normal(0.0, 30.0, 3)
        wdot_dt = None if i % 7 == 0 else 0.02
        want = ref.update_thrust(f_m, w_m, wdot, tau, wdot_dt=wdot_dt, t=1.0)
        got = fast.update_thrust(f_m, w_m, wdot, tau, wdot_dt=wdot_dt, t=1.0)
        assert got is want
        weights.add(ref.downweighted)
        assert _update_agreement(ref, fast) <= TOL
    assert weights == {False, True}


def test_compiled_attitude_update_agrees_with_the_reference() -> None:
    """:meth:`EsesoFilter.update_attitude` (its innovation ``Log(R^T R_meas)`` and noise
    compiled) on random states, and Log itself near zero, at moderate angles and within
    :data:`.eseso_kernel._LOG_NEAR_PI` of pi, where it takes another formula."""
    rng = np.random.default_rng(41)
    ref, fast = _filters()
    for _ in range(200):
        _random_state(ref, rng)
        _same_state(ref, fast)
        R_meas = ref.R @ exp_so3(rng.normal(0.0, 0.05, 3))
        roll, pitch = rng.uniform(-1.0, 1.0, 2)
        var_rp, var_yaw = rng.uniform(1e-5, 1e-3, 2)  # S well conditioned (as above)
        want = ref.update_attitude(R_meas, roll, pitch, var_rp, var_yaw, t=1.0)
        assert fast.update_attitude(R_meas, roll, pitch, var_rp, var_yaw, t=1.0) is want
        assert _update_agreement(ref, fast) <= TOL
    for _ in range(300):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = rng.choice([rng.uniform(0.0, 1e-6), rng.uniform(0.0, 3.0),
                            np.pi - rng.uniform(0.0, 1e-4)])
        R = exp_so3(angle * axis)
        assert _gap(eseso_kernel.log_so3(R), log_so3(R)) <= TOL


def test_compiled_injection_and_huber_test_agree_with_the_reference() -> None:
    """The injection of a correction into the one-array state, and ``y^T S^-1 y``."""
    rng = np.random.default_rng(16)
    ref, fast = _filters()
    for _ in range(200):
        _random_state(ref, rng)
        _same_state(ref, fast)
        dx = rng.normal(size=N_ERR) * np.sqrt(np.diag(ref.P))
        ref.inject(dx)
        eseso_kernel._inject_into(fast.x, dx)
        assert _agreement(ref, fast) <= TOL
        H = rng.normal(size=(3, N_ERR)) / np.sqrt(np.diag(ref.P))
        S, y = ref._project(H) + np.eye(3), rng.normal(size=3) * 3.0
        want = float(y @ np.linalg.solve(S, y))
        assert abs(eseso_kernel.mahalanobis(S, y) - want) <= TOL * want


def test_compiled_estimates_agree_with_the_reference() -> None:
    """The ESESO pipeline's published values (:meth:`Eseso.estimates`) on random states,
    and a covariance with a NaN published as NaN by both."""
    rng = np.random.default_rng(37)
    ref, fast = Eseso(EsesoConfig()), Eseso(EsesoConfig())
    ref.filter.compiled = False
    for _ in range(200):
        _random_state(ref.filter, rng)
        ref.filter.disturbance_excess = rng.normal(0.0, 100.0, 3)
        _same_state(ref.filter, fast.filter)
        ref.w_m = fast.w_m = rng.normal(0.0, 1.0, 3)
        want, got = ref.estimates(), fast.estimates()
        assert list(got) == list(want) == list(Eseso.columns)
        assert _gap(np.array(list(got.values())), np.array(list(want.values()))) <= TOL
    ref.filter.P[0, 0] = fast.filter.P[0, 0] = np.nan
    assert np.isnan(ref.estimates()["std_north"]) and np.isnan(fast.estimates()["std_north"])


def test_compiled_divergence_test_agrees_with_the_reference() -> None:
    """:meth:`EsesoFilter.finite`: a non-finite covariance entry or position is
    divergence, in both; a non-finite bias is not looked at, in both."""
    start, _ = _filters()
    _random_state(start, np.random.default_rng(3))
    for where, value in [(None, 0.0), (("P", (4, 17)), np.nan), (("P", (0, 0)), np.inf),
                         (("p", 2), -np.inf), (("p", 0), np.nan), (("b_a", 1), np.nan)]:
        ref, fast = _filters()
        _same_state(start, ref)
        _same_state(start, fast)
        for f in (ref, fast):
            if where is not None:
                getattr(f, where[0])[where[1]] = value
        assert fast.finite() is ref.finite() is (where is None or where[0] == "b_a")


def test_a_singular_innovation_covariance_raises_in_both() -> None:
    ref, fast = _filters()
    for f in (ref, fast):
        f.initialize(np.eye(3), np.zeros(3))
        f.P[:] = 0.0
        with pytest.raises(np.linalg.LinAlgError):
            f.update_depth(1.0, 0.0)


def test_compiled_filter_agrees_on_every_step_of_a_real_replay(tmp_path: Path,
                                                               monkeypatch) -> None:
    """Every propagation, update, thrust update and attitude update (their models, noise,
    adaptation and Huber weight around the update) of the ESESO's replay of the committed
    BlueROV2 log (30 s: 1,499 propagations, 1,050 updates, 300 thrust and 300 attitude
    updates) is repeated from the same state by the compiled filter; the two must agree
    to :data:`TOL` (measured: 7.3e-15 at worst, an attitude update)."""
    methods = {name: getattr(EsesoFilter, name)
               for name in ("propagate", "update", "update_thrust", "update_attitude")}
    worst = dict.fromkeys(methods, 0.0)
    calls = dict.fromkeys(methods, 0)

    def twin(name, method):
        def checked(self: EsesoFilter, *args, **kwargs):
            if not self.compiled:
                return method(self, *args, **kwargs)
            ref = copy.deepcopy(self)
            ref.compiled = False
            out = method(ref, *args, **kwargs)
            got = method(self, *args, **kwargs)
            assert got == out
            worst[name] = max(worst[name], _agreement(ref, self) if name == "propagate"
                              else _update_agreement(ref, self))
            calls[name] += 1
            _same_state(ref, self)  # go on from the reference's state
            return out
        return checked

    for name, method in methods.items():
        monkeypatch.setattr(EsesoFilter, name, twin(name, method))
    assert cli_main(["replay", str(GOLDEN_ROV), "--out", str(tmp_path), "--no-plot",
                     "--pipelines", "eseso"]) == 0
    assert calls["propagate"] > 1000 and calls["update"] > 1000
    assert calls["update_thrust"] > 200 and calls["update_attitude"] > 200
    assert max(worst.values()) <= TOL, worst


def test_the_comparison_sees_a_difference_beyond_rounding() -> None:
    """A negative control: a covariance entry moved by 1e-10 of its scale, a small
    variance moved by 1e-10 of itself, and a vector component by 1e-10 of the vector's
    largest are each caught; a difference of 1e-14 is not."""
    rng = np.random.default_rng(5)
    ref, _ = _filters()
    _random_state(ref, rng)
    P = ref.P.copy()
    moved = P.copy()
    moved[TH.start, XI.start] += 1e-10 * np.sqrt(P[TH.start, TH.start] * P[XI.start, XI.start])
    assert _gap(moved, P) > TOL
    small = P.copy()
    small[12, 12] *= 1 + 1e-10  # a gyro-bias variance, ~1e-9 of the largest
    assert _gap(small, P) > TOL
    v = np.array([1.0, 1e-6, 3.0])
    assert _gap(v + np.array([0.0, 3e-10, 0.0]), v) > TOL
    assert _gap(P * (1 + 1e-14), P) <= TOL


def test_the_kernel_is_switched_off_by_the_environment(monkeypatch) -> None:
    monkeypatch.setenv(KERNEL_ENV, "0")
    assert eseso_filter.compiled_kernel() is None
    assert not EsesoFilter(filter_params(EsesoConfig())).compiled
    monkeypatch.setenv(KERNEL_ENV, "1")
    assert EsesoFilter(filter_params(EsesoConfig())).compiled


def test_the_kernels_blocks_are_the_filters() -> None:
    """The kernel names the error state's blocks and the nominal state's entries by offsets
    of its own (it cannot import the filter that imports it): they must be the filter's."""
    blocks = ("P_", "V_", "TH", "BA", "BG", "G_", "XI", "BI")
    for name in blocks:
        offset = getattr(eseso_kernel, "_" + name.rstrip("_"))
        assert offset == getattr(eseso_filter, name).start, name
    assert eseso_kernel._N == N_ERR
    for name in ("P", "V", "R", "BA", "BG", "G", "XI", "BI"):  # the nominal state's array
        assert getattr(eseso_kernel, "_X" + name) == getattr(eseso_filter, "X_" + name).start
    assert eseso_kernel._NX == eseso_filter.N_NOMINAL


WARM_THEN_REPLAY = """
import json, sys
from numba.core.registry import CPUDispatcher
from onboard.cli import main
from onboard.core.config import from_dict
from onboard.estimators import eseso_kernel
from onboard.pipelines.eseso import create

def signatures():
    return {name: len(f.signatures) for name, f in vars(eseso_kernel).items()
            if isinstance(f, CPUDispatcher)}

create(from_dict({"vehicle": {"class": "bluerov2"}}))
warm = signatures()
main(["replay", sys.argv[1], "--out", sys.argv[2], "--no-plot"])
print(json.dumps([warm, signatures()]))
"""


def test_a_pipeline_made_runs_its_replay_without_loading_another_kernel(tmp_path):
    """Making the ESESO pipeline loads (from numba's cache, or compiles) every kernel a
    replay then calls, with the types it calls them with (``warm_kernels``): a live
    service's ticks never wait on numba. In a fresh process, so that nothing is loaded
    before."""
    r = subprocess.run([sys.executable, "-c", WARM_THEN_REPLAY,
                        str(REPO / "tests" / "data" / "replay" / "bluerov2-circle.tlog"),
                        str(tmp_path / "out")], cwd=tmp_path, capture_output=True, text=True,
                       timeout=300, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert r.returncode == 0, r.stderr
    warm, after = json.loads(r.stdout.strip().splitlines()[-1])
    assert sum(warm.values()) >= 7, warm
    assert after == warm
