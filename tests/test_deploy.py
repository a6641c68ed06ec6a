"""Deployment as documented: secrets as systemd credentials readable under
``DynamicUser=yes``, the deploy example's Zenoh TLS + user/password, ``make install`` into
a prefix and ``systemd-analyze verify`` of the installed unit. docs/service.md "Install",
docs/security.md."""

from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess
import time
from pathlib import Path

import pytest

from onboard.core.config import ConfigError, ZenohOut, load
from onboard.service.credentials import private_file_problem, read_user_password, resolve_secret
from onboard.service.signing import load_signing_key
from tests.helpers.installed import clean_env, dependency_view, fresh_venv, run_installed
from tests.helpers.tls import make_test_certificates, open_tls_acl_router
from tests.helpers.waiting import wait_until

REPO = Path(__file__).resolve().parents[1]
ZENOH_DIR = REPO / "config" / "zenoh"
KEY = bytes(range(32))


def _acl(*entries: tuple[int, int, int]) -> bytes:
    """A ``system.posix_acl_access`` value: version 2, then (tag, perm, id) entries."""
    return struct.pack("<I", 2) + b"".join(struct.pack("<HHI", *e) for e in entries)


def _set_acl(path: Path, *entries: tuple[int, int, int]) -> None:
    try:
        os.setxattr(path, "system.posix_acl_access", _acl(*entries))
    except OSError as err:
        pytest.skip(f"this file system takes no POSIX ACL: {err.strerror}")


USER_OBJ, USER, GROUP_OBJ, GROUP, MASK, OTHER = 0x01, 0x02, 0x04, 0x08, 0x10, 0x20
NO_ID = 0xFFFFFFFF


def test_credential_names_resolve_in_the_credentials_directory_and_need_it(tmp_path, monkeypatch):
    monkeypatch.delenv("CREDENTIALS_DIRECTORY", raising=False)
    assert resolve_secret("/etc/onboard/x.key", "k") == Path("/etc/onboard/x.key")
    with pytest.raises(ConfigError, match=r"k: credential:a\.key needs \$CREDENTIALS_DIRECTORY"):
        resolve_secret("credential:a.key", "k")
    monkeypatch.setenv("CREDENTIALS_DIRECTORY", str(tmp_path))
    assert resolve_secret("credential:a.key", "k") == tmp_path / "a.key"
    for bad in ("credential:", "credential:../etc/shadow", "credential:.."):
        with pytest.raises(ConfigError, match="plain file name"):
            resolve_secret(bad, "k")


def test_a_credential_as_systemd_hands_it_over_is_read_and_acls_to_others_are_refused(tmp_path, monkeypatch):
    """systemd writes a credential mode 0400 and grants the unit's user read access by an
    ACL entry, which shows as group bits (the mask) in the mode: accepted. An ACL that lets
    another user or a group read the key is refused, as are plain group/other bits."""
    monkeypatch.setenv("CREDENTIALS_DIRECTORY", str(tmp_path))
    key = tmp_path / "onboard-mavlink.key"
    key.write_bytes(KEY)
    key.chmod(0o400)
    me = os.geteuid()
    _set_acl(key, (USER_OBJ, 4, NO_ID), (USER, 4, me), (GROUP_OBJ, 0, NO_ID), (MASK, 4, NO_ID),
             (OTHER, 0, NO_ID))
    assert key.stat().st_mode & 0o777 == 0o440  # what the old mode-bits check refused
    assert private_file_problem(key) is None
    assert load_signing_key("credential:onboard-mavlink.key") == KEY
    _set_acl(key, (USER_OBJ, 4, NO_ID), (USER, 4, me + 4242), (GROUP_OBJ, 0, NO_ID),
             (MASK, 4, NO_ID), (OTHER, 0, NO_ID))
    with pytest.raises(ConfigError, match=f"accessible by user {me + 4242}.*chmod 600"):
        load_signing_key("credential:onboard-mavlink.key")
    _set_acl(key, (USER_OBJ, 4, NO_ID), (GROUP_OBJ, 4, NO_ID), (GROUP, 4, 20), (MASK, 4, NO_ID),
             (OTHER, 0, NO_ID))
    with pytest.raises(ConfigError, match="accessible by its group"):
        load_signing_key("credential:onboard-mavlink.key")
    # a named entry masked to nothing grants nothing
    _set_acl(key, (USER_OBJ, 4, NO_ID), (USER, 4, me + 1), (GROUP_OBJ, 0, NO_ID), (MASK, 0, NO_ID),
             (OTHER, 0, NO_ID))
    assert private_file_problem(key) is None
    os.removexattr(key, "system.posix_acl_access")
    key.chmod(0o604)
    with pytest.raises(ConfigError, match=r"accessible by group or others \(mode 0604\)"):
        load_signing_key("credential:onboard-mavlink.key")


