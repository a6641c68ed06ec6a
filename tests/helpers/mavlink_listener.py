"""Reading what the service sends over MAVLink, as a ground station would (pymavlink)."""

from __future__ import annotations

import socket

from pymavlink.dialects.v20 import common as mavlink2


def receive_mavlink(sock: socket.socket, key: bytes | None = None) -> list:
    """Every MAVLink message waiting on the UDP socket ``sock``, decoded by pymavlink.

    Reads datagrams until none arrives for 0.5 s; frames pymavlink cannot decode
    (``BAD_DATA``) are left out. With a 32-byte signing ``key``, only frames signed with
    that key are returned (unsigned ones are refused)."""
    mav = mavlink2.MAVLink(None)
    mav.robust_parsing = True
    if key is not None:
        mav.signing.secret_key = key
        mav.signing.allow_unsigned_callback = lambda *a: False
    out = []
    sock.settimeout(0.5)
    while True:
        try:
            data = sock.recv(65536)
        except socket.timeout:
            return out
        for m in mav.parse_buffer(data) or []:
            if m.get_type() != "BAD_DATA":
                out.append(m)
