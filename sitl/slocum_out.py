"""A Slocum glider's flight log as the glider writes it: a "dinkum binary" ``.dbd`` file.

The layout (Teledyne Webb Research, encoding version 5), as a file declares it:

* an ASCII header of ``num_ascii_tags`` lines ``key: value``;
* the sensor list, a line per sensor ``s: T <number> <index in cycle> <bytes> <name>
  <units>``, in the file (``sensor_list_factored: 0``) or in ``<crc>.cac`` beside it;
* the known bytes ``s``, ``a``, the integer 0x1234, the float 123.456 and the double
  123456789.12345, in the byte order of the values that follow;
* a record per cycle: ``d``, two state bits per sensor (four a byte, the first sensor in
  the high bits: 0 not updated, 1 updated with the value it had, 2 a new value, which
  follows), then the new values in sensor order (1 byte a signed integer, 2 a signed
  integer, 4 a float, 8 a double); ``X`` ends the file.

The glider opens a file with a cycle that carries every sensor's value: :meth:`DbdWriter.
write` puts one first. Latitude and longitude are degrees and decimal minutes
(``DDMM.MMMM``, signed), :func:`ddmm`.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from pathlib import Path

VALUE_FORMATS = {1: "b", 2: "h", 4: "f", 8: "d"}
"""struct format of a sensor's value by its size in bytes."""
UNCHANGED = None
"""A cycle's value for "updated, with the value it had" (state 1)."""


def ddmm(degrees: float) -> float:
    """Decimal degrees -> the glider's signed ``DDMM.MMMM``."""
    sign = -1.0 if degrees < 0 else 1.0
    d = abs(degrees)
    whole = int(d)
    return sign * (whole * 100.0 + (d - whole) * 60.0)


class DbdWriter:
    """Cycles into a ``.dbd`` file. ``sensors``: (name, units, bytes) in cycle order."""

    def __init__(self, sensors: Sequence[tuple[str, str, int]], full_filename: str,
                 crc: str = "0badcafe") -> None:
        for name, _, size in sensors:
            if size not in VALUE_FORMATS:
                raise ValueError(f"sensor {name}: {size} bytes is no dinkum value size")
        self.sensors = list(sensors)
        self.full_filename = full_filename
        self.crc = crc

    def sensor_lines(self) -> str:
        """The sensor list, as in the file or its ``.cac`` cache."""
        return "".join(f"s: T {i} {i} {size} {name} {units}\n"
                       for i, (name, units, size) in enumerate(self.sensors))

    def header(self, extension: str, factored: bool) -> str:
        """The ASCII header's lines."""
        n = len(self.sensors)
        tags = {"dbd_label": "DBD(dinkum_binary_data)file", "encoding_ver": "5",
                "num_ascii_tags": "", "all_sensors": "T",
                "the8x3_filename": "00010000", "full_filename": self.full_filename,
                "filename_extension": extension, "mission_name": "SITL.MI",
                "fileopen_time": "Thu_Jan__1_00:00:00_1970",
                "sensors_per_cycle": str(n), "num_label_lines": "3",
                "num_segments": "1", "segment_filename_0": self.full_filename,
                "total_num_sensors": str(n), "state_bytes_per_cycle": str((n + 3) // 4),
                "sensor_list_crc": self.crc,
                "sensor_list_factored": "1" if factored else "0"}
        tags["num_ascii_tags"] = str(len(tags))
        return "".join(f"{k}: {v}\n" for k, v in tags.items())

    def cycle(self, values: Mapping[str, float | None], order: str = ">") -> bytes:
        """One cycle's record: ``values`` maps a sensor to its new value, or to
        :data:`UNCHANGED`; a sensor absent was not updated."""
        n = len(self.sensors)
        state = bytearray((n + 3) // 4)
        data = bytearray()
        for k, (name, _, size) in enumerate(self.sensors):
            if name not in values:
                continue
            v = values[name]
            bits = 1 if v is UNCHANGED else 2
            state[k >> 2] |= bits << (6 - 2 * (k & 3))
            if v is not UNCHANGED:
                data += struct.pack(order + VALUE_FORMATS[size],
                                    int(round(v)) if size < 4 else v)
        return b"d" + bytes(state) + bytes(data)

    def write(self, path: Path, cycles: Sequence[Mapping[str, float | None]],
              opening: Mapping[str, float] | None = None, order: str = ">",
              cache_dir: Path | None = None, truncate: int = 0) -> Path:
        """Write ``path``: the header, the sensor list (in ``cache_dir/<crc>.cac`` where
        given), the known bytes, the opening cycle of every sensor (``opening``'s values,
        0 where it has none; none where ``opening`` is an empty mapping), ``cycles``, the
        end. ``truncate`` cuts that many bytes off the end (a file cut short)."""
        out = bytearray(self.header(path.suffix.lstrip("."), cache_dir is not None)
                        .encode())
        if cache_dir is not None:
            (cache_dir / f"{self.crc}.cac").write_text(self.sensor_lines())
        else:
            out += self.sensor_lines().encode()
        out += b"sa" + struct.pack(order + "hfd", 0x1234, 123.456, 123456789.12345)
        if opening is None or opening:
            first = dict.fromkeys((s[0] for s in self.sensors), 0.0)
            first.update(opening or {})
            out += self.cycle(first, order)
        for values in cycles:
            out += self.cycle(values, order)
        out += b"X"
        path.write_bytes(bytes(out[:len(out) - truncate]))
        return path
