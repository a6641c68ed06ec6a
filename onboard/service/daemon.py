"""The onboard service: ``onboard run --config FILE`` (the systemd ExecStart).

One asyncio loop, one thread doing estimation::

    transports (serial/pty, UDP, TCP; reconnect with backoff)      drivers.transports
      (UDP: drained by the ticks, drivers.transports.Poller)
      -> Intake.receive: record raw bytes + receive time;            onboard.service.intake
         Intake.parse (at the tick, or while it waits for a sample):
         parse, bounded queue (drops counted per input)
      -> every 1/rate_hz s on the monotonic clock (_Ticker): Intake.tick: onboard.engine
         push queued samples (checked, rejections counted with their reason, GNSS only
         at the surface), step the pipelines
      -> Zenoh (every tick), MAVLink (rate_hz), health at 1 Hz      onboard.service.publishers
      -> set and drift to chart plotters (NMEA VDR, Signal K; rate_hz) publishers.chartplot
      -> the MAVLink sessions with the autopilots, every 0.1 s      onboard.service.mavlink_session
      -> adaptive state saved atomically every state_save_interval_s onboard.service.persistence
      -> systemd: READY=1 once inputs and publishers are up, STATUS every 5 s,
         WATCHDOG=1 from the tick loop itself                        onboard.service.sdnotify

SIGTERM or SIGINT stops it gracefully: STOPPING=1, the last state saved, the recording
flushed and closed, the Zenoh liveliness token withdrawn.

Relative paths in the configuration (``service.state_file``, ``service.recorder.directory``)
are resolved against the state directory: ``--state-dir``, else ``$STATE_DIRECTORY``
(systemd's ``StateDirectory=``), else the current directory; the recorder directory is
resolved against ``$LOGS_DIRECTORY`` (systemd's ``LogsDirectory=``) when that is set and
``--state-dir`` is not given.

Nothing that arrives on an input can stop the service: a parser exception is counted as
``parse:<input>:parser_error``, a failing publisher or disk is counted and reported in the
health events, a vanished port is reopened with backoff.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import math
import os
import signal
import sys
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import msgspec

from onboard.drivers.transports import Poller, SinkError, Transport, open_transport
from onboard.core.config import Config, ConfigError, SourceConfig, load_all
from onboard.core.messages import EstimateRecord, HealthRecord
from onboard.core.outputs import Output, check as check_outputs
from onboard.core.stats import preload as preload_chi2
from onboard.engine import Engine
from onboard.service.events import log_level, severity as event_severity
from onboard.service.config_check import check_config
from onboard.service.intake import Intake
from onboard.service.persistence import StateFile, plain
from onboard.service.recorder import Recorder, config_to_dict
from onboard.service.sdnotify import Notifier
from onboard.service.signing import open_signing

log = logging.getLogger("onboard.service")

HEALTH_PERIOD_S = 1.0
STATUS_PERIOD_S = 5.0
SILENT_AFTER_S = 3.0
"""An input with no bytes for this long is reported silent (s)."""
READY_WAIT_S = 1.0
"""Longest wait (s) for the inputs to connect before READY=1 (a missing port does not
hold the service back: it becomes READY degraded and keeps reconnecting)."""
FINE_SLEEP_S = 0.0012
"""With ``tick_wait_s = 0``, the last part (wall s) of the wait for a tick's grid time is
slept in ``time.sleep`` (epoll, under asyncio, only wakes with millisecond granularity,
rounded up; this removes ~0.5 ms of average lateness at the cost of blocking the loop for
< 1.2 ms per tick)."""
PHASE_WINDOW = 10
"""A tick's fresh sample is predicted to arrive as far after its grid time as the earliest
of the last this many ticks' did (the inputs' phase against the grid is steady: one late
arrival does not delay the next wake-ups)."""
ARRIVAL_LEAD_S = 0.001
"""A tick whose fresh sample is predicted wakes this long (service s) before the
predicted arrival: the resolution of the event loop's timers (epoll's millisecond,
rounded up), so that the wake-up is not after the arrival."""
ARRIVAL_SLACK_S = 0.001
"""It then waits for the sample on the UDP sockets themselves (``Poller.wait``: the loop
blocked, no wake-up of its own) until this long (service s) after the predicted arrival;
past that, it watches the inputs from the loop (a second wake-up)."""
MAX_TICK_LAG_S = 1.0
"""A tick more than this late (wall s) means the loop stalled: the missed ticks are skipped."""
SESSION_POLL_S = 0.1
"""The MAVLink sessions are polled by the tick loop, after the tick, every this many
service seconds (every tick at rate_hz <= 10)."""


class ServiceClock:
    """The service's time base: seconds on the monotonic clock, optionally scaled.

    ``now()`` is ``origin + speed * (monotonic - start)``. The live service uses
    ``speed = 1`` and ``origin = time.monotonic()`` at start (so ``now()`` is the monotonic
    clock); the demo runs the simulator and the service ``speed`` times faster than the
    wall clock on one shared scaled clock.
    """

    def __init__(self, speed: float = 1.0, origin: float | None = None,
                 start: float | None = None) -> None:
        if not speed > 0:
            raise ValueError("clock speed must be positive")
        self.speed = speed
        self._start = time.monotonic() if start is None else start
        """The time.monotonic() instant at which ``now() == origin``."""
        self.origin = self._start if origin is None else origin
        self.utc_offset_s = time.time() - (time.monotonic() - self._start) - self.origin
        """UTC (POSIX s, the system clock when the clock was made) less service time: the
        estimate records' ``utc`` is ``t + utc_offset_s`` (:meth:`utc`), recorded in the
        recording's meta so that a replay gives the same."""

    def now(self) -> float:
        """Service time (s)."""
        return self.origin + (time.monotonic() - self._start) * self.speed

    def utc(self, t: float) -> float:
        """The UTC (POSIX s) of service time ``t``: the system clock when the clock was
        made plus the service time since (a correction of the system clock later shows at
        the next start; scaled, a faster simulation keeps its own UTC time line)."""
        return t + self.utc_offset_s

    def wall_delay(self, t: float) -> float:
        """Wall seconds until service time ``t`` (<= 0 when past)."""
        return (t - self.now()) / self.speed


