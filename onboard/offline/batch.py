"""``onboard batch LOG|DIR... --out DIR [--config FILE ...] [--jobs N] [--scheduler ADDRESS]
[--diagnose] [--force]``: a season of logs, each replayed (and diagnosed) on its own.

Every log given, or found in the folders given (:func:`find_logs`), is one task, a pure
function of (log, config, output folder): :func:`run_log` calls the same code as
``onboard replay`` (:func:`onboard.offline.replay.choose_config`,
:func:`onboard.offline.replay.replay`) and, with ``--diagnose``, ``onboard diagnose``
(:func:`onboard.offline.diagnose.diagnose`), so a log's ``estimates.csv`` is
byte-identical to ``onboard replay LOG --out X``'s. The tasks run on local processes
(``--jobs N``, default the cores) or, with ``--scheduler ADDRESS``, on the Dask
distributed cluster there (``distributed.Client(ADDRESS)``; its workers must see the logs
and ``--out`` at the same paths). Each log writes into its own folder ``DIR/<name>``
(:func:`folder_names`) and, last, ``DIR/<name>/run.json``, its row of ``runs.parquet``:
a log whose ``run.json`` says it was replayed (and diagnosed, when asked) is skipped on
the next run unless ``--force`` (the batch is resumable). Then ``DIR/runs.parquet`` and
``DIR/current.parquet`` are written (:mod:`onboard.offline.batch_tables`, docs/batch.md)
and, with ``--diagnose``, ``DIR/season.md``.

A log that fails (unreadable, not enough data to diagnose, an internal error) fails
alone, its one-line reason in its row, in the table printed at the end and on the last
line. Exit status: 0 every log replayed, 3 some failed, 2 bad usage or nothing could be
read (architecture.md §4.1).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import socket
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Iterator, Sequence

from onboard.core.errors import OutputFailed, SigtermAsInterrupt, UsageError
from onboard.drivers.logs import TIME_NAMES, is_log, is_log_dir

RUN_FILE = "run.json"
"""The file a task writes last in its log's folder: its row of runs.parquet (resuming)."""
DIAGNOSE_DIR = "diagnose"
"""The sub-folder of a log's folder that ``--diagnose`` writes diagnosis.json into."""
BATCH_WRITES = ("runs.parquet", "current.parquet", "season.md")
"""What ``onboard batch`` writes in ``--out DIR`` besides the logs' folders."""
NAME_MAX_BYTES = 200
"""The longest name of a log's folder (bytes of UTF-8): file systems take 255, and its
numbering (``-2``) must fit too; a longer one is shortened (:func:`_fitted`)."""
EXIT_SOME_FAILED = 3
"""Exit status when some logs failed and the others were replayed."""
PROGRESS_EVERY_S = 1.0
"""The progress line on a terminal is redrawn this often while logs run (s)."""
SECONDS_PER_HOUR = 3600.0
SCHEDULER_PROBE_S = 2.0
"""Seconds a first plain TCP connection to a ``tcp://`` scheduler may take: refused, the
batch stops at once (exit 2); else distributed's client tries for 10 s."""
SCHEDULER_CONNECT_S = 15.0
"""Seconds the client may take to reach the scheduler, its handshake included."""


@dataclass(frozen=True)
class Found:
    """What :func:`find_logs` made of the arguments: the logs, and the files skipped as
    not logs, each with why."""

    logs: list[str] = field(default_factory=list)
    skipped: list[tuple[str, str]] = field(default_factory=list)
    bases: list[str | None] = field(default_factory=list)
    """Per log, the folder given that it was found in (None: given itself)."""


