"""The ESESO's calibration on and off its design point: RMSE, 1- and 2-sigma coverage, NIS.

The ESESO in ``config/bluerov2.toml`` is told the simulated BlueROV2's own mass, added mass,
damping, thrust curve and sensor noise, so its consistency on the nominal
``bluerov2-circle`` only shows that the code agrees with itself. Here the plant and the
sensors are perturbed (:mod:`sitl.mismatch`: mass and added mass +-20 %, damping +-30 %,
thrust -25 %, a 0.15 s thruster lag, every sensor's noise doubled, and all at once) while
the filter keeps the nominal configuration, and for each case and seed this module runs
``bluerov2-circle`` through ``sitl.runner`` (its PID) and the onboard engine, and reports

* per axis, the RMS error and the fraction of the errors within one and two published
  sigmas (target 0.68 and 0.95; too confident and too timid are both misses) of the body
  velocity ``u v w`` and of the disturbance ``dist_x dist_y dist_z`` against the true
  lumped disturbance (:func:`lumped_truth`: the push plus what the filter's model gets
  wrong, which is what ``dist_*`` is; nominally the push);
* the mean NIS of every update channel, the thrust channel (which carries the
  disturbance) included, against the 95 % band of a chi-square mean.

Run ``python -m validation.reports.eseso_calibration --seeds 1 2 3 --out
docs/eseso-mpc.md``; the table goes between ``<!-- eseso-calibration:begin -->`` and
``<!-- eseso-calibration:end -->``.
"""

from __future__ import annotations

import argparse
import math
import sys
from functools import cache
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from validation.reports.mismatch import chi2_mean_band

SECONDS = 120.0
"""Simulated seconds per run."""
AFTER_S = 10.0
"""Errors and coverage are taken after this many seconds (the start-up transient)."""
AXES = {"velocity": (("u", "u"), ("v", "v"), ("w", "w")),
        "disturbance": (("dist_x", "disturbance_x"), ("dist_y", "disturbance_y"),
                        ("dist_z", "disturbance_z"))}
"""Per quantity, the (estimate column, truth field) of each axis."""
P_ALONE = "@P"
"""Suffix of a disturbance column's sigma from the filter's covariance alone (``sqrt(P[xi,
xi])``, what its gain uses and the published sigma before issue 32's deliverable 7),
beside the published one (the covariance plus the excess the thrust innovations show)."""
CHANNELS = {"thrust": 3, "dvl": 3, "attitude": 3, "vog": 2, "depth": 1}
"""The update channels of the NIS columns and their dimensions."""
BEGIN = "<!-- eseso-calibration:begin -->"
END = "<!-- eseso-calibration:end -->"


def cases() -> list[Any]:
    """The mismatch cases of the table, nominal first (:class:`sitl.mismatch.MismatchCase`)."""
    from onboard.sitl.mismatch import CASES, MismatchCase

    named = [CASES[k] for k in ("nominal", "mass+20", "mass-20", "damping+30",
                                "damping-30")]
    return named + [MismatchCase("thrust-25", thrust_scale=0.75), CASES["lag0.15"],
                    CASES["noise2x"],
                    MismatchCase("off-design", mass_scale=1.2, damping_scale=0.7,
                                 thrust_scale=0.75, lag_s=0.15, noise_scale=2.0)]


def _case(name: str) -> Any:
    return next(c for c in cases() if c.name == name)


@cache
def run(case: str, seed: int, seconds: float = SECONDS) -> dict[str, Any]:
    """One ``bluerov2-circle`` run with the plant and sensors perturbed by ``case`` and the
    ESESO nominal (``config/bluerov2.toml``): :func:`fly` of a fresh simulation."""
    from onboard.core import config as config_mod

    return fly(config_mod.load("bluerov2"), case, simulate_case(case, seed, seconds))


def simulate_case(case: str, seed: int, seconds: float) -> Any:
    """The simulator's ``(t, samples, truth)`` steps of ``bluerov2-circle`` perturbed by
    ``case`` (an iterator: flown as it is consumed)."""
    from onboard.sitl.mismatch import perturb_scenario
    from onboard.sitl.runner import simulate

    return simulate(perturb_scenario("bluerov2-circle", _case(case)), seconds, seed=seed)


