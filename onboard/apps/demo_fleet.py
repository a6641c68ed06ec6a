"""``onboard demo --fleet [NAME]``: a fleet of simulated vehicles, each feeding its own
service, on one Zenoh router, with the true current field beside.

What runs (all on 127.0.0.1)::

    per vehicle of the fleet (sitl.fleet): a SITL child process (onboard.apps.demo's, on
    the vehicle's own protocols: MAVLink over UDP, NMEA fixes and headings on a pty for
    a boat, Water Linked DVL JSON over TCP for an AUV; stamped with the vehicle's own
    UTC) -> its own onboard service (in-process, vehicle id and MAVLink system id its
    own, a Zenoh client of the shared router, its recording under demo-out/fleet/<id>/)
    the shared Zenoh router; a shore view subscribed to onboard/** on it

The demo's moving parts are :class:`FleetMember` s, started in order by
:func:`run_members` and stopped in reverse: one :class:`SimulatorMember` and one
:class:`ServiceMember` per vehicle. A fleet service that fuses the vehicles' currents is
one more member on the same router: :class:`CommandMember` runs any command with the
router's endpoint (e.g. ``onboard fleet --connect ENDPOINT``), passed in ``extra``.

Live, every wall second (or :data:`LIVE_LINES` times a run): per vehicle its newest
water current with its one-sigma beside the true current at its true position and time
(the field of :mod:`sitl.current_field`, read from the child's truth file as it is
written). At the end, per vehicle: the RMS error per component of the current it
published as known (its one-sigma at most ``[pipelines.current] unknown_above_std_mps``)
against the truth at the same time, and the share within 1.96 of its sigma.
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import json
import math
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, Sequence, TextIO

import msgspec
import numpy as np

from onboard.apps import demo
from onboard.apps.demo import (LIVE_LINES, LinkPlan, _free_port, _port_free, _read_json,
                               DEFAULT_ROUTER, demo_config)
from onboard.core.config import Config, load
from onboard.core.errors import SigtermAsInterrupt, UsageError
from onboard.core.outputs import Output, check as check_outputs

DEFAULT_FLEET = "fleet-demo"
FLEET_DURATION_S = 300.0
"""Simulated seconds of the default fleet demo."""
FLEET_SPEED = 5.0
"""Clock speed-up of the fleet demo (several simulators and services share the CPU)."""
Z95 = 1.96


class FleetMember(Protocol):
    """One moving part of the fleet demo: started in order, stopped in reverse."""

    name: str

    async def start(self, start: float) -> None:
        """Start; ``start`` is the time.monotonic() instant of the fleet's t = 0."""

    async def stop(self) -> None:
        """Stop and release everything (also after a failed start)."""


@dataclass
class SimulatorMember:
    """A fleet vehicle's simulator: the demo's SITL child on the vehicle's own links."""

    plan: LinkPlan
    start_delay_s: float
    speed: float
    name: str = ""
    hello: dict[str, Any] = field(default_factory=dict)
    result: dict[str, Any] = field(default_factory=dict)
    proc: subprocess.Popen | None = None
    _done: Any = None

    async def spawn(self) -> dict[str, Any]:
        """Start the child and return its hello (its pty and DVL links)."""
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "onboard.apps.demo", "--sitl-child",
             json.dumps(dataclasses.asdict(self.plan))],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, bufsize=1)
        hello = await _read_json(self.proc, 60.0)
        if hello is None:
            raise RuntimeError(f"{self.name}: the simulator did not start "
                               f"(exit status {self.proc.poll()})")
        self.hello = hello
        return hello

    async def start(self, start: float) -> None:
        """Tell the child when its t = 0 is: the fleet's plus the vehicle's launch delay."""
        assert self.proc is not None and self.proc.stdin is not None
        self.proc.stdin.write(json.dumps({"start": start + self.start_delay_s / self.speed}) + "\n")
        self.proc.stdin.flush()
        self._done = asyncio.ensure_future(
            _read_json(self.proc, self.plan.duration_s / self.speed + 120.0))

    def done(self) -> bool:
        """Whether the child has reported the end of its run."""
        if self._done is not None and self._done.done():
            msg = self._done.result()
            self.result = msg if isinstance(msg, dict) else {}
            return True
        return False

    async def stop(self) -> None:
        """Close the child's stdin (it stops), wait for it (killed after 10 s)."""
        p = self.proc
        if p is None:
            return
        try:
            if p.stdin is not None:
                p.stdin.close()
        except OSError:
            pass
        try:
            p.wait(10.0)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
        if p.stdout is not None:
            p.stdout.close()
        self.proc = None