def test_the_user_password_file_holds_one_user_colon_password_line(tmp_path, monkeypatch):
    monkeypatch.setenv("CREDENTIALS_DIRECTORY", str(tmp_path))
    f = tmp_path / "onboard-zenoh-user"
    for text, ok in (("boat1:s3cr:et\n", ("boat1", "s3cr:et")), ("boat1\n", None),
                     ("boat1:\n", None), ("a:b\nc:d\n", None), (":pw\n", None)):
        f.write_text(text)
        f.chmod(0o600)
        if ok:
            assert read_user_password("credential:onboard-zenoh-user", "k") == ok
        else:
            with pytest.raises(ConfigError, match="k: "):
                read_user_password("credential:onboard-zenoh-user", "k")
    f.chmod(0o644)
    with pytest.raises(ConfigError, match="chmod 600"):
        read_user_password("credential:onboard-zenoh-user", "k")
    monkeypatch.setenv("CREDENTIALS_DIRECTORY", str(tmp_path / "missing"))
    with pytest.raises(ConfigError, match="No such file"):
        read_user_password("credential:onboard-zenoh-user", "k")




def _credentials() -> dict[str, str]:
    return dict(line.split(":", 1) for line in (ZENOH_DIR / "credentials.example.txt").read_text().split())


@pytest.mark.integration
def test_the_deploy_example_publishes_over_tls_with_its_credentials_to_the_acl_router(tmp_path, monkeypatch):
    """config/deploy-example.toml's [service.zenoh] as shipped (only the router's address
    and the JSON5 file's location replaced), its secrets in a credentials directory as
    systemd makes it, against config/zenoh/router-acl.json5 on tls/: shore receives the
    estimates; a wrong password in the credential cannot connect."""
    import msgspec
    import zenoh

    from onboard.core.messages import EstimateRecord
    from onboard.service.publishers.zenoh_pub import ZenohPublisher, session_config

    router, ep, certs = open_tls_acl_router(tmp_path)
    creds = tmp_path / "credentials"
    creds.mkdir(mode=0o700)
    shutil.copy(certs["ca_pem"], creds / "onboard-zenoh-ca.pem")
    (creds / "onboard-zenoh-user").write_text(f"boat1:{_credentials()['boat1']}\n")
    for f in creds.iterdir():
        f.chmod(0o400)
    monkeypatch.setenv("CREDENTIALS_DIRECTORY", str(creds))
    shipped = load(REPO / "config" / "deploy-example.toml").service.zenoh
    assert shipped.connect[0].startswith("tls/") and shipped.user_password_file.startswith("credential:")
    assert shipped.tls_root_ca_certificate.startswith("credential:")
    zcfg = msgspec.structs.replace(shipped, connect=[ep],
                                   config_file=str(ZENOH_DIR / "vehicle-boat1.json5"))
    shore_conf = session_config("client", connect=[ep])
    shore_conf.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(certs["ca_pem"])))
    shore_conf.insert_json5("transport/auth/usrpwd", json.dumps(
        {"user": "shore", "password": _credentials()["shore"]}))
    shore = zenoh.open(shore_conf)
    pub = ZenohPublisher(zcfg, "boat1")
    try:
        got: list[str] = []
        shore.declare_subscriber("onboard/**", lambda s: got.append(str(s.key_expr)))
        pub.start()
        rec = EstimateRecord(vehicle="boat1", pipeline="current", t=1.0, values={"north": 0.2})
        assert wait_until(lambda: (pub.publish_estimates([rec]), "onboard/boat1/est/current" in got)[1], 8.0)
        (creds / "onboard-zenoh-user").chmod(0o600)
        (creds / "onboard-zenoh-user").write_text("boat1:not-the-password\n")
        wrong = ZenohPublisher(zcfg, "boat1")
        with pytest.raises(Exception, match="(?i)unable to connect"):
            wrong.start()
        wrong.close()
    finally:
        pub.close()
        shore.close()
        router.close()


