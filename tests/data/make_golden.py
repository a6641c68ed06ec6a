"""Regenerate the golden replay files in ``tests/data/replay``.

Each case is a short simulated log (the input, committed) and the ``estimates.csv`` that
``onboard replay`` writes for it (the expected output, committed beside it). The test
``tests/test_golden.py`` replays every input and compares the output byte for byte.

Run this only when a change of the estimates is intended, and say why in the commit::

    python tests/data/make_golden.py            # expected outputs only
    python tests/data/make_golden.py --inputs   # also re-simulate the input logs
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent / "replay"

CASES: dict[str, tuple[str, float, int]] = {
    # name: (SITL scenario, seconds, seed)
    "jaiabot-turns": ("jaiabot-turns", 40.0, 1),    # nav, aie, kf, current (surface boat)
    "bluerov2-circle": ("bluerov2-circle", 30.0, 1),  # eseso, current (ROV, DVL)
    "gavia-tidal": ("gavia-tidal", 20.0, 1),          # current (torpedo AUV, 3-D)
}


def replay_to(log: Path, expected: Path) -> None:
    """Run ``onboard replay`` on ``log`` and copy its estimates.csv to ``expected``."""
    from onboard.cli import main as cli_main

    with tempfile.TemporaryDirectory() as tmp:
        status = cli_main(["replay", str(log), "--out", tmp, "--no-plot"])
        if status != 0:
            raise SystemExit(f"replay of {log} failed with status {status}")
        shutil.copyfile(Path(tmp) / "estimates.csv", expected)


def main(argv: list[str] | None = None) -> int:
    """Write the expected outputs (and with ``--inputs`` the input logs)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--inputs", action="store_true", help="re-simulate the input logs too")
    args = ap.parse_args(argv)
    HERE.mkdir(parents=True, exist_ok=True)
    for name, (scenario, seconds, seed) in CASES.items():
        log = HERE / f"{name}.tlog"
        if args.inputs or not log.exists():
            from onboard.sitl.runner import run_to_tlog

            run_to_tlog(scenario, log, duration=seconds, seed=seed)
        replay_to(log, HERE / f"{name}.estimates.csv")
        print(f"{name}: {log.stat().st_size} bytes in, expected output written", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
