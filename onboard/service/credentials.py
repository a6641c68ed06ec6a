"""Secrets of the service: systemd credentials and the privacy check of secret files.

Under the unit's ``DynamicUser=yes`` the service has no fixed uid, so it cannot own a
secret file in ``/etc``. systemd's credentials solve that (systemd.exec(5),
"Credentials"): ``LoadCredential=onboard-mavlink.key`` in ``systemd/onboard.service``
makes systemd read ``/etc/credstore/onboard-mavlink.key`` (root only) at each start and
place a copy in ``$CREDENTIALS_DIRECTORY`` that only the unit's user can read; a missing
one is skipped. In the configuration a secret is named ``credential:NAME``::

    [service.mavlink]
    signing_key_file = "credential:onboard-mavlink.key"

which :func:`resolve_secret` turns into ``$CREDENTIALS_DIRECTORY/NAME``. Run by hand
(``sudo CREDENTIALS_DIRECTORY=/etc/credstore onboard run ...``) the same names work.

Every secret file must be private: :func:`private_file_problem` refuses a file that a
group, another user or everyone may access. systemd grants the dynamic user access to a
credential through a POSIX ACL entry on a mode-0400 file, which shows as group bits in
the mode (the ACL mask); the check therefore reads the ACL itself
(``system.posix_acl_access``) and accepts a named-user entry for the service's own uid.
"""

from __future__ import annotations

import os
import stat
import struct
from pathlib import Path

from onboard.core.config import ConfigError

CREDENTIAL_PREFIX = "credential:"
"""A configured path starting with this names a systemd credential."""

_ACL_XATTR = "system.posix_acl_access"
_ACL_USER_OBJ, _ACL_USER, _ACL_GROUP_OBJ, _ACL_GROUP, _ACL_MASK, _ACL_OTHER = (
    0x01, 0x02, 0x04, 0x08, 0x10, 0x20)
_ACL_ENTRY = struct.Struct("<HHI")


def resolve_secret(value: str, key: str) -> Path:
    """The file a configured secret names: ``credential:NAME`` is
    ``$CREDENTIALS_DIRECTORY/NAME``; anything else is a path.

    Raises ConfigError (naming ``key``) when a credential is asked for but systemd set no
    credentials directory, or the name is not a plain file name.
    """
    if not value.startswith(CREDENTIAL_PREFIX):
        return Path(value)
    name = value[len(CREDENTIAL_PREFIX):]
    if not name or "/" in name or name in (".", ".."):
        raise ConfigError(f"{key}: {value!r}: a credential is a plain file name")
    base = os.environ.get("CREDENTIALS_DIRECTORY", "")
    if not base:
        raise ConfigError(f"{key}: {value} needs $CREDENTIALS_DIRECTORY, which systemd sets "
                          f"for LoadCredential= (systemd/onboard.service); by hand: "
                          f"CREDENTIALS_DIRECTORY=/etc/credstore onboard run ...")
    return Path(base) / name


def missing_hint(value: str) -> str:
    """What to add to "no such file" for ``value``: where a credential comes from."""
    if not value.startswith(CREDENTIAL_PREFIX):
        return ""
    name = value[len(CREDENTIAL_PREFIX):]
    return (f" (systemd loads it from /etc/credstore/{name}, root-owned, mode 0600, and "
            f"skips it when missing; the unit needs LoadCredential={name})")


def _acl_entries(path: Path) -> list[tuple[int, int, int]] | None:
    """The file's access ACL as (tag, perm, id) entries (None: no ACL, or none readable)."""
    try:
        raw = os.getxattr(path, _ACL_XATTR)
    except (OSError, AttributeError):  # no ACL (ENODATA), or not supported here
        return None
    if len(raw) < 4 or (len(raw) - 4) % _ACL_ENTRY.size:
        return None
    return [_ACL_ENTRY.unpack_from(raw, off) for off in range(4, len(raw), _ACL_ENTRY.size)]


def private_file_problem(path: str | Path, st: os.stat_result | None = None) -> str | None:
    """Why ``path`` is not private (None: only its owner, root and this process's user can
    access it). Reads the POSIX ACL when there is one (see the module docstring)."""
    p = Path(path)
    st = st if st is not None else p.stat()
    mode = stat.S_IMODE(st.st_mode)
    entries = _acl_entries(p)
    if not entries:
        if mode & (stat.S_IRWXG | stat.S_IRWXO):
            return f"is accessible by group or others (mode {mode:04o})"
        return None
    mask = next((perm for tag, perm, _ in entries if tag == _ACL_MASK), 7)
    me = {os.geteuid(), st.st_uid}
    for tag, perm, ident in entries:
        if tag == _ACL_OTHER and perm:
            return f"is accessible by others (mode {mode:04o})"
        if tag == _ACL_GROUP_OBJ and perm & mask:
            return f"is accessible by its group (ACL, mode {mode:04o})"
        if tag == _ACL_GROUP and perm & mask:
            return f"is accessible by group {ident} (ACL)"
        if tag == _ACL_USER and perm & mask and ident not in me:
            return f"is accessible by user {ident} (ACL)"
    return None


def read_secret(value: str, key: str, *, max_bytes: int = 1 << 16) -> tuple[Path, bytes]:
    """(path, content) of the configured secret ``value`` (see :func:`resolve_secret`),
    checked private. Raises ConfigError, naming ``key``, when it is missing, unreadable,
    larger than ``max_bytes`` or not private."""
    p = resolve_secret(value, key)
    try:
        st = p.stat()
        with open(p, "rb") as f:
            raw = f.read(max_bytes + 1)
    except OSError as err:
        hint = missing_hint(value) if isinstance(err, FileNotFoundError) else ""
        raise ConfigError(f"{key}: {p}: {err.strerror}{hint}") from None
    problem = private_file_problem(p, st)
    if problem is not None:
        raise ConfigError(f"{key}: {p} {problem}; chmod 600 it")
    if len(raw) > max_bytes:
        raise ConfigError(f"{key}: {p} is larger than {max_bytes} bytes")
    return p, raw


def read_user_password(value: str, key: str) -> tuple[str, str]:
    """``(user, password)`` from the secret file ``value``: one line ``user:password``,
    the format of the Zenoh router's ``dictionary_file`` (config/zenoh/credentials.example.txt)."""
    p, raw = read_secret(value, key)
    lines = [ln.strip() for ln in raw.decode("utf-8", "replace").splitlines() if ln.strip()]
    if len(lines) != 1 or ":" not in lines[0] or lines[0].startswith(":"):
        raise ConfigError(f"{key}: {p} must hold one line 'user:password'")
    user, _, password = lines[0].partition(":")
    if not password:
        raise ConfigError(f"{key}: {p}: the password after 'user:' is empty")
    return user, password
