"""estimates.csv (architecture.md §4.2), written as the replay ticks: a row per tick, ``t``
since the first sample, ``run``, then a column per ``<pipeline>.<quantity>``.

The replay's per-tick writer, in the compiled build's list (setup.py)."""

from __future__ import annotations

import bisect
from pathlib import Path
from typing import Sequence

from onboard.core.errors import OutputFailed
from onboard.core.messages import EstimateRecord
from onboard.engine import Engine


def _fmt(v: float) -> str:
    """Deterministic text for a float: 10 significant digits, empty for NaN."""
    return "" if v != v else f"{v:.10g}"


class EstimatesCsv:
    """Streams ticks into estimates.csv: ``t`` since the first sample, ``run`` (the run
    the tick belongs to, :class:`Runs`), then a column per ``<pipeline>.<quantity>``,
    empty where a pipeline has no estimate.

    Attributes:
        runs: per run, its number, name, first and last ``t`` and rows.
    """

    def __init__(self, path: Path, columns: Sequence[str], t0: float | None,
                 runs: Runs | None = None) -> None:
        """``columns``: ``t`` then the pipelines' columns (:attr:`Engine.columns`);
        ``run`` is written after ``t``. ``runs`` tells each tick's run (default: one)."""
        self.columns = [columns[0], RUN_COLUMN, *columns[1:]]
        self.index = {c: i for i, c in enumerate(self.columns)}
        self.t0 = t0
        self.rows = 0
        self.run_of = runs if runs is not None else Runs()
        self.runs: list[dict] = []
        self._by_pipeline: dict[str, dict[str, int]] = {}
        """Per pipeline: quantity -> column index (the quantities it has written)."""
        self.path = path
        try:
            self._f = open(path, "w", encoding="utf-8", newline="\n")
            self._f.write(",".join(self.columns) + "\n")
        except OSError as err:
            raise self._failed(err) from None

    def _column(self, pipeline: str, quantity: str) -> int | None:
        """Index of ``<pipeline>.<quantity>``, None if that is not a column (cached)."""
        i = self.index.get(pipeline + "." + quantity)
        if i is not None:
            self._by_pipeline.setdefault(pipeline, {})[quantity] = i
        return i

    def write(self, t: float, records: Sequence[EstimateRecord]) -> None:
        """One row at tick time ``t`` (s); values as :func:`_fmt` writes them."""
        if self.t0 is None:
            self.t0 = t
        row = [""] * len(self.columns)
        row[0] = tt = f"{t - self.t0:.6f}"
        row[1] = self._run(t, float(tt))
        by_pipeline = self._by_pipeline
        for rec in records:
            index = by_pipeline.get(rec.pipeline)
            if index is None:
                index = by_pipeline[rec.pipeline] = {}
            for k, v in rec.values.items():
                i = index.get(k)
                if i is None:
                    i = self._column(rec.pipeline, k)
                    if i is None:
                        continue
                row[i] = "" if v != v else f"{v:.10g}"   # _fmt, inline
        try:
            self._f.write(",".join(row) + "\n")
        except OSError as err:
            raise self._failed(err) from None
        self.rows += 1

    def _run(self, t: float, t_csv: float) -> str:
        """The run of the tick at ``t`` (s, log clock; ``t_csv`` as written), counted in
        :attr:`runs`."""
        k, name = self.run_of.at(t)
        runs = self.runs
        if not runs or runs[-1]["run"] != k:
            runs.append({"run": k, "name": name, "t_start": t_csv, "t_end": t_csv,
                         "rows": 0})
        last = runs[-1]
        last["t_end"] = t_csv
        last["rows"] += 1
        return str(k)

    def close(self) -> None:
        """Close the file (rows already written are complete lines)."""
        try:
            self._f.close()
        except OSError as err:
            raise self._failed(err) from None

    def _failed(self, err: OSError) -> OutputFailed:
        """estimates.csv could not be written: the replay cannot go on without it."""
        return OutputFailed(f"{self.path}: cannot write: {err.strerror or err}")


RUN_COLUMN = "run"
"""The column of estimates.csv after ``t``: the run (0, 1, ...) the row belongs to."""


class Runs:
    """The run of each tick: a new one at each time segment of the engine's time line
    (a clock jump, :mod:`onboard.engine.timeline`) and at each run of a CSV log (a file of a
    directory, or a ``run_column`` value; :attr:`CsvReader.runs`). Runs are numbered
    from 0 in the order they start; a name says which it is (the CSV run's name, or
    ``segment <n>``; empty for a log of one run)."""

    def __init__(self, engine: Engine | None = None, csv_runs: Sequence = ()) -> None:
        """``engine``: its time line's segments; ``csv_runs``: the reader's runs (each
        with ``name`` and ``t_start`` on the log clock), in order."""
        self.engine = engine
        self.starts = [r.t_start for r in csv_runs]
        self.names = [r.name for r in csv_runs]
        self._key: tuple[int, int] | None = None
        self._k = -1

    def at(self, t: float) -> tuple[int, str]:
        """(run number, name) of the tick at ``t`` (s, log clock)."""
        seg = _segment_of(self.engine.timeline.segments, t) if self.engine else 0
        part = bisect.bisect_right(self.starts, t) - 1
        key = (seg, max(part, 0))
        if key != self._key:
            self._key = key
            self._k += 1
        if self.names:
            return self._k, self.names[key[1]]
        return self._k, f"segment {seg + 1}" if seg > 0 else ""


def _segment_of(segments: Sequence, t: float) -> int:
    """The index of the segment the tick at ``t`` (s) belongs to: the newest that spans
    ``t``, else the newest that started before it (a tick past its newest sample, or in a
    gap), else 0. The time line adds a segment when its jump is confirmed, which is before
    the last ticks of the old one (``onboard.engine.run``)."""
    for k in range(len(segments) - 1, -1, -1):
        if segments[k].start <= t <= segments[k].end:
            return k
    for k in range(len(segments) - 1, -1, -1):
        if segments[k].start <= t:
            return k
    return 0
