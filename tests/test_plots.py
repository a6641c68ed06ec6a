"""track.png (onboard/offline/plots.py): the measured track labelled by what it is, the
current with its sigma, every label inside the figure, and a drawing whose cost does not
grow with the log's length."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("matplotlib", reason="pip install 'onboard[plot]'")

from onboard.offline import plots  # noqa: E402
from onboard.offline.plots import (MAX_POINTS, SIGMA_BAND, decimate, plot_track,  # noqa: E402
                                   position_label, read_columns, track_figure)


def _cols(n: int, *, gap_at: int | None = None) -> dict[str, list[float]]:
    """A boat circling at 10 Hz for ``n`` rows in a current known after the first tenth
    (north 0.25, east -0.15 m/s, one-sigma 0.04), unknown before; a 60 s gap after row
    ``gap_at``."""
    t = np.arange(n) * 0.1
    if gap_at is not None:
        t[gap_at:] += 60.0
    ang = 0.05 * np.arange(n)
    known = np.arange(n) >= n // 10
    nan = np.full(n, math.nan)
    return {"t": t.tolist(), "run": [0.0] * n,
            "nav.north": (20 * np.cos(ang)).tolist(), "nav.east": (20 * np.sin(ang)).tolist(),
            "aie.north": (20 * np.cos(ang) + 0.3).tolist(), "aie.east": (20 * np.sin(ang)).tolist(),
            "current.north": np.where(known, 0.25, nan).tolist(),
            "current.east": np.where(known, -0.15, nan).tolist(),
            "current.std_north": np.where(known, 0.04, 0.9).tolist(),
            "current.std_east": np.where(known, 0.04, 0.9).tolist()}


def _draw(fig):
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return canvas.get_renderer()


def test_the_measured_track_is_labelled_by_what_the_log_holds():
    assert position_label("tlog") == position_label("nmea") == "GNSS fixes"
    assert position_label("csv", "gnss") == "GNSS fixes"
    assert position_label("csv", "navigation") == "logged navigation track"
    assert position_label("csv") == position_label("csv", "unstated") == "logged positions"
    fig = track_figure(_cols(500), "glider.csv", position_label("csv", "navigation"))
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert labels == ["logged navigation track", "aie"]


def test_replay_labels_a_csv_track_by_its_config(tmp_path, monkeypatch):
    """The glider's config says its positions are its navigation (`[csv] position_kind =
    "navigation"`): replay hands that label to the figure, not "GNSS"."""
    from onboard.core import config
    from onboard.offline.replay import replay

    csv = tmp_path / "nav.csv"
    rows = ["t,lat,lon,yaw"] + [f"{k},{63.4 + 1e-6 * k:.7f},10.3,{k % 360}"
                                for k in range(50)]
    csv.write_text("\n".join(rows) + "\n")
    seen = []
    monkeypatch.setattr(plots, "plot_track", lambda *a: seen.append(a) or None)
    for kind, label in (("navigation", "logged navigation track"), ("unstated", "logged positions")):
        cfg = config.from_dict({"csv": {"time": "t", "lat_deg": "lat", "lon_deg": "lon",
                                        "heading": "yaw", "heading_unit": "deg",
                                        "position_kind": kind}})
        replay(str(csv), cfg, tmp_path / kind)
        assert seen[-1][2:] == ("nav.csv", label)


def test_the_current_panel_draws_each_component_with_its_sigma_band():
    fig = track_figure(_cols(2000), "log.tlog")
    track, panel = fig.axes
    assert "Current" in panel.get_title()
    lines = {tuple(np.unique(np.asarray(ln.get_ydata(), float)[np.isfinite(
        np.asarray(ln.get_ydata(), float))])) for ln in panel.get_lines()}
    assert (0.25,) in lines and (-0.15,) in lines
    # each band spans the value +- 2 published sigmas where published
    spans = sorted((round(float(p.get_paths()[0].vertices[:, 1].min()), 6),
                    round(float(p.get_paths()[0].vertices[:, 1].max()), 6))
                   for p in panel.collections if len(p.get_paths()) == 1
                   and p.get_paths()[0].vertices[:, 1].max() < 0.9)
    assert (round(-0.15 - SIGMA_BAND * 0.04, 6), round(-0.15 + SIGMA_BAND * 0.04, 6)) in spans
    assert (round(0.25 - SIGMA_BAND * 0.04, 6), round(0.25 + SIGMA_BAND * 0.04, 6)) in spans
    legend = [t.get_text() for t in panel.get_legend().get_texts()]
    assert legend == ["north ± 2 sigma", "east ± 2 sigma", "unknown (not published)"]
    assert track.collections  # the current's arrows on the map


def _arrow_extent(key) -> tuple[np.ndarray, np.ndarray]:
    """The display-space corners (min, max) of a drawn quiver key's arrow (its polygon
    placed at its offset; ``get_window_extent`` does not compute it)."""
    v = key.vector
    verts = np.vstack([p.vertices for p in v.get_paths()])
    off = v.get_offset_transform().transform(np.asarray(v.get_offsets()))[0]
    pts = v.get_transform().transform(verts) + off
    return pts.min(axis=0), pts.max(axis=0)


def _inside(lo, hi, box) -> bool:
    return box.x0 <= lo[0] and hi[0] <= box.x1 and box.y0 <= lo[1] and hi[1] <= box.y1


def test_every_label_and_the_scale_arrow_lie_inside_the_figure():
    """The issue: the 0.5 m/s key was cut at the right edge (its arrow reached 761 px of a
    700 px figure). Every drawn text (titles, ticks in view, legends) lies inside the
    figure, and the key's arrow and label inside the map."""
    from matplotlib.quiver import QuiverKey

    for cols in (_cols(3000), {k: v for k, v in _cols(3000).items()
                               if not k.startswith("current")}):
        fig = track_figure(cols, "a log with a long name, run 216 to 239.csv")
        renderer = _draw(fig)
        w, h = fig.get_size_inches()
        drawn = fig.get_tightbbox(renderer)  # inches: every artist drawn, ticks in view
        assert drawn.x0 >= 0 and drawn.y0 >= 0 and drawn.x1 <= w and drawn.y1 <= h, drawn
        keys = fig.findobj(QuiverKey)
        assert bool(keys) == ("current.north" in cols)
        for key in keys:
            assert _inside(*_arrow_extent(key), key.axes.bbox)
            b = key.text.get_window_extent(renderer)
            assert _inside((b.x0, b.y0), (b.x1, b.y1), key.axes.bbox)
    # negative control: a key placed as the old figure placed its own, at the right edge
    # with the label to its west, reaches beyond the map and the figure
    track = fig.axes[0]
    q = track.quiver([0.0], [0.0], [1.0], [0.0], scale_units="xy", scale=0.05)
    old = track.quiverkey(q, 0.9, 0.9, 0.5, "0.5 m/s", labelpos="W", coordinates="axes")
    _draw(fig)
    assert not _inside(*_arrow_extent(old), fig.bbox)


def test_decimation_keeps_every_break_and_no_false_one():
    n = 50_000
    t = np.arange(n) * 0.1
    t[30_000:] += 60.0                      # a gap after row 29 999
    run = np.where(np.arange(n) < 40_000, 0, 1)  # a new run at row 40 000
    y = np.arange(n, dtype=float)
    td, yd = decimate(t, y, run=run)
    assert len(td) <= MAX_POINTS + 10
    breaks = np.flatnonzero(np.isnan(td))
    assert len(breaks) == 2                 # not one per decimated step
    assert yd[breaks[0] - 1] == 29_999 and yd[breaks[0] + 1] == 30_000
    assert yd[breaks[1] - 1] == 39_999 and yd[breaks[1] + 1] == 40_000
    assert yd[0] == 0 and yd[-1] == n - 1
    short = decimate(t[:100], y[:100])
    assert len(short[0]) == 100 and not np.isnan(short[0]).any()


def test_the_drawing_does_not_grow_with_the_log():
    """What makes a long replay's plot slow is per-point work: the lines of a 100 000-row
    log carry at most MAX_POINTS points each and the figure the same artists as a short
    one (measured: the BlueBoat's 19 238 rows plot in 1.0 s, 0.3 s of it drawing)."""
    small, big = track_figure(_cols(1000), "s"), track_figure(_cols(100_000, gap_at=5), "b")
    assert len(big.findobj()) == len(small.findobj())
    for ax in big.axes:
        for line in ax.get_lines():
            assert len(line.get_xdata()) <= MAX_POINTS + 10


def test_read_columns_reads_the_wanted_columns_with_empty_cells_as_nan(tmp_path):
    p = tmp_path / "estimates.csv"
    p.write_text("t,run,nav.north,aie.speed\n0.0,0,1.5,\n0.1,0,,2.0\n")
    cols = read_columns(p, lambda h: h != "aie.speed")
    assert list(cols) == ["t", "run", "nav.north"]
    assert cols["nav.north"][0] == 1.5 and math.isnan(cols["nav.north"][1])
    assert math.isnan(read_columns(p)["aie.speed"][0])
    (tmp_path / "empty.csv").write_text("t,run,nav.north\n")
    assert read_columns(tmp_path / "empty.csv") == {"t": [], "run": [], "nav.north": []}


def test_plot_track_writes_the_png(tmp_path):
    p = tmp_path / "estimates.csv"
    cols = _cols(800)
    names = list(cols)
    rows = [",".join(names)] + [",".join("" if math.isnan(cols[h][i]) else repr(cols[h][i])
                                         for h in names) for i in range(800)]
    p.write_text("\n".join(rows) + "\n")
    out = plot_track(p, tmp_path / "track.png", "log", "GNSS fixes")
    assert out == str(tmp_path / "track.png") and Path(out).stat().st_size > 20_000


def test_a_gliders_dive_current_is_an_arrow_from_the_middle_of_its_fixes():
    """Pipeline dac's newest dive repeated on every row: one arrow per dive, from the
    midpoint of its fixes, pointing where the water went, inside the map with its key;
    no dive columns, no dive arrow."""
    from matplotlib.quiver import Quiver, QuiverKey

    n = 400
    cols = {k: v for k, v in _cols(n).items() if not k.startswith("current")}
    nan = [math.nan] * (n // 4)
    for name, dive1, dive2 in (("dac.north", 0.1, -0.2), ("dac.east", 0.3, 0.05),
                               ("dac.std_north", 0.04, 0.05), ("dac.std_east", 0.02, 0.07),
                               ("dac.dive_end", 100.0, 300.0),
                               ("dac.place_north", 5.0, -5.0), ("dac.place_east", 2.0, 8.0)):
        cols[name] = nan + [dive1] * (n // 4) + [dive2] * (n // 2)
    fig = track_figure(cols, "glider")
    renderer = _draw(fig)
    dives = [q for q in fig.findobj(Quiver) if len(q.U) == 2]
    assert len(dives) == 1
    q = dives[0]
    assert np.allclose(q.X, [2.0, 8.0]) and np.allclose(q.Y, [5.0, -5.0])
    assert np.allclose(q.U, [0.3, 0.05]) and np.allclose(q.V, [0.1, -0.2])
    labels = sorted(t.get_text() for t in fig.axes[0].texts if t.get_text().startswith("±"))
    assert labels == ["± 0.04 m/s", "± 0.07 m/s"]   # the larger of north's and east's
    key, = [k for k in fig.findobj(QuiverKey) if "dive" in k.text.get_text()]
    b = key.text.get_window_extent(renderer)
    assert _inside((b.x0, b.y0), (b.x1, b.y1), key.axes.bbox)
    bare = track_figure({k: v for k, v in cols.items() if not k.startswith("dac")}, "boat")
    assert not [k for k in bare.findobj(QuiverKey) if "dive" in k.text.get_text()]