@dataclass(frozen=True)
class Task:
    """One log's work: replay ``log`` with ``configs`` (applied in order; empty: detect
    it, or for a CSV log the bundled config that fits its header) into ``out``, and
    diagnose it into ``out/diagnose`` when ``diagnose``."""

    log: str
    out: str
    name: str
    configs: tuple[str, ...] = ()
    diagnose: bool = False
    force: bool = False

    @property
    def inputs(self) -> str:
        """What the task's outputs depend on besides its log, as its ``run.json`` records
        it (``inputs``): the configs given, with a digest of their files' contents (a
        bundled config by its name); a run of other inputs is not complete."""
        import hashlib

        h = hashlib.sha256()
        for c in self.configs:
            h.update(c.encode() + b"\0")
            h.update(Path(c).read_bytes() if Path(c).is_file() else b"")
        return f"{' '.join(self.configs) or 'detected'} sha256:{h.hexdigest()[:16]}"


def find_logs(paths: Sequence[str], time_columns: Iterable[str] = ()) -> Found:
    """The logs among ``paths``: a file given is a log (it fails if it cannot be read);
    a folder that is one log (:func:`is_log_dir`: CSV runs, a service recording) is one;
    any other folder is searched, in name order, for the files the readers recognise
    (:func:`is_log`) and the folders that are logs, the other files listed as skipped.
    A log found twice (given, and in a folder given) is listed once. ``time_columns``:
    the ``[csv] time`` columns of the configs given, time columns besides
    :data:`TIME_NAMES`."""
    found = Found()
    times = frozenset(c.lower() for c in time_columns)
    for arg in paths:
        p = Path(arg)
        if not p.exists():
            raise UsageError(f"{arg}: no such file or directory")
        if p.is_file() or is_log_dir(p, times):
            found.logs.append(str(p))
            found.bases.append(None)
        else:
            _search(p, found, times, str(p), set())
    seen: set[Path] = set()
    keep = [not (Path(log).resolve() in seen or seen.add(Path(log).resolve()))
            for log in found.logs]
    return Found([x for x, k in zip(found.logs, keep) if k], found.skipped,
                 [b for b, k in zip(found.bases, keep) if k])


def _search(folder: Path, found: Found, times: frozenset[str], base: str,
            searched: set[Path]) -> None:
    """Add the logs in ``folder`` and its sub-folders to ``found`` (found in ``base``),
    and the files that are not logs to its ``skipped``; a folder already ``searched``
    (reached again through a symbolic link, a link to a folder above it included) is
    not searched again."""
    real = folder.resolve()
    if real in searched:
        return
    searched.add(real)
    for f in sorted(folder.iterdir()):
        if f.is_dir():
            if is_log_dir(f, times):
                found.logs.append(str(f))
                found.bases.append(base)
            else:
                _search(f, found, times, base, searched)
            continue
        why = is_log(f, times)
        if why:
            found.skipped.append((str(f), why))
        else:
            found.logs.append(str(f))
            found.bases.append(base)


def one_line(text: str) -> str:
    """``text`` on one line (its lines joined with ``; ``)."""
    return "; ".join(line.strip() for line in text.strip().splitlines() if line.strip())


def folder_names(logs: Sequence[str], bases: Sequence[str | None] | None = None
                 ) -> list[str]:
    """A folder name per log, unique among them and the same run after run whatever
    logs are added to the folders searched: a log found in a folder given (``bases``)
    is named by its path below that folder, its folders joined with ``__``
    (``a__run.tlog`` for ``season/a/run.tlog`` found in ``season``); a log given itself
    (base None) by its file name, prefixed with as many of its parent folders as tell
    it apart from the others given of that name (``p__a__run.tlog``, ``q__a__run.tlog``),
    never above their common folder. Names still shared (``season/a__run.tlog`` beside
    ``season/a/run.tlog``, one path given twice) are numbered ``-2``, ... in order."""
    bases = bases or [None] * len(logs)
    paths = [Path(os.path.abspath(log)) for log in logs]
    names = ["__".join(p.relative_to(os.path.abspath(b)).parts) if b else p.name
             for p, b in zip(paths, bases)]
    given: dict[str, list[int]] = {}
    for i, b in enumerate(bases):
        if b is None:
            given.setdefault(names[i], []).append(i)
    for group in given.values():
        distinct = {paths[i] for i in group}
        if len(distinct) < 2:
            continue
        common = Path(os.path.commonpath([str(p) for p in distinct]))
        parts = [paths[i].relative_to(common).parts for i in group]
        depth = 1
        while len({p[-depth:] for p in parts}) < len(distinct):
            depth += 1
        for i, p in zip(group, parts):
            names[i] = "__".join(p[-depth:])
    return _numbered([_fitted(n) for n in names])


