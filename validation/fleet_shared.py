"""How much of the fleet's current errors is shared: each vehicle's published ``current``
records (a simulated fleet's replayed logs, as :mod:`validation.fleet_world` leaves them)
against the simulator's true field at its place, depth and time, and how the vehicles'
errors go together: the correlation between two vehicles' errors by time lag and by the
distance between them, the share of each vehicle's error variance that the others'
errors share, and each vehicle's error against the water where it was some seconds
before (its estimator's memory of its track; docs/fleet.md, "What the vehicles' errors
are"; docs/algorithms.md §8.9).

    python -m validation.fleet_shared DIR [DIR ...] [--step S]

``DIR``: one seed's folder of ``python -m validation.fleet_world FLEET --out ROOT``
(``ROOT/seed-N``). Errors are about zero, not about their mean: a bias every vehicle
has is a shared error too. It measures the vehicles' estimators (what they publish
against what the water did), nothing of the field's fit.

The share of vehicle ``v``'s error variance that is common: under a one-factor model
``e_v(t) = g(t) + u_v(t)`` (``g`` common to the fleet, ``u_v`` its own, independent), the
mean product of two vehicles' errors at one time is ``E[g^2]``, so the share is
``mean_u E[e_v e_u] / E[e_v^2]`` over the other vehicles ``u`` at the same times; and
``E[g^2]`` against the vehicles' reported variance, ``mean_u E[e_v e_u] / E[s_v s_u]``,
is the fraction of the reported variance a term for an error common to the fleet would
carry (on fleet-survey 1-3 % at the boats, nil at the others: no such term is built).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

LAGS_S = (0, 30, 60, 120, 300, 600)
"""Time lags (s) the cross-correlation is given at."""
DISTANCES_M = (0.0, 50.0, 100.0, 200.0, 400.0, 1e9)
"""Bins (m) of the distance between two vehicles at one time."""
DELAYS_S = (0, 5, 10, 20, 30, 45, 60)
"""Delays (s) an estimate is compared at with the water its vehicle met earlier."""


def errors_on_grid(obs: list, sea, depth, grid: np.ndarray) -> dict[str, np.ndarray]:
    """One vehicle's records on the time ``grid`` (UTC s; NaN outside its records or across
    a gap over 5 s): ``err`` (n, 2) its estimate less the true field at its place and
    depth, ``s`` (n, 2) its reported sigmas, ``ne`` (n, 2) its place (m north, east of the
    sea's origin)."""
    t = np.array([o.utc for o in obs])
    order = np.argsort(t)
    t = t[order]
    rows = [obs[i] for i in order]
    t_d, d = depth
    truth = np.array([sea.at(o.lat_deg, o.lon_deg, float(np.interp(o.utc, t_d, d)), o.utc)
                      for o in rows])
    est = np.array([[o.north, o.east] for o in rows])
    s = np.array([[o.std_north, o.std_east] for o in rows])
    lat0, lon0 = sea.origin
    ne = np.column_stack([
        np.radians(np.array([o.lat_deg for o in rows]) - lat0) * 6.371e6,
        np.radians(np.array([o.lon_deg for o in rows]) - lon0) * 6.371e6 *
        math.cos(math.radians(lat0))])
    j = np.clip(np.searchsorted(t, grid), 1, t.size - 1)
    near = np.minimum(np.abs(t[j] - grid), np.abs(t[j - 1] - grid))
    bad = (grid < t[0]) | (grid > t[-1]) | (near > 5.0)
    out = {}
    for key, val in (("err", est - truth), ("s", s), ("ne", ne)):
        col = np.column_stack([np.interp(grid, t, val[:, c]) for c in range(2)])
        col[bad] = np.nan
        out[key] = col
    return out


def pair_products(a: dict, b: dict, lag: int) -> tuple[np.ndarray, ...]:
    """The products of two vehicles' errors ``lag`` grid steps apart (a's at t, b's at
    t + lag), their squares and reported sigmas' products, and their distance (at a's
    time), where both are known: arrays (k, 2), (k, 2), (k, 2), (k, 2), (k,)."""
    n = a["err"].shape[0]
    ea, eb = a["err"][:n - lag], b["err"][lag:]
    ok = np.isfinite(ea[:, 0]) & np.isfinite(eb[:, 0])
    dist = np.hypot(*(a["ne"][:n - lag] - b["ne"][lag:]).T)
    return (ea[ok] * eb[ok], ea[ok] ** 2, eb[ok] ** 2,
            a["s"][:n - lag][ok] * b["s"][lag:][ok], dist[ok])


def correlation(prod: np.ndarray, sq_a: np.ndarray, sq_b: np.ndarray) -> np.ndarray:
    """Per component, ``E[e_a e_b] / sqrt(E[e_a^2] E[e_b^2])`` (about zero)."""
    return prod.mean(axis=0) / np.sqrt(sq_a.mean(axis=0) * sq_b.mean(axis=0))


def measure(errs: dict[str, dict], step_s: float) -> dict:
    """The figures of one seed's vehicles (:func:`errors_on_grid`): by vehicle, its error
    RMS and mean, its reported sigma, its common share and the common variance as a
    fraction of the reported; by lag, the pairs' correlation; by distance, at lag 0."""
    ids = sorted(errs)
    out: dict = {"vehicles": {}, "lag": {}, "distance": {}}
    for v in ids:
        e, s = errs[v]["err"], errs[v]["s"]
        ok = np.isfinite(e[:, 0])
        shared, reported, own = [], [], []
        for u in ids:
            if u != v:
                prod, sq_v, _, ss, _ = pair_products(errs[v], errs[u], 0)
                if len(prod) > 30:
                    shared.append(prod.mean(axis=0))
                    own.append(sq_v.mean(axis=0))
                    reported.append(ss.mean(axis=0))
        if not shared:   # never at one time with another vehicle
            continue
        out["vehicles"][v] = {
            "rms": np.sqrt(np.nanmean(e[ok] ** 2, axis=0)).tolist(),
            "mean": np.nanmean(e[ok], axis=0).tolist(),
            "reported": np.sqrt(np.nanmean(s[ok] ** 2, axis=0)).tolist(),
            "share": (np.mean(shared, axis=0) / np.mean(own, axis=0)).tolist(),
            "of_reported": (np.mean(shared, axis=0) / np.mean(reported, axis=0)).tolist()}
    for lag_s in LAGS_S:
        lag = int(round(lag_s / step_s))
        pooled = [pair_products(errs[a], errs[b], lag) for a in ids for b in ids if a != b]
        pooled = [p for p in pooled if len(p[0])]
        prod, sq_a, sq_b = (np.concatenate([p[k] for p in pooled]) for k in range(3))
        out["lag"][str(lag_s)] = correlation(prod, sq_a, sq_b).tolist()
        auto = [pair_products(errs[a], errs[a], lag) for a in ids]
        prod, sq_a, sq_b = (np.concatenate([p[k] for p in auto]) for k in range(3))
        out["lag"][f"{lag_s} own"] = correlation(prod, sq_a, sq_b).tolist()
    pooled = [pair_products(errs[a], errs[b], 0) for a in ids for b in ids if a < b]
    prod, sq_a, sq_b, _, dist = (np.concatenate([p[k] for p in pooled]) for k in range(5))
    for lo, hi in zip(DISTANCES_M[:-1], DISTANCES_M[1:]):
        sel = (dist >= lo) & (dist < hi)
        if sel.sum() > 30:
            out["distance"][f"{lo:.0f}-{hi:.0f} m"] = \
                correlation(prod[sel], sq_a[sel], sq_b[sel]).tolist() + [int(sel.sum())]
    return out


def common_time(errs: dict[str, dict], step_s: float) -> float:
    """The 1/e time (s) of the fleet's common error, the mean of the vehicles' errors at
    each time (times at least three vehicles give), averaged over the components: its
    autocorrelation about zero first below 1/e (a constant bias never falls: the record's
    length then)."""
    e = np.stack([errs[v]["err"] for v in sorted(errs)])
    count = np.isfinite(e[:, :, 0]).sum(axis=0)
    g = np.nanmean(e, axis=0)[count >= 3]
    taus = []
    for c in range(2):
        x = g[:, c]
        acf = np.correlate(x, x, "full")[x.size - 1:] / np.arange(x.size, 0, -1)
        acf = acf / acf[0]
        below = np.flatnonzero(acf[: x.size // 2] < math.exp(-1.0))
        taus.append(float(below[0]) * step_s if below.size else x.size // 2 * step_s)
    return float(np.mean(taus))


def delay(rows: list, sea, depth) -> dict[int, list[float]]:
    """A vehicle's error RMS per component (m/s) against the true water where it was
    each of :data:`DELAYS_S` earlier (the true field along its own track, that long
    before): the delay with the least error is its estimator's lag (its estimate is a
    memory of the water it crossed, not the water where it is)."""
    rows = sorted(rows, key=lambda o: o.utc)
    t = np.array([o.utc for o in rows])
    t_d, d = depth
    truth = np.array([sea.at(o.lat_deg, o.lon_deg, float(np.interp(o.utc, t_d, d)), o.utc)
                      for o in rows])
    est = np.array([[o.north, o.east] for o in rows])
    out = {}
    for lag in DELAYS_S:
        ok = t - lag >= t[0]
        met = np.column_stack([np.interp(t - lag, t, truth[:, c]) for c in range(2)])
        out[lag] = np.sqrt(((est - met)[ok] ** 2).mean(axis=0)).tolist()
    return out


def one_seed(root: Path, step_s: float) -> dict:
    """:func:`measure` and :func:`common_time` of one seed's folder."""
    from onboard.sitl.fleet import read_sea
    from validation import fleet_world as fw

    manifest = json.loads((root / "fleet.json").read_text())
    obs = {v["id"]: fw.complete(fw.observations(root / f"replay-{v['id']}" /
                                                "estimates.mcap")[0])
           for v in manifest["vehicles"]}
    obs = {v: rows for v, rows in obs.items() if len(rows) > 10}
    sea, depth = read_sea(root), fw.depth_of(root)
    t0 = min(o.utc for rows in obs.values() for o in rows)
    t1 = max(o.utc for rows in obs.values() for o in rows)
    grid = np.arange(t0, t1, step_s)
    errs = {v: errors_on_grid(rows, sea, depth[v], grid) for v, rows in obs.items()}
    figures = measure(errs, step_s)
    figures["common_time_s"] = common_time(errs, step_s)
    figures["delay"] = {v: delay(rows, sea, depth[v]) for v, rows in obs.items()
                        if rows[-1].utc - rows[0].utc > 4 * DELAYS_S[-1]}
    return figures


def report(name: str, f: dict) -> None:
    """One seed's figures in words."""
    print(f"{name}:")
    for v, g in f["vehicles"].items():
        print(f"  {v}: error RMS {g['rms'][0]:.4f}, {g['rms'][1]:.4f} m/s (mean "
              f"{g['mean'][0]:+.4f}, {g['mean'][1]:+.4f}); reported {g['reported'][0]:.4f}, "
              f"{g['reported'][1]:.4f}; common share {g['share'][0]:.2f}, "
              f"{g['share'][1]:.2f}; common variance / reported {g['of_reported'][0]:.3f}, "
              f"{g['of_reported'][1]:.3f}")
    for k, c in f["lag"].items():
        who = "one vehicle with itself" if k.endswith("own") else "two vehicles"
        print(f"  lag {k.split()[0]:>3} s, {who}: correlation {c[0]:+.2f}, {c[1]:+.2f}")
    for k, c in f["distance"].items():
        print(f"  two vehicles {k} apart (lag 0, {c[2]} s): correlation {c[0]:+.2f}, "
              f"{c[1]:+.2f}")
    print(f"  the common error's 1/e time: {f['common_time_s']:.0f} s")
    for v, by in f["delay"].items():
        best = min(by, key=lambda k: sum(by[k]))
        print(f"  {v} against the water it met earlier: " +
              ", ".join(f"{k} s {r[0]:.4f}, {r[1]:.4f}" for k, r in by.items()) +
              f" m/s; least at {best} s")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m validation.fleet_shared",
                                 description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dirs", type=Path, nargs="+")
    ap.add_argument("--step", type=float, default=1.0, help="time grid step (s)")
    a = ap.parse_args(argv)
    for d in a.dirs:
        report(str(d), one_seed(d, a.step))
    return 0


if __name__ == "__main__":
    sys.exit(main())
