"""Waiting on a condition instead of sleeping a fixed time (robust on a loaded machine)."""

from __future__ import annotations

import time
from collections.abc import Callable


def wait_until(cond: Callable[[], object], timeout: float, poll_s: float = 0.05) -> bool:
    """Poll ``cond`` every ``poll_s`` seconds until it is truthy or ``timeout`` seconds have
    passed; return its last value's truth (checked once more at the deadline)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(poll_s)
    return bool(cond())
