"""The long fuzz campaign: >= 100,000 inputs per parser (``slow``, outside the default suite).

    .venv/bin/python -m pytest -m slow tests/fuzz/test_campaign.py     # 100k inputs per parser
    ONBOARD_FUZZ_N=1000 .venv/bin/python -m pytest -m slow tests/fuzz/test_campaign.py  # a look

Same targets and properties as the property tests (:data:`tests.fuzz.targets.TARGETS`),
driven by a seeded mutation fuzzer instead of hypothesis (an order of magnitude more inputs
per second): input ``i`` of parser ``name`` is built from ``random.Random(f"{name}:{i}")``,
so any finding is reproduced by its (name, i) alone, from the repository root::

    import random
    from tests.fuzz import targets
    make, run = targets.TARGETS["recording"]
    rng = random.Random("recording:1234"); run(make(rng), rng)

Every exception and property violation is recorded by signature (type, innermost project
function, first line of the message) with the first and count of inputs that hit it; the
run continues. The result goes to ``$ONBOARD_FUZZ_REPORT`` (JSON, default
``fuzz-campaign.json`` in the temp dir); the test fails on any signature that is not a
known, reported bug (:data:`tests.fuzz.known_bugs.KNOWN_BUGS`). Results: docs/fuzzing.md.
"""

from __future__ import annotations

import json
import os
import random
import re
import tempfile
import time
import traceback
from pathlib import Path

import pytest

from tests.fuzz import targets
from tests.fuzz.known_bugs import KNOWN_BUGS, bug_signature

FUZZ_DIR = Path(__file__).resolve().parent
"""Where the targets' and properties' assertions live (a violation's signature names them)."""

N = int(os.environ.get("ONBOARD_FUZZ_N", "100000"))
REPORT = Path(os.environ.get("ONBOARD_FUZZ_REPORT",
                             Path(tempfile.gettempdir()) / "fuzz-campaign.json"))

UNGUARDED = {
    "nmea": lambda d, r: targets.run_nmea(d, [r.randrange(len(d) + 1)],
                                          r.choice(("rx", "utc"))),
    "mavlink": lambda d, r: targets.run_mavlink(d[0], [r.randrange(len(d[0]) + 1),
                                                       r.randrange(len(d[0]) + 1)], d[1]),
    "dvl_json": lambda d, r: targets.run_dvl(d, [r.randrange(len(d) + 1)]),
    "pd6": lambda d, r: targets.run_pd6(d, [r.randrange(len(d) + 1)],
                                        r.choice(("rx", "instrument")),
                                        r.choice(("ship", "instrument"))),
    "csv": lambda d, r: targets.run_csv(d, targets.csv_format(), "c.csv"),
    "tlog": lambda d, r: targets.run_tlog(d, "c.tlog"),
    "dataflash": lambda d, r: targets.run_dataflash(d, "c.bin"),
    "recording": lambda d, r: targets.run_recording(d[0], d[1], "c.onbrec"),
    "recording_v2": lambda d, r: targets.run_recording_v2(d[0], d[1], "c2.onbrec"),
    "text": lambda d, r: targets.run_text(d, "c.txt"),
}
"""The targets without the known-bug guard: the campaign classifies every exception itself."""


KNOWN_VIOLATIONS: dict[str, str] = {}
"""Property violations already reported (docs/fuzzing.md) and still open, by signature
(:func:`signature` -> finding). Empty: every reported violation is fixed, so any
signature fails the campaign."""


def signature(err: BaseException) -> str:
    """One line per kind of failure: exception type, innermost project function, first
    line of the message with numbers blanked; for a broken property, the assertion's
    source line in the fuzz targets."""
    typ, file, func = bug_signature(err)
    msg = str(err).splitlines()[0][:100] if str(err) else ""
    msg = re.sub(r"0x[0-9a-fA-F]+|\d+", "#", msg)  # one signature, whatever the byte values
    if isinstance(err, AssertionError):
        # the property, not the values: the assertion's source line
        frames = [f for f in traceback.extract_tb(err.__traceback__)
                  if Path(f.filename).resolve().parent == FUZZ_DIR]
        msg = frames[-1].line if frames else msg
        file, func = (Path(frames[-1].filename).name, frames[-1].name) if frames else (file, func)
    return f"{typ} in {file}:{func}: {msg}"


def campaign(name: str, n: int) -> dict:
    """Run ``n`` inputs of parser ``name``; the findings by signature with their count and
    first input, the bytes fuzzed and the wall time."""
    make, _ = targets.TARGETS[name]
    run = UNGUARDED[name]
    if name == "csv":
        fmt = targets.csv_format()
        run = lambda d, r: targets.run_csv(d, fmt, "c.csv")  # noqa: E731 - load the config once
    found: dict[str, dict] = {}
    t0 = time.perf_counter()
    total_bytes = 0
    for i in range(n):
        rng = random.Random(f"{name}:{i}")
        data = make(rng)
        total_bytes += len(data[0] if isinstance(data, tuple) else data)
        try:
            run(data, rng)
        except Exception as err:  # noqa: BLE001 - the campaign records everything
            sig = signature(err)
            f = found.setdefault(sig, {"count": 0, "first_input": i,
                                       "known": bug_signature(err) in KNOWN_BUGS
                                       or sig in KNOWN_VIOLATIONS})
            f["count"] += 1
    return {"parser": name, "inputs": n, "bytes": total_bytes,
            "wall_s": round(time.perf_counter() - t0, 1), "findings": found}


def _merge(result: dict) -> None:
    data = json.loads(REPORT.read_text()) if REPORT.exists() else {}
    data[result["parser"]] = result
    REPORT.write_text(json.dumps(data, indent=2) + "\n")


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(targets.TARGETS))
def test_campaign(name):
    """No input of parser ``name`` raises or breaks a property, except known bugs."""
    result = campaign(name, N)
    _merge(result)
    unknown = {s: f for s, f in result["findings"].items() if not f["known"]}
    assert not unknown, json.dumps(unknown, indent=2)
