"""The current pipeline's calibration on the figure runs: docs/current.md, "Calibrated sigma".

Run ``python -m validation.reports.current_coverage``: per run of
:data:`COVERAGE_RUNS` (the figure runs of ``runs.CURRENT_RUNS``, flown by
``current_validation``), the RMS error against the mean published sigma and the 1- and
2-sigma coverage per axis (a calibrated Gaussian: 0.68 / 0.95), printed as the page's
Markdown table, row by row as each run ends.
"""

from __future__ import annotations

import argparse
import math
from typing import Any, Sequence

from validation.reports import runs

COVERAGE_RUNS = (("gavia-tidal", "kf"), ("gavia-tidal", "hgo"), ("spheroid-sawtooth", "kf"),
                 ("spheroid-sawtooth", "hgo"), ("effect-current", "kf"), ("boat-tidal", "kf"),
                 ("jaiabot-turns", "kf"), ("twin-thruster-turns", "kf"))
"""The runs (``runs.CURRENT_RUNS`` keys) and observers of the coverage table."""
AXES = ("north", "east", "down")


def _fmt(x: float) -> str:
    return f"{x:.3f}" if math.isfinite(x) else "-"


def row(key: str, observer: str, m: dict[str, Any]) -> str:
    """The table's row of one run's ``runs.current_metrics``, over the axes it
    publishes a sigma for."""
    axes = [a for a in AXES if math.isfinite(m[a]["sigma"])]

    def cov(k: str) -> str:
        return " / ".join(f"{m[a][k]:.2f}" if math.isfinite(m[a][k]) else "n/a" for a in axes)

    rs = ", ".join(f"{_fmt(m[a]['rms'])} / {_fmt(m[a]['sigma'])}" for a in axes)
    return f"| {key} | {observer} | {rs} | {cov('cover1')} | {cov('cover2')} |"


def coverage_table(seed: int = 1) -> str:
    """The Markdown table: a :func:`row` per run of :data:`COVERAGE_RUNS` on ``seed``
    (printed as it comes)."""
    lines = [f"| run (seed {seed}) | observer | RMS / sigma N, E, D (m/s) | 1σ cover N / E / D | "
             "2σ cover N / E / D |", "|---|---|---|---|---|"]
    for key, obs in COVERAGE_RUNS:
        lines.append(row(key, obs, runs.current_metrics(key, obs, seed)))
        print(lines[-1], flush=True)
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Print the coverage table of seed 1 (the design point). Returns 0."""
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args(argv)
    print(coverage_table())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
