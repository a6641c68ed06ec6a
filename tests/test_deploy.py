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
from tests.helpers.tls import make_test_certificates

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
    key = tmp_path / "onboard.mavlink.key"
    key.write_bytes(KEY)
    key.chmod(0o400)
    me = os.geteuid()
    _set_acl(key, (USER_OBJ, 4, NO_ID), (USER, 4, me), (GROUP_OBJ, 0, NO_ID), (MASK, 4, NO_ID),
             (OTHER, 0, NO_ID))
    assert key.stat().st_mode & 0o777 == 0o440  # what the old mode-bits check refused
    assert private_file_problem(key) is None
    assert load_signing_key("credential:onboard.mavlink.key") == KEY
    _set_acl(key, (USER_OBJ, 4, NO_ID), (USER, 4, me + 4242), (GROUP_OBJ, 0, NO_ID),
             (MASK, 4, NO_ID), (OTHER, 0, NO_ID))
    with pytest.raises(ConfigError, match=f"accessible by user {me + 4242}.*chmod 600"):
        load_signing_key("credential:onboard.mavlink.key")
    _set_acl(key, (USER_OBJ, 4, NO_ID), (GROUP_OBJ, 4, NO_ID), (GROUP, 4, 20), (MASK, 4, NO_ID),
             (OTHER, 0, NO_ID))
    with pytest.raises(ConfigError, match="accessible by its group"):
        load_signing_key("credential:onboard.mavlink.key")
    # a named entry masked to nothing grants nothing
    _set_acl(key, (USER_OBJ, 4, NO_ID), (USER, 4, me + 1), (GROUP_OBJ, 0, NO_ID), (MASK, 0, NO_ID),
             (OTHER, 0, NO_ID))
    assert private_file_problem(key) is None
    os.removexattr(key, "system.posix_acl_access")
    key.chmod(0o604)
    with pytest.raises(ConfigError, match=r"accessible by group or others \(mode 0604\)"):
        load_signing_key("credential:onboard.mavlink.key")


def test_the_user_password_file_holds_one_user_colon_password_line(tmp_path, monkeypatch):
    monkeypatch.setenv("CREDENTIALS_DIRECTORY", str(tmp_path))
    f = tmp_path / "onboard.zenoh-user"
    for text, ok in (("boat1:s3cr:et\n", ("boat1", "s3cr:et")), ("boat1\n", None),
                     ("boat1:\n", None), ("a:b\nc:d\n", None), (":pw\n", None)):
        f.write_text(text)
        f.chmod(0o600)
        if ok:
            assert read_user_password("credential:onboard.zenoh-user", "k") == ok
        else:
            with pytest.raises(ConfigError, match="k: "):
                read_user_password("credential:onboard.zenoh-user", "k")
    f.chmod(0o644)
    with pytest.raises(ConfigError, match="chmod 600"):
        read_user_password("credential:onboard.zenoh-user", "k")
    monkeypatch.setenv("CREDENTIALS_DIRECTORY", str(tmp_path / "missing"))
    with pytest.raises(ConfigError, match="No such file"):
        read_user_password("credential:onboard.zenoh-user", "k")


def _wait(cond, timeout: float = 8.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.05)
    return cond()


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
    from onboard.tools.service_bench import free_tcp_port

    certs = make_test_certificates(tmp_path)
    ep = f"tls/localhost:{free_tcp_port()}"
    conf = session_config("router", listen=[ep], config_file=str(ZENOH_DIR / "router-acl.json5"))
    conf.insert_json5("transport/auth/usrpwd/dictionary_file",
                      json.dumps(str(ZENOH_DIR / "credentials.example.txt")))
    conf.insert_json5("transport/link/tls/listen_private_key", json.dumps(str(certs["router_key"])))
    conf.insert_json5("transport/link/tls/listen_certificate", json.dumps(str(certs["router_pem"])))
    router = zenoh.open(conf)
    creds = tmp_path / "credentials"
    creds.mkdir(mode=0o700)
    shutil.copy(certs["ca_pem"], creds / "onboard.zenoh-ca.pem")
    (creds / "onboard.zenoh-user").write_text(f"boat1:{_credentials()['boat1']}\n")
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
        assert _wait(lambda: (pub.publish_estimates([rec]), "onboard/boat1/est/current" in got)[1])
        (creds / "onboard.zenoh-user").chmod(0o600)
        (creds / "onboard.zenoh-user").write_text("boat1:not-the-password\n")
        wrong = ZenohPublisher(zcfg, "boat1")
        with pytest.raises(Exception, match="(?i)unable to connect"):
            wrong.start()
        wrong.close()
    finally:
        pub.close()
        shore.close()
        router.close()


def test_the_service_refuses_to_start_with_a_missing_or_readable_zenoh_secret(tmp_path, monkeypatch):
    from onboard.service.daemon import Service
    from tests.helpers.service_config import service_config

    monkeypatch.setenv("CREDENTIALS_DIRECTORY", str(tmp_path))
    cfg = service_config(zenoh={"user_password_file": "credential:onboard.zenoh-user"},
                         mavlink={"enabled": False}, recorder={"enabled": False})
    with pytest.raises(ConfigError, match="service.zenoh.user_password_file: .*No such file"):
        Service(cfg, state_dir=tmp_path)
    (tmp_path / "onboard.zenoh-user").write_text("boat1:pw\n")
    (tmp_path / "onboard.zenoh-user").chmod(0o640)
    with pytest.raises(ConfigError, match="accessible by group or others.*chmod 600"):
        Service(cfg, state_dir=tmp_path)
    cfg = service_config(zenoh={"tls_private_key": str(tmp_path / "k")},
                         mavlink={"enabled": False}, recorder={"enabled": False})
    with pytest.raises(ConfigError, match="tls_private_key and tls_certificate go together"):
        Service(cfg, state_dir=tmp_path)
    assert ZenohOut().user_password_file == ""  # nothing asked, nothing read
