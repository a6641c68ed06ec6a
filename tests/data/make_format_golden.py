"""Regenerate the expected outputs of the format golden files in ``tests/data/<format>/``.

Each input is a small hand-made capture, committed (a few dozen lines of NMEA, Water
Linked DVL JSON, PD6, a survey-boat Arduino+GPS capture, a BlueBoat-style CSV), with
valid records and the damage a real link or logger produces (a bad checksum, a cut-off
line, a repeated reading, lost bottom lock, time going back). Beside each input, the
expected output of reading it as ``onboard replay`` does (:func:`drivers.logs.open_log`,
the format sniffed from the content):

* ``<stem>.samples.jsonl``: the samples, one per line, as msgspec JSON (the ``type``
  tag first, every field, in the order the reader yields them);
* ``<stem>.counts.json``: the sniffed format, the reader, and its counters: records
  seen, samples produced, rejections by reason, records by type.

``tests/test_format_golden.py`` reads every input and compares both outputs byte for
byte. Run this only when a change of a reader's output is intended, and say why in the
commit (the inputs are never regenerated: they are the fixed reference)::

    python tests/data/make_format_golden.py
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import msgspec

HERE = Path(__file__).resolve().parent

CASES: dict[str, str | None] = {
    # input (relative to tests/data): the config whose [csv] mapping reads it, if needed
    "nmea/gnss-compass.nmea": None,
    "dvl_json/a50.jsonl": None,
    "pd6/ensembles.pd6": None,
    "survey_boat/arduino-gps.txt": None,
    "csv/blueboat-run.csv": "blueboat-ntnu-csv",
}
"""The golden inputs."""


def expected_paths(capture: Path) -> tuple[Path, Path]:
    """The committed expected outputs of ``capture``: (samples, counts)."""
    return (capture.with_name(capture.stem + ".samples.jsonl"),
            capture.with_name(capture.stem + ".counts.json"))


def render(capture: Path, config: str | None) -> tuple[str, str]:
    """Read ``capture`` as ``onboard replay`` would; (samples text, counts text)."""
    from onboard.drivers.logs import open_log
    from onboard.core import config as configmod

    csv_format = configmod.load(configmod.resolve(config)).csv if config else None
    fmt, reader = open_log(capture, csv_format)
    lines = [msgspec.json.encode(s).decode() + "\n" for s in reader]
    counts = {"format": fmt, "reader": type(reader).__name__, **reader.stats.as_dict()}
    return "".join(lines), json.dumps(counts, indent=2) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Write the expected outputs of every case."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.parse_args(argv)
    for name, config in CASES.items():
        capture = HERE / name
        samples, counts = render(capture, config)
        samples_path, counts_path = expected_paths(capture)
        samples_path.write_text(samples)
        counts_path.write_text(counts)
        print(f"{name}: {samples.count(chr(10))} samples", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