def _fitted(name: str) -> str:
    """``name`` as a folder name the file systems take: itself when it has at most
    :data:`NAME_MAX_BYTES` bytes, else ``~`` and 8 hex digits of its digest (the same for
    the same name) before as many of its last parts (``__``-joined) as fit, the end of
    its file name at least."""
    if len(name.encode()) <= NAME_MAX_BYTES:
        return name
    import hashlib

    head = f"~{hashlib.sha256(name.encode()).hexdigest()[:8]}"
    parts = name.split("__")
    tail = parts.pop()
    while parts and len(f"{head}__{parts[-1]}__{tail}".encode()) <= NAME_MAX_BYTES:
        tail = f"{parts.pop()}__{tail}"
    while len(f"{head}__{tail}".encode()) > NAME_MAX_BYTES:
        tail = tail[1:]
    return f"{head}__{tail}"


def _numbered(names: list[str]) -> list[str]:
    """``names`` with any duplicate numbered ``-2``, ... after its first."""
    out, count = [], {}
    for n in names:
        count[n] = count.get(n, 0) + 1
        out.append(n if count[n] == 1 else f"{n}-{count[n]}")
    return out


def run_log(task: Task) -> dict:
    """Replay (and diagnose) one log; its row of runs.parquet
    (:func:`onboard.offline.batch_tables.log_row`), also written as ``run.json`` in its
    folder with its current as ``current.parquet`` beside it. Never raises: a log that
    fails gives a row with ``status`` ``failed`` and its one-line ``error``."""
    from onboard.offline import batch_tables

    cpu0, wall0 = time.process_time(), time.perf_counter()
    out = Path(task.out)
    row = batch_tables.empty_row(task.log, task.name)
    row["inputs"] = task.inputs
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            row.update(_replay_and_diagnose(task, out))
    except _FolderRefused as err:   # another log's or command's: its run.json left alone
        row.update(status="failed", error=_failure(err.__cause__ or err),
                   cpu_s=time.process_time() - cpu0, wall_s=time.perf_counter() - wall0)
        return row
    except Exception as err:  # noqa: BLE001 - one log fails, not the batch
        row.update(status="failed", error=_failure(err))
    row["cpu_s"] = time.process_time() - cpu0
    row["wall_s"] = time.perf_counter() - wall0
    try:
        out.mkdir(parents=True, exist_ok=True)
        _write_run(out, json.dumps(row, indent=1, default=str) + "\n")
    except OSError as err:
        row.update(status="failed", error=f"{out / RUN_FILE}: cannot write: "
                   f"{err.strerror or err}")
    return row


def _write_run(out: Path, text: str) -> None:
    """``out/run.json`` replaced by ``text`` at once (written beside it, then renamed): a
    batch stopped while writing it leaves the previous one whole."""
    part = out / f"{RUN_FILE}.part"
    part.write_text(text)
    os.replace(part, out / RUN_FILE)


class _FolderRefused(Exception):
    """A log's folder that the task may not write (another log's or another command's
    outputs, a path that cannot be written): the log fails without writing there; the
    reason is its ``__cause__``."""


def _named(row: dict) -> str:
    """``LOG: reason`` of a failed row (its reason names the log already, or not)."""
    error = row["error"] or ""
    return error if error.startswith(row["log"] + ":") else f"{row['log']}: {error}"


def _failure(err: BaseException) -> str:
    """The one line a failed log is listed with: the message of an unreadable log, of
    bad usage or of an output that could not be written; the type too for anything else
    (an internal error)."""
    from onboard.drivers.base import UnreadableLog

    if isinstance(err, (UsageError, UnreadableLog, OutputFailed)):
        return one_line(str(err))
    return one_line(f"internal error: {type(err).__name__}: {err}")


