"""``onboard fleet``'s field on a fleet it did not build: the simulator's fleet
(:mod:`sitl.fleet`: its own current field, vehicles, protocols and clocks), each vehicle's
log replayed by ``onboard replay`` with its own configs, its ``current`` records (as the
vehicle publishes them on Zenoh, read from the replay's MCAP: ``utc``, ``lat_deg``,
``lon_deg``, ``position_std_m``) fused without one vehicle and predicted along that
vehicle's track, against the true field.

    python -m validation.fleet_world [FLEET] [--seeds 0,1,...] [--without ID]...
                                     [--out DIR] [--every N]

Prints per seed and vehicle left out: the points predicted, the field's RMS error per
component, the share within 1.96 of its sigma (with its 95 % interval: how precisely a
track's correlated errors measure it, validation/coverage.py), and the vehicle's own
estimate's RMS at the same points (what the field is up against), and the RMS and
coverage apart where another vehicle's window is within :data:`REACH` (the field
interpolates) and beyond (it extrapolates); the field's down at the vehicles that give
one (fitted with every vehicle: no other gives a down) against the true field's (none:
the simulator's field is horizontal); then, over the seeds, each figure's median and
range, with a seed's coverage interval and the RMS within reach. ``--without ID`` scores
the same logs again with vehicle ``ID`` left out of every fit (the field without it); a
vehicle whose records have no position (an AUV that never had a GNSS fix) can be neither
fused nor scored: it is named so.
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from validation.coverage import interval

REACH = 0.5
"""A point is within the others' reach where another vehicle's window is nearer than this
in the field's scaled space and time (the fitted length and time scales as units: the
field's signal correlation with that window at least ``exp(-REACH^2 / 2)`` = 0.88); beyond
it the field extrapolates, and its RMS there is reported apart."""


def replay_fleet(root: Path, manifest: dict, reuse: bool = False) -> dict[str, Path]:
    """``onboard replay`` of each vehicle's log with its configs, its records into an
    MCAP (with ``reuse``, an MCAP already there is taken as it is); vehicle -> that
    MCAP."""
    out = {}
    for v in manifest["vehicles"]:
        rep = root / f"replay-{v['id']}"
        out[v["id"]] = rep / "estimates.mcap"
        if reuse and out[v["id"]].exists():
            continue
        rep.mkdir(exist_ok=True)
        configs = [a for c in v["configs"]   # a bundled name, then the vehicle's own file
                   for a in ("--config", str(root / c) if (root / c).exists() else c)]
        subprocess.run([sys.executable, "-m", "onboard", "replay",
                        str(root / v["files"]["tlog"]), *configs, "--out", str(rep),
                        "--no-plot", "--mcap", str(rep / "estimates.mcap"), "--force"],
                       check=True, stdout=subprocess.DEVNULL)
    return out


def observations(mcap: Path) -> tuple[list, dict[str, int]]:
    """The ``current`` records of a replay's MCAP as the field's observations (those
    :func:`onboard.fleet.field.observation` takes), and the others counted by reason."""
    import msgspec
    from mcap.reader import make_reader

    from onboard.core.messages import EstimateRecord
    from onboard.fleet.field import observation

    dec = msgspec.json.Decoder(EstimateRecord)
    obs: list = []
    left: dict[str, int] = {}
    with open(mcap, "rb") as f:
        for _, channel, msg in make_reader(f).iter_messages():
            if channel.topic.endswith("/est/current"):
                o, why = observation(dec.decode(msg.data))
                if o is None:
                    left[why] = left.get(why, 0) + 1
                else:
                    obs.append(o)
    return obs, left


def complete(rows: list) -> list:
    """The observations of ``rows`` that give both horizontal components: where a
    vehicle's own estimate is compared with the truth (the field fuses the others too)."""
    return [o for o in rows if o.north is not None and o.east is not None]


