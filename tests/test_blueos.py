"""The BlueOS extension (blueos/; docs/blueos.md) and the mavlink-router drop-in, checked
as far as a machine without a container engine or registry allows: the Dockerfile's
LABELs parsed and validated as BlueOS reads them (permissions: Docker's create-container
JSON), the extension's configuration valid for the service over each vehicle class, and
the Dockerfile's install steps run in a plain venv (slow)."""

from __future__ import annotations

import configparser
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from onboard.apps.install import PACKAGE_FILES
from onboard.core.config import bundled, load_all
from onboard.service.daemon import check_config
from onboard.service.web.app import parse_listen

REPO = Path(__file__).resolve().parent.parent
DOCKERFILE = REPO / "blueos" / "Dockerfile"
EXTENSION_TOML = REPO / "blueos" / "onboard.toml"
DROP_IN = REPO / "config" / "mavlink-router" / "config.d" / "50-onboard.conf"
DATA_BIND = "/usr/blueos/extensions/onboard:/data"
"""The data folder: blueos/entrypoint.sh keeps the configuration, state and recordings there."""
EXTENSION_TYPES = {"device-integration", "example", "theme", "other", "tool", "extension"}
HOST_CONFIG_KEYS = {"NetworkMode", "Binds", "RestartPolicy", "CpuPeriod", "CpuQuota",
                    "Privileged", "Devices", "PortBindings", "ExtraHosts", "Memory"}
"""HostConfig keys of Docker's create-container API that an extension uses."""


def dockerfile_instructions(text: str) -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) of a Dockerfile, continuation lines joined as Docker does
    (a backslash at the end of a line, inside quotes too), comments dropped."""
    out: list[tuple[str, str]] = []
    buf = ""
    for line in text.splitlines():
        if not buf and (not line.strip() or line.lstrip().startswith("#")):
            continue
        if line.endswith("\\"):
            buf += line[:-1]
            continue
        buf += line
        word, _, rest = buf.strip().partition(" ")
        out.append((word.upper(), rest.strip()))
        buf = ""
    return out


def labels(text: str) -> dict[str, str]:
    """The LABELs, with the ARG defaults substituted for ``${NAME}``."""
    args: dict[str, str] = {}
    out: dict[str, str] = {}
    for word, rest in dockerfile_instructions(text):
        if word == "ARG" and "=" in rest:
            k, v = rest.split("=", 1)
            args[k] = v
        elif word == "LABEL":
            for pair in shlex.split(rest):
                k, v = pair.split("=", 1)
                out[k] = re.sub(r"\$\{(\w+)\}", lambda m: args[m.group(1)], v)
    return out


@pytest.fixture(scope="module")
def label() -> dict[str, str]:
    return labels(DOCKERFILE.read_text())


def test_the_version_label_is_the_packages(label):
    pyproject = tomllib.loads((REPO / "pyproject.toml").read_text())
    assert label["version"] == pyproject["project"]["version"]


def test_permissions_are_create_container_json_with_host_networking_and_the_data_bind(label):
    perm = json.loads(label["permissions"])
    host = perm["HostConfig"]
    assert host["NetworkMode"] == "host"  # BlueOS's zenohd and router on 127.0.0.1
    assert DATA_BIND in host["Binds"]
    assert set(host) <= HOST_CONFIG_KEYS, set(host) - HOST_CONFIG_KEYS
    assert all(re.fullmatch(r"[A-Z_]+=.*", e) for e in perm["Env"])
    # the port exposed is the one the extension's page listens on
    _, port = parse_listen(tomllib.loads(EXTENSION_TOML.read_text())["service"]["web"]["listen"])
    assert f"{port}/tcp" in perm["ExposedPorts"]


def test_the_other_labels_blueos_reads_are_well_formed(label):
    assert label["type"] in EXTENSION_TYPES
    tags = json.loads(label["tags"])
    assert tags and all(isinstance(t, str) for t in tags)
    links = json.loads(label["links"])
    assert links and all(re.fullmatch(r"https://\S+", u) for u in links.values())
    assert re.fullmatch(r"https://\S+\.md", label["readme"])
    assert re.fullmatch(r"core >= \d+\.\d+", label["requirements"])
    assert json.loads(label["company"])["name"]
    authors = json.loads(label["authors"])
    assert authors and all(a["name"] for a in authors)


def test_the_label_parser_rejects_what_docker_would_not_read():  # negative control
    broken = 'LABEL permissions=\'{"HostConfig": {"NetworkMode": "host",}}\'\n'
    with pytest.raises(json.JSONDecodeError):
        json.loads(labels(broken)["permissions"])


@pytest.mark.parametrize("vehicle", ["twin-thruster-boat", "bluerov2", "rudder-boat"])
def test_the_extensions_configuration_is_valid_over_each_vehicle_class(vehicle):
    base = REPO / "config" / f"{vehicle}.toml"
    cfg = load_all([base, EXTENSION_TOML])
    check_config(cfg, str(EXTENSION_TOML))
    assert cfg.vehicle.vehicle_class == vehicle and cfg.service.web.edit_config
    assert cfg.service.zenoh.connect == ["tcp/127.0.0.1:7447"]  # BlueOS's zenohd


def source_copies(text: str) -> dict[str, str]:
    """What the Dockerfile copies into ``/src``, the tree its wheel is built from: {path
    in the repository: path under /src}. As Docker copies: a directory's contents go to
    the target; a file goes into a target ending in ``/``, else to the target itself."""
    out: dict[str, str] = {}
    for word, rest in dockerfile_instructions(text):
        if word != "COPY":
            continue
        *sources, dest = shlex.split(rest)
        if not dest.startswith("/src/"):
            continue
        for src in sources:
            into = dest.endswith("/") and not (REPO / src).is_dir()
            out[src] = (dest + Path(src).name if into else dest).removeprefix("/src/").rstrip("/")
    return out


def test_the_image_builds_its_wheel_from_what_make_install_builds_it_from():
    """The COPY lines into /src are install.PACKAGE_FILES, each at its own path: config/
    among them, so the image's package carries the bundled configs and gains."""
    copies = source_copies(DOCKERFILE.read_text())
    assert set(copies) == set(PACKAGE_FILES) and all(k == v for k, v in copies.items()), copies
    # the negative control: a Dockerfile that leaves config/ out is seen
    without = DOCKERFILE.read_text().replace("COPY config /src/config", "")
    assert "config" not in source_copies(without)


