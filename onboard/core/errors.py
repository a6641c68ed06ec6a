"""Exceptions shared by the command-line tools, and SIGTERM taken as Ctrl-C."""

from __future__ import annotations

import signal
import threading
from typing import Any


class UsageError(Exception):
    """Bad usage or unreadable input: the CLI prints one line and exits with status 2."""


class OutputFailed(Exception):
    """An output could not be written once the work had begun (a full disk, a directory
    removed meanwhile; every path was checked before, :mod:`onboard.core.outputs`): the
    CLI prints one line naming it and exits with status 1."""


class SigtermAsInterrupt:
    """While it lasts, SIGTERM (what systemd, docker and a parent's ``terminate`` send to
    stop a process) raises :class:`KeyboardInterrupt` in the main thread, as Ctrl-C does,
    so that a command's ``finally`` blocks finish its files and stop its children; in
    another thread it does nothing. :meth:`restore` puts the previous handler back."""

    def __init__(self) -> None:
        self._previous: Any = None
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGTERM, signal.default_int_handler)

    def restore(self) -> None:
        """The previous SIGTERM handler back (once)."""
        if self._previous is not None:
            signal.signal(signal.SIGTERM, self._previous)
            self._previous = None
