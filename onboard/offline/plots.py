"""Figures for replay and the docs (matplotlib, imported only when a figure is made).

track.png (:func:`plot_track`): the positions of every pipeline on a map, the measured
track labelled by what it is (:func:`position_label`), the water current as arrows along
the track with a scale arrow inside the map; below, the current's north and east
components over time with their 2-sigma bands, the spans where it was unknown shaded.
Long logs are decimated to at most :data:`MAX_POINTS` points a line (breaks at gaps and
runs kept), the figure is drawn without pyplot, and only the columns it draws are read.
"""

from __future__ import annotations

import csv
import math
import warnings
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from onboard.core.pipeline_config import VELOCITY_PIPELINES

GAP_FACTOR = 3.0
"""A time step longer than this many median steps is a gap: plotted lines break there."""
MAX_POINTS = 4000
"""Points drawn per line at most: a longer series is decimated evenly (its first and last
point, and both sides of every break, kept). Far more than a 7-inch figure resolves at
110 dpi (770 px)."""
MAX_MARKERS = 400
"""Markers drawn on the measured track at most (evenly spaced along it)."""
CURRENT_ARROWS = 30
"""Arrows of the current drawn on the map at most (evenly spaced in time)."""
ARROW_KEY_MPS = 0.5
"""The speed of the map's scale arrow (m/s)."""
ARROW_SHARE = 0.08
"""The scale arrow's length as a share of the map's larger extent."""
SIGMA_BAND = 2.0
"""The current's bands are this many published sigmas either side."""
DPI = 110
"""Resolution of track.png (dots per inch)."""
UNKNOWN_GREY = "0.85"
"""The shade of the spans where the current was unknown."""

ARROW_TRACKS = ("nav", "kf", "aie", "eseso")
"""Where a current arrow starts: the first of these with a position at its row."""
CURRENT_COLUMNS = ("current.north", "current.east", "current.std_north", "current.std_east")
"""The current's columns the figure reads."""
DIVE_COLUMNS = ("dac.dive_end", "dac.place_north", "dac.place_east", "dac.std_north",
                "dac.std_east")
"""A glider's dive currents' columns the figure reads (with ``dac.north``, ``dac.east``)."""
POSITION_LABELS = {
    "gnss": "GNSS fixes",
    "navigation": "logged navigation track",
    "unstated": "logged positions",
}
"""The measured track's label by what the log's positions are (:func:`position_label`)."""


def position_label(log_format: str, csv_positions: str = "unstated") -> str:
    """The legend label of the measured track (pipeline ``nav``): ``GNSS fixes`` for
    every format whose positions are a receiver's fixes (MAVLink GPS_RAW_INT, DataFlash
    GPS, NMEA, recordings); for a CSV log what its config's ``[csv] position_kind``
    (``csv_positions``) says its position columns hold: ``gnss``, ``navigation`` (the
    vehicle's own navigation solution, a glider's dead-reckoned track) or ``unstated``."""
    if log_format != "csv":
        return POSITION_LABELS["gnss"]
    return POSITION_LABELS.get(csv_positions, POSITION_LABELS["unstated"])


def break_gaps(t, *ys, gap_s: float | None = None, run=None) -> tuple[np.ndarray, ...]:
    """``t`` and ``ys`` with a NaN inserted wherever a time step exceeds ``gap_s`` (s;
    default :data:`GAP_FACTOR` median steps) or ``run`` (labels per point) changes, so
    that a plotted line breaks there instead of joining the two sides of a gap."""
    t = np.asarray(t, float)
    if len(t) < 2:
        return (t, *(np.asarray(y, float) for y in ys))
    idx = np.flatnonzero(_cuts(t, gap_s, run)) + 1
    return (np.insert(t, idx, np.nan), *(np.insert(np.asarray(y, float), idx, np.nan)
                                         for y in ys))


