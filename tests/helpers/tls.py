"""Throw-away TLS material for the Zenoh tests, made with the openssl command."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest


def make_test_certificates(d: Path) -> dict[str, Path]:
    """A CA and a router certificate for localhost/127.0.0.1 in ``d`` (TEST ONLY: the keys
    live in the test's temporary directory): ``ca_pem``, ``router_key``, ``router_pem``.
    Skips the test when openssl is not installed."""
    exe = shutil.which("openssl")
    if exe is None:
        pytest.skip("openssl is not installed, so no test certificates (Debian: apt-get install openssl; see README)")
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    (d / "ext.cnf").write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n"
                               "basicConstraints=CA:FALSE\nkeyUsage=digitalSignature\n"
                               "extendedKeyUsage=serverAuth\n")
    for cmd in (
        ["req", "-x509", *ec, "-keyout", "ca.key", "-out", "ca.pem", "-days", "1",
         "-subj", "/CN=onboard-test-ca", "-addext", "basicConstraints=critical,CA:TRUE",
         "-addext", "keyUsage=critical,keyCertSign,cRLSign"],
        ["req", *ec, "-keyout", "router.key", "-out", "router.csr", "-subj", "/CN=localhost"],
        ["x509", "-req", "-in", "router.csr", "-CA", "ca.pem", "-CAkey", "ca.key",
         "-CAcreateserial", "-out", "router.pem", "-days", "1", "-extfile", "ext.cnf"],
    ):
        subprocess.run([exe, *cmd], cwd=d, check=True, capture_output=True, timeout=30)
    return {k: d / f"{k.replace('_', '.')}" for k in ("ca_pem", "router_key", "router_pem")}


def open_tls_acl_router(tmp_path: Path):
    """An in-process Zenoh router as the shipped ``config/zenoh/router-acl.json5`` makes it,
    listening on ``tls/`` with fresh test certificates and the example user/password
    dictionary. Returns ``(router, endpoint, certificates)``; the caller closes the router."""
    import json

    import zenoh

    from onboard.service.publishers.zenoh_pub import session_config
    from onboard.apps.service_bench import free_tcp_port

    zenoh_dir = Path(__file__).resolve().parents[2] / "config" / "zenoh"
    certs = make_test_certificates(tmp_path)
    ep = f"tls/localhost:{free_tcp_port()}"
    conf = session_config("router", listen=[ep], config_file=str(zenoh_dir / "router-acl.json5"))
    conf.insert_json5("transport/auth/usrpwd/dictionary_file",
                      json.dumps(str(zenoh_dir / "credentials.example.txt")))
    conf.insert_json5("transport/link/tls/listen_private_key", json.dumps(str(certs["router_key"])))
    conf.insert_json5("transport/link/tls/listen_certificate", json.dumps(str(certs["router_pem"])))
    return zenoh.open(conf), ep, certs
