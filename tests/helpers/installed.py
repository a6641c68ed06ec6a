"""This checkout installed as a user installs it, for the tests of the wheel, ``make install``
and the systemd unit.

The wheel is built as ``make install`` builds it (:func:`onboard.apps.install.build_wheel`),
offline: ``--no-build-isolation``, with this venv's setuptools. It goes into a fresh venv
(:func:`fresh_venv`) that sees no checkout: its only other packages are this test venv's
third-party distributions, through a folder of links (:func:`dependency_view`) named in a
``.pth`` file, so pip resolves the wheel's dependencies against them with ``--no-index``
and nothing is downloaded. This package's own editable install (its finder and metadata)
is left out of the view: ``import onboard`` can only find the installed wheel.
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
from pathlib import Path

from tests.helpers.imports import REPO

PURELIB = Path(sysconfig.get_paths()["purelib"])
"""This test venv's site-packages: the dependencies an installed wheel is given."""
OWN_ENTRIES = ("onboard-", "__editable__")
"""Entries of site-packages that belong to this package's editable install (by prefix)."""
DEPS_PTH = "onboard-test-deps.pth"
"""The ``.pth`` file of a fresh venv that names its dependency folder."""
OFFLINE_BUILD = ["--no-build-isolation"]
"""pip arguments that build the wheel with this venv's setuptools (no download)."""


def build_wheel(out: Path, source: Path = REPO) -> Path:
    """The wheel of ``source`` (default: this checkout), built offline into ``out`` the way
    ``make install`` builds it."""
    from onboard.apps.install import build_wheel as build

    return build(source, out, sys.executable, OFFLINE_BUILD)


def dependency_view(dest: Path) -> Path:
    """``dest``, a folder of links to every entry of this venv's site-packages but this
    package's own."""
    dest.mkdir(parents=True)
    for entry in PURELIB.iterdir():
        if not entry.name.startswith(OWN_ENTRIES):
            (dest / entry.name).symlink_to(entry)
    return dest


def site_packages(venv: Path) -> Path:
    """The site-packages folder of ``venv``."""
    return next((venv / "lib").glob("python3*/site-packages"))


def fresh_venv(venv: Path, deps: Path) -> Path:
    """A venv at ``venv`` made from the base Python (no pip of its own), whose other
    packages are those of the folder ``deps`` (pip among them); returns its python."""
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True,
                   timeout=120)
    set_dependencies(venv, deps)
    return venv / "bin" / "python"


def set_dependencies(venv: Path, deps: Path | str) -> None:
    """Make ``venv`` see the packages of the folder ``deps`` (its ``.pth`` file)."""
    (site_packages(venv) / DEPS_PTH).write_text(f"{deps}\n")


def clean_env() -> dict[str, str]:
    """This process's environment without PYTHONPATH (which could point at the checkout)."""
    return {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}


def run_installed(venv: Path, *args: str, cwd: Path,
                  timeout: float = 300.0) -> subprocess.CompletedProcess[str]:
    """``onboard ARGS`` of the venv, from ``cwd``."""
    return subprocess.run([str(venv / "bin" / "onboard"), *args], cwd=cwd, env=clean_env(),
                          capture_output=True, text=True, timeout=timeout)