@dataclass
class _Input:
    cfg: SourceConfig
    name: str
    transport: Transport
    task: asyncio.Task | None = None
    silent: bool = False
    t_started: float = 0.0


@dataclass
class ServiceStats:
    """Counters and timings for health, tests and the benchmark."""

    ticks: int = 0
    tick_skips: int = 0
    tick_errors: int = 0
    health_published: int = 0
    state_saves: int = 0
    state_errors: int = 0
    t_start: float = 0.0
    t_ready: float | None = None
    """Wall-clock (time.monotonic) seconds from construction to READY."""
    tick_compute_s: deque[float] = field(default_factory=lambda: deque(maxlen=4096))
    """Wall time of each tick's work (s): push, pipelines, publishing."""
    tick_late_max_s: float = 0.0
    """The largest delay (service s) between a tick's timer and its callback (the loop
    busy or starved of CPU), skipped stalls included."""
    tick_watches: int = 0
    """Ticks that found no fresh sample at their timer and watched the inputs for one
    (``_Ticker``: a second wake-up, or more)."""


def resolve_dirs(args_state_dir: str | None) -> tuple[Path, Path | None]:
    """(state directory, logs directory or None) per the module docstring."""
    if args_state_dir:
        return Path(args_state_dir), None
    state = Path(os.environ.get("STATE_DIRECTORY", "").split(":")[0] or ".")
    logs = os.environ.get("LOGS_DIRECTORY", "").split(":")[0]
    return state, Path(logs) if logs else None


