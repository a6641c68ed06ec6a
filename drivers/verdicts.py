"""The signature verdicts of one chunk: which of its MAVLink frames the verifier rejected.

The shared record of :mod:`drivers.mavlink_signing` (whose :class:`VerdictLog` writes it
while the live service parses a chunk, and whose :class:`VerdictPlayer` rejects the same
frames on replay) and :mod:`drivers.recording` (which stores it as the payload of a
``verdicts`` record right after its chunk).
"""

from __future__ import annotations

import msgspec


class Verdicts(msgspec.Struct, array_like=True):
    """What an input's signature verifier decided while the chunk before this record was
    parsed live (the ``data`` of a ``verdicts`` record; its ``t`` and ``source`` are the
    chunk's). Written only when it rejected at least one frame of the chunk; a chunk with
    no ``verdicts`` record had every frame accepted.

    ``chunk_crc`` (CRC-32 of the chunk's bytes) binds the verdicts to their chunk;
    ``checks`` counts the frames the verifier saw while the chunk was parsed (frames
    completed by it, in parser order); ``rejected`` lists ``(index among those checks,
    reason, the frame's CRC-16)``, the CRC-16 being a check that replay is looking at the
    same frame.
    """

    chunk_crc: int
    checks: int
    rejected: list[tuple[int, str, int]]
