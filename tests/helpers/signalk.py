"""A real Signal K server (npm ``signalk-server``) for the chart plotter tests: started on
free loopback ports with a temporary configuration directory holding two data
connections, an NMEA 0183 UDP input and a Signal K UDP input, and read back over its REST
API. Found in ``$ONBOARD_SIGNALK_DIR``, the checkout's ``.signalk/``, the cache folder
``.ci/run`` installs it in, or on the PATH."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import time
import urllib.error
import urllib.request
from pathlib import Path

SIGNALK_VERSION = "2.23.0"
"""2.23.0 resolves from the registry here; 2.32.0's dependencies do not."""
SIGNALK_INSTALL = f"npm install --prefix ~/.cache/onboard-signalk signalk-server@{SIGNALK_VERSION}"
"""The line the Signal K tests skip with when the server is absent (README, "Install")."""
REPO = Path(__file__).resolve().parents[2]
START_TIMEOUT_S = 180.0
"""Wall time allowed for the server to answer (measured 31 s on a machine loaded 6x;
its start costs about 6 s of CPU)."""
INTERFACES_OFF = ("applicationData", "appstore", "logfiles", "mfd_webapp", "nmea-tcp",
                  "playground", "plugins", "tcp", "wasm", "webapps", "unitpreferences-api")
"""The server's interfaces the tests do not use: off, so nothing binds a fixed port
(the NMEA 0183 TCP server's 10110, the Signal K TCP stream's 8375) and the start is cheaper."""


def signalk_server() -> str | None:
    """The ``signalk-server`` executable, or None."""
    dirs = [os.environ.get("ONBOARD_SIGNALK_DIR", ""), str(REPO / ".signalk"),
            str(Path.home() / ".cache" / "onboard-signalk")]
    for d in filter(None, dirs):
        exe = Path(d) / "node_modules" / ".bin" / "signalk-server"
        if exe.is_file() and shutil.which("node"):
            return str(exe)
    return shutil.which("signalk-server")


def free_port(kind: int) -> int:
    """A loopback port free now for ``kind`` (SOCK_STREAM or SOCK_DGRAM)."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class SignalKServer:
    """``signalk-server`` in a child process with a configuration of its own.

    Attributes:
        http_port: its HTTP (REST, WebSocket) port.
        nmea_port: its NMEA 0183 UDP input (data connection ``onboard-nmea``).
        sk_port: its Signal K UDP input (data connection ``onboard-sk``).
    """

    def __init__(self, exe: str, config_dir: Path) -> None:
        self.exe = exe
        self.config_dir = config_dir
        self.http_port = free_port(socket.SOCK_STREAM)
        self.nmea_port = free_port(socket.SOCK_DGRAM)
        self.sk_port = free_port(socket.SOCK_DGRAM)
        self.proc: subprocess.Popen | None = None

    def settings(self) -> dict:
        """The server's settings.json: the two UDP inputs, no TLS, no mDNS."""
        def udp(pid: str, kind: str, port: int) -> dict:
            return {"id": pid, "enabled": True, "pipeElements": [
                {"type": "providers/simple", "options": {
                    "logging": False, "type": kind, "subOptions": {"type": "udp", "port": port}}}]}

        return {"port": self.http_port, "ssl": False, "mdns": False,
                "interfaces": dict.fromkeys(INTERFACES_OFF, False),
                "pipedProviders": [udp("onboard-nmea", "NMEA0183", self.nmea_port),
                                   udp("onboard-sk", "SignalK", self.sk_port)]}

    def __enter__(self) -> "SignalKServer":
        self.config_dir.mkdir(parents=True, exist_ok=True)
        (self.config_dir / "settings.json").write_text(json.dumps(self.settings()))
        env = dict(os.environ, SIGNALK_DISABLE_SERVER_UPDATES="1")
        self.proc = subprocess.Popen([self.exe, "-c", str(self.config_dir)], env=env,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        deadline = time.monotonic() + START_TIMEOUT_S
        while self.get("/signalk") is None:
            if self.proc.poll() is not None:
                raise RuntimeError(f"signalk-server exited: {self.proc.stderr.read()[-2000:]!r}")
            if time.monotonic() > deadline:
                self.__exit__()
                raise TimeoutError(f"signalk-server did not answer within {START_TIMEOUT_S} s")
            time.sleep(0.5)
        return self

    def __exit__(self, *exc: object) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)

    def get(self, path: str) -> object | None:
        """The JSON at ``path`` of its HTTP API, or None (not found, not up)."""
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{self.http_port}{path}", timeout=5) as r:
                return json.load(r)
        except (urllib.error.URLError, ConnectionError, TimeoutError, ValueError):
            return None

    def wait_for(self, path: str, pred, timeout_s: float = 20.0) -> object | None:
        """The JSON at ``path`` once ``pred`` holds for it (polled), else the last seen."""
        deadline = time.monotonic() + timeout_s
        while True:
            got = self.get(path)
            if (got is not None and pred(got)) or time.monotonic() > deadline:
                return got
            time.sleep(0.2)
