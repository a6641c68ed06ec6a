"""Calm-water calibration: the effects that belong to a vehicle, measured once.

Every hull slows down in turns and has more than linear drag; a small propeller's thrust
is not linear in its command. Those are the vehicle's own physics, not faults: measure them
once on a log in calm water with no known disturbance, and give them to ``onboard
diagnose`` as ``known`` (``[diagnose] known = {...}``), so that later logs are
diagnosed for what *changed* (a current, a fouled propeller, a bent compass)::

    python -m onboard.offline.closure.calibrate calm.tlog --config config/rudder-boat.toml \\
        --effects surge_yaw_coupling quadratic_drag thrust_nonlinearity

prints the TOML table to paste into the vehicle's config.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from onboard.offline.closure import dataset
from onboard.offline.closure import model as M
from onboard.offline.closure.effects import ALL
from onboard.offline.closure.select import _sigma
from onboard.offline.replay import choose_config


def calibrate(log: str, cfg, effects: tuple[str, ...], rate_hz: float = 10.0) -> dict[str, list[float]]:
    """Fit ``effects`` on the whole of ``log`` (with the base model's shaft lag, as
    ``onboard diagnose`` fits them); their parameters, by effect name."""
    ds = dataset.from_log(log, cfg, rate_hz=rate_hz)
    ds = dataset.lag_commands(ds, M.estimate_actuator_lag(ds))
    base0 = M.fit(ds, effects, {}, output_error=False)
    f = M.fit(ds, effects, _sigma(ds, base0), base0.ctx)
    return {name: [float(x) for x in np.asarray(f.theta[name])] for name in effects}


def main(argv: list[str] | None = None) -> int:
    """``python -m onboard.offline.closure.calibrate LOG [--config FILE] --effects NAME...``:
    print the ``[diagnose] known`` line that fixes those effects' parameters."""
    p = argparse.ArgumentParser(prog="python -m onboard.offline.closure.calibrate",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("log")
    p.add_argument("--config")
    p.add_argument("--effects", nargs="+", required=True, choices=sorted(ALL))
    args = p.parse_args(argv)
    cfg, _ = choose_config(args.log, args.config)
    known = calibrate(args.log, cfg, tuple(args.effects))
    items = ", ".join(f"{k} = [{', '.join(f'{v:.6g}' for v in vals)}]" for k, vals in known.items())
    print(f"[diagnose]\nknown = {{ {items} }}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
