"""Packaging: the wheel installs one top-level name, ``onboard``.

The repository keeps ``drivers/``, ``sitl/`` and ``config/`` as top-level folders (the
design card); pyproject.toml installs them as ``onboard.drivers``, ``onboard.sitl`` and
``onboard.bundled`` (the configs and gains, data only), so no other project's ``drivers``
or ``sitl`` can collide with ours in site-packages. The wheel itself, built and installed:
tests/test_wheel.py.
"""

from __future__ import annotations

import tomllib

from tests.helpers.imports import INSTALLED_AS, REPO, module_name


def _setuptools() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]


def test_every_package_folder_is_installed_under_onboard() -> None:
    folders = {module_name(p.parent / "__init__.py")
               for top in ("onboard", "drivers", "sitl", "config")
               for p in (REPO / top).rglob("__init__.py")}
    assert set(_setuptools()["packages"]) == folders
    assert all(name == "onboard" or name.startswith("onboard.") for name in folders)


def test_the_top_level_folders_map_to_their_subpackages() -> None:
    assert _setuptools()["package-dir"] == {v: k for k, v in INSTALLED_AS.items()}


def test_the_code_imports_the_installed_names_only() -> None:
    import onboard.drivers.nmea
    import onboard.sitl.runner

    assert onboard.drivers.nmea.__file__.startswith(str(REPO / "drivers"))
    assert onboard.sitl.runner.__file__.startswith(str(REPO / "sitl"))


def test_the_bundled_data_is_read_from_the_installed_package() -> None:
    """The configs and gains are the data of the package onboard.bundled, found with
    importlib.resources (this editable install maps it to config/), and its package data
    takes every config and gain of the folder into the wheel."""
    from onboard.core.config import BUNDLED_PACKAGE, CONFIG_DIR
    from onboard.pipelines.current import GAIN_DIR

    assert BUNDLED_PACKAGE == INSTALLED_AS["config"]
    assert CONFIG_DIR == REPO / "config" and GAIN_DIR == CONFIG_DIR / "gains"
    data = _setuptools()["package-data"][BUNDLED_PACKAGE]
    shipped = {p.relative_to(CONFIG_DIR) for pattern in data for p in CONFIG_DIR.glob(pattern)}
    assert {p.relative_to(CONFIG_DIR) for p in CONFIG_DIR.glob("*.toml")} <= shipped
    assert {p.relative_to(CONFIG_DIR) for p in GAIN_DIR.glob("*.json")} <= shipped
