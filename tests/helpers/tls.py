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
        pytest.skip("openssl is not installed: cannot make test certificates")
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
