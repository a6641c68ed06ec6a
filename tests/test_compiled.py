"""The compiled build (setup.py, ``ONBOARD_COMPILE=1``): the modules of a replay's hot path
compiled by mypyc from the same Python, installed from their wheel into a fresh venv, give
the pure build's estimates to the byte.

The wheel is built as ``make install`` builds it, offline with this venv's mypyc
(tests/helpers/installed.py), with gcc at ``-O0`` (the C is mypyc's either way; gcc
keeps IEEE arithmetic at every level); the release build, ``-O3``, replays a log in the
slow suite. What is checked: every module of setup.py's list is an
extension module in the installed package (and none of the others is), and a replay of a
boat, an ROV and an AUV log, of the boat's with a GNSS latency correction (whose forks
copy the compiled objects) and of a real log writes the checkout's estimates.csv and
summary.json (but its wall time). The ESESO runs its numpy reference on both sides (its
numba kernels would compile afresh in the fresh venv; tests/test_eseso_kernel.py holds
them to it).
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

from onboard.cli import main as cli_main
from tests.helpers.imports import REPO
from tests.helpers.installed import clean_env, dependency_view, run_installed, site_packages

pytestmark = pytest.mark.integration

mypyc = pytest.importorskip(
    "mypyc", reason="the compiled build needs mypyc: .venv/bin/pip install -e '.[test]'")

REPLAY = REPO / "tests" / "data" / "replay"


def setup_constant(name: str) -> object:
    """A module-level constant of setup.py (which builds when imported)."""
    tree = ast.parse((REPO / "setup.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", None) == name:
            return ast.literal_eval(node.value)
    raise KeyError(name)


COMPILED = [p.removesuffix(".py").replace("/", ".")
            for p in [*setup_constant("COMPILED_MODULES"),  # type: ignore[misc]
                      *setup_constant("GENERATED_MODULES")]]


def test_the_test_extra_pins_the_mypyc_that_setup_py_names():
    import tomllib

    extras = tomllib.loads((REPO / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]["test"]
    assert f"mypy=={setup_constant('MYPYC_VERSION')}" in extras


def compiled_venv(work: Path, opt_level: str) -> Path:
    """The compiled wheel, built at gcc's ``-O<opt_level>``, installed into a fresh venv
    outside the checkout."""
    from onboard.apps.install import build_wheel, make_venv
    from tests.helpers.installed import OFFLINE_BUILD, fresh_venv

    mp = pytest.MonkeyPatch()
    mp.setenv("ONBOARD_COMPILE", "1")
    mp.setenv("ONBOARD_COMPILE_OPT", opt_level)
    try:
        wheel = build_wheel(REPO, work / "dist", sys.executable, OFFLINE_BUILD)
    finally:
        mp.undo()
    assert "-py3-none-any" not in wheel.name, wheel.name  # a platform wheel
    venv = work / "venv"
    fresh_venv(venv, dependency_view(work / "deps"))
    make_venv(venv, sys.executable, ["--no-index"], wheel)
    return venv


@pytest.fixture(scope="module")
def venv(tmp_path_factory) -> Path:
    """The compiled build at ``-O0``: mypyc's C as the release wheel has it, compiled in
    half the time (setup.py's ``OPT_LEVEL``; the release build's own test is slow)."""
    return compiled_venv(tmp_path_factory.mktemp("compiled"), "0")


def probe(venv: Path, code: str) -> object:
    """What ``code``, run by the venv's Python outside the checkout, prints as JSON."""
    r = subprocess.run([str(venv / "bin" / "python"), "-c", code], cwd=venv,
                       env=clean_env(), capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def test_the_listed_modules_and_only_they_are_compiled(venv):
    """What ``onboard bench`` reports of the installed package (``compiled_modules``)."""
    package, compiled = probe(venv, (  # type: ignore[misc]
        "import json, onboard; from onboard.apps.bench import compiled_modules; "
        "print(json.dumps([onboard.__file__, compiled_modules()]))"))
    assert package.startswith(str(site_packages(venv).resolve())), package
    assert compiled == sorted(COMPILED)


def _estimates(out: Path) -> tuple[str, dict]:
    summary = json.loads((out / "summary.json").read_text())
    summary.pop("wall_time_s")
    return (out / "estimates.csv").read_text(), summary


@pytest.mark.parametrize("case", ["jaiabot-turns", "bluerov2-circle", "gavia-tidal"])
def test_the_compiled_replay_is_the_pure_one_to_the_byte(venv, tmp_path, case, monkeypatch):
    monkeypatch.setenv("ONBOARD_ESESO_KERNEL", "0")
    log = REPLAY / f"{case}.tlog"
    r = run_installed(venv, "replay", str(log), "--out", "compiled", "--no-plot",
                      cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert cli_main(["replay", str(log), "--out", str(tmp_path / "pure"), "--no-plot"]) == 0
    assert _estimates(tmp_path / "compiled") == _estimates(tmp_path / "pure")


def test_the_gnss_latency_forks_replay_compiled_as_pure(venv, tmp_path):
    """A GNSS latency correction forks every pipeline with ``copy.deepcopy`` at each
    re-stamped fix (onboard/engine/latency.py): the compiled classes copy as the pure ones
    (``mypyc_attr``), and a copy handles its samples itself, not through methods bound to
    the object it was copied from."""
    overlay = tmp_path / "latency.toml"
    overlay.write_text("[corrections]\ngnss_latency_s = 1.0\n")
    log = REPLAY / "jaiabot-turns.tlog"
    r = run_installed(venv, "replay", str(log), "--config", str(overlay), "--out", "compiled",
                      "--no-plot", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert cli_main(["replay", str(log), "--config", str(overlay), "--out",
                     str(tmp_path / "pure"), "--no-plot"]) == 0
    assert _estimates(tmp_path / "compiled") == _estimates(tmp_path / "pure")


def test_a_real_log_replays_compiled_as_pure(venv, tmp_path, shared_data):
    """A real boat's NMEA log (RTK heading, Doppler speed): another reader, the integrity
    checks' warnings on real sensors."""
    log = shared_data / "usv_rtk_gnss_heading_nmea_shenzhen" / "202412051751.txt"
    r = run_installed(venv, "replay", str(log), "--out", "compiled", "--no-plot",
                      cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert cli_main(["replay", str(log), "--out", str(tmp_path / "pure"), "--no-plot"]) == 0
    assert _estimates(tmp_path / "compiled") == _estimates(tmp_path / "pure")


PUBLISHED_FACTORS_FOLLOW_A_COPY = """
import copy, functools, json
from onboard.core.config import from_dict
from onboard.pipelines import aie, current

def owner(factor):
    return factor.args[0] if isinstance(factor, functools.partial) else factor.__self__

cfg = from_dict({"vehicle": {"class": "rudder-boat"}})
cur, boat = current.create(cfg), aie.create(cfg)
cur_fork, boat_fork = copy.deepcopy(cur), copy.deepcopy(boat)
print(json.dumps([owner(cur_fork.noise.published["velocity"]) is cur_fork]
                 + [owner(f) is boat_fork.surge for f in boat_fork.noise.published.values()]))
"""


def test_a_copied_pipeline_publishes_its_own_noise_factor(venv):
    """The factor a published sigma takes (``ChannelNoise.published``) is read from the
    pipeline's own state: in a deep copy (the GNSS latency's forks) from the copy's. A
    method bound to a compiled object is copied as it is, still the original's; the pure
    build rebinds it, so only the compiled build can fail this."""
    assert probe(venv, PUBLISHED_FACTORS_FOLLOW_A_COPY) == [True, True, True]


RCIE_KERNELS_COMPILED_AS_GENERATED = """
import json, random
from onboard.estimators.rcie import (COMPILED_KERNEL_ORDERS, compile_kernel, packed_index,
                                     rcie_kernel, rcie_kernel_lines)

random.seed(7)
out = []
for n in COMPILED_KERNEL_ORDERS:
    for rate in (False, True):
        compiled = rcie_kernel(n, rate)
        python = compile_kernel(rcie_kernel_lines(n, rate), "python")
        same = type(compiled).__name__ != "function"
        diagonal = [packed_index(n)[(i, i)] for i in range(n)]
        for _ in range(20):
            P = [random.uniform(-0.1, 0.1) for _ in range(n * (n + 1) // 2)]
            for k in diagonal:
                P[k] = random.uniform(0.5, 2.0)
            v = [[random.gauss(0.0, 1.0) for _ in range(n)] for _ in range(4)]
            args = (P, random.uniform(0.5, 2.0), v[0], v[1], random.gauss(0.0, 1.0), v[2],
                    v[3], random.gauss(0.0, 1.0), 0.99, random.choice([0.0, 0.5]), 0.99)
            same = same and repr(compiled(*args)) == repr(python(*args))
        out.append(same)
print(json.dumps(out))
"""


def test_the_rcie_kernels_are_compiled_and_compute_the_generated_lines(venv):
    """The compiled build's RCIE kernels (setup.py's ``GENERATED_MODULES``) are extension
    functions, and each gives the run-time generated Python's results to the last bit
    (``repr``), diverged (None) or not, on random covariances and rows."""
    assert probe(venv, RCIE_KERNELS_COMPILED_AS_GENERATED) == [True] * 12


@pytest.mark.slow
def test_the_release_build_replays_as_pure(tmp_path_factory, tmp_path):
    """The wheel a vehicle installs (``-O3``): the listed modules compiled, and the boat's
    golden log with a GNSS latency (its forks copy the compiled objects) replayed to the
    pure build's estimates to the byte."""
    venv = compiled_venv(tmp_path_factory.mktemp("release"), "3")
    test_the_listed_modules_and_only_they_are_compiled(venv)
    test_the_gnss_latency_forks_replay_compiled_as_pure(venv, tmp_path)


def test_the_metadata_step_of_a_compiled_build_runs_no_mypyc(tmp_path):
    """pip prepares a build's metadata by running setup.py ``dist_info`` before the build:
    with ``ONBOARD_COMPILE=1`` that step writes the metadata without staging or compiling
    anything (mypyc's 20 s are the build's alone)."""
    from onboard.apps.install import copy_package

    src = tmp_path / "src"
    copy_package(REPO, src)
    (tmp_path / "meta").mkdir()
    r = subprocess.run([sys.executable, "setup.py", "--quiet", "dist_info", "--output-dir",
                        str(tmp_path / "meta")], cwd=src, capture_output=True, text=True,
                       env={**clean_env(), "ONBOARD_COMPILE": "1"}, timeout=300)
    assert r.returncode == 0, r.stderr
    assert list((tmp_path / "meta").glob("onboard-*.dist-info/METADATA"))
    assert not (src / "build").exists()  # nothing staged for mypyc (setup.py's STAGE)
