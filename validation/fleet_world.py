"""``onboard fleet``'s field on a fleet it did not build: the simulator's fleet
(:mod:`sitl.fleet`: its own current field, vehicles, protocols and clocks), each vehicle's
log replayed by ``onboard batch`` with its own configs, its ``current.parquet`` fused
without one vehicle and predicted along that vehicle's track, against the true field.

    python -m validation.fleet_world [FLEET] [--seed N] [--out DIR] [--every N]

Prints, per vehicle left out: the points predicted, the field's RMS error per component,
the share within 1.96 of its sigma, and the vehicle's own estimate's RMS at the same
points (what the field is up against). A vehicle whose rows have no position (an AUV that
never had a GNSS fix) can be neither fused nor scored: it is named so.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def replay_fleet(root: Path, manifest: dict) -> dict[str, Path]:
    """``onboard batch`` of each vehicle's log with its configs; vehicle -> its
    current.parquet."""
    tables = {}
    for v in manifest["vehicles"]:
        out = root / f"batch-{v['id']}"
        configs = [a for c in v["configs"]   # a bundled name, then the vehicle's own file
                   for a in ("--config", str(root / c) if (root / c).exists() else c)]
        subprocess.run([sys.executable, "-m", "onboard", "batch", str(root / v["files"]["tlog"]),
                        *configs, "--out", str(out), "--jobs", "1", "--force"],
                       check=True, stdout=subprocess.DEVNULL)
        tables[v["id"]] = out / "current.parquet"
    return tables


def observations(table: Path) -> list:
    """The placed, timed rows of a current.parquet as the field's observations."""
    import pyarrow.parquet as pq

    from onboard.fleet.field import Observation

    return [Observation(vehicle=r["vehicle"], utc=r["utc"].timestamp(), lat_deg=r["lat"],
                        lon_deg=r["lon"], north=r["north"], east=r["east"],
                        std_north=r["std_north"], std_east=r["std_east"])
            for r in pq.read_table(table).to_pylist()
            if None not in (r["utc"], r["lat"], r["lon"], r["std_north"], r["std_east"])]


def left_out(sea, obs: dict[str, list], vehicle: str, every: int) -> dict[str, np.ndarray]:
    """The field without ``vehicle``, predicted at every ``every``-th of its rows: errors
    of the field and of the vehicle's own estimate against the true field, and the
    field's errors in sigmas."""
    from onboard.fleet.field import CurrentField, Hyper, one_blas_thread

    field = CurrentField(hyper=Hyper())
    for other, rows in obs.items():
        if other != vehicle:
            for o in rows:
                field.add(o)
    field.fit()
    err, own, z = [], [], []
    with one_blas_thread():
        for o in obs[vehicle][::every]:
            p = field.predict(o.lat_deg, o.lon_deg, o.utc)
            if p.north is None:
                continue
            tn, te = sea.at(o.lat_deg, o.lon_deg, 0.0, o.utc)
            e = np.array([p.north - tn, p.east - te])
            err.append(e)
            own.append([o.north - tn, o.east - te])
            z.append(np.abs(e) / np.array([p.std_north, p.std_east]))
    return {"err": np.reshape(err, (-1, 2)), "own": np.reshape(own, (-1, 2)),
            "z": np.reshape(z, (-1, 2))}


def main(argv: list[str] | None = None) -> int:
    from onboard.sitl.fleet import get_fleet, read_sea, write_fleet

    ap = argparse.ArgumentParser(prog="python -m validation.fleet_world", description=__doc__)
    ap.add_argument("fleet", nargs="?", default="fleet-channel")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=None, help="keep the logs here")
    ap.add_argument("--every", type=int, default=50, help="predict at every N-th row")
    a = ap.parse_args(argv)
    root = a.out or Path(tempfile.mkdtemp(prefix="fleet-world-"))
    root.mkdir(parents=True, exist_ok=True)
    manifest = write_fleet(get_fleet(a.fleet), root, seed=a.seed)
    tables = replay_fleet(root, manifest)
    obs = {vid: observations(t) for vid, t in tables.items()}
    sea = read_sea(root)
    pooled = []
    for vid, rows in obs.items():
        if not rows:
            print(f"{vid}: no row with a position and a time: neither fused nor scored")
            continue
        r = left_out(sea, obs, vid, a.every)
        if not len(r["err"]):
            print(f"{vid}: the field knows nothing along its track without it")
            continue
        rms = np.sqrt((r["err"] ** 2).mean(axis=0))
        own = np.sqrt((r["own"] ** 2).mean(axis=0))
        print(f"{vid}: {len(r['err'])} points; field RMS north {rms[0]:.3f}, east {rms[1]:.3f} "
              f"m/s, {(r['z'] < 1.96).mean():.2f} within 1.96 sigma; its own estimate "
              f"{own[0]:.3f}, {own[1]:.3f} m/s")
        pooled.append(r)
    if pooled:
        err = np.concatenate([r["err"] for r in pooled])
        z = np.concatenate([r["z"] for r in pooled])
        rms = np.sqrt((err ** 2).mean(axis=0))
        print(f"pooled: RMS north {rms[0]:.3f}, east {rms[1]:.3f} m/s, "
              f"{(z < 1.96).mean():.2f} within 1.96 sigma ({len(err)} points)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
