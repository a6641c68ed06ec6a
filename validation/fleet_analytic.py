"""``onboard fleet``'s field on a current we did not build: the Bickley jet of
del-Castillo-Negrete and Morrison 1993 in Rypina et al. 2007's form and parameters
(:class:`onboard.sitl.current_field.BickleyJet`), scaled to a coastal jet, sampled by a
simulated fleet: the places and times of its vehicles' published ``current`` records
(their replayed logs, as :mod:`validation.fleet_world` leaves them), each record's current
the jet's there plus that vehicle's own error, an AR(1) in time whose sigma per component
and correlation time are those measured of that vehicle's estimate against the
simulator's truth. Each vehicle is left out in turn and predicted along its track.

    python -m validation.fleet_analytic --logs DIR [--seeds 101,102,...] [--every N]
                                        [--u0 M/S] [--half-width M] [--direction DEG]

``DIR``: one seed's folder of ``python -m validation.fleet_world FLEET --out ROOT``
(``ROOT/seed-N``: the fleet's logs and replays). Prints the vehicles' measured errors,
then per seed and vehicle left out the field's RMS per component and its 95 % coverage,
then their median and range over the seeds.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

JET_U0_MPS = 0.3
"""The scaled jet's peak speed (m/s): a headland or channel-mouth jet."""
JET_HALF_WIDTH_M = 120.0
"""Its half-width ``L`` (m): the jet core 240 m across, its waves 450-1400 m long."""
JET_DIRECTION_DEG = 60.0
"""Its direction (deg from north), across the fleet's survey lines."""


def error_model(times: np.ndarray, err: np.ndarray) -> tuple[np.ndarray, float]:
    """A vehicle's own error (n, 2) at ``times`` (s) as an AR(1): its RMS per component
    (m/s) and its correlation time (s): the lag at which its autocorrelation, on a 1-s
    grid, first falls below 1/e (averaged over the components)."""
    rms = np.sqrt((err ** 2).mean(axis=0))
    grid = np.arange(times[0], times[-1], 1.0)
    taus = []
    for c in range(2):
        x = np.interp(grid, times, err[:, c])
        x = x - x.mean()
        acf = np.correlate(x, x, "full")[x.size - 1:] / (x @ x)
        below = np.flatnonzero(acf < math.exp(-1.0))
        taus.append(float(below[0]) if below.size else float(x.size))
    return rms, float(np.mean(taus))


def ar1_at(rng: np.random.Generator, times: np.ndarray, sigma: float, tau: float
           ) -> np.ndarray:
    """An Ornstein-Uhlenbeck sequence at ``times`` (s, increasing): stationary sigma
    ``sigma``, correlation time ``tau`` (s), started in its stationary distribution."""
    out = np.empty(times.size)
    out[0] = rng.normal(0.0, sigma)
    phi = np.exp(-np.diff(times) / tau)
    drive = rng.normal(0.0, 1.0, times.size - 1) * sigma * np.sqrt(1.0 - phi ** 2)
    for i in range(1, times.size):
        out[i] = phi[i - 1] * out[i - 1] + drive[i - 1]
    return out


def measured_errors(obs: dict[str, list], sea, depth) -> dict[str, tuple[np.ndarray, float]]:
    """Each vehicle's :func:`error_model` from its records against the simulator's true
    field at its depth."""
    out = {}
    for vid, rows in obs.items():
        if len(rows) < 10:
            continue
        t = np.array([o.utc for o in rows])
        t_d, d = depth[vid]
        truth = np.array([sea.at(o.lat_deg, o.lon_deg, float(np.interp(o.utc, t_d, d)), o.utc)
                          for o in rows])
        est = np.array([[o.north, o.east] for o in rows], dtype=float)   # None: NaN
        known = np.isfinite(est).all(axis=1)   # the records that give both components
        out[vid] = error_model(t[known], (est - truth)[known])
    return out


def sampled(obs: dict[str, list], jet, errors: dict, seed: int) -> dict[str, list]:
    """The records of ``obs`` with their current replaced by the ``jet``'s at their place
    and time plus their vehicle's AR(1) error (``errors``), seeded by ``seed``."""
    import dataclasses

    rng = np.random.default_rng(seed)
    out = {}
    for vid in sorted(errors):
        rows = obs[vid]
        (s_n, s_e), tau = errors[vid]
        t = np.array([o.utc for o in rows])
        e_n, e_e = ar1_at(rng, t, s_n, tau), ar1_at(rng, t, s_e, tau)
        c_n, c_e = jet.at(np.array([o.lat_deg for o in rows]),
                          np.array([o.lon_deg for o in rows]), 0.0, t)
        out[vid] = [dataclasses.replace(  # a component the vehicle did not give stays None
            o, north=None if o.north is None else float(c_n[i] + e_n[i]),
            east=None if o.east is None else float(c_e[i] + e_e[i]), down=None, std_down=None)
            for i, o in enumerate(rows)]
    return out


def jet_sea(origin: tuple[float, float], utc0: float, u0: float, half_width: float,
            direction_deg: float):
    """The scaled Bickley jet as a sea about ``origin`` (its axis through it)."""
    from onboard.sitl.current_field import BickleyJet, SeaField

    return SeaField(origin, (BickleyJet.coastal(u0, half_width,
                                                direction=math.radians(direction_deg),
                                                t_ref=utc0),))


def main(argv: list[str] | None = None) -> int:
    from onboard.sitl.fleet import read_sea
    from validation import fleet_world as fw

    ap = argparse.ArgumentParser(prog="python -m validation.fleet_analytic",
                                 description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--logs", type=Path, required=True)
    ap.add_argument("--seeds", default="101,102,103,104,105,106,107,108")
    ap.add_argument("--every", type=int, default=50)
    ap.add_argument("--u0", type=float, default=JET_U0_MPS)
    ap.add_argument("--half-width", type=float, default=JET_HALF_WIDTH_M)
    ap.add_argument("--direction", type=float, default=JET_DIRECTION_DEG)
    a = ap.parse_args(argv)
    manifest = json.loads((a.logs / "fleet.json").read_text())
    obs = {v["id"]: fw.observations(a.logs / f"replay-{v['id']}" / "estimates.mcap")[0]
           for v in manifest["vehicles"]}
    sea, depth = read_sea(a.logs), fw.depth_of(a.logs)
    errors = measured_errors(obs, sea, depth)
    for vid, ((s_n, s_e), tau) in errors.items():
        print(f"{vid}: its estimate's error RMS {s_n:.3f}, {s_e:.3f} m/s, correlation "
              f"time {tau:.0f} s")
    jet = jet_sea(sea.origin, min(o.utc for rows in obs.values() for o in rows), a.u0,
                  a.half_width, a.direction)
    depth0 = {vid: (np.array([0.0, 1e12]), np.zeros(2)) for vid in errors}  # a 2-D jet
    per_seed = []
    for seed in (int(s) for s in a.seeds.split(",")):
        fake = sampled(obs, jet, errors, seed)
        figures = {}
        for vid in fake:
            fig = fw.score(jet, depth0, fake, vid, set(), a.every)
            if fig is not None:
                figures["bickley jet", vid] = fig
            print(f"seed {seed}, {vid} left out: " + fw.describe(fig), flush=True)
        per_seed.append(figures)
    fw.spread(per_seed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
