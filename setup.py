"""The optional compiled build: ``ONBOARD_COMPILE=1`` compiles the modules on a replay's
hot path with mypyc (docs/performance.md, "The compiled build").

The modules are the readable Python as written: mypyc compiles them to C extensions from
their type annotations, and the estimates are the pure build's to the byte
(tests/test_compiled.py). The compiled modules' classes that are copied or subclassed,
each subclass too (it is not inherited), carry
``@mypyc_attr(allow_interpreted_subclasses=True)`` (a no-op in Python): compiled, they can
then be deep-copied (the GNSS latency's fixed-lag forks, onboard/engine/latency.py) and
subclassed by Python code (the tests' doubles, the MCAP reader's tlog reader). Without
``ONBOARD_COMPILE=1`` the wheel is pure Python, as the vehicle's install from source and
the editable development install are (do not set it for an editable install: its
extensions would shadow the edited ``.py`` files). Everything else about the package is in
pyproject.toml.

    pip install "mypy==<MYPYC_VERSION>"
    ONBOARD_COMPILE=1 pip wheel --no-build-isolation --no-deps -w dist .
"""

import importlib.util
import os
import shutil
import sys

from setuptools import setup

MYPYC_VERSION = "1.15.0"
"""The mypy (mypyc) release the compiled build is tested with: its C differs by release."""

COMPILED_MODULES = [
    # the boats' pipelines (aie, kf, current) and their estimators
    "onboard/estimators/increment_filter.py",
    "onboard/estimators/rcie.py",
    "onboard/estimators/noise_learning.py",
    "onboard/estimators/rls.py",
    "onboard/estimators/kalman.py",
    "onboard/estimators/current_kf.py",
    "onboard/estimators/track.py",
    "onboard/estimators/path_accel.py",
    "onboard/estimators/model_identification.py",
    "onboard/estimators/vehicle_models.py",
    "onboard/estimators/input_models.py",
    "onboard/estimators/reconstruction.py",
    "onboard/estimators/measurement_points.py",
    "onboard/estimators/axis_model.py",
    "onboard/pipelines/surge_heading.py",
    "onboard/pipelines/aie.py",
    "onboard/pipelines/kf.py",
    "onboard/pipelines/current.py",
    "onboard/pipelines/current_samples.py",
    "onboard/pipelines/current_health.py",
    # the measured track every estimate is compared with
    "onboard/pipelines/nav.py",
    # the engine: per sample and per tick
    "onboard/engine/engine.py",
    "onboard/engine/checks.py",
    "onboard/engine/timeline.py",
    "onboard/engine/sources.py",
    "onboard/engine/whereabouts.py",
    "onboard/engine/corrections.py",
    "onboard/engine/inputs.py",
    "onboard/monitor/integrity.py",
    "onboard/monitor/innovations.py",
    "onboard/monitor/track_course.py",
    "onboard/monitor/current_resolution.py",
    "onboard/core/stats.py",
    "onboard/core/so3.py",
    "onboard/core/geo.py",
    # the replay's own: the tlog reader and its MAVLink decoders, estimates.csv
    "onboard/drivers/tlog.py",
    "onboard/drivers/mavlink.py",
    "onboard/drivers/logclock.py",
    "onboard/offline/estimates_csv.py",
]
"""The compiled modules, by their paths as installed (the checkout's drivers/ is
``onboard/drivers``, :data:`PACKAGE_DIRS`)."""

GENERATED_MODULES = {
    # the RCIE's straight-line kernels, which onboard/estimators/rcie.py otherwise
    # generates and compiles into Python at run time
    "onboard/estimators/rcie_kernels.py": ("onboard/estimators/rcie.py",
                                           "compiled_kernels_source"),
}
"""Modules of the compiled build alone, written from a function of the package: path ->
(the module defining it, its name)."""

MYPY_OPTIONS = ["--follow-imports=silent", "--ignore-missing-imports"]
"""The compiled modules are type-checked; the modules they import are read for their
types only, and numpy, scipy and msgspec are taken as they declare themselves."""

PACKAGE_DIRS = {"onboard": "onboard", "onboard/drivers": "drivers"}
"""Where each installed package's sources are in the checkout (pyproject.toml's
package-dir, for the packages a compiled module is in)."""

STAGE = "build/mypyc-src"
"""The compiled modules' sources laid out as installed, for mypyc to name them as they are
imported (drivers/tlog.py is ``onboard.drivers.tlog``)."""

OPT_LEVEL = os.environ.get("ONBOARD_COMPILE_OPT", "3")
"""gcc's optimisation level: ``-O3`` for the wheel a vehicle installs; ``0`` builds the
same C in about half the time, for checking what mypyc generates (the default test suite's
build, tests/test_compiled.py; gcc keeps IEEE arithmetic at every level, ``C_FLAGS``)."""

C_FLAGS = [
    # the same rounding on every architecture: no fused multiply-add where the Python
    # source has a multiplication and an addition (aarch64's compilers fuse by default)
    "-ffp-contract=off",
    # mypyc's runtime headers trip gcc 12's bounds warning, which mypyc makes an error
    "-Wno-array-bounds",
]


def staged(modules: list[str]) -> list[str]:
    """The paths of ``modules`` (as installed) in a copy of the package laid out as
    installed (:data:`STAGE`), with :data:`GENERATED_MODULES` written into it."""
    shutil.rmtree(STAGE, ignore_errors=True)
    skip = shutil.ignore_patterns("__pycache__", "*.so")
    for package, source in sorted(PACKAGE_DIRS.items()):
        shutil.copytree(source, os.path.join(STAGE, package), ignore=skip, dirs_exist_ok=True)
    for path, (module, function) in GENERATED_MODULES.items():
        spec = importlib.util.spec_from_file_location("_generator", module)
        generator = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(generator)
        with open(os.path.join(STAGE, path), "w", encoding="utf-8") as f:
            f.write(getattr(generator, function)())
    return [os.path.join(STAGE, m) for m in modules]


METADATA_COMMANDS = ("egg_info", "dist_info")
"""The setup.py commands that write only the package's metadata. A PEP 517 build runs one
first (pip's "Preparing metadata"), which needs no extension: mypyc's type check and C
generation (about 20 s) then runs once, in the build itself, not twice."""


def metadata_only(argv: list[str]) -> bool:
    """Whether setup.py was run (``argv``) for a metadata command: its first argument that
    is not an option is one of :data:`METADATA_COMMANDS`."""
    command = next((a for a in argv[1:] if not a.startswith("-")), None)
    return command in METADATA_COMMANDS


def ext_modules() -> list:
    """The compiled extensions when ``ONBOARD_COMPILE=1`` and setup.py builds, else none."""
    if os.environ.get("ONBOARD_COMPILE") != "1" or metadata_only(sys.argv):
        return []
    try:
        from mypyc.build import mypycify
    except ImportError as err:
        raise SystemExit(
            f"ONBOARD_COMPILE=1 needs mypyc in the build environment: pip install "
            f"'mypy=={MYPYC_VERSION}', then build with --no-build-isolation") from err
    # a C file per module: gcc on one file of every module took twice the CPU
    # (docs/performance.md, "The compiled build")
    exts = mypycify([*MYPY_OPTIONS, *staged([*COMPILED_MODULES, *GENERATED_MODULES])],
                    opt_level=OPT_LEVEL, multi_file=True)
    for ext in exts:
        ext.extra_compile_args = [*ext.extra_compile_args, *C_FLAGS]
    return exts


setup(ext_modules=ext_modules())
