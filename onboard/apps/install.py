"""``make install``: the service on a vehicle computer, from the wheel of this source tree.

Run by the Makefile with the system Python (standard library only, nothing of ours
installed yet)::

    sudo make install                         # PREFIX=/opt/onboard SYSCONFDIR=/etc/onboard
    make install DESTDIR=/tmp/stage           # staged, for a package
    make install PREFIX=$HOME/o SYSCONFDIR=$HOME/o/etc UNITDIR=$HOME/o/unit CREDSTORE=$HOME/o/cred
    make install WHEEL=dist/onboard-0.1.0-py3-none-any.whl   # a wheel built elsewhere

What goes where (each path under ``DESTDIR`` when given):

==========================================  ==========================================
``PREFIX/venv``                             a virtual environment with this package:
                                            its wheel (built from SOURCE by the venv's
                                            pip, or ``WHEEL``) installed, as any user
                                            installs it, bundled configs and gains
                                            inside; the unit runs
                                            ``PREFIX/venv/bin/python -m onboard``; with
                                            ``DESTDIR`` its scripts (``bin/onboard``,
                                            ``bin/pip``, ``activate``) name
                                            ``PREFIX/venv``, not the staged path
``SYSCONFDIR/onboard.toml``                 config/deploy-example.toml, only if absent
``SYSCONFDIR/onboard.env``                  systemd/onboard.env.example, only if absent
``SYSCONFDIR/zenoh-vehicle.json5``          config/zenoh/vehicle-boat1.json5 (no secret),
                                            only if absent
``PREFIX/doc/``                             docs/service.md and docs/security.md, which
                                            the unit's ``Documentation=`` names (``systemctl
                                            help onboard``); always replaced
``UNITDIR/onboard.service``                 systemd/onboard.service with PREFIX and
                                            SYSCONFDIR put in; always replaced
``CREDSTORE/``                              created mode 0700 if absent: the secrets go
                                            there (LoadCredential=, docs/security.md)
==========================================  ==========================================

A configuration already in place is never overwritten (the new example is written beside
it as ``*.dist``); the package in the venv always is (the same version too), its
dependencies are installed where missing. The state and log directories are not created
here: systemd creates them at the first start (``StateDirectory=``, ``LogsDirectory=``),
owned by the unit's dynamic user. Without ``DESTDIR``, and where ``systemd-analyze``
exists, the installed unit is checked with ``systemd-analyze verify``; a failure fails the
install.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

SOURCE = Path(__file__).resolve().parents[2]
"""The source tree this module belongs to."""
UNIT_PREFIX = "/opt/onboard"
UNIT_SYSCONFDIR = "/etc/onboard"
"""The paths written in systemd/onboard.service, replaced by the ones installed to."""
DOCS = ("service.md", "security.md")
"""The pages of docs/ installed into ``PREFIX/doc/``: the service's and its hardening's,
the unit's ``Documentation=``."""


def _stage(destdir: str, path: str) -> Path:
    """``path`` under ``destdir`` (both absolute paths)."""
    return Path(destdir + path) if destdir else Path(path)


def _say(text: str) -> None:
    print(f"install: {text}", flush=True)