class Service:
    """The daemon, usable in-process (tests, demo, benchmark) or from :func:`main`.

    Parameters:
        cfg: the configuration.
        state_dir: base of relative paths (state file, recordings).
        logs_dir: base of a relative recorder directory, when given.
        clock: the time base (default: the monotonic clock).
        notifier: systemd notifier (default: from the environment).
        on_tick: called ``(t, records)`` after every tick, on the loop (tests, demo).
        on_health: called with every HealthRecord.
        config_paths: the ``--config`` files (the web page shows them and may edit the
            last one).
    """

    def __init__(self, cfg: Config, *, state_dir: str | Path = ".",
                 logs_dir: str | Path | None = None, clock: ServiceClock | None = None,
                 notifier: Notifier | None = None,
                 on_tick: Callable[[float, Sequence[EstimateRecord]], None] | None = None,
                 on_health: Callable[[HealthRecord], None] | None = None,
                 config_paths: Sequence[str | Path] = ()) -> None:
        self.t_construct = time.monotonic()
        self.cfg = cfg
        self.clock = clock or ServiceClock()
        self.notifier = notifier or Notifier()
        self.on_tick = on_tick
        self.on_health = on_health
        self.state_dir = Path(state_dir)
        svc = cfg.service
        self.engine = Engine(cfg)
        self.engine.whereabouts.utc_of = self.clock.utc
        self.stats = ServiceStats(t_start=self.t_construct)
        self.events: deque[str] = deque(maxlen=64)
        self.state_file = StateFile(self._path(svc.state_file), cfg.vehicle.id,
                                    cfg.vehicle.vehicle_class)
        self.restored: dict | None = None
        rec_base = Path(logs_dir) if logs_dir is not None else self.state_dir
        self.recorder_dir = (Path(svc.recorder.directory) if Path(svc.recorder.directory).is_absolute()
                             else rec_base / svc.recorder.directory)
        self.recorder: Recorder | None = None
        self.intake = Intake(self.engine, queue_size=svc.queue_size)
        self.signing = open_signing(svc.mavlink, self._path)  # MAVLink 2 signing: docs/security.md
        if svc.zenoh.enabled:  # a missing or readable-by-others secret stops the start
            from onboard.service.publishers.zenoh_pub import secret_settings

            secret_settings(svc.zenoh)
        self.intake.verifier = self.signing.verifier if self.signing and svc.mavlink.require_signing else None
        self.poller = Poller(self.clock.now, self.clock.speed)
        """Reads the UDP inputs at the ticks (drivers.transports.Poller)."""
        self._ticker: _Ticker | None = None
        """The tick callbacks, once running."""
        self._due = _Due()
        self.inputs: list[_Input] = []
        self.sessions: list = []
        """The MAVLink sessions with the autopilot (onboard.service.mavlink_session)."""
        self.zenoh = None
        self.mavlink = None
        self.chartplot: list = []
        """Set and drift to chart plotters (``[service.nmea_vdr]``, ``[service.signalk]``)."""
        self._tasks: list[asyncio.Task] = []
        self._stop = asyncio.Event()
        self._rate_prev: dict[str, int] = {}
        self._accepted_prev: dict[str, int] = {}
        self._t_rate_prev: float | None = None
        self._health_events: list[str] = []
        self.latest_health: HealthRecord | None = None
        self.config_paths = list(config_paths)
        self.web = None
        """The web page's server (``[service.web]``; onboard.service.web)."""
        self.web_view = None
        """The page's model, fed at every tick and health record."""

    def _path(self, p: str) -> Path:
        q = Path(p)
        return q if q.is_absolute() else self.state_dir / q

    def event(self, text: str) -> None:
        """Record an event: log, health ``events`` (next 1 Hz record), STATUSTEXT; logged
        at its STATUSTEXT severity's level (:mod:`onboard.service.events`: WARNING for a
        loss, failure or error, INFO otherwise)."""
        log.log(log_level(event_severity(text)), "%s", text)
        self.events.append(text)
        self._health_events.append(text)

    # ------------------------------------------------------------------ lifecycle

    async def start(self) -> None:
        """Restore state, open recorder, publishers and inputs; then READY=1."""
        cfg, svc = self.cfg, self.cfg.service
        if self.signing is not None:  # the first signed frames then need no save on the loop
            await asyncio.get_running_loop().run_in_executor(None, self.signing.reserve_now)
        loaded = self.state_file.load()
        if loaded.state is not None:
            failed = self.engine.set_state(loaded.state)
            self.restored = loaded.state
            if failed:
                aside = self.state_file.move_aside()
                loaded.message += (f"; not restored: {', '.join(failed)}: the file kept as "
                                   f"{aside}")
                loaded.ok = False
        if loaded.state is not None or not loaded.ok:
            self.event(loaded.message)
        else:
            log.info("%s", loaded.message)
        if svc.recorder.enabled:
            meta = {"vehicle": cfg.vehicle.id, "config": config_to_dict(cfg),
                    "sources": {self._name(i, s): s.kind for i, s in enumerate(svc.sources)},
                    "queue_size": svc.queue_size, "state": self.restored,
                    "utc_offset_s": self.clock.utc_offset_s}
            try:
                self.recorder = Recorder(self.recorder_dir, flush_interval_s=svc.recorder.flush_interval_s,
                                         rotate_mb=svc.recorder.rotate_mb,
                                         max_total_mb=svc.recorder.max_total_mb, meta=meta,
                                         clock=self.clock.now, on_event=self.event,
                                         min_free_mb=svc.recorder.min_free_mb,
                                         version=2 if self.intake.verifier is not None else 1)
                self.intake.recorder = self.recorder
            except OSError as err:
                self.event(f"recorder disabled: cannot write {self.recorder_dir}: {err.strerror}")
        for i, src in enumerate(svc.sources):
            name = self._name(i, src)
            self.intake.add_source(name, src.kind)
            tr = open_transport(src.url, clock=self.clock.now, queue_size=svc.queue_size,
                                on_event=lambda text, n=name: self.event(f"{n}: {text.split(': ', 1)[-1]}"),
                                idle_timeout_s=src.idle_timeout_s,
                                zenoh_session=self.zenoh_session)
            self.inputs.append(_Input(src, name, tr, t_started=self.clock.now()))
        for inp in self.inputs:  # inputs open while the publishers start
            inp.task = asyncio.create_task(self._read(inp), name=f"input:{inp.name}")
            self._tasks.append(inp.task)
            link = self.intake.sources[inp.name].link
            if inp.cfg.kind == "mavlink" and link is not None:
                from onboard.service.mavlink_session import MavlinkSession

                sess = MavlinkSession(inp.name, cfg, inp.cfg, link, inp.transport,
                                      self.clock.now, self.event, signing=self.signing,
                                      poll_s=SESSION_POLL_S / self.clock.speed)
                self.sessions.append(sess)  # polled by the tick loop (no task of its own)
        try:
            await self._start_publishers()
        except BaseException:
            for t in self._tasks:
                t.cancel()
            await asyncio.gather(*self._tasks, return_exceptions=True)
            self._tasks.clear()
            if self.recorder is not None:
                self.recorder.close()
            raise
        if svc.web.listen:
            await self._start_web()
        deadline = time.monotonic() + READY_WAIT_S
        await asyncio.get_running_loop().run_in_executor(None, preload_chi2)  # while inputs connect
        while time.monotonic() < deadline and not all(i.transport.stats.connected for i in self.inputs):
            await asyncio.sleep(0.01)
        self._tasks.append(asyncio.create_task(self._tick_loop(), name="ticks"))
        self.stats.t_ready = time.monotonic() - self.t_construct
        up = sum(i.transport.stats.connected for i in self.inputs)
        self.notifier.ready(f"ready: {up}/{len(self.inputs)} inputs up, "
                            f"{len(self.engine.pipelines)} pipelines at {cfg.engine.rate_hz:g} Hz")
        log.info("ready in %.2f s: %d/%d inputs up", self.stats.t_ready, up, len(self.inputs))

    def zenoh_session(self) -> object | None:
        """The session of ``[service.zenoh]`` once open (None before): the one session the
        publisher, the ``zenoh:`` inputs and a ``zenoh:`` MAVLink out share."""
        return self.zenoh.session if self.zenoh is not None else None

    @staticmethod
    def _name(i: int, src: SourceConfig) -> str:
        return src.name or f"{src.kind}{i}"

    async def _start_publishers(self) -> None:
        cfg = self.cfg
        if cfg.service.mavlink.enabled and not self._open_mavlink():
            self._tasks.append(asyncio.create_task(self._mavlink_retry(), name="mavlink-retry"))
        self._open_chartplot()
        if cfg.service.zenoh.enabled:
            if not await self._open_zenoh():
                self._tasks.append(asyncio.create_task(self._zenoh_retry(), name="zenoh-retry"))

    def _open_mavlink(self) -> bool:
        """Open MAVLink out; a bad key file or signing setup is a configuration error
        (raised: the service must not run unsigned by mistake); a link that cannot be
        opened (serial port missing) is an event and retried."""
        from onboard.service.publishers.mavlink_pub import MavlinkPublisher

        pub = MavlinkPublisher(self.cfg.service.mavlink, self.cfg.vehicle.system_id,
                               clock=self.clock.now, signing=self.signing,
                               zenoh_session=self.zenoh_session)
        try:
            pub.start()
        except ConfigError:
            raise
        except Exception as err:  # noqa: BLE001 - pymavlink raises assorted errors
            self.event(f"mavlink out: cannot open {self.cfg.service.mavlink.url}: {err}")
            pub.close()
            return False
        self.mavlink = pub
        return True

    def _open_chartplot(self) -> None:
        """The set-and-drift outputs that are enabled (onboard.service.publishers.chartplot)."""
        from onboard.service.publishers.chartplot import NmeaVdrPublisher, SignalKPublisher

        svc = self.cfg.service
        declination = lambda: self.engine.declination.report.deg  # noqa: E731
        outs = [(svc.nmea_vdr, NmeaVdrPublisher), (svc.signalk, SignalKPublisher)]
        for out_cfg, cls in outs:
            if out_cfg.enabled:
                pub = cls(out_cfg, declination=declination, clock=self.clock.now)
                pub.start()
                self.chartplot.append(pub)

    async def _mavlink_retry(self) -> None:
        delay = 1.0
        while self.mavlink is None:
            await asyncio.sleep(delay)
            delay = min(delay * 2.0, 30.0)
            if self._open_mavlink():
                self.event("mavlink out: open")

    async def _open_zenoh(self) -> bool:
        from onboard.service.publishers.zenoh_pub import ZenohPublisher

        pub = ZenohPublisher(self.cfg.service.zenoh, self.cfg.vehicle.id, on_event=self.event)
        try:
            await asyncio.get_running_loop().run_in_executor(None, pub.start)
        except Exception as err:  # noqa: BLE001 - zenoh raises its own ZError
            self.event(f"zenoh: cannot open session: {str(err).split(' at ')[0]}")
            pub.close()
            return False
        self.zenoh = pub
        return True

    async def _start_web(self) -> None:
        """Serve the web page; a port that cannot be bound is an event, not a stop."""
        from onboard.service.web.app import make_server
        from onboard.service.web.config_edit import ConfigEditor
        from onboard.service.web.view import LiveView

        web = self.cfg.service.web
        self.web_view = LiveView(origin=self._origin, vehicle=self.cfg.vehicle.id)
        editor = ConfigEditor(self.config_paths, web.edit_config) if self.config_paths else None
        server = make_server(web.listen, self.web_view, editor)
        try:
            await server.start()
        except OSError as err:
            self.event(f"web: cannot listen on {web.listen}: {err.strerror}")
            return
        self.web = server
        log.info("web page on http://%s:%d/", server.host, server.port)

    def _origin(self, pipeline: str) -> tuple[float, float] | None:
        """(lat, lon) in degrees of the local origin of ``pipeline``'s positions."""
        for p in self.engine.pipelines:
            frame = p.frame if p.name == pipeline else None
            if frame is not None:
                return frame.lat0, frame.lon0
        return None

    async def _zenoh_retry(self) -> None:
        delay = 1.0
        while self.zenoh is None:
            await asyncio.sleep(delay)
            delay = min(delay * 2.0, 30.0)
            if await self._open_zenoh():
                self.event("zenoh: session open")

    async def _read(self, inp: _Input) -> None:
        """Feed one input's chunks to the intake, forever: the transport hands each chunk
        to :meth:`Intake.receive` (:meth:`drivers.transports.Transport.pump`: a UDP input
        when the tick loop drains :attr:`poller`, the others as they are read; the intake
        parses the chunks kept at the tick or when the tick waits for a sample) and
        reconnects by itself; an unexpected error (a bug) is logged and the input
        restarted after 1 s."""
        receive = self.intake.receive
        name, kind = inp.name, inp.cfg.kind
        direct = not inp.transport.drained_by(self.poller)  # else the poller tells the ticker

        def sink(data: bytes, t_rx: float) -> None:
            receive(name, kind, data, t_rx)
            ticker = self._ticker
            if direct and ticker is not None and ticker.waiting:
                ticker.arrival()

        while True:
            try:
                await inp.transport.pump(sink, self.poller)
            except asyncio.CancelledError:
                raise
            except Exception as err:  # noqa: BLE001
                cause = err.__cause__ if isinstance(err, SinkError) and err.__cause__ else err
                log.error("input %s failed", name, exc_info=cause)
                self.event(f"{name}: input failed ({type(cause).__name__}), restarting")
            await asyncio.sleep(1.0)

    async def run(self) -> None:
        """Start (if not started) and run until :meth:`request_stop`; then shut down."""
        if not self._tasks:
            await self.start()
        try:
            await self._stop.wait()
        finally:
            await self.shutdown()

    def request_stop(self) -> None:
        """Ask :meth:`run` to shut down (safe to call from a signal handler)."""
        self._stop.set()

    async def shutdown(self) -> None:
        """Graceful stop: STOPPING=1, tasks cancelled, state saved, recording closed."""
        self.notifier.stopping("stopping")
        for t in self._tasks:
            t.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks.clear()
        loop = asyncio.get_running_loop()  # files are fsync'ed off the loop, even now
        await loop.run_in_executor(None, self._save_state_now)
        if self.recorder is not None:
            await loop.run_in_executor(None, self.recorder.close)
        if self.web is not None:
            await self.web.close()
        if self.zenoh is not None:
            self.zenoh.close()
        if self.mavlink is not None:
            self.mavlink.close()
        for pub in self.chartplot:
            pub.close()
        if self.signing is not None:
            await loop.run_in_executor(None, self.signing.close)
        self.notifier.close()

    # ------------------------------------------------------------------ the loop

    async def _tick_loop(self) -> None:
        """Run the ticks until cancelled (:class:`_Ticker`: timer and reader callbacks,
        no task step per tick)."""
        ended: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        ticker = _Ticker(self, ended)
        try:
            await ended
        finally:
            ticker.cancel()

    def _periodic(self, now: float) -> None:
        """What is due after a tick: health (1 Hz), STATUS, the state save, the recorder's
        flush, the MAVLink sessions (every ``SESSION_POLL_S``)."""
        due = self._due
        if now >= due.health:
            due.health += HEALTH_PERIOD_S * max(1, math.ceil((now - due.health) / HEALTH_PERIOD_S))
            self._health(now)
        if now >= due.status:
            due.status = now + STATUS_PERIOD_S
            self.notifier.status(self.status_line())
        if now >= due.save:
            due.save = now + self.cfg.service.state_save_interval_s
            self._save_state_async()
        if self.recorder is not None:
            self.recorder.poll(now)

    def _poll_sessions(self, now: float) -> None:
        """One step of every MAVLink session (a session bug is logged, never raised)."""
        for sess in self.sessions:
            try:
                sess.poll(now)
            except Exception:  # noqa: BLE001 - a session bug must not stop the ticks
                log.exception("mavlink session %s failed", sess.name)

    def _tick(self, t: float, now: float) -> None:
        records = self.intake.tick(t)
        self.stats.ticks += 1
        if self.zenoh is not None and records:
            self.zenoh.publish_estimates(records, self.engine.location_fixes(records))
        if self.mavlink is not None:
            self.mavlink.publish_estimates(records, now)
        for pub in self.chartplot:
            pub.publish_estimates(records, now)
        if self.web_view is not None and records:
            self.web_view.feed_estimates(records)
        if self.on_tick is not None:
            self.on_tick(t, records)

    def _health(self, now: float) -> None:
        for inp in self.inputs:
            t_last = inp.transport.stats.t_last_rx
            quiet = now - (t_last if t_last is not None else inp.t_started)
            if not inp.silent and quiet > SILENT_AFTER_S:
                inp.silent = True
                self.event(f"{inp.name}: silent for {quiet:.0f} s")
            elif inp.silent and quiet < SILENT_AFTER_S:
                inp.silent = False
                self.event(f"{inp.name}: data again")
        h = self.health(now)
        self.latest_health = h
        self.stats.health_published += 1
        if self.zenoh is not None:
            self.zenoh.publish_health(h)
        if self.mavlink is not None:
            self.mavlink.publish_health(h, now)
        for pub in self.chartplot:
            pub.publish_health(h)
        if self.web_view is not None:
            self.web_view.feed_health(h)
        if self.on_health is not None:
            self.on_health(h)

    def health(self, now: float) -> HealthRecord:
        """The HealthRecord at ``now``: per-input and per-sample-stream rates (samples/s
        since the previous call), engine and parser rejections, drops, innovations, NIS,
        the events since the previous call."""
        dt = now - self._t_rate_prev if self._t_rate_prev is not None else None
        rates: dict[str, float] = {}
        for name, st in self.intake.sources.items():
            prev = self._rate_prev.get(name, 0)
            rates[name] = (st.samples - prev) / dt if dt else 0.0
            self._rate_prev[name] = st.samples
        for key, n in self.engine.accepted.items():
            k = ":".join(key) if isinstance(key, tuple) else str(key)
            prev = self._accepted_prev.get(k, 0)
            rates[k] = (n - prev) / dt if dt else 0.0
            self._accepted_prev[k] = n
        self._t_rate_prev = now
        for sess in self.sessions:
            rates.update(sess.rates())
        events, self._health_events = self._health_events[-20:], []
        h = self.engine.health(now, rates, events)
        for text in h.events[len(events):]:  # the engine's own (sources, streams, alerts)
            log.log(log_level(event_severity(text)), "%s", text)
        dropped = dict(self.intake.dropped)
        for inp in self.inputs:
            if inp.transport.stats.dropped_chunks:
                dropped[f"{inp.name}:chunks"] = inp.transport.stats.dropped_chunks
        if self.stats.tick_skips:
            dropped["ticks"] = self.stats.tick_skips
        if self.recorder is not None and self.recorder.dropped:
            dropped["recorder"] = self.recorder.dropped  # records that missed the disk
        rejected = dict(h.rejected)
        rejected.update(self.intake.parse_rejections())
        for name, st in self.intake.sources.items():
            if st.link is not None:
                for who, n in st.link.ignored.items():
                    rejected[f"parse:{name}:ignored:{who}"] = n
        return msgspec.structs.replace(h, rejected=rejected, dropped=dropped)

    def status_line(self) -> str:
        """The one-line systemd STATUS: tick rate, live inputs, pipelines estimating,
        samples rejected and dropped."""
        up = sum(i.transport.stats.connected and not i.silent for i in self.inputs)
        est = ",".join(sorted(self.engine.latest)) or "none yet"
        rej = sum(self.engine.rejected.values())
        return (f"{self.cfg.engine.rate_hz:g} Hz, inputs {up}/{len(self.inputs)} live, "
                f"estimating {est}, {rej} samples rejected, {sum(self.intake.dropped.values())} dropped")

    # ------------------------------------------------------------------ persistence

    def _save_state_async(self) -> None:
        state = plain(self.engine.get_state())  # a copy taken between ticks
        loop = asyncio.get_running_loop()
        fut = loop.run_in_executor(None, self.state_file.save, state)
        fut.add_done_callback(self._saved)

    def _saved(self, fut: asyncio.Future) -> None:
        err = fut.exception()
        if err is None:
            self.stats.state_saves += 1
        else:
            self.stats.state_errors += 1
            self.event(f"state save failed: {err}")

    def _save_state_now(self) -> None:
        try:
            self.state_file.save(self.engine.get_state())
            self.stats.state_saves += 1
        except (OSError, TypeError, ValueError) as err:
            self.stats.state_errors += 1
            log.error("state save failed: %s", err)