def _replay_and_diagnose(task: Task, out: Path) -> dict:
    """The replay's (and diagnosis's) figures for the row; raises what failed."""
    from onboard.core.outputs import Output, check, existing
    from onboard.offline import batch_tables
    from onboard.offline.replay import REPLAY_WRITES, replay

    outs = [Output("--out", out, "dir", (*REPLAY_WRITES, RUN_FILE))]
    if task.diagnose:   # imported only then: model closure's imports take a second
        from onboard.offline.diagnose import DIAGNOSE_WRITES

        outs.append(Output("--out", out / DIAGNOSE_DIR, "dir", DIAGNOSE_WRITES))
    try:
        check(outs, force=task.force or _ours(task),
              inputs=[task.log, *existing(task.configs)])
    except UsageError as err:
        raise _FolderRefused() from err
    (out / batch_tables.LOG_CURRENT).unlink(missing_ok=True)
    out.mkdir(parents=True, exist_ok=True)   # the folder is the batch's from now on
    _write_run(out, json.dumps({"log": task.log, "name": task.name,
                                "status": "running"}) + "\n")
    cfg, note = _config(task)
    places = batch_tables.Places()   # each row's, as its records carried it
    summary = replay(task.log, cfg, out, config_note=note, plot=False, on_records=places)
    clock = batch_tables.clock_of(summary)
    est = batch_tables.read_estimates(out / "estimates.csv")
    figures = batch_tables.replay_figures(summary, est, clock)
    batch_tables.write_log_current(out, summary, est, clock, places)
    if task.diagnose:
        figures.update(_diagnose(task, cfg, out / DIAGNOSE_DIR))
    return figures


def _ours(task: Task) -> bool:
    """True when ``task``'s folder holds what a batch wrote for the same log (an
    unfinished run, a killed one included: its ``run.json`` says ``running``, or a failed
    one, or one of other inputs: redone without ``--force``); a folder holding another
    log's or another command's outputs is reused only with ``--force``. A ``run.json``
    that cannot be read as a row (empty, cut short: a crash, a power loss) is a batch's
    unfinished run: only a batch writes that file."""
    try:
        row = json.loads((Path(task.out) / RUN_FILE).read_text())
    except OSError:
        return False
    except ValueError:
        return True
    return not isinstance(row, dict) or same_log(row.get("log", ""), task.log)


def same_log(a: str, b: str) -> bool:
    """Whether paths ``a`` and ``b`` name the same log, however each was written
    (relative, through ``..`` or a symbolic link)."""
    try:
        return Path(a).resolve() == Path(b).resolve()
    except (OSError, RuntimeError):   # a loop of links
        return os.path.abspath(a) == os.path.abspath(b)


def _config(task: Task):
    """(config, note) for ``task``: its ``--config`` files, else what ``onboard replay``
    would detect; a CSV log without ``--config`` takes the bundled config that fits its
    header best (:func:`onboard.drivers.csvlog.fitting_configs`), else fails naming what
    to write."""
    from onboard.drivers.logs import sniff
    from onboard.offline import batch_tables
    from onboard.offline.replay import choose_config

    if not task.configs and sniff(task.log) in ("csv", "csv-dir"):
        from onboard.drivers.csvlog import csv_header, fitting_configs

        fits = fitting_configs(csv_header(task.log))
        if fits:
            cfg, _ = choose_config(task.log, [fits[0]])
            return cfg, f"from {fits[0]} {batch_tables.FITTED_CONFIG}"
    return choose_config(task.log, list(task.configs) or None)