@pytest.mark.integration
def test_a_vehicle_listening_on_tls_uses_its_key_and_certificate_from_credentials(tmp_path, monkeypatch):
    """A vehicle that shore connects to (``listen = ["tls/..."]``): its private key and
    certificate are credentials; a shore session trusting the CA receives its estimates."""
    import zenoh

    from onboard.core.messages import EstimateRecord
    from onboard.service.publishers.zenoh_pub import ZenohPublisher, session_config
    from onboard.apps.service_bench import free_tcp_port

    certs = make_test_certificates(tmp_path)
    creds = tmp_path / "credentials"
    creds.mkdir(mode=0o700)
    shutil.copy(certs["router_key"], creds / "onboard-zenoh-tls.key")
    shutil.copy(certs["router_pem"], creds / "onboard-zenoh-tls.pem")
    for f in creds.iterdir():
        f.chmod(0o400)
    monkeypatch.setenv("CREDENTIALS_DIRECTORY", str(creds))
    ep = f"tls/localhost:{free_tcp_port()}"
    pub = ZenohPublisher(ZenohOut(mode="peer", listen=[ep],
                                  tls_private_key="credential:onboard-zenoh-tls.key",
                                  tls_certificate="credential:onboard-zenoh-tls.pem"), "boat1")
    pub.start()
    conf = session_config("client", connect=[ep])
    conf.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(certs["ca_pem"])))
    shore = zenoh.open(conf)
    try:
        got: list[str] = []
        shore.declare_subscriber("onboard/**", lambda s: got.append(str(s.key_expr)))
        rec = EstimateRecord(vehicle="boat1", pipeline="kf", t=1.0, values={"speed": 1.0})
        assert wait_until(lambda: (pub.publish_estimates([rec]), "onboard/boat1/est/kf" in got)[1], 8.0)
    finally:
        shore.close()
        pub.close()
    (creds / "onboard-zenoh-tls.key").chmod(0o644)
    with pytest.raises(ConfigError, match="tls_private_key: .*accessible by group or others"):
        ZenohPublisher(ZenohOut(listen=[ep], tls_private_key="credential:onboard-zenoh-tls.key",
                                tls_certificate="credential:onboard-zenoh-tls.pem"), "b").start()


def test_the_service_refuses_to_start_with_a_missing_or_readable_zenoh_secret(tmp_path, monkeypatch):
    from onboard.service.daemon import Service
    from tests.helpers.service_config import service_config

    monkeypatch.setenv("CREDENTIALS_DIRECTORY", str(tmp_path))
    cfg = service_config(zenoh={"user_password_file": "credential:onboard-zenoh-user"},
                         mavlink={"enabled": False}, recorder={"enabled": False})
    with pytest.raises(ConfigError, match="service.zenoh.user_password_file: .*No such file.*"
                                          "/etc/credstore/onboard-zenoh-user"):
        Service(cfg, state_dir=tmp_path)
    (tmp_path / "onboard-zenoh-user").write_text("boat1:pw\n")
    (tmp_path / "onboard-zenoh-user").chmod(0o640)
    with pytest.raises(ConfigError, match="accessible by group or others.*chmod 600"):
        Service(cfg, state_dir=tmp_path)
    cfg = service_config(zenoh={"tls_private_key": str(tmp_path / "k")},
                         mavlink={"enabled": False}, recorder={"enabled": False})
    with pytest.raises(ConfigError, match="tls_private_key and tls_certificate go together"):
        Service(cfg, state_dir=tmp_path)
    assert ZenohOut().user_password_file == ""  # nothing asked, nothing read


# --------------------------------------------------------------------------- disk faults

def _records(n: int, t0: float = 0.0):
    from onboard.drivers.recording import RawRecord

    return [RawRecord(t=t0 + i * 0.01, source="gps", kind="nmea", data=b"$GPGGA,%d\r\n" % i)
            for i in range(n)]


def test_a_disk_that_refuses_every_write_is_counted_reported_and_never_raises(tmp_path):
    """/dev/full: the kernel answers ENOSPC to every write."""
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full here")
    from onboard.drivers.recording import RecordingWriter
    from onboard.service.recorder import Recorder

    events: list[str] = []
    rec = Recorder(tmp_path, clock=lambda: 0.0, on_event=events.append, fsync=False,
                   open_writer=lambda path, v: RecordingWriter("/dev/full", fsync=False, version=v))
    for r in _records(50):
        rec.write(r)
    rec.flush(wait=True)
    rec.close()
    assert rec.write_errors >= 1 and rec.lost_records == 50 and rec.dropped == 50
    assert any("No space left on device" in e and "records lost" in e for e in events), events


