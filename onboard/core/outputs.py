"""Every path a command writes, checked before the command does any work.

A command lists what it will write as :class:`Output` values and calls :func:`check`
first; a path that cannot be written is a :class:`~onboard.core.errors.UsageError` of one
line naming the flag and the path (``onboard COMMAND: --gpx out/x.gpx: no directory
out``, exit status 2), before any log is read or any simulation flown. The rules
(docs/architecture.md §4.1):

* **A file** (``--mcap FILE``, ``--write-config FILE``, ``--tlog FILE`` ...): its
  directory exists and is writable (a file is never written into a directory the command
  would have to invent: a typo there is refused, not created), or is the same command's
  directory output, which it creates first (``--out d --write-config d/overlay.toml``:
  one path, named twice); it is not a directory; it
  exists already only with ``--force``, which replaces it (unless the command replaces it
  by design: ``replace``).
* **A directory** (``--out DIR``, ``--state-dir DIR``): not a file; created with its
  missing parents when absent (the nearest existing one must be a writable directory);
  when it holds what a previous run of the command wrote (``writes``: the names the
  command puts in it, e.g. a replay's ``estimates.csv``), it is reused only with
  ``--force``. An empty directory, or one holding other files, is fine.
* No output is an input (the log, a ``--config`` file), lies inside an input directory (a
  folder of CSV runs would read a replay's ``estimates.csv`` as a run), or is named twice
  (``--gpx x`` and ``--geojson x``, or ``--mcap DIR/estimates.csv``); ``--force`` does not
  lift these.

Writability is probed by creating (and removing) a temporary file in the directory: the
permission bits alone do not tell (root ignores them; a read-only mount does not).
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Literal, Sequence

from onboard.core.errors import UsageError

PROBE_PREFIX = ".onboard-write-check-"
"""Name prefix of the temporary file that probes a directory's writability."""


@dataclass(frozen=True)
class Output:
    """One path a command writes.

    Attributes:
        flag: how the user named it, for the message (``--out``, ``--gpx``,
            ``ONBOARD_BENCH_DETAIL``).
        path: the path as given.
        kind: ``file`` or ``dir``.
        writes: for a directory, the names the command writes in it (an existing one of
            them is a previous run's: reused only with ``--force``).
        replace: for a file, the command replaces it by design (no ``--force`` needed).
    """

    flag: str
    path: Path
    kind: Literal["file", "dir"] = "file"
    writes: tuple[str, ...] = ()
    replace: bool = False

    def files(self) -> list[Path]:
        """The files it stands for: the file itself, or the directory's ``writes``."""
        if self.kind == "file":
            return [self.path]
        return [self.path / name for name in self.writes]


def check(outputs: Iterable[Output], *, force: bool = False,
          inputs: Sequence[str | Path] = ()) -> None:
    """Raise :class:`UsageError` (one line) for the first of ``outputs`` that breaks a
    rule of the module docstring; ``force``: replace existing files, reuse a directory
    of a previous run; ``inputs``: the paths the command reads."""
    outs = list(outputs)
    _not_inputs(outs, inputs)
    _not_twice(outs)
    made = {out.path.absolute() for out in outs if out.kind == "dir"}
    for out in outs:
        if out.kind == "dir":
            _check_dir(out, force)
        elif not (out.path.parent.absolute() in made and not out.path.parent.exists()):
            _check_file(out, force)   # else: in a directory output, created and checked


def existing(paths: Iterable[str | Path] | None) -> list[Path]:
    """Those of ``paths`` that are files or directories (a ``--config`` may also name a
    bundled config, which no output can overwrite): inputs for :func:`check`."""
    if isinstance(paths, (str, Path)):
        paths = [paths]
    return [Path(p) for p in paths or () if Path(p).exists()]


def _check_file(out: Output, force: bool) -> None:
    p = out.path
    if p.is_dir():
        raise UsageError(f"{out.flag} {p}: is a directory; give a file name")
    parent = p.parent
    if parent.exists() and not parent.is_dir():
        raise UsageError(f"{out.flag} {p}: {parent} is a file, not a directory")
    if not parent.is_dir():
        raise UsageError(f"{out.flag} {p}: the directory {parent} does not exist; "
                         "create it first")
    if p.exists() and not (force or out.replace):
        raise UsageError(f"{out.flag} {p}: exists; --force replaces it")
    _probe(out, parent)
    if p.exists() and not os.access(p, os.W_OK):
        raise UsageError(f"{out.flag} {p}: cannot write: permission denied")


def _check_dir(out: Output, force: bool) -> None:
    p = out.path
    if p.exists() and not p.is_dir():
        raise UsageError(f"{out.flag} {p}: is a file; {out.flag} needs a directory")
    if p.is_dir():
        previous = [n for n in out.writes if (p / n).exists()]
        if previous and not force:
            raise UsageError(f"{out.flag} {p}: holds a previous run's {', '.join(previous)}; "
                             f"--force replaces them, or give another {out.flag}")
        _probe(out, p)
        return
    base = _nearest_existing(p)
    if not base.is_dir():
        raise UsageError(f"{out.flag} {p}: {base} is a file, not a directory")
    _probe(out, base)


def _nearest_existing(p: Path) -> Path:
    """``p``'s nearest ancestor that exists (the current directory for a relative path
    with none)."""
    for a in p.absolute().parents:
        if a.exists():
            return a
    return Path(p.anchor or ".")


def _probe(out: Output, directory: Path) -> None:
    """Create and remove a temporary file in ``directory``; a failure is the one line."""
    try:
        fd, name = tempfile.mkstemp(prefix=PROBE_PREFIX, dir=directory)
    except OSError as err:
        raise UsageError(f"{out.flag} {out.path}: cannot write in {directory}: "
                         f"{err.strerror or err}") from None
    os.close(fd)
    os.unlink(name)


def _key(p: Path) -> Path:
    """A path's identity for comparison: absolute, symbolic links resolved."""
    return p.resolve()


def _not_inputs(outs: Sequence[Output], inputs: Sequence[str | Path]) -> None:
    ins = [_key(Path(i)) for i in inputs]
    for out in outs:
        for f in [out.path, *out.files()]:
            k = _key(f)
            for i in ins:
                if k == i:
                    raise UsageError(f"{out.flag} {out.path}: is the input; "
                                     "give another path")
                if i.is_dir() and i in k.parents:
                    raise UsageError(f"{out.flag} {out.path}: inside the input directory "
                                     f"{i}; give a path outside it")


def _not_twice(outs: Sequence[Output]) -> None:
    seen: dict[Path, Output] = {}
    for out in outs:
        for f in out.files():
            k = _key(f)
            first = seen.get(k)
            if first is not None:
                raise UsageError(f"{first.flag} and {out.flag} name the same file {f}; "
                                 "give each its own")
            seen[k] = out
