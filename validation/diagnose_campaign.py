"""False-alarm and recovery rates of ``onboard diagnose`` over simulator seeds.

For each boat, the clean scenario is flown with every seed and diagnosed with the boat's
calm-water configuration: a *false alarm* is a log on which anything is named or an
unexplained residual is reported. Each effect scenario is flown with the same seeds: the
effect is *recovered* when the injected effect is named (the others may come along; they
are counted apart as extras). Logs are cached in ``--work`` by scenario and seed, so a
change to the diagnosis reruns only the diagnosis::

    python -m validation.diagnose_campaign --seeds 1-10 --work /tmp/campaign
    python -m validation.diagnose_campaign --boat twin-thruster --seeds 1-3 --no-effects

prints one line per scenario: runs, the rate, and the seeds that missed. docs/diagnose.md
keeps the table with its date.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path

from validation.reports.runs import DIAGNOSE_SCENARIOS, REPO, SITL_DIAGNOSE_CONFIG

BOATS: dict[str, dict] = {
    "rudder-boat": {
        "config": SITL_DIAGNOSE_CONFIG,
        "clean": "clean",
        "effects": DIAGNOSE_SCENARIOS,
    },
    "twin-thruster": {
        "config": REPO / "config" / "sitl-twin-thruster.toml",
        "clean": "clean-twin-thruster",
        "effects": {"effect-thruster-swap": ("actuator_mapping",)},
    },
    "catamaran": {
        "config": REPO / "config" / "sitl-catamaran.toml",
        "clean": "cat-clean",
        "effects": {"cat-gps-latency": ("gps_latency",)},
    },
}
"""Each boat's calm-water configuration, clean scenario and effect scenarios (with the
effects that must be named)."""


@dataclass
class Outcome:
    """One diagnosed log: what was named, and whether a residual was left unexplained."""

    scenario: str
    seed: int
    named: tuple[str, ...]
    unexplained: bool
    params: dict = field(default_factory=dict)


def diagnose_seed(scenario: str, seed: int, config_path: Path, work: Path,
                  base_terms: tuple[str, ...] | None = None) -> Outcome:
    """Fly ``scenario`` with ``seed`` (cached in ``work``) and diagnose it with the
    configuration at ``config_path`` (and the base model's ``base_terms``, default the
    configuration's: :func:`onboard.offline.diagnose.diagnose`)."""
    from onboard.core import config
    from onboard.offline.diagnose import diagnose
    from onboard.sitl.runner import run_to_tlog

    d = work / f"{scenario}-s{seed}"
    d.mkdir(parents=True, exist_ok=True)
    log = d / "log.tlog"
    if not log.exists() or log.stat().st_size == 0:
        tmp = d / "log.tlog.part"
        run_to_tlog(scenario, tmp, d / "truth.jsonl", seed=seed)
        tmp.rename(log)
    out = d / ("out" if base_terms is None else "out-" + "-".join(base_terms))
    doc = diagnose(str(log), config.load(config_path), out, base_terms=base_terms)
    named = tuple(e["name"] for e in doc["effects"] if e["detected"])
    params = {e["name"]: e["params"] for e in doc["effects"] if e["detected"]}
    return Outcome(scenario, seed, named, bool(doc.get("unexplained")), params)


def is_false_alarm(o: Outcome) -> bool:
    """A clean log on which anything is named or a residual is left unexplained."""
    return bool(o.named) or o.unexplained


def recovered(o: Outcome, expected: tuple[str, ...]) -> bool:
    """Every expected effect is named."""
    return set(expected) <= set(o.named)


def parse_seeds(text: str) -> list[int]:
    """``"1-10"`` or ``"1,4,7"`` (or both, comma-separated) as a list of seeds."""
    out: list[int] = []
    for part in text.split(","):
        if "-" in part:
            a, b = part.split("-")
            out += list(range(int(a), int(b) + 1))
        elif part:
            out.append(int(part))
    return out


def main(argv: list[str] | None = None) -> int:
    """Run the campaign and print the rates (module docstring)."""
    p = argparse.ArgumentParser(prog="python -m validation.diagnose_campaign",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--boat", choices=sorted(BOATS), action="append")
    p.add_argument("--seeds", default="1-10")
    p.add_argument("--work", default="/tmp/diagnose-campaign")
    p.add_argument("--no-effects", action="store_true", help="clean logs only")
    p.add_argument("--only", nargs="*", help="these scenarios only")
    p.add_argument("--json", help="also write every outcome to this file")
    p.add_argument("--base-terms", nargs="*", help="the base model's optional terms "
                   "(actuator_lag course_lag speed_drift, or none); default the config's")
    args = p.parse_args(argv)
    seeds = parse_seeds(args.seeds)
    work = Path(args.work)
    rows = []
    for boat in args.boat or list(BOATS):
        spec = BOATS[boat]
        todo = [(spec["clean"], None)]
        if not args.no_effects:
            todo += list(spec["effects"].items())
        for scenario, expected in todo:
            if args.only and scenario not in args.only:
                continue
            terms = None if args.base_terms is None else tuple(args.base_terms)
            outs = [diagnose_seed(scenario, s, spec["config"], work, terms) for s in seeds]
            if expected is None:
                bad = [o for o in outs if is_false_alarm(o)]
                what = "false alarms"
            else:
                bad = [o for o in outs if not recovered(o, expected)]
                what = "recovered"
            n_ok = len(bad) if expected is None else len(outs) - len(bad)
            misses = ", ".join(f"s{o.seed}:{'+'.join(o.named) or '-'}"
                               f"{'+unexplained' if o.unexplained else ''}" for o in bad)
            print(f"{boat:14s} {scenario:28s} {what:12s} {n_ok}/{len(outs)} "
                  f"({100.0 * n_ok / len(outs):.0f} %)  {misses}", flush=True)
            rows += [{"boat": boat, **vars(o)} for o in outs]
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=list))
    return 0


if __name__ == "__main__":
    sys.exit(main())