class _FlakyDisk:
    """A writer factory whose files fail with ``errno`` while ``failing`` is set."""

    def __init__(self, err: int) -> None:
        self.err = err
        self.failing = True

    def __call__(self, path: Path, version: int):
        from onboard.drivers.recording import RecordingWriter

        disk = self

        class Writer(RecordingWriter):
            def flush(self) -> None:
                if disk.failing:
                    raise OSError(disk.err, os.strerror(disk.err))
                super().flush()

        return Writer(path, fsync=False, version=version)


def test_eio_loses_only_the_batches_it_hits_and_recording_resumes(tmp_path):
    import errno

    from onboard.drivers.recording import read_records
    from onboard.service.recorder import Recorder

    disk = _FlakyDisk(errno.EIO)
    events: list[str] = []
    rec = Recorder(tmp_path, clock=lambda: 0.0, on_event=events.append, open_writer=disk)
    for r in _records(10):
        rec.write(r)
    rec.flush(wait=True)
    disk.failing = False
    later = _records(5, t0=10.0)
    for r in later:
        rec.write(r)
    rec.flush(wait=True)
    rec.close()
    assert rec.lost_records == 10 and rec.write_errors >= 1
    assert any("Input/output error" in e for e in events), events
    got = [r.data for f in rec.files for r in read_records(f)]
    assert [r.data for r in later] == [d for d in got if d.startswith(b"$GPGGA")][-5:]


def test_low_free_space_deletes_the_oldest_recordings_then_pauses_and_resumes(tmp_path):
    from onboard.service.recorder import Recorder

    old = [tmp_path / f"onboard-2020010{i}T000000Z-abcd-0000.onbrec" for i in range(3)]
    for i, p in enumerate(old):
        p.write_bytes(b"ONBREC01" + bytes(100_000))
        os.utime(p, (1e9 + i, 1e9 + i))
    free = {"bytes": 10_000_000}
    events: list[str] = []
    rec = Recorder(tmp_path, clock=lambda: 0.0, on_event=events.append, min_free_mb=1.0,
                   free_space=lambda d: free["bytes"] + sum(100_000 for p in old if not p.exists()))
    rec.DISK_CHECK_S = 0.0
    free["bytes"] = 950_000  # 50 kB short: the oldest file (100 kB) goes
    rec.write(_records(1)[0])
    rec.flush(wait=True)
    rec.poll(0.0)
    assert [p.exists() for p in old] == [False, True, True] and not rec.paused
    assert any("low disk space" in e and "deleted the oldest" in e for e in events), events
    free["bytes"] = 0  # nothing left to delete would be enough: pause
    rec.write(_records(1)[0])
    rec.flush(wait=True)
    rec.poll(0.0)
    assert rec.paused and any("disk full" in e and "paused" in e for e in events), events
    for r in _records(7):
        rec.write(r)
    assert rec.dropped_records == 7
    free["bytes"] = 5_000_000
    rec.flush(wait=True)  # an empty flush still lets the worker look at the disk
    rec._submit(rec._append_job, b"", 0).result()
    rec.poll(0.0)
    assert not rec.paused and any("recording again" in e and "7 records" in e for e in events)
    rec.close()


