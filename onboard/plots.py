"""Figures for replay and the docs (matplotlib, imported only when a figure is made)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

GAP_FACTOR = 3.0
"""A time step longer than this many median steps is a gap: plotted lines break there."""


def break_gaps(t, *ys, gap_s: float | None = None, run=None) -> tuple[np.ndarray, ...]:
    """``t`` and ``ys`` with a NaN inserted wherever a time step exceeds ``gap_s`` (s;
    default :data:`GAP_FACTOR` median steps) or ``run`` (labels per point) changes, so
    that a plotted line breaks there instead of joining the two sides of a gap."""
    t = np.asarray(t, float)
    if len(t) < 2:
        return (t, *(np.asarray(y, float) for y in ys))
    dt = np.diff(t)
    if gap_s is None:
        pos = dt[dt > 0]
        gap_s = GAP_FACTOR * float(np.median(pos)) if len(pos) else np.inf
    cut = dt > gap_s
    if run is not None:
        cut |= np.asarray(run)[1:] != np.asarray(run)[:-1]
    idx = np.flatnonzero(cut) + 1
    return (np.insert(t, idx, np.nan), *(np.insert(np.asarray(y, float), idx, np.nan)
                                         for y in ys))


def read_columns(path: Path) -> dict[str, list[float]]:
    """estimates.csv as columns of floats (NaN for empty cells)."""
    with open(path, newline="") as f:
        rows = csv.reader(f)
        header = next(rows)
        cols: dict[str, list[float]] = {h: [] for h in header}
        for row in rows:
            for h, v in zip(header, row):
                cols[h].append(float(v) if v else float("nan"))
    return cols


def plot_track(estimates_csv: Path, out_png: Path) -> str | None:
    """North/east track of every pipeline that has one, the lines broken across gaps in
    the log (:func:`break_gaps` on the ``t`` column); None if none has a track.
    Raises ImportError without matplotlib."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = read_columns(estimates_csv)
    pairs = [(c[:-6], c, c[:-6] + ".east") for c in cols if c.endswith(".north")
             and c[:-6] + ".east" in cols]
    pairs = [p for p in pairs if any(v == v for v in cols[p[1]])]
    if not pairs:
        return None
    fig, ax = plt.subplots(figsize=(7, 6))
    for name, n, e in pairs:
        style = {"lw": 0.8, "marker": ".", "ms": 2} if name == "nav" else {"lw": 1.2}
        _, east, north = break_gaps(cols["t"], cols[e], cols[n])
        ax.plot(east, north, label="GNSS" if name == "nav" else name, **style)
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend()
    ax.set_title(f"Track: {estimates_csv.parent.name}")
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    plt.close(fig)
    return str(out_png)