def _cuts(t: np.ndarray, gap_s: float | None, run) -> np.ndarray:
    """Per step of ``t`` (length ``len(t) - 1``): whether a line breaks there (a step
    longer than ``gap_s``, default :data:`GAP_FACTOR` median steps, or a new run)."""
    dt = np.diff(t)
    if gap_s is None:
        pos = dt[dt > 0]
        gap_s = GAP_FACTOR * float(np.median(pos)) if len(pos) else np.inf
    cut = dt > gap_s
    if run is not None:
        r = np.asarray(run)
        cut |= r[1:] != r[:-1]
    return cut


def decimate(t, *ys, run=None, max_points: int = MAX_POINTS) -> tuple[np.ndarray, ...]:
    """``t`` and ``ys`` as :func:`break_gaps` gives them, with at most about
    ``max_points`` points: every k-th point, the first and last, and both sides of every
    break (found on the full series, so the longer steps of the decimated one are not
    taken for gaps)."""
    t = np.asarray(t, float)
    n = len(t)
    if n < 2:
        return (t, *(np.asarray(y, float) for y in ys))
    cut = _cuts(t, None, run)
    segment = np.concatenate(([0], np.cumsum(cut)))
    keep = np.zeros(n, bool)
    keep[::max(1, math.ceil(n / max_points))] = True
    keep[[0, -1]] = True
    edges = np.flatnonzero(cut)
    keep[edges] = True
    keep[edges + 1] = True
    return break_gaps(t[keep], *(np.asarray(y, float)[keep] for y in ys), gap_s=math.inf,
                      run=segment[keep])


def _cell(text: str) -> float:
    """One estimates.csv cell as a float (NaN when empty)."""
    return float(text) if text else math.nan


def read_columns(path: Path, wanted: Callable[[str], bool] | None = None
                 ) -> dict[str, list[float]]:
    """estimates.csv as columns of floats (NaN for empty cells); only the columns whose
    name ``wanted`` accepts (default: all)."""
    with open(path, newline="") as f:
        header = next(csv.reader(f), [])
        pick = [i for i, h in enumerate(header) if wanted is None or wanted(h)]
        if not pick:
            return {}
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # a header without rows
            table = np.loadtxt(f, delimiter=",", usecols=pick, converters=_cell, ndmin=2,
                               dtype=float)
    return {header[i]: table[:, k].tolist() for k, i in enumerate(pick)}


def _drawn(name: str) -> bool:
    """Whether track.png reads column ``name``: time, run, positions and the current."""
    return (name in ("t", "run") or name in CURRENT_COLUMNS or name in DIVE_COLUMNS
            or name.endswith((".north", ".east")))


def position_pairs(cols: dict[str, list[float]]) -> list[tuple[str, str, str]]:
    """(pipeline, its north column, its east column) of every pipeline with a position
    (m) in ``cols`` (not :data:`VELOCITY_PIPELINES`), that has at least one value."""
    pairs = [(c[:-6], c, c[:-6] + ".east") for c in cols if c.endswith(".north")
             and c[:-6] + ".east" in cols and c[:-6] not in VELOCITY_PIPELINES]
    return [p for p in pairs if any(v == v for v in cols[p[1]])]