@pytest.mark.integration
def test_recorder_errors_reach_health_and_statustext_and_no_fsync_runs_on_the_loop(tmp_path, monkeypatch):
    """The whole service over UDP (MAVLink in, MAVLink out signed, recorder rotating every
    few kB, state saved every 0.2 s): os.fsync never runs on the event loop's thread; then
    the recorder's disk fails (EIO) and the loss reaches the health record
    (``dropped["recorder"]``, an event) and a STATUSTEXT, while ticks go on."""
    import asyncio
    import errno
    import socket
    import threading

    from pymavlink.dialects.v20 import ardupilotmega as mavlink2

    from onboard.service.daemon import Service
    from onboard.apps.service_bench import free_udp_port
    from tests.helpers.mavlink_listener import receive_mavlink
    from tests.helpers.service_config import service_config

    fsync_threads: list[int] = []
    real_fsync = os.fsync

    def spy(fd: int) -> None:
        fsync_threads.append(threading.get_ident())
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", spy)
    key = tmp_path / "mavlink.key"
    key.write_bytes(KEY)
    key.chmod(0o600)
    port_in, port_out = free_udp_port(), free_udp_port()
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", port_out))
    cfg = service_config(sources=[{"name": "ap", "kind": "mavlink", "url": f"udp:127.0.0.1:{port_in}"}],
                         zenoh={"enabled": False}, state_save_interval_s=0.2,
                         mavlink={"url": f"udpout:127.0.0.1:{port_out}", "signing_key_file": str(key)},
                         recorder={"rotate_mb": 0.004, "flush_interval_s": 0.05})
    healths = []
    svc = Service(cfg, state_dir=tmp_path, on_health=healths.append)
    disk = _FlakyDisk(errno.EIO)
    disk.failing = False
    loop_thread: list[int] = []

    async def main() -> None:
        loop_thread.append(threading.get_ident())
        await svc.start()
        svc.recorder._open_writer = disk  # the next files are on the flaky disk
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        mav = mavlink2.MAVLink(None, srcSystem=3, srcComponent=1)
        for i in range(60):  # 3 s of a 20 Hz attitude stream
            tx.sendto(mav.attitude_encode(i * 50, 0.0, 0.0, 0.1, 0.0, 0.0, 0.0).pack(mav),
                      ("127.0.0.1", port_in))
            if i == 30:
                disk.failing = True
            await asyncio.sleep(0.05)
        await asyncio.sleep(1.2)  # one more health record
        svc.request_stop()
        await svc.run()
        tx.close()

    asyncio.run(main())
    msgs = receive_mavlink(gcs)
    gcs.close()
    assert len(fsync_threads) >= 5, "the recorder, state and signing files were fsync'ed"
    assert loop_thread[0] not in fsync_threads
    assert svc.recorder.files and len(svc.recorder.files) >= 3  # it rotated
    assert svc.recorder.lost_records > 0
    assert healths[-1].dropped.get("recorder", 0) > 0
    events = [e for h in healths for e in h.events]
    assert any(e.startswith("recorder: write error") for e in events), events
    texts = [m.text for m in msgs if m.get_type() == "STATUSTEXT"]
    assert any(t.startswith("recorder: write error") for t in texts), texts
    assert svc.stats.ticks > 30 and svc.stats.tick_errors == 0


# --------------------------------------------------------------------------- make install

def documentation_paths(unit: str) -> list[str]:
    """The paths of the ``file://`` URIs of a unit's ``Documentation=`` lines."""
    out = []
    for line in unit.splitlines():
        if line.startswith("Documentation="):
            out += [u[len("file://"):] for u in line.split("=", 1)[1].split()
                    if u.startswith("file://")]
    return out


def test_a_staged_install_puts_config_unit_and_credential_store_in_place_and_keeps_local_edits(tmp_path):
    from onboard.apps.install import main

    stage = tmp_path / "stage"
    assert main(["--destdir", str(stage), "--no-venv"]) == 0
    etc = stage / "etc" / "onboard"
    unit = (stage / "etc" / "systemd" / "system" / "onboard.service").read_text()
    assert unit == (REPO / "systemd" / "onboard.service").read_text()  # default paths
    assert (etc / "onboard.toml").read_text() == (REPO / "config" / "deploy-example.toml").read_text()
    assert (etc / "zenoh-vehicle.json5").read_text() == (ZENOH_DIR / "vehicle-boat1.json5").read_text()
    assert (stage / "etc" / "credstore").stat().st_mode & 0o777 == 0o700
    for f in ("onboard.toml", "onboard.env", "zenoh-vehicle.json5"):
        assert (etc / f).stat().st_mode & 0o777 == 0o644
    docs = documentation_paths(unit)
    assert docs, "the unit names no documentation"
    for path in docs:  # each page the unit's Documentation= names is installed
        assert (stage / path.lstrip("/")).read_text().startswith("# "), path
    assert (stage / "opt" / "onboard" / "doc" / "service.md").read_text() == \
        (REPO / "docs" / "service.md").read_text()
    (etc / "onboard.toml").write_text("# my boat\n")
    assert main(["--destdir", str(stage), "--no-venv"]) == 0
    assert (etc / "onboard.toml").read_text() == "# my boat\n"  # never overwritten
    assert (etc / "onboard.toml.dist").read_text().startswith("# A deployment")
    with pytest.raises(SystemExit):
        main(["--prefix", "relative/path", "--no-venv"])