def fly(cfg: Any, case: str, steps: Any) -> dict[str, Any]:
    """The ESESO of ``cfg`` alone through the engine over the simulated ``steps`` of
    ``case``: ``{"errors": {column: array}, "sigma": {column: array}, "nis": {channel:
    list}}`` (errors estimate minus truth at the truth records after :data:`AFTER_S`;
    each disturbance column's sigma from ``P`` alone under ``column`` + :data:`P_ALONE`)."""
    from onboard.engine import Engine
    from onboard.estimators.eseso_filter import XI
    from onboard.pipelines import eseso as eseso_mod

    p = eseso_mod.create(cfg)
    assert p is not None
    eng = Engine(cfg, pipelines=[p])
    records = eng.monitor.keep(p.name)
    cols = [c for axes in AXES.values() for c, _ in axes]
    err: dict[str, list[float]] = {c: [] for c in cols}
    sig: dict[str, list[float]] = {c: [] for c in cols}
    sig.update({c + P_ALONE: [] for c, _ in AXES["disturbance"]})
    mismatch = _case(case)
    prev = None
    for t, samples, truth in steps:
        for s in samples:
            eng.push(s)
        if truth is None:
            continue
        eng.tick(t)
        rec = eng.latest.get(p.name)
        lumped = lumped_truth(truth, prev, mismatch, cfg.pipelines.eseso.vehicle)
        prev = truth
        if rec is None or not rec.values or t < AFTER_S:
            continue
        for col, field in AXES["velocity"]:
            err[col].append(rec.values[col] - float(getattr(truth, field)))
            sig[col].append(rec.std[col])
        sig_p = np.sqrt(np.maximum(np.diag(p.filter.P)[XI], 0.0))
        for i, (col, _) in enumerate(AXES["disturbance"]):
            err[col].append(rec.values[col] - lumped[i])
            sig[col].append(rec.std[col])
            sig[col + P_ALONE].append(float(sig_p[i]))
    nis: dict[str, list[float]] = {}
    for r in records:
        if math.isfinite(r.nis):
            nis.setdefault(r.channel, []).append(r.nis)
    return {"errors": {c: np.asarray(v) for c, v in err.items()},
            "sigma": {c: np.asarray(v) for c, v in sig.items()}, "nis": nis}


def lumped_truth(truth: Any, prev: Any, case: Any, c: Any) -> Any:
    """The true lumped disturbance (N, body FRD): the force the ESESO's model misses, which
    its ``xi`` estimates (algorithms.md §5.1). With the plant's mass, damping and thrust
    the model's times ``k_m``, ``k_d``, ``k_t`` and its thrusters lagging the command by
    ``T_lag`` (:class:`sitl.mismatch.MismatchCase`)::

        xi = F_ext + (1 - 1/k_t) F_thr - T_lag F_thr' / k_t + (1 - k_d) D(nu) nu
             + (1 - k_m) (M (nu' + w x nu) - A (w x nu) + w x (A nu))

    ``F_ext`` the true push and ``F_thr`` the true thrust in body axes (the truth record's
    ``disturbance_*`` and ``force_*``); ``F_thr / k_t`` is the model's force for the
    lagged command, and ``F_cmd - F_lag = T_lag F_lag'`` that of a first-order lag (of
    the force: the lag acts on the normalized command, whose thrust curve is quadratic;
    to first order the same). ``'`` is the backward difference over the truth records
    (0.1 s; ``prev`` None: zero). Nominally it is the push itself; the model's share of
    the commands the filter sees (PWM outputs at their own rate) is not counted. The
    centre-of-gravity term ``m (w' x r_g + w x (w x r_g))`` is left out of the mass error
    (the truth has no angular acceleration; ``m z_G |w|^2`` is 0.14 N on the circle)."""
    nu = np.array([truth.u, truth.v, truth.w])
    w = np.array([truth.p, truth.q, truth.r])
    push = np.array([truth.disturbance_x or 0.0, truth.disturbance_y or 0.0,
                     truth.disturbance_z or 0.0])
    thrust = np.array([truth.force_x or 0.0, truth.force_y or 0.0, truth.force_z or 0.0])
    added = np.asarray(c.added_mass_kg, float)
    m_vec = c.mass_kg + added
    d = (np.asarray(c.damping_linear, float)
         + np.asarray(c.damping_quadratic, float) * np.abs(nu)) * nu
    nu_dot = np.zeros(3)
    thrust_dot = np.zeros(3)
    if prev is not None and truth.t > prev.t:
        dt = truth.t - prev.t
        nu_dot = (nu - np.array([prev.u, prev.v, prev.w])) / dt
        thrust_dot = (thrust - np.array([prev.force_x or 0.0, prev.force_y or 0.0,
                                         prev.force_z or 0.0])) / dt
    inertial = (m_vec * (nu_dot + np.cross(w, nu)) - added * np.cross(w, nu)
                + np.cross(w, added * nu))
    k_t = case.thrust_scale
    return (push + (1.0 - 1.0 / k_t) * thrust - case.lag_s * thrust_dot / k_t
            + (1.0 - case.damping_scale) * d + (1.0 - case.mass_scale) * inertial)


