"""Adaptive input estimation (algorithms.md §2.3-§2.8) and the ``aie`` pipeline."""

from __future__ import annotations

import json
import math

import msgspec
import numpy as np
import pytest

from onboard.core.config import ConfigError, from_dict
from onboard.estimators.axis_model import AxisModel, discretize
from onboard.estimators.rcie import Rcie, rcie_kernel, unpack
from onboard.pipelines import aie as aie_mod
from onboard.pipelines import kf as kf_mod
from onboard.core.pipeline_config import AieConfig, KfConfig
from onboard.pipelines.aie import axis_filter
from tests.helpers.first_order_boat import SimConfig, run_pipelines, score, simulate


def _textbook_rls(P, th, a, b, e1, rz, rd, lam):
    """§2.6 in matrix form: Gamma, P+, theta+ (numpy reference)."""
    Phi = np.vstack([a, b])
    Rt = np.diag([rz, rd])
    G = lam * np.linalg.inv(Rt) + Phi @ P @ Phi.T
    Pn = (P - P @ Phi.T @ np.linalg.solve(G, Phi @ P)) / lam
    zt = np.array([e1, 0.0])
    thn = th - Pn @ Phi.T @ Rt @ (zt + Phi @ th)
    return Pn, thn


@pytest.mark.parametrize("n", [1, 3, 9])
def test_rls_kernel_matches_the_textbook_update_and_information_form(n: int) -> None:
    rng = np.random.default_rng(n)
    M = rng.standard_normal((n, n))
    P = M @ M.T + np.eye(n)
    th = rng.standard_normal(n)
    a, b = rng.standard_normal(n), rng.standard_normal(n)
    e1, rz, rd, lam = 0.7, 1.0, 0.3, 0.98
    packed = [P[i, j] for i in range(n) for j in range(i, n)]
    # rows a = h s with h = 1 and b = g (the size penalty)
    Qn, sn, thn, tr, _ = rcie_kernel(n, False)(packed, 1.0, th.tolist(), a.tolist(), 1.0,
                                               [], b.tolist(), e1, lam / rz, lam / rd, lam)
    Pn = [sn * x for x in Qn]
    Pr, thr = _textbook_rls(P, th, a, b, e1, rz, rd, lam)
    assert np.allclose(unpack(Pn, n), Pr, atol=1e-10)
    assert np.allclose(thn, thr, atol=1e-10)
    assert tr == pytest.approx(np.trace(Pr))
    # information form: P+^-1 = lam P^-1 + Phi~^T R~ Phi~
    info = lam * np.linalg.inv(P) + rz * np.outer(a, a) + rd * np.outer(b, b)
    assert np.allclose(np.linalg.inv(np.array(unpack(Pn, n))), info, atol=1e-8)


def test_rls_kernel_reports_a_non_positive_gamma() -> None:
    k = rcie_kernel(1, False)
    assert k([-10.0], 1.0, [0.0], [1.0], 1.0, [], [1.0], 0.0, 1.0, 1.0, 1.0) is None