def test_the_installer_run_from_an_installed_package_says_to_use_a_clone(tmp_path, monkeypatch,
                                                                         capsys):
    """``python -m onboard.apps.install`` ships in the wheel, but installs from the source
    tree (the unit, the example config, the docs): run from an installed package it stops
    with one line saying so (exit 2) before it makes anything, not a traceback."""
    from onboard.apps import install

    monkeypatch.setattr(install, "SOURCE", tmp_path / "site-packages")
    stage = tmp_path / "stage"
    with pytest.raises(SystemExit) as err:
        install.main(["--destdir", str(stage), "--no-venv"])
    assert err.value.code == 2
    assert "run 'sudo make install' in a clone of the repository" in capsys.readouterr().err
    assert not stage.exists()


def test_a_staged_venv_names_the_prefix_it_runs_from_not_the_staging_directory(tmp_path):
    """With DESTDIR the venv is made under the staging directory; its scripts, activate
    and pyvenv.cfg are rewritten to name PREFIX/venv (the python symlinks stay)."""
    from onboard.apps.install import relocate_venv

    venv = tmp_path / "stage" / "opt" / "onboard" / "venv"
    (venv / "bin").mkdir(parents=True)
    script = venv / "bin" / "onboard"
    script.write_text(f"#!{venv}/bin/python\nimport sys\n")
    script.chmod(0o755)
    (venv / "bin" / "activate").write_text(f'VIRTUAL_ENV="{venv}"\n')
    (venv / "bin" / "python").symlink_to("/usr/bin/python3")
    (venv / "pyvenv.cfg").write_text(f"home = /usr/bin\ncommand = python3 -m venv {venv}\n")
    changed = relocate_venv(venv, "/opt/onboard/venv")
    assert sorted(p.name for p in changed) == ["activate", "onboard", "pyvenv.cfg"]
    assert script.read_text() == "#!/opt/onboard/venv/bin/python\nimport sys\n"
    assert script.stat().st_mode & 0o777 == 0o755
    assert (venv / "bin" / "activate").read_text() == 'VIRTUAL_ENV="/opt/onboard/venv"\n'
    assert os.readlink(venv / "bin" / "python") == "/usr/bin/python3"
    assert str(tmp_path) not in (venv / "pyvenv.cfg").read_text()


