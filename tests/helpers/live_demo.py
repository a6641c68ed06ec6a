"""A live demo run (``onboard.apps.demo.run_demo``: the simulator and the in-process
service on a shared clock) flown again slower while the machine could not keep up, so that
a test's accuracy checks look at a run that kept up, or at the slowest one flown."""

from __future__ import annotations

import asyncio
import io

from onboard.apps.service_bench import free_tcp_port

MAX_LATE_S = 1.0
"""A run whose simulator or service fell further behind the shared clock than this
(simulated s; the demo warns) could not keep up with its speed: it is flown again at half
the speed, down to ``MIN_SPEED``."""
MIN_SPEED = 2.5
TIMEOUT_S = 180.0
"""Wall seconds a run at 10x may take before it is taken for hung (scaled for slower runs)."""


def demo_that_kept_up(*args, speed: float = 10.0, **kwargs):
    """``run_demo(*args, speed=speed, **kwargs)`` on a free router port, flown again at half
    the speed while it fell behind; (the result, what it printed)."""
    from onboard.apps.demo import run_demo

    while True:
        out = io.StringIO()
        res = asyncio.run(asyncio.wait_for(
            run_demo(*args, speed=speed, out=out,
                     router_endpoint=f"tcp/127.0.0.1:{free_tcp_port()}", **kwargs),
            TIMEOUT_S * max(1.0, 10.0 / speed)))
        print(f"{args[0] if args else 'demo'} at {speed:g}x: simulator {res.sim_late_s:.2f} s, "
              f"service {res.service_late_s:.2f} s behind the clock at worst")
        if not max(res.sim_late_s, res.service_late_s) > MAX_LATE_S or speed / 2 < MIN_SPEED:
            return res, out.getvalue()
        speed /= 2