def pooled(case: str, seeds: Sequence[int]) -> dict[str, Any]:
    """Per column, RMS error and 1-/2-sigma coverage over ``seeds``; per channel, the mean
    NIS, its count and its 95 % band."""
    runs = [run(case, s) for s in seeds]
    out: dict[str, Any] = {"axes": {}, "nis": {}}
    for axes in AXES.values():
        for col, _ in axes:
            e = np.concatenate([r["errors"][col] for r in runs])
            s = np.concatenate([r["sigma"][col] for r in runs])
            z = np.abs(e) / np.maximum(s, 1e-12)
            out["axes"][col] = _scores(e, s)
            if col + P_ALONE in runs[0]["sigma"]:
                out["axes"][col + P_ALONE] = _scores(
                    e, np.concatenate([r["sigma"][col + P_ALONE] for r in runs]))
    for ch, dim in CHANNELS.items():
        v = [x for r in runs for x in r["nis"].get(ch, [])]
        if v:
            lo, hi = chi2_mean_band(len(v), dim)
            out["nis"][ch] = {"mean": float(np.mean(v)), "n": len(v), "lo": lo, "hi": hi}
    return out


def _scores(e: Any, s: Any) -> dict[str, float]:
    """RMS error, RMS sigma and the 1-/2-sigma coverage of errors ``e`` with sigmas ``s``."""
    z = np.abs(e) / np.maximum(s, 1e-12)
    return {"rms": float(np.sqrt(np.mean(e * e))), "sigma": float(np.sqrt(np.mean(s * s))),
            "cover1": float(np.mean(z <= 1.0)), "cover2": float(np.mean(z <= 2.0))}


def _cover(c1: float, c2: float) -> str:
    """``c1 / c2`` with ↑ (too timid: above 0.8 / 0.99) or ↓ (too confident: below 0.6 /
    0.9) on each."""
    def mark(x: float, lo: float, hi: float) -> str:
        return f"{x:.2f}" + (" ↓" if x < lo else " ↑" if x > hi else "")
    return f"{mark(c1, 0.6, 0.8)} / {mark(c2, 0.9, 0.99)}"


def _nis(p: dict[str, float] | None) -> str:
    if p is None:
        return "—"
    m = p["mean"]
    return f"{m:.2f}" + (" ↑" if m > p["hi"] else " ↓" if m < p["lo"] else "")