@pytest.mark.integration
def test_make_install_into_a_prefix_gives_a_venv_with_bundled_data_and_a_verified_unit(
        tmp_path):
    """``make install`` with every directory under a temporary prefix (no root): the wheel
    of this tree built and installed into the venv, offline (the venv made beforehand
    without pip, its dependencies this test venv's: tests/helpers/installed.py; PIP_ARGS
    ``--no-index --no-build-isolation``), the config, the unit pointing at that venv. The
    installed package replays a log from outside the checkout with the bundled config it
    detects; systemd-analyze verify passes on the installed unit."""
    if shutil.which("make") is None:
        pytest.skip("make is not installed (Debian: apt-get install make)")
    p = {k: str(tmp_path / k) for k in ("opt", "etc", "unit", "credstore")}
    venv = Path(p["opt"]) / "venv"
    venv_python = fresh_venv(venv, dependency_view(tmp_path / "deps"))
    r = subprocess.run(["make", "-s", "install", f"PREFIX={p['opt']}", f"SYSCONFDIR={p['etc']}",
                        f"UNITDIR={p['unit']}", f"CREDSTORE={p['credstore']}",
                        "PIP_ARGS=--no-index --no-build-isolation"],
                       cwd=REPO, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "onboard-0.1.0-py3-none-any.whl built from" in r.stdout, r.stdout
    where = subprocess.run([str(venv_python), "-c", "import onboard.core.config as m; "
                            "print(m.__file__); print(m.CONFIG_DIR)"], cwd=tmp_path,
                           env=clean_env(), capture_output=True, text=True, timeout=60)
    assert where.returncode == 0, where.stderr
    site = p["opt"] + "/venv/lib/"
    assert all(line.startswith(site) for line in where.stdout.split()), where.stdout
    log = REPO / "tests" / "data" / "replay" / "jaiabot-turns.tlog"
    replay = run_installed(venv, "replay", str(log), "--out", "replay", "--no-plot", cwd=tmp_path)
    assert replay.returncode == 0, replay.stderr
    assert "(detected: SERVO1_FUNCTION=26 steering" in replay.stdout, replay.stdout
    assert (tmp_path / "replay" / "estimates.csv").stat().st_size > 0
    unit = Path(p["unit"]) / "onboard.service"
    text = unit.read_text()
    assert f"\nExecStart={venv_python} -m onboard run --config ${{ONBOARD_CONFIG}}\n" in text
    assert f"\nEnvironment=ONBOARD_CONFIG={p['etc']}/onboard.toml\n" in text
    assert "\nLoadCredential=onboard-zenoh-user\n" in text and "\nDynamicUser=yes\n" in text
    docs = documentation_paths(text)
    assert docs and all(d.startswith(p["opt"] + "/doc/") and Path(d).is_file() for d in docs), docs
    assert load(Path(p["etc"]) / "onboard.toml").service.zenoh.config_file == f"{p['etc']}/zenoh-vehicle.json5"
    exe = shutil.which("systemd-analyze")
    if exe is None:
        pytest.skip("systemd-analyze is not installed (Debian: apt-get install systemd); "
                    "the install itself passed")
    v = subprocess.run([exe, "verify", str(unit)], capture_output=True, text=True, timeout=120)
    assert v.returncode == 0 and not v.stderr.strip(), v.stderr
    broken = tmp_path / "broken.service"  # the check can fail: a missing ExecStart binary
    broken.write_text(text.replace(str(venv_python), str(tmp_path / "nothing" / "python")))
    v = subprocess.run([exe, "verify", str(broken)], capture_output=True, text=True, timeout=120)
    assert v.returncode != 0 or v.stderr.strip()


# --------------------------------------------------------------------------- MAVLink out

@pytest.mark.integration
def test_mavlink_out_on_a_serial_port_nobody_reads_never_blocks_and_counts_its_drops():
    """A pseudo-terminal whose other end is not read fills up after a few kB, and then a
    serial write blocks: the publisher's calls still return (the writer thread waits), the
    overflow is counted, and once the port is read the frames are whole MAVLink."""
    import pty
    import threading

    from onboard.core.config import MavlinkOut
    from onboard.core.messages import EstimateRecord
    from onboard.service.publishers.mavlink_pub import MavlinkPublisher, WriterThread

    master, slave = pty.openpty()
    pub = MavlinkPublisher(MavlinkOut(url=os.ttyname(slave) + ",115200", rate_hz=1000.0), 3,
                           clock=lambda: 0.0)
    pub.start()
    link = pub.link
    assert isinstance(link, WriterThread)
    caller = threading.get_ident()
    rec = EstimateRecord(vehicle="v", pipeline="current", t=0.0,
                         values={"north": 0.1, "east": -0.2, "down": 0.0},
                         std={"north": 0.01, "east": 0.01, "down": 0.01})
    for i in range(3000):  # ~100 kB: far more than a pty holds
        pub._next_est = -1.0
        pub.publish_estimates([rec], now=float(i))
    assert link.dropped > 0  # the queue filled while the port was full: counted, not waited for
    assert link._thread.ident != caller
    os.set_blocking(master, False)
    mav = _mavlink2_parser()
    msgs = []
    for _ in range(200):
        try:
            data = os.read(master, 65536)
        except BlockingIOError:
            time.sleep(0.01)
            continue
        msgs.extend(m for m in (mav.parse_buffer(data) or []) if m.get_type() != "BAD_DATA")
        if len(msgs) > 100:
            break
    pub.close()
    os.close(master)
    os.close(slave)
    assert {"NAMED_VALUE_FLOAT", "WIND_COV"} <= {m.get_type() for m in msgs}


def _mavlink2_parser():
    """A pymavlink parser of the ardupilotmega dialect."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink2

    mav = mavlink2.MAVLink(None)
    mav.robust_parsing = True
    return mav


def test_records_written_after_close_are_ignored(tmp_path):
    from onboard.service.recorder import Recorder

    rec = Recorder(tmp_path, clock=lambda: 0.0)
    rec.close()
    rec.write(_records(1)[0])
    rec.flush(wait=True)
    rec.close()
    assert rec.records == 0