def depth_of(root: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each vehicle's true (utc, depth) from ``truth-current.csv``."""
    rows: dict[str, list[tuple[float, float]]] = {}
    with open(root / "truth-current.csv") as f:
        for r in csv.DictReader(f):
            rows.setdefault(r["vehicle"], []).append((float(r["utc"]), float(r["depth_m"])))
    return {v: (np.array([a for a, _ in x]), np.array([b for _, b in x]))
            for v, x in rows.items()}


def fused(obs: dict[str, list], leave: set[str]):
    """The field fitted (hyperparameters by marginal likelihood) on every vehicle's
    observations but those of ``leave``."""
    from onboard.fleet.field import CurrentField, Hyper

    field = CurrentField(hyper=Hyper())
    for vid, rows in obs.items():
        if vid not in leave:
            for o in rows:
                field.add(o)
    field.fit()
    return field


def left_out(sea, depth, obs: dict[str, list], vehicle: str, without: set[str],
             every: int) -> dict[str, np.ndarray]:
    """The field without ``vehicle`` (and ``without``), predicted at every ``every``-th of
    its rows at its depth: errors of the field and of the vehicle's own estimate against
    the true field, and the field's errors in sigmas."""
    from onboard.fleet.field import one_blas_thread

    field = fused(obs, without | {vehicle})
    fitted = getattr(field.fitted, "central", field.fitted)   # an Averaged field's scales
    err, own, z, reach = [], [], [], []
    t_d, d = depth[vehicle]
    with one_blas_thread():
        for o in complete(obs[vehicle])[::every]:
            p = field.predict(o.lat_deg, o.lon_deg, o.utc)
            if p.north is None:
                continue
            tn, te = sea.at(o.lat_deg, o.lon_deg, float(np.interp(o.utc, t_d, d)), o.utc)
            e = np.array([p.north - tn, p.east - te])
            err.append(e)
            own.append([o.north - tn, o.east - te])
            z.append(np.abs(e) / np.array([p.std_north, p.std_east]))
            x = np.array([*fitted.obs.plane.to_ne(o.lat_deg, o.lon_deg), o.utc - field.t_ref])
            reach.append(fitted.tree.query(x / fitted.scale)[0])
    return {"err": np.reshape(err, (-1, 2)), "own": np.reshape(own, (-1, 2)),
            "z": np.reshape(z, (-1, 2)), "reach": np.array(reach)}


def down_at(obs: dict[str, list], without: set[str], every: int) -> dict[str, np.ndarray]:
    """The field's down (fitted with every vehicle but ``without``) at every ``every``-th
    row of the vehicles that give one, against the true down (0: the simulator's field is
    horizontal): errors and errors in sigmas."""
    from onboard.fleet.field import one_blas_thread

    field = fused(obs, without)
    err, z = [], []
    with one_blas_thread():
        for vid, rows in obs.items():
            for o in rows[::every]:
                if vid in without or o.down is None:
                    continue
                p = field.predict(o.lat_deg, o.lon_deg, o.utc)
                if p.down is not None:
                    err.append(p.down)
                    z.append(abs(p.down) / p.std_down)
    return {"err": np.array(err), "z": np.array(z)}


def one_seed(fleet: str, seed: int, root: Path, without: list[set[str]], every: int,
             reuse: bool = False) -> dict:
    """Simulate ``fleet`` with ``seed`` into ``root``, replay it, and score each vehicle
    left out (and the down), once per set of vehicles in ``without`` left out of every
    fit; prints a line per figure; returns the figures by (set, vehicle). With ``reuse``
    the logs and replays already in ``root`` are scored again (the simulator and the
    replays are deterministic for a seed: only the field's own code is run)."""
    from onboard.sitl.fleet import get_fleet, read_manifest, read_sea, write_fleet

    root.mkdir(parents=True, exist_ok=True)
    if reuse and (root / "fleet.json").exists():
        manifest = read_manifest(root)
    else:
        manifest = write_fleet(get_fleet(fleet), root, seed=seed)
    obs = {}
    for vid, mcap in replay_fleet(root, manifest, reuse).items():
        obs[vid], left = observations(mcap)
        if left:
            print(f"seed {seed} {vid}: records not fused: {left}")
    sea, depth = read_sea(root), depth_of(root)
    figures: dict = {}
    for leave in without:
        label = "without " + ", ".join(sorted(leave)) if leave else "every vehicle"
        for vid in obs:
            if vid not in leave:
                fig = score(sea, depth, obs, vid, leave, every)
                if fig is not None:
                    figures[label, vid] = fig
                print(f"seed {seed} {label}, {vid} left out: " + describe(fig), flush=True)
        down = down_at(obs, leave, every)
        if len(down["err"]):
            figures[label, "down"] = fig = {
                "points": len(down["err"]), "rms": np.sqrt((down["err"] ** 2).mean()),
                "coverage": float((down["z"] < 1.96).mean())}
            print(f"seed {seed} {label}, down at the diving vehicles: {fig['points']} "
                  f"points; RMS {fig['rms']:.3f} m/s, {fig['coverage']:.2f} within 1.96 "
                  "sigma", flush=True)
    return figures


def score(sea, depth, obs: dict[str, list], vehicle: str, leave: set[str], every: int
          ) -> dict | None:
    """:func:`left_out`'s figures for ``vehicle`` (None: not placed, or nothing known
    along its track)."""
    if not obs[vehicle]:
        return None
    r = left_out(sea, depth, obs, vehicle, leave, every)
    if not len(r["err"]):
        return None
    hits = [r["z"][:, 0] < 1.96, r["z"][:, 1] < 1.96]
    near = r["reach"] <= REACH
    parts = {name: {"points": int(m.sum()), "rms": np.sqrt((r["err"][m] ** 2).mean(axis=0)),
                    "coverage": float((r["z"][m] < 1.96).mean())}
             for name, m in (("near", near), ("far", ~near)) if m.any()}
    return {"points": len(r["err"]), "rms": np.sqrt((r["err"] ** 2).mean(axis=0)),
            "coverage": float((r["z"] < 1.96).mean()), "hits": hits,
            "own": np.sqrt((r["own"] ** 2).mean(axis=0)), **parts}


def describe(fig: dict | None) -> str:
    """A vehicle's figures in words."""
    if fig is None:
        return "no record with a position, or the field knows nothing along its track"
    text = (f"{fig['points']} points; field RMS north {fig['rms'][0]:.3f}, east "
            f"{fig['rms'][1]:.3f} m/s, {interval(fig['hits']).text()} within 1.96 sigma "
            f"(95 % interval); its own "
            f"estimate {fig['own'][0]:.3f}, {fig['own'][1]:.3f} m/s")
    for name, words in (("near", "within the others' reach"), ("far", "beyond it")):
        if name in fig:
            f = fig[name]
            text += (f"; {words} {f['points']}: RMS {f['rms'][0]:.3f}, {f['rms'][1]:.3f} "
                     f"m/s, {f['coverage']:.2f} within 1.96 sigma")
    return text


def spread(per_seed: list[dict]) -> None:
    """Each vehicle's figures over the seeds: median and range (a seed changes the
    sensors' noise and so each vehicle's own error, not the sea or the tracks), and how
    precisely one seed measures the coverage (its 95 % interval: the seeds share the sea's
    structure, so their agreement is not a measure of another sea's)."""
    for key in sorted({k for f in per_seed for k in f}):
        got = [f[key] for f in per_seed if key in f]
        rms = np.array([np.atleast_1d(g["rms"]) for g in got])
        cov = np.array([g["coverage"] for g in got])
        parts = [f"{len(got)} seeds"]
        for k, name in enumerate(("north", "east") if rms.shape[1] == 2 else ("down",)):
            parts.append(f"RMS {name} {np.median(rms[:, k]):.3f} "
                         f"({rms[:, k].min():.3f}-{rms[:, k].max():.3f}) m/s")
        parts.append(f"coverage {np.median(cov):.2f} ({cov.min():.2f}-{cov.max():.2f})")
        near = np.array([g["near"]["rms"] for g in got if "near" in g]).reshape(-1, 2)
        if len(near):
            parts.append(f"within the others' reach RMS north {np.median(near[:, 0]):.3f}, "
                         f"east {np.median(near[:, 1]):.3f} m/s (median of {len(near)}; "
                         f"both <= 0.03 in {int((near.max(axis=1) <= 0.03).sum())})")
        if all("hits" in g for g in got):
            each = [interval(g["hits"]) for g in got]
            parts.append(f"a seed's 95 % interval {np.median([c.low for c in each]):.2f}-"
                         f"{np.median([c.high for c in each]):.2f} (median; "
                         f"{np.median([c.n_eff for c in each]):.0f} effective samples of "
                         f"{np.median([c.n for c in each]):.0f})")
        print(f"over the seeds, {key[0]}, {key[1]}: " + ", ".join(parts))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m validation.fleet_world", description=__doc__)
    ap.add_argument("fleet", nargs="?", default="fleet-channel")
    ap.add_argument("--seeds", default="0", help="comma-separated simulator seeds")
    ap.add_argument("--without", action="append", default=[],
                    help="score again with this vehicle left out of every fit "
                         "(repeatable: one more pass each)")
    ap.add_argument("--out", type=Path, default=None, help="keep the logs here")
    ap.add_argument("--every", type=int, default=50, help="predict at every N-th row")
    ap.add_argument("--reuse", action="store_true",
                    help="score the logs and replays already under --out again")
    a = ap.parse_args(argv)
    root = a.out or Path(tempfile.mkdtemp(prefix="fleet-world-"))
    seeds = [int(s) for s in a.seeds.split(",")]
    leave = [set()] + [{v} for v in a.without]
    per_seed = [one_seed(a.fleet, seed, root / f"seed-{seed}", leave, a.every, a.reuse)
                for seed in seeds]
    if len(seeds) > 1:
        spread(per_seed)
    return 0


if __name__ == "__main__":
    sys.exit(main())
