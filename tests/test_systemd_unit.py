"""The installed unit under a real systemd as PID 1 (tests/helpers/systemd_boot.py).

What only systemd itself can show: the unit as ``make install`` lays it out starts with
``DynamicUser=yes``, reads its secrets as credentials, reports ready (``Type=notify``),
publishes over TLS with the credential's user/password to the shipped ACL router, is
killed and restarted by the watchdog when its loop stalls, and stops cleanly with its
adaptive state saved in the ``StateDirectory``.

The install is staged as ``make install DESTDIR=...`` stages it, the package included (its
wheel built and installed into the staged venv), so the unit reads nothing of the checkout
and the test runs from a clone anywhere, ``/tmp`` too (which the unit cannot see). The
staged venv's dependencies are this test venv's site-packages, bound read-only into the
booted system at :data:`BOUND_DEPS` (tests/helpers/installed.py builds it offline).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from onboard.apps.service_bench import free_udp_port
from tests.helpers.installed import PURELIB, dependency_view, fresh_venv, set_dependencies
from tests.helpers.systemd_boot import booted_systemd, skip_unless_available
from tests.helpers.tls import open_tls_acl_router
from tests.helpers.waiting import wait_until

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[1]
SIM_S = 40.0
DYNAMIC_UIDS = range(61184, 65520)  # systemd's range for DynamicUser=
BOUND_DEPS = "/opt/onboard-test/site-packages"
"""Where the booted system sees this test venv's site-packages (the staged venv's
dependencies)."""
OFFLINE_INSTALL = "--no-index --no-build-isolation"
"""make install's PIP_ARGS here: no download (the build and the dependencies are local)."""


def _deploy_config(example: str, endpoint: str, mav_port: int, gcs_port: int) -> str:
    """The shipped deploy example with only the hardware replaced: one MAVLink autopilot on
    UDP instead of the serial ports and the DVL, the test router instead of the shore's."""
    head, rest = example.split("[[service.sources]]", 1)
    rest = rest[rest.index("\n[service]\n"):]
    sources = f'[[service.sources]]\nname = "autopilot"\nkind = "mavlink"\nurl = "udp:127.0.0.1:{mav_port}"\n'
    text = head + sources + rest
    text = re.sub(r'(?m)^connect = \["tls/[^"]*"\]', f'connect = ["{endpoint}"]', text, count=1)
    text = re.sub(r'(?m)^url = "udpout:[^"]*"', f'url = "udpout:127.0.0.1:{gcs_port}"', text, count=1)
    assert endpoint in text and f"{gcs_port}" in text
    return text


def _stage(stage: Path, endpoint: str, ca_pem: Path, mav_port: int, gcs_port: int) -> None:
    """``make install DESTDIR=stage``, the package included (the venv made beforehand,
    seeing this test venv's packages, so the install needs no download; then pointed at
    :data:`BOUND_DEPS`), the secrets in the credential store as the README says, and a
    drop-in shortening the watchdog."""
    from onboard.apps.install import main as install

    venv = stage / "opt" / "onboard" / "venv"
    fresh_venv(venv, dependency_view(stage.parent / "deps"))
    assert install(["--destdir", str(stage), f"--pip-args={OFFLINE_INSTALL}"]) == 0
    set_dependencies(venv, BOUND_DEPS)
    etc = stage / "etc" / "onboard"
    (etc / "onboard.toml").write_text(_deploy_config((etc / "onboard.toml").read_text(),
                                                     endpoint, mav_port, gcs_port))
    users = dict(line.split(":", 1) for line in
                 (REPO / "config" / "zenoh" / "credentials.example.txt").read_text().split())
    store = stage / "etc" / "credstore"
    shutil.copy(ca_pem, store / "onboard-zenoh-ca.pem")
    (store / "onboard-zenoh-user").write_text(f"boat1:{users['boat1']}\n")
    for f in store.iterdir():
        f.chmod(0o600)
    dropin = stage / "etc" / "systemd" / "system" / "onboard.service.d"
    dropin.mkdir(parents=True)
    conf = "[Service]\nWatchdogSec=3\nRestartSec=1\n"
    if any(str(p).startswith(("/root/", "/home/")) for p in _readable()):
        # the unit hides home directories (ProtectHome=yes); this test's Python lives in
        # one, where an installed service's (/usr) never does
        conf += "ProtectHome=read-only\n"
    (dropin / "test.conf").write_text(conf)


def _readable() -> list[Path]:
    """What the unit's dynamic user reads from this machine outside the staged tree and
    :data:`BOUND_DEPS`: the Python the staged venv is made from."""
    return [Path(sys._base_executable).resolve().parent]  # type: ignore[attr-defined]


def _shore(endpoint: str, ca_pem: Path, got: dict[str, int]):
    import zenoh

    from onboard.service.publishers.zenoh_pub import session_config

    users = dict(line.split(":", 1) for line in
                 (REPO / "config" / "zenoh" / "credentials.example.txt").read_text().split())
    conf = session_config("client", connect=[endpoint])
    conf.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(ca_pem)))
    conf.insert_json5("transport/auth/usrpwd", json.dumps({"user": "shore", "password": users["shore"]}))
    shore = zenoh.open(conf)
    shore.declare_subscriber("onboard/**", lambda s: got.__setitem__(str(s.key_expr),
                                                                     got.get(str(s.key_expr), 0) + 1))
    return shore