def table(seeds: Sequence[int]) -> str:
    """The markdown tables: coverage and RMSE per axis, NIS per channel, per case."""
    rows = {c.name: (c.describe(), pooled(c.name, seeds)) for c in cases()}
    head = ("| case | plant against the filter's model | "
            + " | ".join(f"{col} RMSE / sigma" for axes in AXES.values() for col, _ in axes)
            + " |\n|---|---|" + "---|" * 6 + "\n")
    cov = ("| case | " + " | ".join(f"{col} 1σ / 2σ" for axes in AXES.values()
                                     for col, _ in axes) + " |\n|---|" + "---|" * 6 + "\n")
    nis = ("| case | " + " | ".join(f"{ch} ({d})" for ch, d in CHANNELS.items())
           + " |\n|---|" + "---|" * len(CHANNELS) + "\n")
    for name, (what, p) in rows.items():
        a = p["axes"]
        cells = []
        for axes in AXES.values():
            for col, _ in axes:
                unit = "m/s" if col in "uvw" else "N"
                digits = 4 if unit == "m/s" else 2
                cells.append(f"{a[col]['rms']:.{digits}f} / {a[col]['sigma']:.{digits}f}")
        head += f"| {name} | {what} | " + " | ".join(cells) + " |\n"
        cov += f"| {name} | " + " | ".join(_cover(a[c]["cover1"], a[c]["cover2"])
                                            for axes in AXES.values() for c, _ in axes) + " |\n"
        nis += f"| {name} | " + " | ".join(_nis(p["nis"].get(ch)) for ch in CHANNELS) + " |\n"
    dist = [c for c, _ in AXES["disturbance"]]
    own = ("| case | " + " | ".join(f"{c} sigma P / published" for c in dist) + " | "
           + " | ".join(f"{c} 1σ / 2σ P → published" for c in dist)
           + " |\n|---|" + "---|" * 6 + "\n")
    for name, (_, p) in rows.items():
        a = p["axes"]
        own += (f"| {name} | " + " | ".join(
            f"{a[c + P_ALONE]['sigma']:.2f} / {a[c]['sigma']:.2f}" for c in dist) + " | "
            + " | ".join(_cover(a[c + P_ALONE]["cover1"], a[c + P_ALONE]["cover2"]) + " → "
                         + _cover(a[c]["cover1"], a[c]["cover2"]) for c in dist) + " |\n")
    nom = rows["nominal"][1]["nis"]
    bands = ", ".join(f"{ch} [{v['lo']:.2f}, {v['hi']:.2f}]" for ch, v in nom.items())
    s = ", ".join(str(x) for x in seeds)
    return (f"Generated by `python -m validation.reports.eseso_calibration` "
            f"(`bluerov2-circle` through `sitl.runner`, its PID, {SECONDS:.0f} s, seeds {s} "
            f"pooled, after {AFTER_S:.0f} s; the ESESO always told the nominal vehicle and "
            "noise, with its default model uncertainty (damping, thrust "
            f"{_rel_stds()}) in the lumped disturbance's process noise and its noise scales "
            "learnt from the innovations). Errors against the simulator's truth; the "
            "disturbance against the true lumped disturbance, the push plus the model's "
            "error (`lumped_truth`; nominally the push).\n\n"
            "RMS error / RMS published sigma (m/s for u v w, N for dist):\n\n" + head
            + "\nCoverage: fraction of errors within 1 and 2 published sigmas (target "
            "0.68 / 0.95; ↓ below 0.6 / 0.9, too confident; ↑ above 0.8 / 0.99, too "
            "timid):\n\n" + cov
            + "\nMean NIS per update channel (dimension), pooled (↑ above, ↓ below the 95 % "
            "band of its mean; no mark: inside). Nominal bands: " + bands + ".\n\n" + nis
            + "\nThe disturbance's sigma from the filter's covariance alone (`sqrt(P[xi, "
            "xi])`, what its gain and so the controller's `xi` use; the published sigma "
            "before issue 32) against the published one (plus the error variance the "
            "thrust innovations show beyond `P`): RMS sigma (N) and coverage, P alone → "
            "published:\n\n" + own)


def _rel_stds() -> str:
    """The configured relative one-sigmas of damping and thrust, as percentages."""
    from onboard.core.pipeline_config import EsesoConfig

    c = EsesoConfig().process
    return " / ".join(f"{100 * x:.0f} %" for x in (c.damping_rel_std, c.thrust_rel_std))


def write(path: Path, text: str) -> None:
    """Put ``text`` between the markers of ``path``."""
    doc = path.read_text()
    i, j = doc.index(BEGIN) + len(BEGIN), doc.index(END)
    path.write_text(doc[:i] + "\n" + text + doc[j:])


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: ``--seeds``, ``--out`` (a markdown file with the markers)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--out", type=Path)
    args = ap.parse_args(argv)
    text = table(args.seeds)
    if args.out:
        write(args.out, text)
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
