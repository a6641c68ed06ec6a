"""A real systemd as PID 1, booted in private PID and mount namespaces over a copy-on-write
view of this machine's root file system, for tests of the installed unit.

``booted_systemd(stage)`` mounts an overlay whose lower layer is ``/`` and whose upper
layer is a tmpfs, copies the staged install tree ``stage`` (``etc/``, ``opt/`` ... as
``make install DESTDIR=stage`` lays it out) into it, binds the directories it is given
read-only at the paths it is given (a fresh tmpfs covers ``/tmp`` in there, and a unit
has its own private ``/tmp`` anyway: what lies in the host's ``/tmp`` is seen only through
such a bind), chroots and execs ``/lib/systemd/systemd --system`` into an empty target.
Nothing it writes (the unit's state directory, tmpfiles, the journal) reaches the real
file system, and killing PID 1 of the namespace ends every process in it. The network is
shared with the test, so a service in there reaches a router or a simulator the test runs
on loopback.

Needs root, util-linux (``unshare``, ``nsenter``), the overlay file system and systemd;
the test is skipped with the Debian install line otherwise.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest

SYSTEMD = Path("/lib/systemd/systemd")
INSTALL_LINE = "sudo apt-get install systemd util-linux"

# Runs inside `unshare --mount --pid --fork`: $1 an empty scratch directory, $2 the staged
# tree, then directories the unit's dynamic user must be able to traverse (the Python the
# staged venv is made from; /root is 0700 on many machines), then "--", then pairs of a
# host directory and the path where the booted system sees it (read-only).
BOOT_SCRIPT = r"""
set -eu
scratch=$1; stage=$2; shift 2
mount --make-rprivate /
mount -t tmpfs onboard-test "$scratch"
mkdir "$scratch/upper" "$scratch/work" "$scratch/root"
mount -t overlay overlay -o "lowerdir=/,upperdir=$scratch/upper,workdir=$scratch/work" "$scratch/root"
r=$scratch/root
mount -t proc proc "$r/proc"
mount --rbind /sys "$r/sys"
mount --rbind /dev "$r/dev"
mount -t tmpfs tmpfs "$r/run"
mount -t tmpfs tmpfs "$r/tmp"
cp -a "$stage/." "$r/"
while [ $# -gt 0 ] && [ "$1" != -- ]; do
  d=$1; shift
  while [ "$d" != / ]; do chmod o+x "$r$d"; d=$(dirname "$d"); done
done
if [ $# -gt 0 ]; then shift; fi
while [ $# -gt 1 ]; do
  mkdir -p "$r$2"
  mount --bind "$1" "$r$2"
  mount -o remount,bind,ro "$r$2"
  shift 2
done
mkdir -p "$r/run/systemd/system"
printf '[Unit]\nDescription=an empty boot target for tests\n' > "$r/run/systemd/system/onboard-test.target"
mount --make-rshared "$r"
exec chroot "$r" /lib/systemd/systemd --system --unit=onboard-test.target
"""


def skip_unless_available() -> None:
    """Skip the calling test when this machine cannot boot a systemd in a namespace."""
    if sys.platform != "linux" or os.geteuid() != 0:
        pytest.skip("booting systemd in a namespace needs root on Linux")
    missing = [t for t in ("unshare", "nsenter", "chroot") if shutil.which(t) is None]
    if missing or not SYSTEMD.exists():
        pytest.skip(f"{', '.join(missing) or SYSTEMD} not found (Debian: {INSTALL_LINE})")
    if "overlay" not in Path("/proc/filesystems").read_text():
        pytest.skip("the kernel has no overlay file system")


@dataclass
class BootedSystemd:
    """A running systemd: ``pid`` is its PID on the host, ``root`` its root directory as
    the host sees it (``/proc/PID/root``)."""

    pid: int

    @property
    def root(self) -> Path:
        """The booted system's ``/`` seen from the host."""
        return Path(f"/proc/{self.pid}/root")

    def run(self, *argv: str, timeout: float = 30.0) -> subprocess.CompletedProcess[str]:
        """Run ``argv`` inside the booted system (its mounts, PIDs and root)."""
        return subprocess.run(["nsenter", "-t", str(self.pid), "-m", "-p", "-r", "-w", *argv],
                              capture_output=True, text=True, timeout=timeout)

    def show(self, unit: str, *props: str) -> dict[str, str]:
        """``systemctl show UNIT -p ...`` as a dict."""
        out = self.run("systemctl", "show", unit, *(f"--property={p}" for p in props)).stdout
        return dict(line.split("=", 1) for line in out.splitlines() if "=" in line)

    def journal(self, unit: str) -> str:
        """The unit's journal (for assertion messages)."""
        return self.run("journalctl", "--no-pager", "-o", "cat", "-u", unit).stdout

    def wait_for(self, unit: str, timeout: float, **want: str) -> dict[str, str]:
        """Wait until every ``want`` property of ``unit`` has its value; return the last
        properties read (the caller asserts on them)."""
        deadline = time.monotonic() + timeout
        while True:
            props = self.show(unit, *want, "ActiveState", "SubState", "Result")
            if all(props.get(k) == v for k, v in want.items()) or time.monotonic() > deadline:
                return props
            time.sleep(0.2)


def _child_of(pid: int, timeout: float = 10.0) -> int:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
        if children:
            return int(children[0])
        time.sleep(0.05)
    raise RuntimeError("unshare started no child")


@contextmanager
def booted_systemd(stage: Path, scratch: Path, readable: list[Path],
                   binds: Sequence[tuple[Path, str]] = ()) -> Iterator[BootedSystemd]:
    """Boot systemd over ``/`` + ``stage`` (see the module docstring); ``scratch`` is an
    empty directory for the overlay's mounts; every directory above each of ``readable``
    is made traversable inside the overlay; each ``(directory, path)`` of ``binds`` is
    seen read-only at ``path`` in there. Yields once ``systemctl`` answers."""
    skip_unless_available()
    pairs = [str(x) for src, dst in binds for x in (src, dst)]
    proc = subprocess.Popen(["unshare", "--mount", "--pid", "--fork", "--propagation", "private",
                             "sh", "-c", BOOT_SCRIPT, "boot", str(scratch), str(stage),
                             *(str(p) for p in readable), "--", *pairs],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    booted = None
    try:
        booted = BootedSystemd(_child_of(proc.pid))
        deadline = time.monotonic() + 30.0
        while True:
            state = booted.run("systemctl", "is-system-running").stdout.strip()
            if state in ("running", "degraded", "starting", "initializing"):
                break
            if proc.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"systemd did not come up ({state!r}): {proc.stdout.read() if proc.stdout else ''}")
            time.sleep(0.1)
        yield booted
    finally:
        if booted is not None:
            try:
                os.kill(booted.pid, 9)  # PID 1 of the namespace: the kernel ends all of it
            except ProcessLookupError:
                pass
        proc.kill()
        proc.wait(timeout=30)