def test_the_installed_unit_runs_under_systemd_with_credentials_watchdog_and_state(tmp_path):
    skip_unless_available()
    in_tmp = [str(p) for p in _readable() if p.resolve().is_relative_to("/tmp")]
    if in_tmp:
        pytest.skip(f"the Python interpreter ({in_tmp[0]}) lies in /tmp, which the unit cannot "
                    "see (DynamicUser= implies a private /tmp)")
    router, endpoint, certs = open_tls_acl_router(tmp_path)
    mav_port, gcs_port = free_udp_port(), free_udp_port()
    stage, scratch = tmp_path / "stage", tmp_path / "scratch"
    scratch.mkdir()
    _stage(stage, endpoint, certs["ca_pem"], mav_port, gcs_port)
    got: dict[str, int] = {}
    shore = _shore(endpoint, certs["ca_pem"], got)
    env = dict(os.environ, ONBOARD_LOG_LEVEL="WARNING", PYTHONPATH=str(REPO))
    sim = None
    try:
        with booted_systemd(stage, scratch, _readable(), [(PURELIB, BOUND_DEPS)]) as sd:
            # only the unit itself: its ordering on network-online means nothing in here
            sd.run("systemctl", "start", "--job-mode=ignore-requirements", "systemd-journald.service")
            start = sd.run("systemctl", "start", "--no-block", "--job-mode=ignore-requirements",
                           "onboard.service")
            assert start.returncode == 0, start.stderr
            sim = subprocess.Popen(
                [sys.executable, "-m", "onboard", "sitl", "--scenario", "jaiabot-turns",
                 "--realtime", "--duration", str(SIM_S), "--seed", "1",
                 "--link", f"udp:127.0.0.1:{mav_port}"],
                env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)

            # ready (Type=notify: "active" only after READY=1), as a dynamic user
            props = sd.wait_for("onboard.service", 30.0, ActiveState="active")
            assert props["ActiveState"] == "active", (props, sd.journal("onboard.service"))
            # the staged venv runs the installed wheel, its dependencies from the bind
            where = sd.run("/opt/onboard/venv/bin/python", "-c",
                           "import onboard, zenoh; print(onboard.__file__, zenoh.__file__)")
            package, dependency = where.stdout.split()
            assert package.startswith("/opt/onboard/venv/lib/"), where
            assert dependency.startswith(BOUND_DEPS + "/"), where
            main_pid = sd.show("onboard.service", "MainPID")["MainPID"]
            status = sd.run("cat", f"/proc/{main_pid}/status").stdout
            uid = int(re.search(r"(?m)^Uid:\s+(\d+)", status).group(1))
            assert uid in DYNAMIC_UIDS, status

            # the estimates reach the ACL router over TLS with the credential's password
            assert wait_until(lambda: got.get("onboard/boat1/est/aie", 0) > 10, 30.0), \
                (got, sd.journal("onboard.service"))
            # health comes at 1 Hz: after ten estimates at 10 Hz it may be a moment away
            assert wait_until(lambda: got.get("onboard/boat1/health", 0) > 0, 10.0), got
            assert sd.show("onboard.service", "StatusText")["StatusText"], "no STATUS= line"

            # a stalled loop is killed by the watchdog (SIGABRT) and the unit restarted
            os.kill(_host_pid(sd.pid, int(main_pid)), signal.SIGSTOP)
            props = sd.wait_for("onboard.service", 20.0, NRestarts="1", ActiveState="active")
            assert props.get("NRestarts") == "1" and props["ActiveState"] == "active", \
                (props, sd.journal("onboard.service"))
            assert "Watchdog timeout" in sd.journal("onboard.service") or \
                sd.show("onboard.service", "Result")["Result"] in ("watchdog", "success")
            seen = got.get("onboard/boat1/est/aie", 0)
            assert wait_until(lambda: got.get("onboard/boat1/est/aie", 0) > seen + 3, 30.0), got

            # a clean stop saves the adaptive state in the unit's state directory
            stop = sd.run("systemctl", "stop", "onboard.service", timeout=60)
            assert stop.returncode == 0, stop.stderr
            props = sd.show("onboard.service", "ActiveState", "Result", "ExecMainStatus")
            assert props["ActiveState"] == "inactive" and props["Result"] == "success", \
                (props, sd.journal("onboard.service"))
            state = sd.root / "var" / "lib" / "private" / "onboard" / "state" / "adaptive.json"
            assert state.exists(), sd.run("find", "/var/lib/private").stdout
            assert state.stat().st_uid == uid
            recordings = sd.root / "var" / "log" / "private" / "onboard" / "recordings"
            assert any(recordings.iterdir()), "the recorder wrote nothing under LogsDirectory"
    finally:
        if sim is not None:
            sim.kill()
            sim.wait(timeout=30)
        shore.close()
        router.close()


def _host_pid(ns_init: int, ns_pid: int) -> int:
    """The host PID of PID ``ns_pid`` in the PID namespace whose init is ``ns_init``."""
    for status in Path("/proc").glob("[0-9]*/status"):
        try:
            text = status.read_text()
        except OSError:
            continue
        m = re.search(r"(?m)^NSpid:\s+(\d+)\s+(\d+)\s*$", text)
        if m and int(m.group(2)) == ns_pid and _in_namespace_of(int(m.group(1)), ns_init):
            return int(m.group(1))
    raise LookupError(f"PID {ns_pid} of the namespace of {ns_init} not found")


def _in_namespace_of(pid: int, ns_init: int) -> bool:
    try:
        return os.readlink(f"/proc/{pid}/ns/pid") == os.readlink(f"/proc/{ns_init}/ns/pid")
    except OSError:
        return False
