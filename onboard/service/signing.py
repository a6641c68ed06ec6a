"""MAVLink 2 signing for the service: the key file and timestamps that survive restarts.

One :class:`SigningState` per service, shared by the MAVLink inputs (verification,
:class:`drivers.mavlink_signing.SignatureVerifier`) and MAVLink out (signing), as the
MAVLink signing specification asks (https://mavlink.io/en/guide/message_signing.html,
"Timestamp handling"):

* the local timestamp is the largest of the wall clock, the last timestamp sent, every
  accepted incoming timestamp and the persisted ones, so outgoing timestamps keep
  increasing across a restart even when the wall clock went back (no RTC, a bad NTP step);
* the timestamps are stored "at least once a minute" in a small JSON file, mode 0600,
  written atomically (tmp + fsync + rename)::

      {"format": "onboard-mavlink-signing", "version": 1,
       "tx_reserved": <int>, "streams": [[link_id, sysid, compid, timestamp], ...]}

  ``tx_reserved`` is a *reservation*: the file promises that no timestamp up to it has
  been used, and a timestamp beyond it is sent only after a larger reservation (now + 60 s)
  is on disk. So even after a crash the next start begins above every timestamp sent.
  Incoming stream timestamps are saved at most every ``save_interval_s`` (60 s) and at
  stop; after a crash, frames from that last interval could be replayed once.

The key file (``service.mavlink.signing_key_file``) holds the 32-byte secret as raw bytes
or 64 hex digits, or a passphrase whose SHA-256 is the key (MAVProxy's ``signing setup``);
it must be accessible by its owner only (mode 0600 or stricter), or be a systemd credential
(``credential:NAME``, :mod:`onboard.service.credentials`).
"""

from __future__ import annotations

import concurrent.futures
import hashlib
import json
import logging
import os
import time
from pathlib import Path
from typing import Callable

from onboard.drivers.mavlink_signing import (
    TIMESTAMP_UNITS_PER_S,
    SignatureVerifier,
    StreamKey,
    signing_timestamp,
)
from onboard.core.config import ConfigError, MavlinkOut
from onboard.service.credentials import read_secret

log = logging.getLogger(__name__)

STATE_FORMAT = "onboard-mavlink-signing"
STATE_VERSION = 1


def load_signing_key(path: str | Path) -> bytes:
    """The 32-byte signing key from ``path`` (see the module docstring); ``path`` may name
    a systemd credential, ``credential:NAME`` (:mod:`onboard.service.credentials`).

    Raises ConfigError when the file is missing, empty or accessible by group or others
    (a credential's ACL entry for the service's own user is accepted).
    """
    _, raw = read_secret(str(path), "service.mavlink.signing_key_file")
    if len(raw) == 32:
        return raw
    text = raw.decode("utf-8", "replace").strip()
    if not text:
        raise ConfigError(f"service.mavlink.signing_key_file: {path} is empty")
    if len(text) == 64:
        try:
            return bytes.fromhex(text)
        except ValueError:
            pass
    return hashlib.sha256(text.encode()).digest()


def check_signing(cfg: MavlinkOut) -> bytes | None:
    """The signing key the configuration asks for (None: unsigned); ConfigError when
    ``require_signing`` has no key file or the key file is unusable."""
    if cfg.require_signing and not cfg.signing_key_file:
        raise ConfigError("service.mavlink.require_signing is true but no "
                          "signing_key_file is configured")
    return load_signing_key(cfg.signing_key_file) if cfg.signing_key_file else None