@dataclass
class _Due:
    """Service times at which the periodic work after a tick is next due."""

    health: float = math.inf
    status: float = math.inf
    save: float = math.inf
    poll: float = -math.inf


class _Ticker:
    """The service's ticks as event-loop callbacks: a timer at each grid time
    ``k / rate_hz``; with ``tick_wait_s`` > 0 the UDP inputs are drained then and, unless
    the chunks received queued a sample stamped after the grid time, the inputs are watched
    until one does (:meth:`arrival`) or the wait ends; then the tick and what is due after
    it (the tick's newest sample is then milliseconds old, not up to a period).

    The ticks predict their fresh sample's arrival: the earliest delay past their grid
    times at which the last ticks' fresh samples were received (:attr:`phases`). The timer
    of a grid time is then set ``ARRIVAL_LEAD_S`` before that arrival, and after the drain
    the tick blocks on the UDP sockets (:meth:`drivers.transports.Poller.wait`) until the
    sample is there, at most ``ARRIVAL_SLACK_S`` past its prediction: the tick fires at the
    arrival on one wake-up of the loop. It blocks only when the poller reads every input:
    the loop would read the others' bytes, and stamp them, late. When the sample is later,
    or the loop may not block, the tick watches the inputs as above; a wait that ends
    without a fresh sample drops the prediction (the next timer is at the grid time). A
    tick costs the loop its timer and, when the prediction misses, one wake-up per arrival
    while it waits: no task step, future or coroutine per tick.

    A grid time more than ``MAX_TICK_LAG_S`` past (the loop stalled) skips the missed
    ticks. An exception in a tick is counted and logged and the next tick scheduled; one
    in the ticker itself ends ``ended`` with it (the watchdog then sees no ticks)."""

    def __init__(self, svc: "Service", ended: asyncio.Future[None]) -> None:
        self.svc = svc
        self.ended = ended
        self.loop = asyncio.get_running_loop()
        self.period = 1.0 / svc.cfg.engine.rate_hz
        self.wait = min(svc.cfg.service.tick_wait_s, 0.5 * self.period)
        now = svc.clock.now()
        self.k = math.ceil(now / self.period)
        self.t = self.k * self.period
        """The grid time of the coming tick (service s)."""
        self.phases: deque[float] = deque(maxlen=PHASE_WINDOW)
        """Service s from the grid time to the receipt of the chunk that ended the wait, of
        the last ticks that had a fresh sample (empty: no prediction, wake at the grid
        time)."""
        self.t_wake = self.t
        """When the coming tick's timer is due (service s)."""
        self.may_block = bool(svc.inputs) and all(
            inp.transport.drained_by(svc.poller) for inp in svc.inputs)
        """Whether the tick may block the loop for its predicted sample: every input is
        read by the poller's drains, none by the loop."""
        self.waiting = False
        self.handle: asyncio.TimerHandle | None = None
        save_every = svc.cfg.service.state_save_interval_s
        svc._due = _Due(now + HEALTH_PERIOD_S, now + STATUS_PERIOD_S,
                        now + save_every if save_every > 0 else math.inf)
        svc._ticker = self
        self._schedule()

    def cancel(self) -> None:
        """Stop ticking."""
        if self.handle is not None:
            self.handle.cancel()
        if self.waiting:
            self.waiting = False
            self.svc.poller.unwatch()
        self.svc._ticker = None

    def _schedule(self) -> None:
        """The timer of the next grid time: at the predicted arrival of its fresh sample
        when there is one (:attr:`phases`), else at the grid time (waking ``FINE_SLEEP_S``
        early to sleep the rest precisely when ticks do not wait for a sample)."""
        self.t = self.k * self.period
        if self.wait == 0:
            self.t_wake = self.t
            d = self.svc.clock.wall_delay(self.t) - FINE_SLEEP_S
        else:
            phases = self.phases
            ahead = min(max(min(phases) - ARRIVAL_LEAD_S, 0.0), self.wait) if phases else 0.0
            self.t_wake = self.t + ahead
            d = self.svc.clock.wall_delay(self.t_wake)
        self.handle = self.loop.call_later(max(d, 0.0), self._on_grid)

    def _on_grid(self) -> None:
        try:
            self._grid()
        except Exception as err:  # noqa: BLE001 - a bug of the ticker: end the tick task
            if not self.ended.done():
                self.ended.set_exception(err)

    def _grid(self) -> None:
        """At the grid time: skip a stall; wait for a fresh sample; or tick."""
        svc, clock, t = self.svc, self.svc.clock, self.t
        if self.wait == 0:
            d = clock.wall_delay(t)
            if d > 0:
                time.sleep(min(d, FINE_SLEEP_S))
        now = clock.now()
        svc.stats.tick_late_max_s = max(svc.stats.tick_late_max_s, now - self.t_wake)
        if -clock.wall_delay(t) > MAX_TICK_LAG_S:
            k_new = math.floor(now / self.period)
            svc.stats.tick_skips += k_new - self.k
            svc.event(f"estimator loop stalled {now - t:.1f} s: skipped {k_new - self.k} ticks")
            self.k = k_new
            self.t = k_new * self.period
            self._fire(self.t, now, drain=True)
            return
        if self.wait == 0:
            self._fire(t, now, drain=True)
            return
        svc.poller.drain()
        if svc.intake.parse(after=t) or self._await_predicted():
            self._predict()
        else:
            delay = clock.wall_delay(t + self.wait)
            if delay > 0:
                self.waiting = True
                svc.stats.tick_watches += 1
                svc.poller.watch(self.arrival)
                self.handle = self.loop.call_later(delay, self._end_wait)
                return
            self.phases.clear()
        now = clock.now()
        self._fire(max(t, now), now, drain=False)

    def _await_predicted(self) -> bool:
        """Block for the predicted fresh sample on the UDP sockets, at most until
        ``ARRIVAL_SLACK_S`` after its predicted arrival (and the wait's end); return
        whether it came."""
        if not (self.phases and self.may_block):
            return False
        svc, clock = self.svc, self.svc.clock
        end = self.t + min(min(self.phases) + ARRIVAL_SLACK_S, self.wait)
        while svc.poller.wait(clock.wall_delay(end)):
            svc.poller.drain()
            if svc.intake.parse(after=self.t):
                return True
        return False

    def _predict(self) -> None:
        """A fresh sample ended the wait: note how far past the grid time its chunk was
        received."""
        t_rx = self.svc.intake.fresh_rx
        if t_rx is not None:
            self.phases.append(max(t_rx - self.t, 0.0))

    def arrival(self) -> None:
        """Chunks arrived while the tick waits: parse them; a sample queued that is
        stamped after the grid time ends the wait."""
        if self.waiting and self.svc.intake.parse(after=self.t):
            if self.handle is not None:
                self.handle.cancel()
            self._predict()
            self._end_wait(fresh=True)

    def _end_wait(self, fresh: bool = False) -> None:
        """The wait ends: on a fresh sample (``fresh``) or at its deadline (the next
        timer is then at the grid time)."""
        try:
            self.waiting = False
            self.svc.poller.unwatch()
            if not fresh:
                self.phases.clear()
            now = self.svc.clock.now()
            self._fire(max(self.t, now), now, drain=False)
        except Exception as err:  # noqa: BLE001 - as in _on_grid
            if not self.ended.done():
                self.ended.set_exception(err)

    def _fire(self, t: float, now: float, drain: bool) -> None:
        """Tick at ``t`` (``drain``: read the UDP inputs first), publish, do what is due,
        ping the watchdog; schedule the next grid time whatever happens."""
        svc = self.svc
        w0 = time.perf_counter()
        try:
            if drain:
                svc.poller.drain()
            svc._tick(t, now)
            svc._periodic(now)
            if svc.sessions and self.k * self.period >= svc._due.poll:
                svc._due.poll = self.k * self.period + SESSION_POLL_S - 0.5 * self.period
                svc._poll_sessions(now)
        except Exception as err:  # noqa: BLE001 - a pipeline bug must not stop the loop
            svc.stats.tick_errors += 1
            if svc.stats.tick_errors == 1 or svc.stats.tick_errors % 600 == 0:
                log.exception("tick at %.3f failed (%d so far)", t, svc.stats.tick_errors)
                svc.event(f"tick failed ({type(err).__name__}; {svc.stats.tick_errors} "
                          "so far): see the log")
        finally:
            svc.stats.tick_compute_s.append(time.perf_counter() - w0)
            if svc.cfg.service.watchdog:
                svc.notifier.watchdog()
            self.k += 1
            self._schedule()


