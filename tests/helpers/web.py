"""Helpers of the web page tests: a LiveView fed by a short simulator replay, the page's
server on a free port in a thread of its own, and headless Chromium."""

from __future__ import annotations

import asyncio
import shutil
import subprocess
import threading
from pathlib import Path

from onboard.core.config import load
from onboard.engine import Engine, run
from onboard.service.web.app import routes
from onboard.service.web.http import HttpServer
from onboard.service.web.view import LiveView
from onboard.sitl.runner import simulate

CHROMIUM_INSTALL = "sudo apt-get install chromium"
"""The line the browser tests skip with when Chromium is absent."""
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--hide-scrollbars"]


def chromium() -> str | None:
    """The Chromium executable, or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


def replay_view(scenario: str = "effect-current", duration_s: float = 120.0) -> LiveView:
    """A LiveView fed with every tick and the last health record of ``duration_s`` s of
    ``scenario`` through the jaiabot configuration's pipelines (~2.5 s)."""
    engine = Engine(load("sitl-jaiabot"))

    def origin(name: str) -> tuple[float, float] | None:
        frame = next((getattr(p, "frame", None) for p in engine.pipelines if p.name == name), None)
        return None if frame is None else (frame.lat0, frame.lon0)

    view = LiveView(origin=origin)
    samples = (s for _, batch, _ in simulate(scenario, duration=duration_s, seed=1) for s in batch)
    last = [0.0]

    def on_tick(t: float, records: list) -> None:
        view.feed_estimates(records)
        last[0] = t

    run(engine, samples, on_tick)
    view.feed_health(engine.health(last[0], {}, ["replay finished"]))
    return view


class ServerThread:
    """An asyncio server (the page's, or any) served from a thread of its own."""

    def __init__(self, server: HttpServer | None = None, view: LiveView | None = None) -> None:
        self.server = server or HttpServer(routes(view or LiveView()), "127.0.0.1", 0)
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)

    def __enter__(self) -> "ServerThread":
        self.thread.start()
        asyncio.run_coroutine_threadsafe(self.server.start(), self.loop).result(5)
        return self

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.server.port}"

    def __exit__(self, *exc: object) -> None:
        asyncio.run_coroutine_threadsafe(self.server.close(), self.loop).result(5)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)


def screenshot(url: str, out: Path, profile: Path, size: str = "1000,640",
               budget_ms: int = 4000) -> subprocess.CompletedProcess:
    """Load ``url`` in headless Chromium, let its timers and requests run for
    ``budget_ms`` of virtual time, and write a PNG to ``out``."""
    exe = chromium()
    assert exe is not None
    cmd = [exe, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", f"--window-size={size}",
           f"--virtual-time-budget={budget_ms}", f"--screenshot={out}", url]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=60)


def dump_dom(url: str, profile: Path, budget_ms: int = 4000) -> str:
    """The page's DOM after ``budget_ms`` of virtual time (its panel's text)."""
    exe = chromium()
    assert exe is not None
    cmd = [exe, *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
           f"--virtual-time-budget={budget_ms}", "--dump-dom", url]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=60).stdout
