"""Command line: ``onboard <command>`` (also ``python -m onboard``).

The commands and their flags are a contract (architecture.md §4.1). This module only
parses arguments and dispatches; each command's work lives in its own module, imported
when the command runs so that ``onboard run`` on the vehicle never imports plotting or
optimization libraries.

Exit status: 0 success, 2 bad usage, unreadable input or an output path that cannot be
written (one line on stderr, before any work: :mod:`onboard.core.outputs`), 1 an output
that failed once the work had begun (one line naming it) or an internal error.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import Sequence

from onboard import __version__
from onboard.core.errors import OutputFailed, UsageError


LOG_HELP = ("the log to read: .tlog, DataFlash .bin, .mcap (a BlueOS recording), NMEA, DVL "
            "JSON or PD6 capture, CSV file or directory of CSV runs (with a [csv] mapping), "
            "or an onboard recording (.onbrec or its directory); the format is read from "
            "the content")


def _add_zenoh_flags(p: argparse.ArgumentParser) -> None:
    """The Zenoh connection flags shared by every command that talks Zenoh."""
    p.add_argument("--connect", action="append", default=None, metavar="ENDPOINT",
                   help="Zenoh endpoint to connect to (repeatable; default: those of "
                        "--zenoh-config, else tcp/127.0.0.1:7447)")
    p.add_argument("--listen", action="append", default=None, metavar="ENDPOINT",
                   help="Zenoh endpoint to listen on (repeatable)")
    p.add_argument("--mode", choices=("peer", "client"), default=None,
                   help="Zenoh session mode (default: that of --zenoh-config, else client)")
    p.add_argument("--zenoh-config", default="", metavar="FILE",
                   help="Zenoh JSON5 config: TLS, user/password (config/zenoh/shore.json5)")


FORCE_HELP = ("replace files a previous run wrote (an existing FILE, or what DIR holds from "
              "a previous run); without it they are refused before any work")


def build_parser() -> argparse.ArgumentParser:
    """The ``onboard`` argument parser: one subcommand per row of architecture.md §4.1,
    each with a ``handler`` default naming ``module:function`` to run."""
    parser = argparse.ArgumentParser(
        prog="onboard",
        description="Onboard estimation for small marine vehicles: thrust, current, "
        "disturbances, from GPS, IMU, compass, DVL and actuator commands.",
    )
    parser.add_argument("--version", action="version", version=f"onboard {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser("run", help="the onboard service (systemd ExecStart)")
    p.add_argument("--config", required=True, action="append", metavar="FILE",
                   help="vehicle/deployment TOML file; repeat to apply overlays in order "
                        "(later keys win)")
    p.add_argument("--state-dir", default=None, metavar="DIR",
                   help="directory for recordings and state, created if missing and reused "
                        "run after run (default: $STATE_DIRECTORY or the current directory)")
    p.set_defaults(handler="onboard.service.daemon:main")

    p = sub.add_parser("demo", help="simulated vehicle + service + shore view on loopback")
    p.add_argument("--duration", type=float, default=None,
                   help="simulated seconds (default 150)")
    p.add_argument("--scenario", default=None, help="SITL scenario (default: effect-current)")
    p.add_argument("--realtime", action="store_true", help="run at wall-clock speed")
    p.add_argument("--keep-state", action="store_true",
                   help="keep the adaptive state in demo-out/state and restore it next run "
                        "(default: a fresh temporary state); the demo writes in ./demo-out, "
                        "its recordings replaced each run")
    p.add_argument("--fleet", nargs="?", const="fleet-demo", default=None, metavar="NAME",
                   help="a fleet instead of one vehicle: each vehicle's simulator feeding its "
                        "own service on one Zenoh router (default fleet: fleet-demo)")
    p.set_defaults(handler="onboard.apps.demo_fleet:main")

    p = sub.add_parser("sitl", help="the simulator alone, emitting real protocols")
    p.add_argument("--list", action="store_true", help="list the scenarios and fleets")
    p.add_argument("--scenario", help="scenario name (see --list)")
    p.add_argument("--fleet", metavar="NAME",
                   help="several vehicles in a current field (see --list), written with --out")
    p.add_argument("--glider", action="store_true",
                   help="a Slocum glider's dives, its .dbd flight log and the truth of each "
                        "dive's depth-averaged current, written with --out")
    p.add_argument("--dives", type=int, default=None,
                   help="with --glider: how many dives (default 4)")
    p.add_argument("--out", metavar="DIR",
                   help="with --fleet: one log, truth, capture and config per vehicle, the "
                        "truth of the field and fleet.json in DIR; with --glider: the "
                        ".dbd and its .truth.json")
    p.add_argument("--duration", type=float, default=None, help="simulated seconds")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--tlog", metavar="FILE", help="write the MAVLink stream to this .tlog "
                   "(and the scenario's metadata beside it, FILE's stem + .scenario.json)")
    p.add_argument("--truth", metavar="FILE",
                   help="write the hidden truth (JSON lines) to this file")
    p.add_argument("--link", help="udp:HOST:PORT, tcp:HOST:PORT or pty")
    p.add_argument("--nmea-pty", action="store_true", help="emit NMEA on a pseudo-terminal")
    p.add_argument("--dvl", metavar="tcp:HOST:PORT|pty",
                   help="serve Water Linked DVL JSON on a TCP server, or Teledyne PD6 on a "
                        "pseudo-terminal (pty)")
    p.add_argument("--realtime", action="store_true", help="run at wall-clock speed")
    p.add_argument("--controller", choices=("pid", "nmpc", "nmpc-of", "ampc"), default=None,
                   help="closed-loop controller (bluerov2-circle)")
    p.add_argument("--report", metavar="FILE", help="write a JSON report of the run")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--stream-unasked", action="store_true",
                   help="the --link streams every message unasked (no stream negotiation)")
    p.add_argument("--reboot-at", type=float, action="append", metavar="S",
                   help="reboot the simulated autopilot at S seconds (repeatable)")
    p.add_argument("--other-components", action="store_true",
                   help="a ground station and a camera share the --link")
    p.add_argument("--link-delay", choices=("none", "tether"), default="none",
                   help="with --realtime: the live outputs' frames late by a delay that "
                        "wanders as a real link's (tether: the ArduSub tlog's, sitl.link); "
                        "default none: each frame on its simulation time")
    p.set_defaults(handler="onboard.sitl.cli:main")

    p = sub.add_parser("replay", help="run the pipelines over a recorded log")
    p.add_argument("log", metavar="LOG", help=LOG_HELP)
    p.add_argument("--config", action="append", metavar="FILE",
                   help="vehicle config (default: detect from the log); repeat to apply "
                        "overlays in order, e.g. one written by diagnose --write-config")
    p.add_argument("--out", default="replay-out", metavar="DIR",
                   help="output directory for estimates.csv, summary.json and track.png "
                        "(default ./replay-out; created if missing)")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--no-plot", action="store_true", help="skip the track figure")
    p.add_argument("--pipelines", metavar="NAMES",
                   help="run only these pipelines (comma-separated, e.g. current); the "
                        "others are off, as with enabled = false in the config; each "
                        "one's estimates are those of a replay with every pipeline")
    p.add_argument("--mcap", metavar="FILE", help="also write the estimates as MCAP (the "
                   "live Zenoh channels and schemas; needs the mcap extra)")
    p.add_argument("--geojson", metavar="FILE",
                   help="also write the tracks (one per pipeline and run) and current arrows "
                        "as GeoJSON (lon/lat, RFC 7946) to FILE")
    p.add_argument("--gpx", metavar="FILE",
                   help="also write the tracks (one per pipeline and run) as GPX 1.1 to FILE")
    p.add_argument("--foxglove-layout", metavar="FILE",
                   help="also write a Foxglove layout of the topics the replay published, "
                        "named with its vehicle id, to FILE")
    p.set_defaults(handler="onboard.offline.replay:main")

    p = sub.add_parser("diagnose", help="residuals, the missing effect, before/after")
    p.add_argument("log", metavar="LOG", help=LOG_HELP + "; at least 50 s with a heading "
                   "and a velocity over ground")
    p.add_argument("--config", action="append", metavar="FILE",
                   help="vehicle config (default: detect from the log); repeatable, "
                        "applied in order")
    p.add_argument("--out", default="diagnose-out", metavar="DIR",
                   help="output directory for diagnosis.json, report.html and its figures "
                        "(default ./diagnose-out; created if missing)")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--write-config", metavar="FILE",
                   help="write what the diagnosis found as a TOML config overlay, to pass "
                        "after the config: --config BASE --config FILE")
    p.set_defaults(handler="onboard.offline.diagnose:main")

    p = sub.add_parser("batch", help="replay (and diagnose) a season of logs into one "
                       "folder, with a table of the season (runs.parquet, current.parquet)")
    p.add_argument("logs", nargs="+", metavar="LOG|DIR",
                   help="logs, and folders searched for the files the readers recognise "
                        "(a folder of CSV runs or of .onbrec files is one log); other "
                        "files are listed as skipped")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output directory: a folder per log (estimates.csv, summary.json, "
                        "run.json, current.parquet; diagnose/ with --diagnose), "
                        "runs.parquet, current.parquet (docs/batch.md)")
    p.add_argument("--config", action="append", metavar="FILE",
                   help="vehicle config for every log (default: detected per log; a CSV "
                        "log takes the bundled config its header fits); repeatable, "
                        "applied in order")
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="local worker processes (default: the cores)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the logs on the Dask distributed cluster there, e.g. "
                        "tcp://10.0.0.5:8786 (its workers see the logs and --out at the "
                        "same paths; needs the batch extra)")
    p.add_argument("--diagnose", action="store_true",
                   help="also diagnose each log (diagnose/ in its folder) and write a "
                        "season report, season.md")
    p.add_argument("--force", action="store_true",
                   help="redo the logs done before (default: a log whose outputs are "
                        "complete is skipped) and reuse folders other runs wrote")
    p.set_defaults(handler="onboard.offline.batch:main")

    p = sub.add_parser("shore", help="live view of a vehicle's estimates from Zenoh")
    _add_zenoh_flags(p)
    p.add_argument("--prefix", default="onboard",
                   help="the key prefix the vehicles publish under, [service.zenoh] "
                        "key_prefix (default: onboard)")
    p.add_argument("--vehicle", default="*", help="vehicle id (default: all)")
    p.add_argument("--once", action="store_true", help="print one snapshot and exit")
    p.add_argument("--web", default="", metavar="HOST:PORT",
                   help="serve the live map page on HOST:PORT instead of printing the table")
    p.add_argument("--foxglove", metavar="[HOST:]PORT", help="also serve the records to "
                   "Foxglove on a WebSocket server there (needs the foxglove extra; "
                   "docs/foxglove.md)")
    p.set_defaults(handler="onboard.apps.shore:main")

    p = sub.add_parser("fleet", help="one current field from every vehicle's estimates, "
                       "served on Zenoh (docs/fleet.md)")
    _add_zenoh_flags(p)
    p.add_argument("--prefix", default="onboard",
                   help="the key prefix the vehicles publish under (default: onboard)")
    p.add_argument("--period", type=float, default=5.0, metavar="S",
                   help="seconds between two grids on <prefix>/fleet/current/grid "
                        "(default: 5)")
    p.add_argument("--refit", type=float, default=60.0, metavar="S",
                   help="seconds between two fits of the field's hyperparameters "
                        "(default: 60)")
    p.add_argument("--mcap", metavar="FILE",
                   help="also write every new grid into FILE (MCAP, for Foxglove; needs the "
                        "mcap extra)")
    p.add_argument("--web", default="", metavar="HOST:PORT",
                   help="serve the web page there: the field as arrows with their "
                        "uncertainty over the map, each vehicle's track and estimate")
    p.add_argument("--history", action="append", default=[], metavar="FILE",
                   help="first add the currents of an onboard batch table "
                        "(current.parquet, or the --out folder that holds it; "
                        "docs/batch.md), as if received live (repeatable; needs the "
                        "batch extra)")
    p.add_argument("--at", metavar="LAT,LON|signalk:URL",
                   help="send the field's current here as set and drift (--vdr, --signalk): "
                        "a fixed place, or the own vessel's position on a Signal K server "
                        "(signalk:http://HOST:PORT; docs/chartplotters.md)")
    p.add_argument("--vdr", metavar="udp:HOST:PORT",
                   help="with --at: NMEA 0183 VDR sentences there, once a second")
    p.add_argument("--signalk", metavar="udp:HOST:PORT",
                   help="with --at: Signal K environment.current deltas there (a Signal K "
                        "server's Signal K UDP input), once a second")
    p.add_argument("--max-std", type=float, default=0.0, metavar="M/S",
                   help="with --at: send nothing while the larger one-sigma of the current "
                        "there is above this (default: 0, no bound)")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.set_defaults(handler="onboard.fleet.service:main")

    p = sub.add_parser("bench", help="performance figures")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.set_defaults(handler="onboard.apps.bench:main")

    p = sub.add_parser("design-gain", help="solve the high-gain observer LMI offline")
    p.add_argument("--config", required=True, metavar="FILE")
    p.add_argument("--out", metavar="FILE", help="write the gain here (default: beside the "
                   "config; for a bundled config, its class's bundled gain, replaced)")
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.set_defaults(handler="onboard.apps.design_gain:main")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv`` (default ``sys.argv[1:]``), import the command's module and run it;
    return the exit status (a :class:`UsageError` prints one line and gives 2, as does an
    ImportError that names its ``pip install`` (an optional extra missing), an
    :class:`OutputFailed` one line and 1, Ctrl-C gives 130)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    module_name, func_name = args.handler.split(":")
    try:
        module = importlib.import_module(module_name)
        return int(getattr(module, func_name)(args) or 0)
    except UsageError as err:
        print(f"onboard {args.command}: {err}", file=sys.stderr)
        return 2
    except OutputFailed as err:
        print(f"onboard {args.command}: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    except ImportError as err:   # an optional extra missing: its message names the install
        if "pip install" not in str(err):
            raise
        print(f"onboard {args.command}: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