def _axis_run(sig: float, n: int = 400, seed: int = 0, **over):
    """AIE on one exact §1.2 axis, MA(1) GPS-like noise of std ``sig`` per point."""
    rng = np.random.default_rng(seed)
    top = msgspec.convert({"gate_nis": 1e9, "divergence_nis": 1e9}, AieConfig)
    ac = msgspec.structs.replace(top.surge, **over)
    ax = axis_filter(AxisModel(1.0, 3.0), ac, top)
    k = discretize(1.0, 1.0)
    v = 0.0
    n_prev = sig * rng.standard_normal()
    ev, eu = [], []
    for i in range(n):
        u = 1.5 if (i // 50) % 2 == 0 else 0.8
        y = k.c1 * v + k.c2 * u
        v = k.alpha * v + k.c1 * u
        n_k = sig * rng.standard_normal()
        ax.step(k, y + n_k - n_prev, sig**2, sig**2, None)
        n_prev = n_k
        if i > 100:
            ev.append(ax.kf.v - v)
            eu.append(ax.input.d_hat - u)
    return float(np.sqrt(np.mean(np.square(ev)))), float(np.sqrt(np.mean(np.square(eu)))), ax


def test_rcie_learns_an_unknown_step_input_with_little_noise() -> None:
    ev, eu, ax = _axis_run(0.02)
    # measured: speed 0.058 m/s, input 0.079 m/s^2 (input steps of 0.7 every 50 s; the
    # default rate penalty R_d, tuned for GPS noise, slows the response to each step)
    assert ev < 0.1
    assert eu < 0.15
    assert ax.diverged == 0


def test_aie_axis_under_gps_noise() -> None:
    ev, eu, ax = _axis_run(0.67, n=500)
    # measured: speed 0.280 m/s, input 0.227 m/s^2 at 0.67 m per averaged point (0.198
    # m/s before the increments learned their noise, issue 32: the learned point noise
    # takes the forecast's excess of this unknown-input run, algorithms.md §8); a position
    # filter told that the input is a random walk reaches 0.155 m/s here
    assert ev < 0.3
    assert eu < 0.3
    assert ax.diverged == 0


def test_divergence_is_detected_counted_and_recovered() -> None:
    top = AieConfig()
    ax = axis_filter(AxisModel(1.0, 3.0), top.surge, top)
    k = discretize(1.0, 1.0)
    for _ in range(5):
        ax.step(k, 1.0, 0.3, 0.3, None)
    ax.input.rcie.theta = [1e6] * ax.input.rcie.n          # a blown-up estimator (paper remark 3)
    ax.step(k, 5.0, 0.3, 0.3, None)
    assert ax.diverged == 1
    assert ax.input.rcie.theta == [0.0] * ax.input.rcie.n and ax.input.d_hat == 0.0
    for _ in range(50):
        ax.step(k, 1.0, 0.3, 0.3, None)
    assert math.isfinite(ax.kf.v) and ax.kf.v == pytest.approx(1.0, abs=0.2)
    P = ax.input.rcie.P
    P[0] = math.nan                             # non-finite numbers
    ax.input.rcie.P = P
    ax.step(k, 1.0, 0.3, 0.3, None)
    assert ax.diverged == 2


CONFIG = {aie_mod: AieConfig, kf_mod: KfConfig}
"""Each pipeline module's configuration struct (``[pipelines.aie]``, ``[pipelines.kf]``)."""


def _pipes(cfg: dict | None = None):
    return [mod.build(msgspec.convert(cfg or {}, CONFIG[mod]), 1.5, 0.03)
            for mod in (aie_mod, kf_mod)]


def test_aie_beats_a_kf_with_wrong_input_scaling() -> None:
    """The paper's claim: the KF trusts the commanded input at nominal scaling; when the
    real thrust is 30 % weaker and quadratic in the command, AIE filters better."""
    sim = simulate(SimConfig(duration=300.0, seed=0, gain=2.1, thrust_quadratic=True,
                             quad_drag=0.2))
    pa, pk = _pipes()
    oa, ok = run_pipelines(sim.samples, [pa, pk], sim.t)
    sa, sk = score(sim, oa), score(sim, ok)
    # measured: speed AIE 0.445 vs KF 0.879 m/s; position AIE 4.27 vs KF 4.60 m
    assert sa["speed"] < 0.8 * sk["speed"]
    assert sa["position"] < sk["position"]
    assert pa.health().surge.diverged == 0


def test_pipeline_columns_health_and_state_roundtrip() -> None:
    sim = simulate(SimConfig(duration=120.0, seed=1))
    pa, _ = _pipes()
    out = run_pipelines(sim.samples, [pa], sim.t)[0]
    assert pa.columns == ("north", "east", "heading", "speed", "yaw_rate", "surge_input",
                          "yaw_input", "std_north", "std_east", "std_speed", "std_heading")
    for c in pa.columns:
        assert np.isfinite(out[c][-1])
    h = pa.health().flat()
    for key in ("surge.steps", "surge.diverged", "surge.V_d", "heading.steps",
                "heading.diverged", "heading.theta_norm"):
        assert key in h and math.isfinite(h[key])
    assert not any(k.endswith(("nis", "innovation", ".S")) for k in h)  # innovations apart
    recs = pa.innovations()
    channels = {r.channel for r in recs}
    assert channels == {"surge.increment", "heading.increment"}   # no Doppler speed here
    assert all(r.dof == 1 and len(r.z) == 1 and len(r.S) == 1 and r.S[0] > 0.0
               and math.isclose(r.nis, r.z[0] ** 2 / r.S[0]) for r in recs)
    assert pa.innovations() == []   # taken
    st = json.loads(json.dumps(pa.get_state()))
    fresh = _pipes()[0]
    fresh.set_state(st)
    assert fresh.surge.input.rcie.theta == pa.surge.input.rcie.theta
    assert fresh.surge.model.a == pa.surge.model.a
    fresh.set_state({"surge": {"rcie": {"theta": [1.0]}, "model": {"a": "x"}}})  # ignored
    assert fresh.surge.input.rcie.theta == pa.surge.input.rcie.theta


@pytest.mark.parametrize("mod", [aie_mod, kf_mod])
def test_fixes_before_the_first_heading_do_not_poison_the_surge_axis(mod) -> None:
    """The first surge windows close on fixes alone (no heading source yet: the chord
    along the course); when the compass then starts, the next increment has no previous
    heading to turn from and must not turn the speed and position into NaN for good."""
    sim = simulate(SimConfig(duration=60.0, seed=1))
    late = [s for s in sim.samples
            if not (type(s).__name__ in ("Heading", "Attitude", "ImuSample") and s.t < 3.0)]
    assert len(late) < len(sim.samples)
    p = mod.build(CONFIG[mod](), 1.5, 0.03)
    out = run_pipelines(late, [p], sim.t)[0]
    for c in ("north", "east", "speed", "heading"):
        assert np.isfinite(out[c][-1]), c
    assert score(sim, out)["speed"] < 0.3


def test_aie_runs_without_commands_and_with_1hz_irregular_gps() -> None:
    rng = np.random.default_rng(7)
    sim = simulate(SimConfig(duration=300.0, seed=2, gps_hz=1.0))
    samples = [s for s in sim.samples
               if type(s).__name__ != "ActuatorCommand"
               and not (type(s).__name__ == "GnssFix" and rng.uniform() < 0.2)]
    pa, pk = _pipes()
    oa, ok = run_pipelines(samples, [pa, pk], sim.t)
    sa = score(sim, oa)
    # measured: AIE speed 0.655 m/s (KF 1.04), heading 0.024 rad, position 6.2 m with
    # 1 Hz GPS missing 20 % of fixes and no commands at all
    assert sa["speed"] < 0.75
    assert sa["heading"] < 0.035
    assert sa["position"] < 7.0


def test_create_decodes_the_config_and_names_bad_keys() -> None:
    p = aie_mod.create(from_dict({"pipelines": {"aie": {"heading": {"n_c": 3}}}}))
    assert p is not None and p.name == "aie"
    assert p.yaw.input.rcie.n == 7
    with pytest.raises(ConfigError, match="pipelines.aie"):
        aie_mod.create(from_dict({"pipelines": {"aie": {"surge": {"lamda": 1.0}}}}))
    assert aie_mod.create(from_dict({"vehicle": {"class": "bluerov2"}})) is None


def test_bench_step_ratio_reports_both_timings() -> None:
    from onboard.apps.bench import aie_step_ratio

    r = aie_step_ratio(n=300, repeats=1)
    assert set(r) == {"aie_axis_step_us", "filterpy_kf3_step_us", "ratio"}
    assert r["ratio"] > 0.0   # speed is measured by onboard bench, never asserted here


def test_rcie_rejects_bad_hyperparameters() -> None:
    with pytest.raises(ValueError):
        Rcie(2, 1, r_z=1.0, r_d=1.0, r_theta=1.0, lam=1.5, u_scale=1.0, z_scale=1.0,
             u_max=1.0)


def test_adaptive_input_error_variance_follows_the_innovations() -> None:
    """ASE (§2.8): with adaptive = true, V_d moves toward the value that makes the
    predicted innovation variance match the sample variance, and stays bounded."""
    sim = simulate(SimConfig(duration=200.0, seed=4, gain=2.1, thrust_quadratic=True))
    pa = aie_mod.build(msgspec.convert({"adaptive": True}, AieConfig), 1.5, 0.03)
    out = run_pipelines(sim.samples, [pa], sim.t)[0]
    h = pa.health().flat()
    assert h["surge.V_d"] != AieConfig().surge.v_d
    assert 0.0 < h["surge.V_d"] <= 10.0 * AieConfig().surge.u_max ** 2
    sc = score(sim, out)
    # measured: V_d 0.1 -> 41.8 (m/s^2)^2 and speed 0.80 m/s (0.79 before the windows
    # closed at the output), worse than the fixed tuned V_d (0.63 m/s on this run):
    # matching the innovation variance loosens the filter here, which is why ASE is
    # off by default
    assert sc["speed"] < 0.9


def _straight_run(p, acc_of, sog=1.0, duration=30.0, jump_at=None):
    """Feed ``p`` a boat going north at ``sog`` m/s (fixes at 5 Hz with Doppler speed,
    compass at 10 Hz, no noise); ``acc_of(t)`` is each fix's ``h_acc_m`` (None: absent);
    the fix at ``jump_at`` s is 10 m east of the track. Returns the outputs per tick."""
    from onboard.core.geo import LocalFrame
    from onboard.core.messages import GnssFix, Heading

    fr = LocalFrame(47.0, 8.0)
    outs = []
    for i in range(int(duration * 10)):
        t = 0.1 * i
        batch = [Heading(t=t, source="c", heading_rad=0.0)]
        if i % 2 == 0:
            east = 10.0 if jump_at is not None and abs(t - jump_at) < 1e-6 else 0.0
            lat, lon = fr.to_latlon(sog * t, east)
            batch.append(GnssFix(t=t, source="g", lat_deg=lat, lon_deg=lon, sog_mps=sog,
                                 cog_rad=0.0, h_acc_m=acc_of(t)))
        outs.append((t, dict(p.step(t, batch))))
    return outs


@pytest.mark.parametrize("mod", [aie_mod, kf_mod])
def test_a_fix_reporting_a_large_error_is_weighted_accordingly(mod) -> None:
    """Receiver accuracy as measurement noise (gnss_accuracy): a fix 10 m off the track
    that reports h_acc 10 m moves the published position ~45x less than with the
    configured 1.5 m noise; a fix reporting better than configured does not stiffen the
    anchor (the published track is the same as without the report)."""
    def east_after(cfg, acc_jump, acc):
        p = mod.build(msgspec.convert(cfg, CONFIG[mod]), 1.5, 0.03, 0.1)
        outs = _straight_run(p, lambda t: acc_jump if abs(t - 20.0) < 1e-6 else acc,
                             jump_at=20.0)
        return max(abs(o.get("east", 0.0)) for t, o in outs if 20.0 <= t < 21.0)

    with_acc = east_after({}, 10.0, 1.5)
    fixed = east_after({"gnss_accuracy": False}, 10.0, 1.5)
    # measured: 0.5 m with the configured noise (the anchor gain 0.05 times 10 m),
    # 0.011 m with the reported 10 m (gain 0.05 x 1.5^2 / 10^2)
    assert fixed > 0.4
    assert with_acc < fixed / 20.0
    assert east_after({}, 0.3, 0.3) == pytest.approx(fixed, rel=1e-6)


def test_fix_accuracy_bounds_are_checked_and_bad_reports_counted() -> None:
    p = aie_mod.build(AieConfig(), 1.5, 0.03, 0.1)
    seen = iter((0.0, -1.0, math.nan))
    _straight_run(p, lambda t: next(seen, 1.0), duration=2.0)
    assert p.health().accuracy_rejected == 3
    with pytest.raises(ValueError, match="gnss_accuracy_min_m"):
        aie_mod.build(msgspec.convert({"gnss_accuracy_min_m": 2.0,
                                       "gnss_accuracy_max_m": 1.0}, AieConfig))


@pytest.mark.parametrize("close", [True, False])
def test_the_newest_fix_is_in_the_estimate_at_the_next_tick(close: bool) -> None:
    """close_at_output: a speed step reported by the fix at 20.0 s is in the speed
    published at the 20.0 s tick (the window closes when estimates are asked for);
    without it, one tick later (the window ends a quarter step after the fix)."""
    from onboard.core.geo import LocalFrame
    from onboard.core.messages import GnssFix, Heading

    # v_d = 1 (the former default): this test is of the window timing; at the tuned
    # v_d = 0.0067 the command-less filter crosses half of the 1 m/s step 8 ticks later
    # (docs/aie.md section 4)
    p = kf_mod.build(msgspec.convert({"close_at_output": close, "surge": {"v_d": 1.0}},
                                     KfConfig), 1.5, 0.03, 0.01)
    fr = LocalFrame(47.0, 8.0)
    north, speed = 0.0, {}
    for i in range(250):
        t = 0.1 * i
        v = 1.0 if t < 20.0 - 1e-9 else 2.0
        north += 0.1 * v
        batch = [Heading(t=t, source="c", heading_rad=0.0)]
        if i % 2 == 0:
            lat, lon = fr.to_latlon(north, 0.0)
            batch.append(GnssFix(t=t, source="g", lat_deg=lat, lon_deg=lon, sog_mps=v,
                                 cog_rad=0.0))
        speed[i] = p.step(t, batch).get("speed", 0.0)
    jumped = [i for i in range(190, 210) if speed[i] > 1.5]
    assert jumped and jumped[0] == (200 if close else 201)
    # an early-closed window is no gap: no restart, no dead reckoning
    assert p.health().surge.restarts == 0


@pytest.mark.parametrize("mod", [aie_mod, kf_mod])
def test_a_doppler_speed_reporting_a_poor_accuracy_is_down_weighted(mod) -> None:
    """Receiver speed accuracy as the Doppler speed's noise (gnss_accuracy): for 20 s the
    speed over ground carries 0.5 m/s of noise and the receiver reports ``speed_acc_mps``
    0.5; the published speed follows the (exact) positions instead of the noise, so its
    error in that period is less than half that of the run taking the configured 0.1 m/s."""
    from onboard.core.geo import LocalFrame
    from onboard.core.messages import GnssFix, Heading

    def speed_rms(cfg) -> float:
        p = mod.build(msgspec.convert(cfg, CONFIG[mod]), 1.5, 0.03, 0.1)
        rng = np.random.default_rng(7)
        fr = LocalFrame(47.0, 8.0)
        err = []
        for i in range(400):
            t = 0.1 * i
            batch = [Heading(t=t, source="c", heading_rad=0.0)]
            if i % 2 == 0:
                bad = 15.0 <= t < 35.0
                lat, lon = fr.to_latlon(1.0 * t, 0.0)
                sog = 1.0 + (rng.normal(0.0, 0.5) if bad else 0.0)
                batch.append(GnssFix(t=t, source="g", lat_deg=lat, lon_deg=lon,
                                     sog_mps=abs(sog), cog_rad=0.0,
                                     speed_acc_mps=0.5 if bad else 0.05))
            out = p.step(t, batch)
            if 20.0 <= t < 35.0:
                err.append(out["speed"] - 1.0)
        return float(np.sqrt(np.mean(np.square(err))))

    aware, fixed = speed_rms({}), speed_rms({"gnss_accuracy": False})
    # measured (20-35 s): aie 0.279 vs 0.387 m/s, kf 0.361 vs 0.407 m/s (the positions
    # are exact but taken at the configured 1.5 m, so they settle the speed only slowly).
    # Before the noise was learned (issue 32): aie 0.157 vs 0.401, kf 0.179 vs 0.419: the
    # scale learned while the receiver reported 0.05 m/s and its speeds were exact (the
    # floor, 0.2 sigma) multiplies the 0.5 m/s it reports in the poor period too, until
    # the 200-update window catches up (algorithms.md §8)
    assert aware < 0.92 * fixed
    assert aware < 0.4


def _doppler_run(mod, speed: float, course_off_rad: float, duration: float = 20.0):
    """A boat heading north (compass 0) whose track runs ``course_off_rad`` off its
    heading at ``speed`` m/s (fixes at 5 Hz with that SOG and COG, no noise). Returns the
    pipeline, its ``surge.rate`` records and its last output."""
    from onboard.core.geo import LocalFrame
    from onboard.core.messages import GnssFix, Heading

    p = mod.build(CONFIG[mod](), 1.5, 0.03, 0.1)
    fr = LocalFrame(47.0, 8.0)
    recs, out = [], {}
    for i in range(int(duration * 10)):
        t = 0.1 * i
        batch = [Heading(t=t, source="c", heading_rad=0.0)]
        if i % 2 == 0:
            d = speed * t
            lat, lon = fr.to_latlon(d * math.cos(course_off_rad), d * math.sin(course_off_rad))
            batch.append(GnssFix(t=t, source="g", lat_deg=lat, lon_deg=lon, sog_mps=speed,
                                 cog_rad=course_off_rad % (2 * math.pi)))
        out = dict(p.step(t, batch))
        recs += [r for r in p.innovations() if r.channel == "surge.rate"]
    return p, recs, out


@pytest.mark.parametrize("mod", [aie_mod, kf_mod])
@pytest.mark.parametrize("speed,course_off_deg", [(0.05, 0.0), (0.05, 180.0), (0.09, 30.0)])
def test_a_doppler_speed_of_unknown_sign_is_not_used(mod, speed, course_off_deg) -> None:
    """Below DOPPLER_SIGN_MIN_SPEED_MPS (0.1 m/s) the course is noise and ahead cannot be
    told from astern: no Doppler row, every such fix a ``surge.rate`` rejection of reason
    ``sign_unknown``."""
    from onboard.pipelines.surge_heading import SIGN_UNKNOWN

    p, recs, out = _doppler_run(mod, speed, math.radians(course_off_deg))
    assert len(recs) == 100 and all(not r.accepted and r.reason == SIGN_UNKNOWN for r in recs)
    assert p.health().rate_steps == 0
    # from the position increments alone after 20 s: |speed| at most the true one
    assert abs(out["speed"]) <= speed + 0.01


@pytest.mark.parametrize("mod", [aie_mod, kf_mod])
@pytest.mark.parametrize("speed,course_off_deg", [(1.0, 0.0), (1.0, 180.0), (0.4, 60.0),
                                                  (0.4, -120.0), (0.12, 180.0)])
def test_a_doppler_speed_of_known_sign_is_used_signed(mod, speed, course_off_deg) -> None:
    """Above the threshold and off abeam the Doppler speed is used, negative astern: the
    published path speed is the speed over ground, signed by the course against the
    heading."""
    off = math.radians(course_off_deg)
    p, recs, out = _doppler_run(mod, speed, off)
    assert recs and all(r.reason != "sign_unknown" for r in recs)
    assert p.health().rate_steps == 99  # every fix after the first window
    # measured: +-1.0, +-0.3996 (aie), +-0.3995 (kf), -0.12
    assert out["speed"] == pytest.approx(math.copysign(speed, math.cos(off)), abs=0.01)