def install_file(src: Path, dst: Path, mode: int, *, keep: bool, text: str | None = None) -> str:
    """Copy ``src`` (or write ``text``) to ``dst`` with ``mode``; with ``keep`` an
    existing ``dst`` stays and the new one goes to ``dst.dist``. Returns what was done."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    data = text.encode() if text is not None else src.read_bytes()
    target = dst
    if keep and dst.exists():
        if dst.read_bytes() == data:
            return f"{dst} unchanged"
        target = dst.with_name(dst.name + ".dist")
    tmp = target.with_name(f".{target.name}.tmp")
    tmp.write_bytes(data)
    tmp.chmod(mode)
    os.replace(tmp, target)
    return f"{dst} kept, new version in {target}" if target != dst else f"{dst} written"


def unit_text(prefix: str, sysconfdir: str) -> str:
    """systemd/onboard.service for an install at ``prefix`` and ``sysconfdir``."""
    text = (SOURCE / "systemd" / "onboard.service").read_text()
    return text.replace(UNIT_PREFIX + "/", prefix.rstrip("/") + "/").replace(
        UNIT_SYSCONFDIR + "/", sysconfdir.rstrip("/") + "/")


SOURCE_NEEDS = ("systemd/onboard.service", "systemd/onboard.env.example",
                "config/deploy-example.toml", "config/zenoh/vehicle-boat1.json5",
                "docs/service.md", "docs/security.md")
"""What the install takes from the source tree besides the wheel."""
PACKAGE_FILES = ("pyproject.toml", "setup.py", "README.md", "onboard", "drivers", "sitl", "config")
"""What the wheel is built from (pyproject.toml maps drivers/, sitl/ and config/ into it)."""
WHEEL_GLOB = "onboard-*.whl"
"""The file name of this package's wheel (``onboard-VERSION-py3-none-any.whl``)."""


