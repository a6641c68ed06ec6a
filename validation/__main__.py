"""``python -m validation COMMAND``: the evidence behind the published numbers, from a
checkout (docs/reproducing.md).

* ``figures``: recompute the README's and the docs tables' figures; write or check
  docs/figures.json; regenerate the tables from it (:mod:`validation.figures`).
* ``tune``: tune a filter's noise parameters by the common protocol and evaluate them on
  held-out runs (:mod:`validation.tuning`).

Exit status as ``onboard``'s: 0 success, 1 a figure outside its tolerance, 2 bad usage.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import Sequence

from onboard.core.errors import UsageError


def build_parser() -> argparse.ArgumentParser:
    """The parser: one subcommand per tool, each with a ``handler`` naming
    ``module:function``."""
    parser = argparse.ArgumentParser(prog="python -m validation", 
                                     description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser("figures", help="recompute the README's and the docs tables' "
                       "figures; write or check docs/figures.json, regenerate the tables")
    p.add_argument("--only", action="append", default=None, metavar="PATTERN",
                   help="figures whose name matches this glob or prefix (repeatable), "
                        "e.g. 'aie.*' or current.gavia_tidal")
    p.add_argument("--write", metavar="FILE", help="write the figures to FILE (merged into "
                   "it when it exists), e.g. docs/figures.json")
    p.add_argument("--check", metavar="FILE", help="compare with FILE; exit 1 when a "
                   "figure is outside its tolerance")
    p.add_argument("--readme", metavar="FILE", help="rewrite FILE's figures block from the "
                   "file written (alone: from docs/figures.json, nothing recomputed)")
    p.add_argument("--docs", metavar="DIR", help="rewrite the generated tables of the pages "
                   "in DIR (e.g. docs) from the file written (alone: from "
                   "docs/figures.json, nothing recomputed)")
    p.add_argument("--results", metavar="FILE", help="write the results file (CSV: name, "
                   "scenario, seed, value, unit, reference) from the file written (alone: "
                   "from docs/figures.json), e.g. docs/results.csv")
    p.set_defaults(handler="validation.figures:main")

    p = sub.add_parser("tune", help="tune a filter's noise parameters by the common "
                       "protocol and evaluate it on held-out runs (validation/tuning.py)")
    p.add_argument("variants", nargs="*", metavar="VARIANT",
                   help="aie, kf, an ablation variant or eseso (see --list)")
    p.add_argument("--list", action="store_true", help="list the variants")
    p.add_argument("--budget", type=int, default=None,
                   help="objective evaluations per variant (default: the protocol's)")
    p.add_argument("--no-tune", action="store_true",
                   help="evaluate the shipped defaults only")
    p.add_argument("--out", metavar="FILE", help="merge the results into this JSON file")
    p.add_argument("--page", metavar="FILE", help="rewrite the ablation table of this page "
                   "(docs/aie.md) from --out (alone: from docs/tuning.json)")
    p.set_defaults(handler="validation.tuning_eseso:tune_command")

    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv``, run the command; a :class:`UsageError` prints one line and gives 2."""
    args = build_parser().parse_args(argv)
    module_name, func_name = args.handler.split(":")
    try:
        return int(getattr(importlib.import_module(module_name), func_name)(args) or 0)
    except UsageError as err:
        print(f"python -m validation {args.command}: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
