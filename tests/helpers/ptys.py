"""Pseudo-terminals standing in for serial devices in the transport tests."""

from __future__ import annotations

import os
import tty


def pty_behind(link: str) -> int:
    """A new raw pseudo-terminal with ``link`` (a ``/dev/serial/by-id``-style symlink)
    re-pointed at it atomically, as udev does when a device (re)appears; returns the
    master descriptor, which the caller closes."""
    master, slave = os.openpty()
    tty.setraw(master)
    name = os.ttyname(slave)
    os.close(slave)
    tmp = link + ".new"
    os.symlink(name, tmp)
    os.replace(tmp, link)
    return master