def plot_track(estimates_csv: Path, out_png: Path, title: str | None = None,
               position: str = POSITION_LABELS["gnss"]) -> str | None:
    """track.png of :func:`track_figure` for ``estimates_csv``, titled ``title`` (the
    log's name; default the folder's), the measured track labelled ``position``
    (:func:`position_label`); None if no pipeline has a position. Raises ImportError
    without matplotlib."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = track_figure(read_columns(estimates_csv, _drawn),
                       title or estimates_csv.parent.name, position)
    if fig is None:
        return None
    FigureCanvasAgg(fig).print_png(str(out_png))
    return str(out_png)


def track_figure(cols: dict[str, list[float]], title: str,
                 position: str = POSITION_LABELS["gnss"]):
    """A matplotlib Figure: the positions (m) of every pipeline that has one, one line per
    run (broken across runs and gaps in the log, :func:`break_gaps`), the measured one
    (``nav``) labelled ``position``, with the current as arrows along the track; and, when
    the ``current`` pipeline published one, its components over time with their
    :data:`SIGMA_BAND` sigma bands in a panel of its own. None if no pipeline has a
    position."""
    from matplotlib.figure import Figure

    pairs = position_pairs(cols)
    if not pairs:
        return None
    current = _current_series(cols)
    if current is None:
        fig = Figure(figsize=(7, 6.5), dpi=DPI, layout="constrained")
        ax = fig.add_subplot()
    else:
        fig = Figure(figsize=(7, 9.5), dpi=DPI, layout="constrained")
        ax, ax_c = fig.subplots(2, 1, gridspec_kw={"height_ratios": [3, 1.3]})
        _plot_current(ax_c, current)
    run = cols.get("run")
    for name, n, e in pairs:
        _, east, north = decimate(cols["t"], cols[e], cols[n], run=run)
        if name == "nav":
            ax.plot(east, north, lw=0.8, marker=".", ms=3,
                    markevery=max(1, len(east) // MAX_MARKERS), label=position)
        else:
            ax.plot(east, north, lw=1.2, label=name)
    if current is not None:
        _current_arrows(ax, cols, pairs)
    _dive_arrows(ax, cols, pairs)
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper left", fontsize="small", framealpha=0.85)
    runs = len(set(run)) if run else 1
    ax.set_title(f"Track: {title}" + (f" ({runs} runs)" if runs > 1 else ""))
    return fig


class _Current:
    """The current's published samples: time, north and east (NaN where unknown) and
    their one-sigma (NaN where not reported)."""

    def __init__(self, cols: dict[str, list[float]]) -> None:
        def col(name: str) -> np.ndarray:
            return np.asarray(cols.get(name, [math.nan] * len(cols["t"])), float)

        self.t = np.asarray(cols["t"], float)
        self.north, self.east = col("current.north"), col("current.east")
        self.std_north, self.std_east = col("current.std_north"), col("current.std_east")
        self.run = cols.get("run")

    def published(self) -> np.ndarray:
        """Rows where both horizontal components were published."""
        return np.isfinite(self.north) & np.isfinite(self.east)

    def unknown(self) -> np.ndarray:
        """Rows where the pipeline ran (a sigma reported) but published neither component."""
        ran = np.isfinite(self.std_north) | np.isfinite(self.std_east)
        return ran & ~np.isfinite(self.north) & ~np.isfinite(self.east)


def _current_series(cols: dict[str, list[float]]) -> _Current | None:
    """The current of ``cols``; None when it never published a horizontal component."""
    if "current.north" not in cols and "current.east" not in cols:
        return None
    cur = _Current(cols)
    if not (np.isfinite(cur.north).any() or np.isfinite(cur.east).any()):
        return None
    return cur


def _plot_current(ax, cur: _Current) -> None:
    """The current's north and east components (m/s) over time, each with its
    :data:`SIGMA_BAND` sigma band; the spans where neither was published shaded."""
    from matplotlib.patches import Patch

    t, n, e, sn, se = decimate(cur.t, cur.north, cur.east, cur.std_north, cur.std_east,
                               run=cur.run)
    handles, labels = [], []
    for value, sigma, label, color in ((n, sn, "north", "tab:blue"),
                                       (e, se, "east", "tab:red")):
        (line,) = ax.plot(t, value, lw=1.0, color=color)
        ok = np.isfinite(value) & np.isfinite(sigma)
        band = ax.fill_between(t, value - SIGMA_BAND * sigma, value + SIGMA_BAND * sigma,
                               where=ok, color=color, alpha=0.2, lw=0)
        handles.append((band, line))
        labels.append(f"{label} ± {SIGMA_BAND:g} sigma")
    unknown = decimate(cur.t, cur.unknown().astype(float), run=cur.run)[1]
    if np.nansum(unknown) > 0:
        ax.fill_between(t, 0.0, 1.0, where=unknown > 0.5, color=UNKNOWN_GREY, lw=0,
                        transform=ax.get_xaxis_transform())
        handles.append(Patch(color=UNKNOWN_GREY))
        labels.append("unknown (not published)")
    ax.axhline(0.0, color="0.6", lw=0.6)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("current (m/s)")
    ax.set_title("Current: where the water flows to, north and east components")
    ax.grid(True, alpha=0.3)
    ax.legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, -0.22),
              ncols=len(labels), fontsize="small", frameon=False)


def _arrow_scale(extent_m: float) -> float:
    """The arrows' scale (m/s per metre of map) on a map ``extent_m`` (m, at least 1 m)
    across: the :data:`ARROW_KEY_MPS` key as long as :data:`ARROW_SHARE` of it."""
    return ARROW_KEY_MPS / (ARROW_SHARE * max(extent_m, 1.0))


def dive_rows(end) -> np.ndarray:
    """The rows of pipeline ``dac``'s columns where each dive first appears, in time order
    (its rows repeat the newest dive until the next); ``end`` its ``dac.dive_end``."""
    end = np.asarray(end, float)
    known = np.flatnonzero(np.isfinite(end))
    _, first = np.unique(end[known], return_index=True)
    return known[first]


def _dive_arrows(ax, cols: dict[str, list[float]],
                 pairs: Iterable[tuple[str, str, str]]) -> None:
    """Each dive's depth-averaged current (pipeline ``dac``) as an arrow from the middle
    of the two fixes that bound the dive, labelled with its one-sigma (the larger of north's
    and east's), on the scale of :func:`_current_arrows`."""
    if "dac.dive_end" not in cols:
        return
    rows = dive_rows(cols["dac.dive_end"])
    if not rows.size:
        return

    def at(name: str) -> np.ndarray:
        return np.asarray(cols[name], float)[rows]

    extent = max(np.nanmax(cols[c]) - np.nanmin(cols[c]) for _, n, e in pairs for c in (n, e))
    q = ax.quiver(at("dac.place_east"), at("dac.place_north"), at("dac.east"),
                  at("dac.north"), angles="xy", scale_units="xy", scale=_arrow_scale(extent),
                  width=0.006, color="tab:green", zorder=4)
    sigma = np.maximum(at("dac.std_north"), at("dac.std_east"))
    for x, y, s in zip(at("dac.place_east"), at("dac.place_north"), sigma):
        ax.annotate(f"± {s:.2f} m/s", (x, y), textcoords="offset points", xytext=(4, -10),
                    fontsize="x-small", color="tab:green")
    ax.quiverkey(q, 0.12, 0.05, ARROW_KEY_MPS, f"dive current {ARROW_KEY_MPS:g} m/s",
                 labelpos="N", coordinates="axes", fontproperties={"size": "small"})


def _current_arrows(ax, cols: dict[str, list[float]],
                    pairs: Iterable[tuple[str, str, str]]) -> None:
    """The published current as at most :data:`CURRENT_ARROWS` arrows on the map, each
    from the position of the first :data:`ARROW_TRACKS` pipeline with one at its row,
    with a :data:`ARROW_KEY_MPS` scale arrow inside the map's lower right corner."""
    cur = _Current(cols)
    tracks = {name: (np.asarray(cols[n], float), np.asarray(cols[e], float))
              for name, n, e in pairs}
    order = [tracks[p] for p in ARROW_TRACKS if p in tracks] or list(tracks.values())
    north = np.full(len(cur.t), math.nan)
    east = np.full(len(cur.t), math.nan)
    for tn, te in order:
        fill = ~np.isfinite(north) & np.isfinite(tn) & np.isfinite(te)
        north[fill], east[fill] = tn[fill], te[fill]
    rows = np.flatnonzero(cur.published() & np.isfinite(north))
    if not len(rows):
        return
    rows = rows[np.unique(np.linspace(0, len(rows) - 1, min(CURRENT_ARROWS, len(rows)))
                          .astype(int))]
    extent = max(np.nanmax(north) - np.nanmin(north), np.nanmax(east) - np.nanmin(east))
    q = ax.quiver(east[rows], north[rows], cur.east[rows], cur.north[rows], angles="xy",
                  scale_units="xy", scale=_arrow_scale(extent), width=0.004,
                  color="tab:purple", alpha=0.8, zorder=3)
    ax.quiverkey(q, 0.88, 0.05, ARROW_KEY_MPS, f"current {ARROW_KEY_MPS:g} m/s",
                 labelpos="N", coordinates="axes", fontproperties={"size": "small"})
