"""Adaptive state across restarts: saved atomically at intervals, restored on start.

What is kept is whatever the pipelines return from ``get_state()`` (RLS coefficients and
covariances, AIE coefficients, identified model parameters, the current estimate, and the
measurement noise each channel learned, ``noise``: algorithms.md §9), wrapped in a
versioned envelope::

    {"format": "onboard-state", "version": 1, "vehicle": "<id>", "vehicle_class": "...",
     "saved_at": <POSIX s>, "pipelines": {"<pipeline>": {...}, ...}}

Writes are atomic: a temporary file in the same directory is written, ``fsync``'ed and
renamed over the old one, and the directory is ``fsync``'ed, so a crash or power loss
leaves either the old state or the new one, never a torn file.

Loading never fails the service. A missing file is a cold start. A file that does not
parse, has another format or version, or belongs to another vehicle or class is reported
(the message goes to the log, the health events and STATUSTEXT), ignored and moved aside
as ``<name>.<why>-<UTC time>`` (``corrupt``, ``version``, ``other-vehicle``), so that the
next save neither trips over it nor overwrites it: another vehicle's learned state, or a
newer version's, is kept for whoever it belongs to. So is a file one of whose pipelines
could not take its entry (the service then starts that pipeline as it would without a
file: :meth:`onboard.engine.Engine.set_state`).
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

STATE_FORMAT = "onboard-state"
STATE_VERSION = 1


@dataclass
class LoadResult:
    """The outcome of :meth:`StateFile.load`: the pipelines' state (None on a cold start
    or a rejected file) and a one-line human-readable message."""

    state: dict[str, Any] | None
    message: str
    ok: bool
    """False when a file was there but could not be used."""


def plain(x: Any) -> Any:
    """A JSON-safe deep copy: NaN/inf become None, tuples lists, numpy scalars and arrays
    plain Python. Take it on the estimator loop (the pipelines keep mutating their arrays);
    write it from any thread."""
    if isinstance(x, dict):
        return {str(k): plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if hasattr(x, "tolist"):  # numpy arrays and scalars
        return plain(x.tolist())
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


class StateFile:
    """The adaptive-state file of one vehicle.

    Parameters:
        path: the file (its directory is created on the first save).
        vehicle: the vehicle id the state belongs to.
        vehicle_class: the vehicle class; a state of another class is ignored.
    """

    def __init__(self, path: str | Path, vehicle: str, vehicle_class: str = "") -> None:
        self.path = Path(path)
        self.vehicle = vehicle
        self.vehicle_class = vehicle_class
        self.saves = 0
        self.save_errors = 0

    def load(self) -> LoadResult:
        """Read the state; never raises (see the module docstring)."""
        p = self.path
        if not p.exists():
            return LoadResult(None, f"no saved state at {p}: cold start", True)
        try:
            raw = p.read_bytes()
        except OSError as err:
            return LoadResult(None, f"state file {p} unreadable ({err.strerror}): ignored", False)
        try:
            doc = json.loads(raw)
        except (ValueError, UnicodeDecodeError) as err:
            aside = self.move_aside()
            return LoadResult(None, f"state file {p} is corrupt ({err.__class__.__name__}: "
                              f"{str(err)[:80]}): ignored, kept as {aside}", False)
        if not isinstance(doc, dict) or doc.get("format") != STATE_FORMAT:
            aside = self.move_aside()
            return LoadResult(None, f"state file {p} is not an onboard state file: ignored, "
                              f"kept as {aside}", False)
        if doc.get("version") != STATE_VERSION:
            aside = self.move_aside("version")
            return LoadResult(None, f"state file {p} has version {doc.get('version')!r}, "
                              f"this service reads {STATE_VERSION}: ignored, kept as {aside}",
                              False)
        if doc.get("vehicle") != self.vehicle:
            aside = self.move_aside("other-vehicle")
            return LoadResult(None, f"state file {p} belongs to vehicle {doc.get('vehicle')!r}, "
                              f"not {self.vehicle!r}: ignored, kept as {aside}", False)
        if self.vehicle_class and doc.get("vehicle_class") not in ("", None, self.vehicle_class):
            aside = self.move_aside("other-vehicle")
            return LoadResult(None, f"state file {p} is for a {doc.get('vehicle_class')}, "
                              f"not a {self.vehicle_class}: ignored, kept as {aside}", False)
        pipelines = doc.get("pipelines")
        if not isinstance(pipelines, dict):
            aside = self.move_aside()
            return LoadResult(None, f"state file {p} has no pipelines table: ignored, kept as "
                              f"{aside}", False)
        age = time.time() - float(doc.get("saved_at", 0.0) or 0.0)
        names = ", ".join(sorted(k for k, v in pipelines.items() if v)) or "none"
        return LoadResult(pipelines, f"restored adaptive state ({names}) saved "
                          f"{age / 3600.0:.1f} h ago", True)

    def move_aside(self, why: str = "corrupt") -> str:
        """Rename the file ``<name>.<why>-<UTC time>`` (``-2``, ``-3`` ... after it when
        that name is taken: two restarts within a second keep both); its new name, or a
        note that it could not be moved."""
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
        aside = self.path.with_name(f"{self.path.name}.{why}-{stamp}")
        k = 1
        while aside.exists():
            k += 1
            aside = self.path.with_name(f"{self.path.name}.{why}-{stamp}-{k}")
        try:
            os.replace(self.path, aside)
        except OSError:
            return "(could not move it aside)"
        return aside.name

    def save(self, pipelines: dict[str, Any]) -> None:
        """Write the state atomically (tmp + fsync + rename + directory fsync).

        Raises OSError on a disk error (the caller counts it and carries on).
        """
        doc = {"format": STATE_FORMAT, "version": STATE_VERSION, "vehicle": self.vehicle,
               "vehicle_class": self.vehicle_class, "saved_at": time.time(),
               "pipelines": plain(pipelines)}
        data = json.dumps(doc, allow_nan=False, separators=(",", ":")).encode()
        d = self.path.parent
        d.mkdir(parents=True, exist_ok=True)
        tmp = d / f".{self.path.name}.tmp-{os.getpid()}"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            try:
                view = memoryview(data)
                while view:
                    n = os.write(fd, view)
                    view = view[n:]
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(tmp, self.path)
        except OSError:
            self.save_errors += 1
            try:
                tmp.unlink()
            except OSError:
                pass
            raise
        try:
            dfd = os.open(d, os.O_RDONLY)
            try:
                os.fsync(dfd)
            finally:
                os.close(dfd)
        except OSError:
            pass  # some filesystems cannot fsync a directory; the rename is done
        self.saves += 1