@dataclass
class ServiceMember:
    """A fleet vehicle's onboard service (in-process) on its simulator's links."""

    cfg: Config
    state_dir: Path
    speed: float
    start_delay_s: float
    name: str = ""
    svc: Any = None

    async def start(self, start: float) -> None:
        """Start the service on the shared clock, from the vehicle's launch."""
        from onboard.service.daemon import Service, ServiceClock

        clock = ServiceClock(speed=self.speed, origin=0.0,
                             start=start + self.start_delay_s / self.speed)
        self.svc = Service(self.cfg, state_dir=self.state_dir, clock=clock)
        await self.svc.start()

    async def stop(self) -> None:
        """Shut the service down (given :data:`onboard.apps.demo.STOP_TIMEOUT_S`)."""
        if self.svc is not None:
            svc, self.svc = self.svc, None
            if not await demo.stop_service(svc, demo.STOP_TIMEOUT_S):
                print(f"{self.name}: not stopped after {demo.STOP_TIMEOUT_S:g} s, left behind",
                      file=sys.stderr, flush=True)


@dataclass
class CommandMember:
    """Any command on the fleet's router (``{endpoint}`` in ``argv`` is replaced by the
    router's endpoint): the seam for a shore process such as a fleet service."""

    argv: list[str]
    name: str = ""
    log: Path | None = None
    """Where its output goes (None: the demo's terminal)."""
    proc: subprocess.Popen | None = None

    async def start(self, start: float) -> None:
        """Start the command, in a process group of its own: Ctrl-C at the terminal
        reaches the demo, which stops the command (:meth:`stop`) in its turn."""
        out = None if self.log is None else open(self.log, "w")  # noqa: SIM115 - the child's
        self.proc = subprocess.Popen(self.argv, stdout=out,
                                     stderr=subprocess.STDOUT if out else None, process_group=0)
        if out is not None:
            out.close()

    async def stop(self) -> None:
        """Terminate the command (killed after 10 s)."""
        if self.proc is not None:
            self.proc.terminate()
            try:
                self.proc.wait(10.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
            self.proc = None


async def run_members(members: Sequence[FleetMember], start: float,
                      until: Any, period_s: float, tick: Any) -> None:
    """Start ``members`` in order for the fleet's t = 0 at ``start`` (monotonic), call
    ``tick()`` every ``period_s`` wall seconds until ``until()`` is true, then stop them
    in reverse order (also on an error)."""
    started: list[FleetMember] = []
    try:
        for m in members:
            await m.start(start)
            started.append(m)
        next_tick = time.monotonic() + 1.0
        while not until():
            if time.monotonic() >= next_tick:
                next_tick += period_s
                tick()
            await asyncio.sleep(0.05)
    finally:
        for m in reversed(started):
            await m.stop()


# --------------------------------------------------------------------------- truth


def last_truth(path: str) -> dict[str, Any] | None:
    """The newest complete truth record of a truth file being written (None: none yet)."""
    try:
        with open(path, "rb") as f:
            f.seek(0, 2)
            size = f.tell()
            f.seek(max(0, size - 4096))
            lines = f.read().split(b"\n")
    except OSError:
        return None
    for line in reversed(lines[:-1] if lines and lines[-1] else lines):
        try:
            return json.loads(line)
        except ValueError:
            continue
    return None


def vehicle_line(vid: str, rec: Any, truth: dict[str, Any] | None) -> str:
    """One vehicle's live line: its current (or unknown, with its sigma) beside the true
    current at its position."""
    parts = [f"{vid:>7}"]
    if truth is not None:
        parts.append(f"t={truth['t']:4.0f} s true N {truth['current_north']:+.3f} "
                     f"E {truth['current_east']:+.3f}")
    if rec is None:
        parts.append("no current yet")
    else:
        for q, label in (("north", "N"), ("east", "E")):
            sd = rec.std.get(q)
            if q in rec.values:
                parts.append(f"est {label} {rec.values[q]:+.3f} ± {sd:.3f}" if sd is not None
                             else f"est {label} {rec.values[q]:+.3f}")
            else:
                parts.append(f"est {label} unknown" + (f" (sigma {sd:.2f})" if sd else ""))
    return " | ".join(parts)


def score_vehicle(history: list[Any], truth: list[Any], after_s: float = 0.0
                  ) -> dict[str, dict[str, float]]:
    """Per component: ``n`` known estimates (published, t > ``after_s``), their RMS error
    against the truth at the same time (linear interpolation) and the share within
    1.96 sigma."""
    out: dict[str, dict[str, float]] = {}
    if not truth:
        return out
    tt = np.array([r.t for r in truth])
    for q, key in (("north", "current_north"), ("east", "current_east")):
        tv = np.array([getattr(r, key) for r in truth])
        rows = [(r.t, r.values[q], r.std.get(q, math.nan)) for r in history
                if r.pipeline == "current" and q in r.values and r.t > after_s]
        if not rows:
            out[q] = {"n": 0, "rms": math.nan, "cover95": math.nan}
            continue
        t, v, sd = (np.array(c) for c in zip(*rows))
        err = v - np.interp(t, tt, tv)
        out[q] = {"n": len(rows), "rms": float(np.sqrt(np.mean(err**2))),
                  "cover95": float(np.mean(np.abs(err) < Z95 * sd))}
    return out


# --------------------------------------------------------------------------- the demo


def vehicle_config(fleet: Any, v: Any) -> Config:
    """The vehicle's onboard config, as the offline fleet writes it: its kind's bundled
    config (``sitl.fleet.BASE_CONFIGS``) with its identity."""
    from onboard.sitl.fleet import BASE_CONFIGS, vehicle_class

    base = load(BASE_CONFIGS[v.kind])
    ident = msgspec.structs.replace(base.vehicle, id=v.id, vehicle_class=vehicle_class(v),
                                    system_id=v.system_id,
                                    description=f"{v.kind} of fleet {fleet.name}")
    return msgspec.structs.replace(base, vehicle=ident)


async def _vehicle_members(fleet: Any, v: Any, *, seed: int, fleet_seed: int, speed: float,
                           duration_s: float, endpoint: str, out_dir: Path, state_root: Path
                           ) -> tuple[SimulatorMember, ServiceMember]:
    dur = max(1.0, duration_s - v.start_delay_s)
    dvl = v.kind == "torpedo-auv"
    plan = LinkPlan(scenario=v.id, duration_s=dur, seed=seed, speed=speed,
                    mavlink_udp_port=_free_port(socket.SOCK_DGRAM),
                    dvl_tcp_port=_free_port(socket.SOCK_STREAM) if dvl else None,
                    truth_path=str(out_dir / f"{v.id}.truth.jsonl"),
                    nmea=v.kind == "rudder-boat", fleet=fleet.name,
                    fleet_seed=fleet_seed)
    sim = SimulatorMember(plan, v.start_delay_s, speed, name=f"{v.id} simulator")
    hello = await sim.spawn()
    cfg = demo_config(vehicle_config(fleet, v), mav_port=plan.mavlink_udp_port,
                      nmea_pty=hello["nmea_pty"],
                      dvl_port=plan.dvl_tcp_port if hello["dvl"] else None,
                      zenoh_endpoint=endpoint, mavlink_out="udpout:127.0.0.1:14550",
                      state_file=str(state_root / v.id / "adaptive.json"))
    (out_dir / v.id).mkdir(parents=True, exist_ok=True)
    return sim, ServiceMember(cfg, out_dir / v.id, speed, v.start_delay_s,
                              name=f"{v.id} service")


async def run_fleet_demo(fleet_name: str = DEFAULT_FLEET, duration_s: float = FLEET_DURATION_S,
                         *, speed: float = FLEET_SPEED, seed: int = 1,
                         out_dir: Path = Path("demo-out") / "fleet",
                         router_endpoint: str | None = None, out: TextIO | None = sys.stdout,
                         extra: Sequence[FleetMember] = ()) -> dict[str, Any]:
    """Run the fleet demo (see the module docstring); ``extra`` members (e.g. a
    :class:`CommandMember` running a fleet service) start after the vehicles. Returns
    per vehicle its records received over Zenoh, its truth and its score
    (:func:`score_vehicle`)."""
    from onboard.apps.shore import ShoreView, open_session
    from onboard.service.publishers.zenoh_pub import open_router
    from onboard.sitl.fleet import get_fleet
    from onboard.sitl.runner import read_truth

    def say(text: str) -> None:
        if out is not None:
            print(text, file=out, flush=True)

    fleet = get_fleet(fleet_name).at_seed(seed)
    out_dir = Path(out_dir)
    shutil.rmtree(out_dir, ignore_errors=True)
    out_dir.mkdir(parents=True, exist_ok=True)
    endpoint = router_endpoint or (DEFAULT_ROUTER if _port_free(7447) else
                                   f"tcp/127.0.0.1:{_free_port(socket.SOCK_STREAM)}")
    state_root = Path(tempfile.mkdtemp(prefix="onboard-fleet-state-"))
    router = open_router(endpoint)
    shore = sub = None
    members: list[Any] = []
    sims: list[SimulatorMember] = []
    view = ShoreView(keep_history=True)
    t_wall0 = time.monotonic()
    try:
        shore = open_session([endpoint], None, "client")
        sub = shore.declare_subscriber("onboard/**", view.on_sample)
        for i, v in enumerate(fleet.vehicles):
            members += await _vehicle_members(fleet, v, seed=seed + i, fleet_seed=seed,
                                              speed=speed, duration_s=duration_s,
                                              endpoint=endpoint,
                                              out_dir=out_dir, state_root=state_root)
        for m in extra:
            if isinstance(m, CommandMember):
                m.argv = [a.replace("{endpoint}", endpoint) for a in m.argv]
            members.append(m)
        sims = [m for m in members if isinstance(m, SimulatorMember)]
        say(f"onboard demo --fleet {fleet.name}: {len(fleet.vehicles)} vehicles "
            f"({fleet.description}), {duration_s:g} s simulated at {speed:g}x, "
            f"Zenoh router {endpoint}")
        for v, s in zip(fleet.vehicles, sims):
            say(f"  {v.id}: {v.kind} flying {v.pattern}, system id {v.system_id}, "
                f"launched at t={v.start_delay_s:g} s; MAVLink udp:{s.plan.mavlink_udp_port}"
                + (f", NMEA {s.hello['nmea_pty']}" if s.hello.get("nmea_pty") else "")
                + (f", DVL JSON tcp:{s.plan.dvl_tcp_port}" if s.hello.get("dvl") else ""))
        start = time.monotonic() + 1.0
        deadline = start + duration_s / speed + 60.0

        def tick() -> None:
            with view.lock:
                cur = {veh: r for (veh, p), r in view.estimates.items() if p == "current"}
            for v, s in zip(fleet.vehicles, sims):
                if not s.done():
                    say("  " + vehicle_line(v.id, cur.get(v.id), last_truth(s.plan.truth_path)))

        await run_members(members, start,
                          lambda: all(s.done() for s in sims) or time.monotonic() > deadline,
                          max(1.0, duration_s / speed / LIVE_LINES), tick)
    finally:
        for m in reversed(members):
            await m.stop()
        if sub is not None:
            sub.undeclare()
        if shore is not None:
            shore.close()
        router.close()
        shutil.rmtree(state_root, ignore_errors=True)
    with view.lock:
        history = list(view.history)
    result: dict[str, Any] = {}
    say("")
    say("each vehicle's current, where it published it as known, against the true field "
        "at its position (RMS error, share within 1.96 sigma):")
    for v in fleet.vehicles:
        path = out_dir / f"{v.id}.truth.jsonl"
        truth = read_truth(path) if path.exists() else []
        mine = [r for r in history if r.vehicle == v.id]
        sc = score_vehicle(mine, truth)
        result[v.id] = {"estimates": mine, "truth": truth, "score": sc}
        say(f"  {v.id:>7}: " + "; ".join(
            f"{q} {s['n']} known, rms {s['rms']:.3f} m/s, {100 * s['cover95']:.0f} % in 1.96 sigma"
            if s["n"] else f"{q} never known" for q, s in sc.items()))
    late = {s.plan.scenario: float(s.result.get("late_s", math.nan)) for s in sims}
    for vid, lag in late.items():
        if math.isfinite(lag) and lag > demo.LATE_WARN_S:
            say(f"warning: {vid}'s simulator fell up to {lag:.1f} s (simulated) behind the "
                f"shared clock: this machine could not keep up with {speed:g}x, its samples "
                "reached its service that late; rerun on a quieter machine"
                + (" or with --realtime" if speed > 1.0 else ""))
    say(f"done in {time.monotonic() - t_wall0:.1f} s wall; recordings under {out_dir}")
    return result


def main(args: argparse.Namespace) -> int:
    """``onboard demo``'s entry point: ``--fleet NAME [--duration S] [--realtime]`` runs
    the fleet demo, anything else the single vehicle's (:func:`onboard.apps.demo.main`)."""
    if not getattr(args, "fleet", None):
        return demo.main(args)
    if args.scenario or getattr(args, "keep_state", False):
        raise UsageError("--fleet takes --duration and --realtime only")
    duration = FLEET_DURATION_S if args.duration is None else float(args.duration)
    if not (duration > 0 and math.isfinite(duration)):
        raise UsageError(f"--duration must be a positive number of seconds, got {args.duration}")
    from onboard.sitl.fleet import get_fleet

    get_fleet(args.fleet)   # an unknown name: one line, exit 2, before anything starts
    check_outputs([Output("the demo's folder", demo.OUT_DIR, "dir")])
    out_dir = demo.OUT_DIR / "fleet"
    page = f"127.0.0.1:{_free_port(socket.SOCK_STREAM)}"
    fusion = CommandMember([sys.executable, "-m", "onboard", "fleet", "--connect", "{endpoint}",
                            "--web", page], name="fleet", log=demo.OUT_DIR / "fleet-service.log")
    print(f"the fleet's current field (onboard fleet): http://{page}/, its log "
          f"{fusion.log}", flush=True)
    terminate = SigtermAsInterrupt()   # its members stopped, as on Ctrl-C
    try:
        res = asyncio.run(run_fleet_demo(args.fleet, duration, out_dir=out_dir,
                                         extra=[fusion],
                                         speed=1.0 if args.realtime else FLEET_SPEED))
    finally:
        terminate.restore()
    return 0 if any(r["estimates"] for r in res.values()) else 1
