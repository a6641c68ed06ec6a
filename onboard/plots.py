"""Figures for replay and the docs (matplotlib, imported only when a figure is made)."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


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
    """North/east track of every pipeline that has one; None if none has."""
    cols = read_columns(estimates_csv)
    pairs = [(c[:-6], c, c[:-6] + ".east") for c in cols if c.endswith(".north")
             and c[:-6] + ".east" in cols]
    pairs = [p for p in pairs if any(v == v for v in cols[p[1]])]
    if not pairs:
        return None
    fig, ax = plt.subplots(figsize=(7, 6))
    for name, n, e in pairs:
        style = {"lw": 0.8, "marker": ".", "ms": 2} if name == "nav" else {"lw": 1.2}
        ax.plot(cols[e], cols[n], label="GNSS" if name == "nav" else name, **style)
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