class SigningState:
    """Key, outgoing timestamp and incoming stream timestamps, persisted in ``path``.

    Parameters:
        key: the 32-byte secret.
        path: the timestamp file (created mode 0600 with its directory on the first save).
        max_future_s: passed to the verifier (0: no bound on future timestamps).
        reserve_s: how far ahead (s) an outgoing-timestamp reservation reaches.
        save_interval_s: longest time (s) between saves of changed incoming timestamps.
        wall: the wall clock (POSIX s); mono: a monotonic clock (s) for the save interval.
    """

    def __init__(self, key: bytes, path: str | Path, *, max_future_s: float = 0.0,
                 reserve_s: float = 60.0, save_interval_s: float = 60.0,
                 wall: Callable[[], float] = time.time,
                 mono: Callable[[], float] = time.monotonic) -> None:
        self.key = key
        self.path = Path(path)
        self.reserve = int(reserve_s * TIMESTAMP_UNITS_PER_S)
        self.save_interval_s = save_interval_s
        self.wall = wall
        self.mono = mono
        self.saves = 0
        self.save_errors = 0
        self.message = ""
        """What the timestamp file held at start (one line, for the log and the health events)."""
        streams, self.tx_reserved, self.message = self._load()
        """No outgoing timestamp above ``tx_reserved`` has been used (this run or before)."""
        self.tx_last = self.tx_reserved
        """The last timestamp sent; after a restart, the persisted reservation."""
        high = max([self.tx_reserved - self.reserve, *streams.values()], default=0)
        self.verifier = SignatureVerifier(key, streams=streams, high=high,
                                          max_future_s=max_future_s, wall=wall,
                                          on_accept=self._on_accept)
        self._dirty = False
        self._next_save = mono() + save_interval_s
        self._pool: concurrent.futures.ThreadPoolExecutor | None = None
        self._saving: concurrent.futures.Future[bool] | None = None

    # ------------------------------------------------------------------ outgoing

    def next_tx(self, current: int = 0) -> int:
        """The timestamp for the next outgoing frame: above ``current`` (the signer's own
        counter), every timestamp sent before (this run or persisted) and the local
        timestamp; a new reservation is saved first when it would pass the old one."""
        t = max(current, self.tx_last + 1, self.verifier.local_timestamp())
        if t > self.tx_reserved:
            if self._saving is not None:
                self._saving.result()  # a renewal under way: it may cover t
            if t > self.tx_reserved:  # the first frame without reserve(), or a stalled disk
                self.tx_reserved = t + self.reserve
                self.save()
        elif t > self.tx_reserved - self.reserve // 2:
            self.save_async(t + self.reserve)  # renewed in the background, well ahead
        self.tx_last = t
        if t > self.verifier.high:
            self.verifier.high = t
        return t

    # ------------------------------------------------------------------ incoming

    def _on_accept(self) -> None:
        self._dirty = True
        if self.mono() >= self._next_save:
            self._next_save = self.mono() + self.save_interval_s
            self.save_async()

    def reserve_now(self) -> None:
        """Save a reservation from the local timestamp now (blocking: call it off the event
        loop at start), so that the frames that follow need no save before they leave."""
        t = max(self.tx_last + 1, self.verifier.local_timestamp())
        if t + self.reserve // 2 > self.tx_reserved:
            self.tx_reserved = t + self.reserve
            self.save()

    def save_async(self, tx_reserved: int | None = None) -> None:
        """Save in a worker thread (no fsync on the caller's thread), the reservation
        raised to ``tx_reserved`` once it is on disk; nothing when a save is under way."""
        if self._saving is not None and not self._saving.done():
            return
        if self._pool is None:
            self._pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="signing")
        doc = self._doc(max(self.tx_reserved, tx_reserved or 0))
        self._dirty = False
        self._saving = self._pool.submit(self._write, doc)

    # ------------------------------------------------------------------ file

    def _load(self) -> tuple[dict[StreamKey, int], int, str]:
        p = self.path
        if not p.exists():
            return {}, 0, f"no signing timestamps at {p}: starting from the wall clock"
        try:
            doc = json.loads(p.read_bytes())
            if doc.get("format") != STATE_FORMAT or doc.get("version") != STATE_VERSION:
                raise ValueError("not an onboard signing-timestamp file")
            tx = int(doc["tx_reserved"])
            streams = {(int(a), int(b), int(c)): int(ts) for a, b, c, ts in doc["streams"]}
        except (OSError, ValueError, TypeError, KeyError, AttributeError) as err:
            return {}, 0, (f"signing timestamps {p} unusable ({type(err).__name__}: "
                           f"{str(err)[:80]}): starting from the wall clock")
        return streams, tx, (f"signing timestamps restored from {p} "
                             f"({len(streams)} incoming streams)")

    def save(self) -> bool:
        """Write the timestamps atomically (mode 0600); False (counted, logged) on a disk
        error: signing goes on, only the restart guarantee is weakened."""
        doc = self._doc(self.tx_reserved)
        self._dirty = False
        if not self._write(doc):
            self._dirty = True
            return False
        return True

    def _doc(self, tx_reserved: int) -> dict:
        return {"format": STATE_FORMAT, "version": STATE_VERSION, "tx_reserved": tx_reserved,
                "streams": [[*k, v] for k, v in sorted(self.verifier.streams.items())]}

    def _write(self, doc: dict) -> bool:
        data = json.dumps(doc, separators=(",", ":")).encode()
        d = self.path.parent
        tmp = d / f".{self.path.name}.tmp-{os.getpid()}"
        try:
            d.mkdir(parents=True, exist_ok=True)
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            try:
                os.write(fd, data)
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(tmp, self.path)
        except OSError as err:
            self.save_errors += 1
            log.warning("cannot save signing timestamps to %s: %s", self.path, err.strerror)
            return False
        self.saves += 1
        self._next_save = self.mono() + self.save_interval_s
        if doc["tx_reserved"] > self.tx_reserved:
            self.tx_reserved = doc["tx_reserved"]
        return True

    def close(self) -> None:
        """Wait for a background save; save the incoming stream timestamps if they changed
        since the last save."""
        if self._saving is not None:
            self._saving.result()
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
        if self._dirty:
            self.save()


def open_signing(cfg: MavlinkOut, resolve: Callable[[str], Path] = Path) -> SigningState | None:
    """The service's signing state from ``[service.mavlink]`` (None: no key file).

    ``resolve`` turns the configured ``signing_state_file`` into a path (the service
    resolves it against its state directory). Raises ConfigError as :func:`check_signing`.
    """
    key = check_signing(cfg)
    if key is None:
        return None
    st = SigningState(key, resolve(cfg.signing_state_file), max_future_s=cfg.signing_max_future_s)
    log.info("%s", st.message)
    return st


__all__ = ["SigningState", "check_signing", "load_signing_key", "open_signing",
           "signing_timestamp"]
