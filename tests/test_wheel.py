"""The wheel, installed as a vehicle installs it: built (as ``make install`` builds it), put
into a fresh venv outside the checkout (not editable), and run from a directory outside it.

What only an installed wheel can show: the bundled configs that autodetection and
``--config NAME`` load, and the high-gain observer's designed gains, are inside the
package (read with importlib.resources), so the replay of a log gives the checkout's
estimates to the byte. The wheel carries neither the docs machinery (``validation/``) nor
the tests. A wheel built without the bundled data cannot replay a log whose config it
detects (the negative control). tests/helpers/installed.py says how the venv gets its dependencies
offline.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

import onboard.pipelines.current as current
from onboard.apps.install import PACKAGE_FILES, make_venv
from onboard.cli import main as cli_main
from tests.helpers.imports import REPO
from tests.helpers.installed import (
    build_wheel,
    clean_env,
    dependency_view,
    fresh_venv,
    run_installed,
)

pytestmark = pytest.mark.integration

REPLAY = REPO / "tests" / "data" / "replay"
NO_BUNDLED_DATA = '"onboard.bundled" = ["*.toml", "gains/*.json"]\n'
"""The package-data line of pyproject.toml without which the wheel holds no configs."""
HGO_OVERLAY = '[pipelines.current]\nobserver = "hgo"\n'
"""A user's overlay: the current from the high-gain observer, at the bundled designed gain."""


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    """A directory outside the checkout (the tests run from it)."""
    path = tmp_path_factory.mktemp("wheel")
    assert not path.resolve().is_relative_to(REPO)
    return path


@pytest.fixture(scope="module")
def wheel(work) -> Path:
    return build_wheel(work / "dist")


@pytest.fixture(scope="module")
def deps(work) -> Path:
    return dependency_view(work / "deps")


def _install(wheel: Path, venv: Path, deps: Path) -> Path:
    """``wheel`` installed into a fresh ``venv`` as make install does, offline."""
    fresh_venv(venv, deps)
    make_venv(venv, sys.executable, ["--no-index"], wheel)
    return venv


@pytest.fixture(scope="module")
def venv(wheel, deps, work) -> Path:
    return _install(wheel, work / "venv", deps)


def _replay_installed(venv: Path, log: Path, out: Path, *config: str) -> str:
    """``onboard replay`` of the installed wheel from ``out``'s parent; its estimates."""
    args = [a for c in config for a in ("--config", c)]
    r = run_installed(venv, "replay", str(log), "--out", out.name, "--no-plot", *args,
                      cwd=out.parent)
    assert r.returncode == 0, r.stderr
    return (out / "estimates.csv").read_text()


def _replay_checkout(log: Path, out: Path, *config: str) -> str:
    """The same replay by the checkout (this test venv's editable install)."""
    args = [a for c in config for a in ("--config", c)]
    assert cli_main(["replay", str(log), "--out", str(out), "--no-plot", *args]) == 0
    return (out / "estimates.csv").read_text()