def test_the_entrypoint_runs_a_bundled_config_by_name(label):
    """The vehicle class is a bundled config's name, found inside the installed package;
    nothing of the repository is copied into the image beside it."""
    entry = (REPO / "blueos" / "entrypoint.sh").read_text()
    assert '--config "$vehicle"' in entry and "/opt/onboard/config" not in DOCKERFILE.read_text()
    default = re.search(r"vehicle=\$\{ONBOARD_VEHICLE:-([\w-]+)\}", entry).group(1)
    (env,) = [e for e in json.loads(label["permissions"])["Env"]
              if e.startswith("ONBOARD_VEHICLE=")]
    assert {default, env.split("=", 1)[1]} <= set(bundled())
    assert "--state-dir \"$data\"" in entry and DATA_BIND.endswith(":/data")


def test_armv7_takes_numpy_scipy_and_msgspec_from_piwheels_as_wheels_only():
    script = (REPO / "blueos" / "install.sh").read_text()
    arm = script.split("linux/arm/v7)")[1].split(";;")[0]
    assert "https://www.piwheels.org/simple" in arm and "--only-binary numpy,scipy,msgspec" in arm


def test_the_mavlink_router_drop_in_feeds_the_input_and_takes_the_estimates():
    ini = configparser.ConfigParser()
    ini.read_string(DROP_IN.read_text())
    to_service, from_service = ini["UdpEndpoint onboard"], ini["UdpEndpoint onboard-out"]
    assert (to_service["Mode"], to_service["Address"]) == ("Normal", "127.0.0.1")
    assert to_service["Port"] == "14551"
    assert (from_service["Mode"], from_service["Port"]) == ("Server", "14552")
    doc = (REPO / "docs" / "blueos.md").read_text()
    assert 'url = "udp:127.0.0.1:14551"' in doc and 'url = "udpout:127.0.0.1:14552"' in doc


@pytest.mark.slow
@pytest.mark.integration
def test_the_images_install_steps_give_a_working_service_in_a_plain_venv(tmp_path):
    # 112 s measured (a wheel of this tree; numpy, scipy, zenoh, ... from pip's cache)
    src, venv = tmp_path / "src", tmp_path / "venv"
    src.mkdir()
    for name, dest in source_copies(DOCKERFILE.read_text()).items():  # the image's /src
        copy = shutil.copytree if (REPO / name).is_dir() else shutil.copy2
        copy(REPO / name, src / dest)
    env = {**os.environ, "TARGETPLATFORM": "linux/amd64"}
    env.pop("PIP_NO_CACHE_DIR", None)
    run = subprocess.run(["sh", str(REPO / "blueos" / "install.sh"), str(src), str(venv)],
                         env=env, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    probe = ("from onboard.service.web.app import static_file; "
             "assert b'<title>onboard</title>' in static_file('index.html'); "
             "from onboard.core.config import load; "
             "from onboard.pipelines.current import GAIN_DIR; "
             "assert load('twin-thruster-boat').vehicle.vehicle_class == 'twin-thruster-boat'; "
             f"assert GAIN_DIR.is_relative_to({str(venv)!r}); "
             "import numpy, scipy, msgspec, zenoh, pymavlink; print('ok')")
    out = subprocess.run([str(venv / "bin" / "python"), "-c", probe], capture_output=True,
                         text=True, cwd=tmp_path, timeout=120)
    assert out.stdout.strip() == "ok", out.stderr[-2000:]
    pkgs = subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "list", "--format=json"],
                          capture_output=True, text=True, timeout=120).stdout
    names = {p["name"].lower() for p in json.loads(pkgs)}
    assert not names & {"matplotlib", "cvxpy", "casadi", "pytest"}  # lean: no extra
    assert sys.version_info >= (3, 11)