def _diagnose(task: Task, cfg, out: Path) -> dict:
    """The diagnosis's figures for the row (:func:`onboard.offline.diagnose.diagnose`)."""
    from onboard.offline import batch_tables
    from onboard.offline.diagnose import diagnose

    out.mkdir(parents=True, exist_ok=True)
    try:
        doc = diagnose(task.log, cfg, out)
    except UsageError as err:   # a log too short or without what closure needs
        return {"diagnosed": False, "diagnose_error": one_line(str(err))}
    return batch_tables.diagnosis_figures(doc)


def is_complete(task: Task) -> dict | None:
    """The row of ``task``'s previous run when its outputs are complete (replayed, and
    diagnosed when asked, of the same log and the same :attr:`Task.inputs`; a row
    written before ``inputs`` was recorded counts as of the same), else None."""
    from onboard.offline import batch_tables

    out = Path(task.out)
    try:
        row = json.loads((out / RUN_FILE).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(row, dict):
        return None
    same = same_log(row.get("log", ""), task.log) and \
        row.get("inputs", task.inputs) == task.inputs
    done = row.get("status") == "ok" and (not task.diagnose or row.get("diagnosed")
                                          or row.get("diagnose_error"))
    files = all((out / n).exists() for n in ("estimates.csv", "summary.json",
                                              batch_tables.LOG_CURRENT))
    return row if same and done and files else None


# -- running the tasks ---------------------------------------------------------------

def run_local(tasks: Sequence[Task], jobs: int) -> Iterator[dict]:
    """The rows of ``tasks`` run on ``jobs`` local processes, as they finish."""
    from concurrent.futures import ProcessPoolExecutor, as_completed

    if jobs <= 1 or len(tasks) <= 1:
        for t in tasks:
            yield run_log(t)
        return
    pool = ProcessPoolExecutor(max_workers=min(jobs, len(tasks)), initializer=_worker_signals)
    try:
        futures = {pool.submit(run_log, t): t for t in tasks}
        for f in as_completed(futures):
            yield _result(f, futures[f])
    except BaseException:   # Ctrl-C or SIGTERM of this process alone: its workers stop too
        workers = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in workers:
            proc.terminate()
        raise
    pool.shutdown()


def _worker_signals() -> None:
    """A local worker ends at SIGTERM (the batch's ``terminate`` when it is stopped),
    whatever handler it inherited from the batch."""
    import signal

    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _result(future, task: Task) -> dict:
    """The row of a finished ``future`` of ``task``; a worker that died under it (killed,
    out of memory) fails that log alone."""
    try:
        return future.result()
    except Exception as err:  # noqa: BLE001 - BrokenProcessPool, KilledWorker, ...
        from onboard.offline import batch_tables

        row = batch_tables.empty_row(task.log, task.name)
        row.update(status="failed", error=one_line(f"the worker failed: "
                                                   f"{type(err).__name__}: {err}"))
        return row


def _refused(address: str) -> bool:
    """Whether a ``tcp://HOST:PORT`` scheduler address refuses the connection at once
    (nothing listens there: distributed's client would retry it until its timeout)."""
    host, _, port = address.removeprefix("tcp://").rpartition(":")
    if not port.isdigit():
        return False
    try:
        socket.create_connection((host.strip("[]"), int(port)), SCHEDULER_PROBE_S).close()
    except ConnectionRefusedError:
        return True
    except OSError:  # unreachable, unresolved, another scheme: the client will say
        pass
    return False


def connect(address: str):
    """A ``distributed.Client`` of the scheduler at ``address``; :class:`UsageError` when
    none answers there within :data:`SCHEDULER_CONNECT_S` (nothing listening, a host
    that does not resolve, a server that is not a Dask scheduler: whatever the client
    raises, or a handshake that never ends)."""
    import threading

    try:
        from distributed import Client
    except ImportError:
        raise UsageError("--scheduler needs dask distributed: pip install "
                         "'onboard[batch]'") from None
    if _refused(address):
        raise UsageError(f"--scheduler {address}: cannot connect: connection refused")
    got: list = []

    def attempt() -> None:
        try:
            got.append(Client(address, timeout="10s"))
        except Exception as err:  # noqa: BLE001 - what a peer that is not Dask makes it raise
            got.append(err)
    thread = threading.Thread(target=attempt, name="dask-connect", daemon=True)
    thread.start()
    thread.join(SCHEDULER_CONNECT_S)
    if not got:
        raise UsageError(f"--scheduler {address}: no Dask scheduler answered within "
                         f"{SCHEDULER_CONNECT_S:g} s")
    if isinstance(got[0], Exception):
        raise UsageError(f"--scheduler {address}: cannot connect: "
                         f"{one_line(str(got[0])) or type(got[0]).__name__}") from None
    return got[0]


def run_dask(tasks: Sequence[Task], client) -> Iterator[dict]:
    """The rows of ``tasks`` run on the Dask distributed cluster of ``client``
    (:func:`connect`), as they finish."""
    import uuid

    from distributed import as_completed

    run = uuid.uuid4().hex[:8]   # two batches on one cluster keep their tasks apart
    futures = client.map(run_log, tasks, pure=False,
                         key=[f"onboard-batch-{run}-{t.name}" for t in tasks])
    task_of = dict(zip((f.key for f in futures), tasks))
    for f in as_completed(futures):
        yield _result(f, task_of[f.key])


class Progress:
    """The batch's progress on stderr: on a terminal one line redrawn in place (a bar,
    logs done of all and how many of them a run before did, failed, log-hours replayed by
    this run, elapsed), every
    :data:`PROGRESS_EVERY_S` while logs run (a long log shows its time passing) and at
    each log done; otherwise a line per log as it finishes."""

    BAR_WIDTH = 30
    """Characters of the bar."""

    def __init__(self, total: int, tty: bool) -> None:
        import threading

        self.total, self.tty = total, tty
        self.done = self.failed = self.skipped = 0
        self.log_s = 0.0
        self.t0 = time.monotonic()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        if tty:
            threading.Thread(target=self._tick, daemon=True).start()

    def add(self, row: dict, skipped: bool = False) -> None:
        """Count ``row`` and show it."""
        with self._lock:
            self.done += 1
            self.failed += row["status"] != "ok"
            self.skipped += skipped
            if not skipped:   # the hours replayed by this run, not by a run before
                self.log_s += row.get("duration_s") or 0.0
        if self.tty:
            self._draw()
            return
        state = "skipped (done before)" if skipped else row["status"]
        why = f": {row['error']}" if row.get("error") else ""
        print(f"[{self.done}/{self.total}] {state} {row['name']}{why}", file=sys.stderr,
              flush=True)

    def _tick(self) -> None:
        while not self._stop.wait(PROGRESS_EVERY_S):
            self._draw()

    def _draw(self) -> None:
        with self._lock:
            filled = round(self.BAR_WIDTH * self.done / max(self.total, 1))
            print(f"\r[{'#' * filled}{'.' * (self.BAR_WIDTH - filled)}] {self.done}/"
                  f"{self.total} logs" + (f" ({self.skipped} done before)" if self.skipped
                                          else "") + f", {self.failed} failed, "
                  f"{self.log_s / SECONDS_PER_HOUR:.2f} log-h replayed, "
                  f"{time.monotonic() - self.t0:.0f} s", end="", file=sys.stderr, flush=True)

    def close(self) -> None:
        """Stop redrawing and end the line (a terminal)."""
        self._stop.set()
        if self.tty:
            with self._lock:
                print(file=sys.stderr)


def run_batch(tasks: Sequence[Task], jobs: int, scheduler,
              on_row: Callable[[dict, bool], None] = lambda row, skipped: None
              ) -> list[dict]:
    """Every task's row, in the order of ``tasks``: a complete previous one for a task
    without ``force`` (:func:`is_complete`), else the task run on the cluster of
    ``scheduler`` (a client, :func:`connect`) or on ``jobs`` local processes; ``on_row``
    is told of each (and whether it was skipped) as it comes."""
    rows: dict[str, dict] = {}
    todo = []
    for t in tasks:
        previous = None if t.force else is_complete(t)
        if previous is not None:
            rows[t.name] = previous
            on_row(previous, True)
        else:
            todo.append(t)
    results: Iterable[dict] = run_dask(todo, scheduler) if scheduler is not None and \
        todo else run_local(todo, jobs)
    for row in results:
        rows[row["name"]] = row
        on_row(row, False)
    return [rows[t.name] for t in tasks]


# -- the command ---------------------------------------------------------------------

def plan(args) -> tuple[list[Task], Found]:
    """The tasks of ``onboard batch``'s arguments, every output path checked first
    (:func:`onboard.core.outputs.check`); bad usage is a :class:`UsageError`."""
    from onboard.core.outputs import Output, check, existing

    if args.jobs is not None and args.jobs < 1:
        raise UsageError(f"--jobs {args.jobs}: give 1 or more")
    time_columns = []
    if args.config:   # a config that does not load is bad usage, said before any work
        from onboard.core import config as configmod

        try:
            time_columns.append(configmod.load_all(args.config).csv.time)
        except Exception as err:  # noqa: BLE001 - whatever the loader refuses
            raise UsageError(f"--config {' '.join(args.config)}: {one_line(str(err))}"
                             ) from None
    found = find_logs(args.logs, time_columns)
    if not found.logs:
        raise UsageError("no log found in " + ", ".join(args.logs) + (
            f" ({len(found.skipped)} file(s) skipped as not logs)" if found.skipped else ""))
    out = Path(args.out)
    names = folder_names(found.logs, found.bases)
    inputs = [*map(Path, args.logs), *map(Path, found.logs), *existing(args.config)]
    # the logs' folders are checked by their tasks (resuming reuses them)
    check([Output("--out", out, "dir", ())], inputs=inputs)
    check([Output("--out", out / n, "dir", ()) for n in names], inputs=inputs)
    # absolute: a cluster's workers do not share this process's working directory
    configs = tuple(os.path.abspath(c) if Path(c).is_file() else c
                    for c in args.config or ())
    tasks = [Task(os.path.abspath(log), os.path.abspath(out / n), n, configs,
                  bool(args.diagnose), bool(args.force))
             for log, n in zip(found.logs, names)]
    return tasks, found


def main(args) -> int:
    """``onboard batch``: plan, run every log (skipping those done before), write
    runs.parquet, current.parquet (and season.md with ``--diagnose``), print the table,
    the skipped files and the failed logs; exit status 0, 3 or 2 (module docstring)."""
    from onboard.offline import batch_tables

    batch_tables.require_pyarrow()
    tasks, found = plan(args)
    client = connect(args.scheduler) if args.scheduler else None
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    progress = Progress(len(tasks), sys.stderr.isatty())
    jobs = args.jobs or os.cpu_count() or 1
    terminate = SigtermAsInterrupt()   # SIGTERM stops the workers and exits 130, as Ctrl-C
    try:
        rows = run_batch(tasks, jobs, client, progress.add)
    finally:
        terminate.restore()
        progress.close()
        if client is not None:
            client.close()
    written = batch_tables.write_tables(out, rows)
    print(batch_tables.table_text(rows))
    for path, why in found.skipped:
        print(f"skipped {path}: not a log ({why})")
    if args.diagnose:
        from onboard.offline.closure.report import unit_of

        report = batch_tables.season_report(rows, unit_of)
        (out / "season.md").write_text(report)
        written.append(str(out / "season.md"))
        print(report)
    failed = [r for r in rows if r["status"] != "ok"]
    ok = len(rows) - len(failed)
    before = f" ({progress.skipped} of them by a run before: skipped)" if progress.skipped else ""
    print(f"{ok} of {len(rows)} logs replayed{before}; wrote {', '.join(written)}")
    for r in failed:
        print(f"failed {_named(r)}")
    if not ok:
        print("onboard batch: no log could be read", file=sys.stderr)
        return 2
    return EXIT_SOME_FAILED if failed else 0