def test_the_wheel_holds_the_bundled_data_and_neither_the_docs_machinery_nor_the_tests(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    configs = {f"onboard/bundled/{p.name}" for p in (REPO / "config").glob("*.toml")}
    gains = {f"onboard/bundled/gains/{p.name}" for p in (REPO / "config" / "gains").glob("*.json")}
    static = {f"onboard/service/web/static/{p.name}"
              for p in (REPO / "onboard" / "service" / "web" / "static").iterdir()}
    assert configs and gains and static and static <= names
    # exactly these: the Zenoh and mavlink-router examples (with their example passwords)
    # stay in the repository
    bundled = {n for n in names if n.startswith("onboard/bundled/")}
    assert bundled == configs | gains | {"onboard/bundled/__init__.py"}, bundled
    tops = {n.split("/")[0] for n in names}
    assert tops == {"onboard", wheel.name.split("-py3")[0] + ".dist-info"}, tops
    assert not [n for n in names if re.search(r"(^|/)(validation|tests?)(/|$)", n)]


def test_the_installed_package_is_the_wheel_and_reads_its_data_from_itself(venv, work):
    probe = ("import sys, onboard; from onboard.core.config import CONFIG_DIR, bundled; "
             "from onboard.pipelines.current import GAIN_DIR; "
             "from onboard.service.web.app import static_file; "
             "assert b'<title>onboard</title>' in static_file('index.html'); "
             "print(onboard.__file__); print(CONFIG_DIR); print(GAIN_DIR); "
             "print(' '.join(bundled())); print(' '.join(sys.path))")
    r = subprocess.run([str(venv / "bin" / "python"), "-c", probe], cwd=work, env=clean_env(),
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    package, config_dir, gain_dir, names, path = r.stdout.splitlines()
    site = str(venv.resolve() / "lib")
    assert package.startswith(site) and config_dir.startswith(site), r.stdout
    assert Path(gain_dir) == Path(config_dir) / "gains"
    assert (Path(gain_dir) / "torpedo-auv.json").is_file()
    assert names.split() == sorted(p.stem for p in (REPO / "config").glob("*.toml"))
    assert str(REPO) not in path.split(), path


@pytest.mark.parametrize("case", ["jaiabot-turns", "bluerov2-circle", "gavia-tidal"])
def test_the_installed_wheel_replays_a_log_by_autodetection_as_the_checkout(venv, work, case,
                                                                          monkeypatch):
    # both on the ESESO's numpy reference: its numba kernels would compile afresh in the
    # fresh venv (~8 s of CPU); they are tested against it in tests/test_eseso_kernel.py
    monkeypatch.setenv("ONBOARD_ESESO_KERNEL", "0")
    log = REPLAY / f"{case}.tlog"
    got = _replay_installed(venv, log, work / f"auto-{case}")
    assert got == _replay_checkout(log, work / f"auto-{case}-checkout")


def test_a_named_bundled_config_and_its_designed_gain_work_from_the_installed_wheel(
        venv, work, monkeypatch):
    """``--config torpedo-auv`` (a bundled name) and a user's overlay given as a relative
    file path, which selects the high-gain observer: its designed gain is the bundled
    config/gains/torpedo-auv.json, read from the installed package. Without that file the
    observer falls back to its analytic gain and the current differs (the control)."""
    (work / "hgo.toml").write_text(HGO_OVERLAY)
    log = REPLAY / "gavia-tidal.tlog"
    got = _replay_installed(venv, log, work / "named", "torpedo-auv", "hgo.toml")
    monkeypatch.chdir(work)
    want = _replay_checkout(log, work / "named-checkout", "torpedo-auv", "hgo.toml")
    assert got == want
    monkeypatch.setattr(current, "GAIN_DIR", work / "no-gains")
    analytic = _replay_checkout(log, work / "named-analytic", "torpedo-auv", "hgo.toml")
    assert analytic != want


def test_a_wheel_without_the_bundled_data_cannot_load_the_config_it_detects(deps, work):
    """The negative control: a wheel built from this tree without the bundled data's
    package-data line exits 2 naming the config it detected and no bundled one."""
    src = work / "src-without-data"
    src.mkdir()
    for name in PACKAGE_FILES:
        copy = shutil.copytree if (REPO / name).is_dir() else shutil.copy2
        copy(REPO / name, src / name)
    pyproject = (REPO / "pyproject.toml").read_text()
    assert NO_BUNDLED_DATA in pyproject
    (src / "pyproject.toml").write_text(pyproject.replace(NO_BUNDLED_DATA, ""))
    bare = _install(build_wheel(work / "dist-without-data", src), work / "venv-bare", deps)
    r = run_installed(bare, "replay", str(REPLAY / "jaiabot-turns.tlog"), "--no-plot",
                      "--out", "out", cwd=work)
    assert r.returncode == 2
    assert "rudder-boat: no such config file (bundled: )" in r.stderr, r.stderr