EXIT_INTERRUPTED = 130
"""Exit status of ``onboard run`` stopped by SIGINT (Ctrl-C), as every command's
(architecture.md §4.1); stopped by SIGTERM (systemd's stop) it is 0."""


async def run_service(cfg: Config, state_dir: Path, logs_dir: Path | None = None,
                      config_paths: Sequence[str | Path] = ()) -> int:
    """Run until SIGTERM/SIGINT, then stop gracefully; return the exit status: 0 after
    SIGTERM, :data:`EXIT_INTERRUPTED` after SIGINT (the first signal decides)."""
    svc = Service(cfg, state_dir=state_dir, logs_dir=logs_dir, config_paths=config_paths)
    loop = asyncio.get_running_loop()
    stopped_by: list[int] = []

    def stop(sig: int) -> None:
        stopped_by.append(sig)
        svc.request_stop()

    for sig in (signal.SIGTERM, signal.SIGINT):
        try:
            loop.add_signal_handler(sig, stop, sig)
        except (NotImplementedError, RuntimeError):
            pass
    await svc.run()
    return EXIT_INTERRUPTED if stopped_by[:1] == [signal.SIGINT] else 0


LOG_LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL")
"""The values ``ONBOARD_LOG_LEVEL`` takes (any case; empty or unset: INFO)."""


