"""Packaging: the wheel installs one top-level name, ``onboard``.

The repository keeps ``drivers/`` and ``sitl/`` as top-level folders (the design card);
pyproject.toml installs them as ``onboard.drivers`` and ``onboard.sitl``, so no other
project's ``drivers`` or ``sitl`` can collide with ours in site-packages.
"""

from __future__ import annotations

import tomllib

from tests.helpers.imports import INSTALLED_AS, REPO, module_name


def _setuptools() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]


def test_every_package_folder_is_installed_under_onboard() -> None:
    folders = {module_name(p.parent / "__init__.py") for top in ("onboard", "drivers", "sitl")
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
