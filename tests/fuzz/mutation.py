"""Mutations of valid inputs: bytes flipped, cut, inserted, duplicated; text fields replaced
by hostile tokens; a stream cut into chunks."""

from __future__ import annotations

import random

HOSTILE = ("", "nan", "NaN", "inf", "-inf", "1e999", "-1e999", "0", "-0", "x", "1.2.3",
           "99999999999", "-1", "1e-320", " ", "+", "--1", "0x10", "\x00", "\xff", "1_0", "٣", "∞")
"""Tokens that break number parsing in interesting ways."""


def mutate(data: bytes, rng: random.Random, n_ops: int = 3) -> bytes:
    """Byte-level mutations: flip, set to a magic value, delete, insert, duplicate, cut."""
    b = bytearray(data)
    for _ in range(n_ops):
        op = rng.randrange(7)
        if not b:
            b += rng.randbytes(rng.randint(1, 16))
            continue
        i = rng.randrange(len(b))
        if op == 0:
            b[i] ^= 1 << rng.randrange(8)
        elif op == 1:
            b[i] = rng.choice((0x00, 0xFF, 0xFD, 0xFE, 0xA3, 0x95, 0xA5, 0x5A, 0x24, 0x2A,
                               0x2C, 0x0A, 0x0D, 0x7B, 0x22, 0x3A, 0x80, 0x7F))
        elif op == 2:
            del b[i:i + rng.randint(1, 32)]
        elif op == 3:
            b[i:i] = rng.randbytes(rng.randint(1, 32))
        elif op == 4:
            j = rng.randrange(len(b))
            b[i:i] = b[j:j + rng.randint(1, 64)]
        elif op == 5:
            del b[i:]
        else:
            b[i] = rng.randrange(256)
    return bytes(b)


def mutate_fields(line: str, rng: random.Random, sep: str = ",") -> str:
    """Replace, drop or add comma-separated fields with hostile tokens."""
    f = line.split(sep)
    for _ in range(rng.randint(1, 3)):
        op = rng.randrange(4)
        i = rng.randrange(len(f))
        if op == 0:
            f[i] = rng.choice(HOSTILE)
        elif op == 1 and len(f) > 1:
            del f[i]
        elif op == 2:
            f.insert(i, rng.choice(HOSTILE))
        else:
            f[i] = f[i] + rng.choice(HOSTILE)
    return sep.join(f)


def chunked(data: bytes, cuts: list[int]) -> list[bytes]:
    """``data`` cut at the offsets ``cuts`` (each modulo ``len(data) + 1``), in order."""
    points = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    return [data[a:b] for a, b in zip(points, points[1:])]
