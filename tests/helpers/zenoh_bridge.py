"""A MAVLink UDP link bridged onto Zenoh the way BlueOS's mavlink-server does it.

mavlink-server's ``zenohraw`` driver (bluerobotics/mavlink-server
``src/lib/drivers/zenoh/raw.rs``) publishes every frame it routes as one sample on
``mavlink_raw/out`` (encoding ``application/octet-stream;mavlink``) and writes the bytes
of every sample on ``mavlink_raw/in`` into its router. :class:`UdpZenohBridge` does the
same for one UDP peer (the simulator's autopilot): datagrams received on its port go to
``<prefix>/out``, samples on ``<prefix>/in`` go back to the address the last datagram
came from.
"""

from __future__ import annotations

import socket
import threading

RAW_ENCODING = "application/octet-stream;mavlink"


class UdpZenohBridge:
    """UDP ``127.0.0.1:<port>`` <-> Zenoh ``<prefix>/out`` and ``<prefix>/in`` on
    ``session`` (a zenoh.Session); :attr:`port` is where the autopilot sends.
    ``to_zenoh`` / ``to_udp`` count the frames carried each way."""

    def __init__(self, session, prefix: str = "mavlink_raw", port: int = 0) -> None:
        import zenoh

        self.session = session  # a session nobody holds is closed by Zenoh
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", port))
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.peer: tuple[str, int] | None = None
        self.to_zenoh = 0
        self.to_udp = 0
        self._pub = session.declare_publisher(f"{prefix}/out",
                                              encoding=zenoh.Encoding(RAW_ENCODING))
        self._sub = session.declare_subscriber(f"{prefix}/in", self._inject)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="udp-zenoh-bridge", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data, addr = self.sock.recvfrom(65536)
            except (socket.timeout, OSError):
                continue
            self.peer = addr
            try:
                self._pub.put(data)
            except Exception:  # noqa: BLE001 - the session closed under us: stop
                return
            self.to_zenoh += 1

    def _inject(self, sample) -> None:
        if self.peer is None:
            return
        try:
            self.sock.sendto(sample.payload.to_bytes(), self.peer)
            self.to_udp += 1
        except OSError:
            pass

    def close(self) -> None:
        """Stop the thread, undeclare, close the socket."""
        self._stop.set()
        self._thread.join(2.0)
        for obj in (self._sub, self._pub):
            try:
                obj.undeclare()
            except Exception:  # noqa: BLE001 - the session may be closed already
                pass
        self.sock.close()
