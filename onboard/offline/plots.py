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


VELOCITY_PIPELINES = frozenset({"current"})
"""Pipelines whose ``north``/``east`` are a velocity (m/s), not a position: not a track."""
CURRENT_ARROWS = 40
"""Arrows drawn in the current's panel at most (evenly spaced in time)."""


def position_pairs(cols: dict[str, list[float]]) -> list[tuple[str, str, str]]:
    """(pipeline, its north column, its east column) of every pipeline with a position
    (m) in ``cols`` (not :data:`VELOCITY_PIPELINES`), that has at least one value."""
    pairs = [(c[:-6], c, c[:-6] + ".east") for c in cols if c.endswith(".north")
             and c[:-6] + ".east" in cols and c[:-6] not in VELOCITY_PIPELINES]
    return [p for p in pairs if any(v == v for v in cols[p[1]])]


def plot_track(estimates_csv: Path, out_png: Path, title: str | None = None) -> str | None:
    """track.png of :func:`track_figure` for ``estimates_csv``, titled ``title`` (the
    log's name; default the folder's); None if no pipeline has a position. Raises
    ImportError without matplotlib."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = track_figure(read_columns(estimates_csv), title or estimates_csv.parent.name)
    if fig is None:
        return None
    fig.savefig(out_png, dpi=110)
    plt.close(fig)
    return str(out_png)


def track_figure(cols: dict[str, list[float]], title: str):
    """The positions (m) of every pipeline that has one, one line per run (broken across
    runs and gaps in the log, :func:`break_gaps`); and, when the ``current`` pipeline
    published one, the current as arrows over time in a panel of its own. None if no
    pipeline has a position."""
    import matplotlib.pyplot as plt

    pairs = position_pairs(cols)
    if not pairs:
        return None
    current = _current_arrows(cols)
    if current is None:
        fig, ax = plt.subplots(figsize=(7, 6))
    else:
        fig, (ax, ax_c) = plt.subplots(2, 1, figsize=(7, 9),
                                       gridspec_kw={"height_ratios": [3, 1]})
        _plot_current(ax_c, *current)
    run = cols.get("run")
    for name, n, e in pairs:
        style = {"lw": 0.8, "marker": ".", "ms": 2} if name == "nav" else {"lw": 1.2}
        _, east, north = break_gaps(cols["t"], cols[e], cols[n], run=run)
        ax.plot(east, north, label="GNSS" if name == "nav" else name, **style)
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend()
    runs = len(set(run)) if run else 1
    ax.set_title(f"Track: {title}" + (f" ({runs} runs)" if runs > 1 else ""))
    fig.tight_layout()
    return fig


def _current_arrows(cols: dict[str, list[float]]
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(t, north, east) of at most :data:`CURRENT_ARROWS` published currents (m/s),
    evenly spaced in time; None when none was published."""
    if "current.north" not in cols or "current.east" not in cols:
        return None
    t = np.asarray(cols["t"], float)
    n = np.asarray(cols["current.north"], float)
    e = np.asarray(cols["current.east"], float)
    ok = np.flatnonzero(np.isfinite(n) & np.isfinite(e))
    if not len(ok):
        return None
    pick = ok[np.unique(np.linspace(0, len(ok) - 1, min(CURRENT_ARROWS, len(ok))).astype(int))]
    return t[pick], n[pick], e[pick]


def _plot_current(ax, t: np.ndarray, north: np.ndarray, east: np.ndarray) -> None:
    """The current as arrows from the time axis (a stick plot: up is toward north, right
    toward east, the length its speed), with a 0.5 m/s key."""
    q = ax.quiver(t, np.zeros_like(t), east, north, angles="uv", scale_units="y",
                  scale=1.0, width=0.004, color="tab:blue")
    top = max(0.25, float(np.nanmax(np.hypot(north, east))) * 1.15)
    ax.set_ylim(-top, top)
    ax.axhline(0.0, color="0.6", lw=0.6)
    ax.quiverkey(q, 0.9, 0.9, 0.5, "0.5 m/s", labelpos="W", coordinates="axes")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("current (m/s)\nup: toward north")
    ax.set_title("Current: where the water flows to (arrows over time)")
    ax.grid(True, alpha=0.3)