def env_log_level(value: str) -> str:
    """The logging level named by ``ONBOARD_LOG_LEVEL`` (``value``), upper-cased; empty:
    INFO. Any other name is a :class:`ConfigError` that lists the levels."""
    level = value.strip().upper() or "INFO"
    if level not in LOG_LEVELS:
        raise ConfigError(f"ONBOARD_LOG_LEVEL={value!r}: expected one of "
                          f"{', '.join(LOG_LEVELS)}")
    return level


def main(args: argparse.Namespace) -> int:
    """``onboard run --config FILE [--config OVERLAY ...] [--state-dir DIR]``: the
    files are applied in order (:func:`onboard.core.config.load_all`)."""
    logging.basicConfig(level=env_log_level(os.environ.get("ONBOARD_LOG_LEVEL", "")),
                        format="%(levelname)s %(name)s: %(message)s", stream=sys.stderr)
    paths = [args.config] if isinstance(args.config, str) else list(args.config)
    cfg = load_all(paths)
    check_config(cfg, " + ".join(paths))
    mav = cfg.service.mavlink
    if mav.require_signing or mav.signing_key_file:
        from onboard.service.publishers.mavlink_pub import check_signing

        check_signing(mav)  # fail before anything starts, with one line
    state_dir, logs_dir = resolve_dirs(getattr(args, "state_dir", None))
    check_outputs([Output("--state-dir", state_dir, "dir")]
                  + ([Output("$LOGS_DIRECTORY", logs_dir, "dir")] if logs_dir else []))
    try:
        state_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise ConfigError(f"state directory {state_dir}: {err.strerror}") from None
    return asyncio.run(run_service(cfg, state_dir, logs_dir, paths))