def copy_package(source: Path, dest: Path) -> None:
    """:data:`PACKAGE_FILES` of ``source`` copied into the new folder ``dest``, without
    compiled files."""
    dest.mkdir()
    for name in PACKAGE_FILES:
        if (source / name).is_dir():
            shutil.copytree(source / name, dest / name,
                            ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.so"))
        else:
            shutil.copy2(source / name, dest / name)


def build_wheel(source: Path, out: Path, python: str, pip_args: list[str]) -> Path:
    """The wheel of the package in ``source``, built by ``python -m pip wheel --no-deps``
    (with ``pip_args``) from a copy of :data:`PACKAGE_FILES` in a temporary directory, so
    the build leaves nothing in the source tree; returned as its path in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="onboard-build-") as tmp:
        src, dist = Path(tmp) / "src", Path(tmp) / "dist"
        copy_package(source, src)
        subprocess.run([python, "-m", "pip", "wheel", "--quiet", "--disable-pip-version-check",
                        "--no-deps", "--wheel-dir", str(dist), *pip_args, str(src)], check=True)
        (built,) = dist.glob(WHEEL_GLOB)
        return Path(shutil.move(built, out / built.name))


def make_venv(venv: Path, python: str, pip_args: list[str], wheel: Path | None) -> None:
    """Create (or update) ``venv`` and install ``wheel`` into it (None: the wheel of
    :data:`SOURCE`, built by the venv's pip). The package is always replaced, the same
    version too; its dependencies are installed where missing."""
    if not (venv / "bin" / "python").exists():
        subprocess.run([python, "-m", "venv", str(venv)], check=True)
        _say(f"{venv} created")
    vpy = str(venv / "bin" / "python")
    with tempfile.TemporaryDirectory(prefix="onboard-wheel-") as tmp:
        if wheel is None:
            wheel = build_wheel(SOURCE, Path(tmp), vpy, pip_args)
            _say(f"{wheel.name} built from {SOURCE}")
        pip = [vpy, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", *pip_args]
        subprocess.run([*pip, str(wheel)], check=True)
        subprocess.run([*pip, "--force-reinstall", "--no-deps", str(wheel)], check=True)
        _say(f"{wheel.name} installed into {venv}")


def relocate_venv(venv: Path, final: str) -> list[Path]:
    """Point a venv made at ``venv`` (under ``DESTDIR``) to where it will run, ``final``:
    the first lines of its ``bin/`` scripts (``#!VENV/bin/python``), ``activate``'s
    ``VIRTUAL_ENV`` and ``pyvenv.cfg`` name ``final`` instead of ``venv``. Symbolic links
    are left alone. Returns the files changed."""
    old, new = str(venv).encode(), final.rstrip("/").encode()
    changed = []
    for path in [*sorted((venv / "bin").iterdir()), venv / "pyvenv.cfg"]:
        if path.is_symlink() or not path.is_file():
            continue
        data = path.read_bytes()
        if old in data:
            mode = path.stat().st_mode & 0o7777
            tmp = path.with_name(f".{path.name}.tmp")
            tmp.write_bytes(data.replace(old, new))
            tmp.chmod(mode)
            os.replace(tmp, path)
            changed.append(path)
    return changed


def verify_unit(unit: Path) -> str | None:
    """``systemd-analyze verify`` of ``unit`` (None: passed, or no systemd-analyze here);
    else its complaint."""
    exe = shutil.which("systemd-analyze")
    if exe is None:
        return None
    r = subprocess.run([exe, "verify", str(unit)], capture_output=True, text=True, timeout=120)
    complaint = (r.stderr + r.stdout).strip()
    return complaint if r.returncode != 0 or complaint else None


def main(argv: list[str] | None = None) -> int:
    """Install (see the module docstring); 0 on success, 1 when the unit does not verify."""
    ap = argparse.ArgumentParser(prog="make install", description=__doc__.split("\n")[0])
    ap.add_argument("--destdir", default="")
    ap.add_argument("--prefix", default="/opt/onboard")
    ap.add_argument("--sysconfdir", default="/etc/onboard")
    ap.add_argument("--unitdir", default="/etc/systemd/system")
    ap.add_argument("--credstore", default="/etc/credstore")
    ap.add_argument("--python", default=sys.executable, help="the Python that makes the venv")
    ap.add_argument("--pip-args", default="", help="extra pip arguments (a wheelhouse ...)")
    ap.add_argument("--wheel", default="", help="install this wheel (default: build one)")
    ap.add_argument("--no-venv", action="store_true", help="install files only")
    a = ap.parse_args(argv)
    for name in ("prefix", "sysconfdir", "unitdir", "credstore"):
        if not os.path.isabs(getattr(a, name)):
            ap.error(f"--{name} must be an absolute path")
    missing = [p for p in SOURCE_NEEDS if not (SOURCE / p).exists()]
    if missing:
        ap.error(f"installs from the source tree, and {SOURCE} is not one (no "
                 f"{', '.join(missing)}): run 'sudo make install' in a clone of the "
                 "repository (docs/service.md, Install)")
    d = a.destdir
    if not a.no_venv:
        venv = _stage(d, a.prefix) / "venv"
        make_venv(venv, a.python, a.pip_args.split(),
                  Path(a.wheel).resolve() if a.wheel else None)
        if d:
            final = a.prefix.rstrip("/") + "/venv"
            relocate_venv(venv, final)
            _say(f"{venv}: its scripts name {final}, where it runs once installed")
    etc = _stage(d, a.sysconfdir)
    for src, name in ((SOURCE / "config" / "deploy-example.toml", "onboard.toml"),
                      (SOURCE / "systemd" / "onboard.env.example", "onboard.env"),
                      (SOURCE / "config" / "zenoh" / "vehicle-boat1.json5", "zenoh-vehicle.json5")):
        text = src.read_text().replace(UNIT_SYSCONFDIR + "/", a.sysconfdir.rstrip("/") + "/")
        _say(install_file(src, etc / name, 0o644, keep=True, text=text))
    doc = _stage(d, a.prefix) / "doc"
    for name in DOCS:
        _say(install_file(SOURCE / "docs" / name, doc / name, 0o644, keep=False))
    unit = _stage(d, a.unitdir) / "onboard.service"
    _say(install_file(unit, unit, 0o644, keep=False, text=unit_text(a.prefix, a.sysconfdir)))
    cred = _stage(d, a.credstore)
    if not cred.exists():
        cred.mkdir(parents=True, mode=0o700)
        cred.chmod(0o700)
        _say(f"{cred} created (mode 0700): put the secrets there, chmod 600")
    if not d:
        complaint = verify_unit(unit)
        if complaint:
            print(f"install: systemd-analyze verify {unit}:\n{complaint}", file=sys.stderr)
            return 1
    _say("done. Next: the secrets in the credential store (docs/security.md), then "
         "systemctl daemon-reload && systemctl enable --now onboard")
    return 0


if __name__ == "__main__":
    sys.exit(main())
