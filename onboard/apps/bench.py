"""``onboard bench [--json]``: the performance figures, each measured in one run.

Every figure is a ratio or a distribution measured within the same process, so it holds on a
noisy machine (a laptop on battery, a CI runner shared with other jobs): the reference and
the thing measured run interleaved, several times, and the median is reported.

==============================  =========================================================  =========
key                             what                                                       goal
==============================  =========================================================  =========
``replay_vs_pymavlink_parse``   whole ``onboard replay`` of a 15-min 50 Hz-IMU tlog        <= 3
                                divided by pymavlink's parse-only ``recv_match`` loop
                                over the same file (CPU time of each, median of 5
                                interleaved pairs; the wall-time ratio is in the detail)
``aie_step_vs_filterpy_kf``     one AIE axis step / filterpy ``KalmanFilter(dim_x=3)``     <= 0.5
                                predict+update (median of repeats)
``service_cpu_fraction``        CPU s per wall s of ``onboard run`` fed by SITL            <= 0.015
``sensor_to_zenoh_p50_ms``      sensor receive to Zenoh publication, median (ms)           context
``sensor_to_zenoh_p99_ms``      same, 99th percentile (ms)                                 <= 5
``service_rss_mb``              resident memory of the service (MB)                        <= 100
``startup_to_ready_s``          process start to READY (s)                                 <= 1.5
``mpc_solve_p99_ms``            NMPC solve time on the BlueROV2 circle, p99 (ms)           < 50
``pipeline_step_us``            per-pipeline step cost, µs per engine tick (context)       --
``rov_replay_x_realtime``       simulated seconds of a ``bluerov2-circle`` tlog (50 Hz     >= 200
                                IMU, 10 Hz thruster commands, the ESESO) that ``onboard
                                replay --no-plot`` replays per CPU second (median of 3;
                                ``ONBOARD_BENCH_ROV_MINUTES``, default 10)
``batch_log_hours_per_wall_``   ``onboard batch`` throughput: log-hours replayed per       context
``minute``                      wall-clock minute with 2 local workers, on
                                :data:`BATCH_LOGS` copies of a rudder boat's tlog (the
                                whole command: finding the logs, the replays, the
                                tables); the figure with 1 worker, the speed-up and the
                                CPU time per log-hour are in the detail (``batch``) and
                                on the table's last lines. Added by issue 29 (additive).
``boat_replay_x_realtime``      seconds of the rudder-boat tlog replayed per CPU second    >= 500
                                (the same log, one process, every pipeline; median of
                                3 replays)
``replay_peak_rss_mb``          peak resident memory (MB) of ``onboard replay --no-plot``  <= 100
                                of a 2-h 50 Hz-IMU tlog, in a fresh process (a log's
                                length must not show: the readers stream it)
``diagnose_peak_rss_mb``        peak resident memory (MB) of ``onboard diagnose`` of the   <= 400
                                same log, in a fresh process
``fleet_cpu_share_10``          ``onboard fleet``'s CPU time per second of fleet time      context
                                (1.0: one core) with 10 simulated vehicles publishing
                                their current at 10 Hz, the field's 6-h history filled
                                in (:func:`onboard.fleet.load.measure`: decoding and
                                fusing every record, the field refreshed and its grid
                                made every 5 s, hyperparameters every 60 s). Added by
                                issue 33 (additive).
``fleet_cpu_share_100``         the same with 100 vehicles                                 <= 1
``fleet_query_p99_ms_10``       a ``<prefix>/fleet/current`` query's answer, CPU time,     < 100
                                99th percentile (ms), 10 vehicles (wall time in detail)
``fleet_query_p99_ms_100``      the same with 100 vehicles                                 < 100
``service_wakeups_per_s``       the service's event-loop wake-ups per second in the        <= 40
                                ``service_cpu_fraction`` run: voluntary context switches
                                of its main thread (two per 10 Hz tick: the grid time
                                and the first fresh sample, and a few sleeps outside
                                the loop; one per datagram, 76/s, would be back above
                                the goal). Added by issue 29 (additive).
``service_cpu_fraction_``       ``service_cpu_fraction`` with the traffic late by a link   <= 0.015
``real_link``                   whose delay wanders as the ArduSub tlog's did
                                (``sitl.link.ARDUSUB_TETHER``; the GNSS receiver on a
                                phase of its own): the ticks' predicted arrivals miss
                                more often. Its wake-ups and latencies are in the detail
                                (``service_real_link``); its sensor-to-Zenoh latency
                                counts the link's delay beyond its least, which is the
                                data's age, not the service's. Added by issue 29
                                (additive).
``machine_reference_s``         CPU seconds of a plain Python loop of                      context
                                :data:`REFERENCE_STEPS` integer additions, the least of
                                :data:`REFERENCE_REPEATS` before and as many after the
                                other figures: the machine's speed for pure Python. The
                                real-time factors and CPU fractions move with it from
                                one machine to another (a VM twice as slow halves a
                                real-time factor); the ratios above do not. Added
                                2026-12-03 (additive).
==============================  =========================================================  =========

A piece whose module has not landed (or fails) gives ``null`` in the JSON and
``not available: <reason>`` in the table; the JSON always has exactly the keys above.

Environment: ``ONBOARD_BENCH_FAST=1`` shortens everything (a 20 s log, few repeats; for the
test suite, figures then only show the command works), ``ONBOARD_BENCH_REPEATS=N`` sets the
number of interleaved replay/parse pairs (default 5), ``ONBOARD_BENCH_MINUTES`` the log
length (default 15), ``ONBOARD_BENCH_ROV_MINUTES`` the ROV log's (default 10),
``ONBOARD_BENCH_MEMORY_HOURS`` the length of the memory figures' log
(default 2; 72 s of :func:`synthesize_tlog` when fast), ``ONBOARD_BENCH_DETAIL=FILE``
writes every raw measurement behind the figures (each pair's CPU and wall times, the
replay breakdown, the service's extra figures, the memory runs' CPU times) as JSON.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable

from onboard.core.errors import OutputFailed
from onboard.core.outputs import Output, check as check_outputs
from onboard.core.geo import LocalFrame, wrap_2pi

KEYS: tuple[str, ...] = (
    "replay_vs_pymavlink_parse",
    "aie_step_vs_filterpy_kf",
    "service_cpu_fraction",
    "sensor_to_zenoh_p50_ms",
    "sensor_to_zenoh_p99_ms",
    "service_rss_mb",
    "startup_to_ready_s",
    "mpc_solve_p99_ms",
    "pipeline_step_us",
    "rov_replay_x_realtime",
    "batch_log_hours_per_wall_minute",
    "boat_replay_x_realtime",
    "replay_peak_rss_mb",
    "diagnose_peak_rss_mb",
    "fleet_cpu_share_10",
    "fleet_cpu_share_100",
    "fleet_query_p99_ms_10",
    "fleet_query_p99_ms_100",
    "service_wakeups_per_s",
    "service_cpu_fraction_real_link",
    "machine_reference_s",
)
"""The JSON keys of ``onboard bench --json``, in table order (a contract: tools
reading the JSON rely on these names)."""

GOALS: dict[str, tuple[str, float | None]] = {
    "replay_vs_pymavlink_parse": ("<=", 3.0),
    "aie_step_vs_filterpy_kf": ("<=", 0.5),
    "service_cpu_fraction": ("<=", 0.015),
    "sensor_to_zenoh_p50_ms": ("", None),
    "sensor_to_zenoh_p99_ms": ("<=", 5.0),
    "service_rss_mb": ("<=", 100.0),
    "startup_to_ready_s": ("<=", 1.5),
    "mpc_solve_p99_ms": ("<", 50.0),
    "pipeline_step_us": ("", None),
    "rov_replay_x_realtime": (">=", 200.0),
    "batch_log_hours_per_wall_minute": ("", None),
    "boat_replay_x_realtime": (">=", 500.0),
    "replay_peak_rss_mb": ("<=", 100.0),
    "diagnose_peak_rss_mb": ("<=", 400.0),
    "fleet_cpu_share_10": ("", None),
    "fleet_cpu_share_100": ("<=", 1.0),
    "fleet_query_p99_ms_10": ("<", 100.0),
    "fleet_query_p99_ms_100": ("<", 100.0),
    "service_wakeups_per_s": ("<=", 40.0),
    "service_cpu_fraction_real_link": ("<=", 0.015),
    "machine_reference_s": ("", None),
}
"""Goal of each figure: (comparison, bound); None = context only."""

REPLAY_SCENARIO = "jaiabot-turns"
"""SITL scenario of the replay log: rudder boat, 50 Hz IMU, 5 Hz GPS, 10 Hz compass."""

CLASS_SCENARIOS: tuple[tuple[str, str], ...] = (
    ("rudder-boat", "jaiabot-turns"),
    ("twin-thruster-boat", "twin-thruster-turns"),
    ("bluerov2", "bluerov2-circle"),
    ("torpedo-auv", "gavia-tidal"),
)
"""(bundled config, SITL scenario) pairs used to time every pipeline on the vehicle it
applies to."""


@dataclass
class Settings:
    """How long and how often to measure."""

    fast: bool = False
    minutes: float = 15.0
    repeats: int = 5
    aie_steps: int = 20000
    aie_repeats: int = 5
    mpc_solves: int = 200
    service_s: float = 30.0
    pipeline_sim_s: float = 120.0
    memory_hours: float = 2.0

    @classmethod
    def from_env(cls) -> "Settings":
        """The settings from the environment: ``ONBOARD_BENCH_FAST`` (a short run),
        ``ONBOARD_BENCH_MINUTES`` and ``ONBOARD_BENCH_REPEATS`` (see the module docstring)."""
        fast = os.environ.get("ONBOARD_BENCH_FAST", "") not in ("", "0")
        s = cls(fast=True, minutes=20 / 60, repeats=1, aie_steps=500, aie_repeats=1,
                mpc_solves=5, service_s=1.0, pipeline_sim_s=3.0,
                memory_hours=0.02) if fast else cls()
        if os.environ.get("ONBOARD_BENCH_MINUTES"):
            s.minutes = float(os.environ["ONBOARD_BENCH_MINUTES"])
        if os.environ.get("ONBOARD_BENCH_REPEATS"):
            s.repeats = max(1, int(os.environ["ONBOARD_BENCH_REPEATS"]))
        if os.environ.get("ONBOARD_BENCH_MEMORY_HOURS"):
            s.memory_hours = float(os.environ["ONBOARD_BENCH_MEMORY_HOURS"])
        return s


@dataclass
class Report:
    """Figures (``None`` when not available), why not, and the detail behind each."""

    values: dict[str, Any] = field(default_factory=lambda: {k: None for k in KEYS})
    reasons: dict[str, str] = field(default_factory=dict)
    detail: dict[str, Any] = field(default_factory=dict)

    def missing(self, keys: Iterable[str], reason: str) -> None:
        """Report ``keys`` as not measured (null in the JSON), with ``reason``."""
        for k in keys:
            self.values[k] = None
            self.reasons[k] = reason


class NotAvailable(Exception):
    """A piece of the bench cannot run yet (module missing, optional dependency absent)."""


def _quiet(fn: Callable[[], Any]) -> Any:
    """Run ``fn`` with stdout and stderr captured (no progress output, no prints)."""
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        return fn()


def _import(module: str, attr: str) -> Callable:
    import importlib

    try:
        mod = importlib.import_module(module)
    except ModuleNotFoundError as err:
        raise NotAvailable(f"module {err.name} missing (not written yet or not installed)") from None
    fn = getattr(mod, attr, None)
    if fn is None:
        raise NotAvailable(f"{module}.{attr} missing")
    return fn


# --------------------------------------------------------------------------- the replay log


def make_tlog(path: Path, duration_s: float, seed: int = 0) -> dict[str, Any]:
    """Write a deterministic tlog of ``duration_s`` seconds with a 50 Hz IMU to ``path``.

    With the simulator (:func:`sitl.runner.run_to_tlog`, scenario :data:`REPLAY_SCENARIO`)
    when it is there, else :func:`synthesize_tlog`. Returns what was written.
    """
    try:
        from onboard.sitl.runner import run_to_tlog
    except ImportError:
        run_to_tlog = None
    if run_to_tlog is not None:
        summary = run_to_tlog(REPLAY_SCENARIO, path, duration=duration_s, seed=seed)
        return {"source": f"sitl:{REPLAY_SCENARIO}", "frames": sum(summary.frames.values()),
                "samples": dict(sorted(summary.samples.items()))}
    return synthesize_tlog(path, duration_s, seed)


def synthesize_tlog(path: Path, duration_s: float, seed: int = 0) -> dict[str, Any]:
    """A boat-like tlog from pymavlink encoders alone: HEARTBEAT and SERVO_OUTPUT_RAW at 1 and
    10 Hz, SCALED_IMU 50 Hz, GPS_RAW_INT and GLOBAL_POSITION_INT 5 Hz, ATTITUDE and VFR_HUD
    10 Hz, PARAM_VALUE for the rudder/throttle mapping once. Deterministic for ``seed``."""
    import random

    from pymavlink.dialects.v20 import ardupilotmega as mav

    from onboard.drivers.tlog import TlogWriter

    rng = random.Random(seed)
    m = mav.MAVLink(None, srcSystem=1, srcComponent=1)
    m.robust_parsing = True
    epoch = 1.7e9
    frame = LocalFrame(41.6, -71.3)
    n_ticks = int(round(duration_s * 50))
    frames = 0
    with TlogWriter(path) as w:
        def put(t: float, msg) -> None:
            nonlocal frames
            w.write(epoch + t, msg.pack(m))
            frames += 1

        for i, (name, value) in enumerate((("SERVO1_FUNCTION", 26.0), ("SERVO3_FUNCTION", 70.0))):
            put(0.0, mav.MAVLink_param_value_message(name.encode(), value, 9, 2, i))
        north = east = 0.0
        psi = 0.0
        for k in range(n_ticks):
            t = k / 50.0
            ms = int(t * 1000)
            r = 0.1 * math.sin(0.05 * t)
            psi = wrap_2pi(psi + r / 50.0)
            u = 1.5 + 0.5 * math.sin(0.01 * t)
            north += u * math.cos(psi) / 50.0
            east += u * math.sin(psi) / 50.0
            put(t, mav.MAVLink_scaled_imu_message(
                ms, int(rng.gauss(0, 50)), int(rng.gauss(0, 50)), int(-1000 + rng.gauss(0, 50)),
                int(rng.gauss(0, 5)), int(rng.gauss(0, 5)), int(r * 1000), 200, 0, -400))
            if k % 50 == 0:
                put(t, mav.MAVLink_heartbeat_message(11, 3, 209, 0, 4, 3))
            if k % 5 == 0:
                put(t, mav.MAVLink_attitude_message(ms, 0.0, 0.0, psi - math.pi, 0.0, 0.0, r))
                put(t, mav.MAVLink_vfr_hud_message(u, u, int(math.degrees(psi)) % 360, 40, 0, 0))
                put(t, mav.MAVLink_servo_output_raw_message(
                    ms * 1000, 0, 1500 + int(r * 1000), 1500, 1700, 1500, 0, 0, 0, 0))
            if k % 10 == 0:
                lat, lon = frame.to_latlon(north, east)
                put(t, mav.MAVLink_gps_raw_int_message(
                    ms * 1000, 3, int(lat * 1e7), int(lon * 1e7), 0, 120, 65535,
                    int(u * 100), int(math.degrees(psi) * 100) % 36000, 12))
                put(t, mav.MAVLink_global_position_int_message(
                    ms, int(lat * 1e7), int(lon * 1e7), 0, 0, int(u * math.cos(psi) * 100),
                    int(u * math.sin(psi) * 100), 0, int(math.degrees(psi) * 100) % 36000))
    return {"source": "synthetic (pymavlink encoders)", "frames": frames}


# --------------------------------------------------------------------------- the figures


def bench_replay(s: Settings, workdir: Path, rep: Report) -> None:
    """``replay_vs_pymavlink_parse``: interleaved pairs, median ratio."""
    from onboard.drivers.tlog import pymavlink_parse_seconds
    from onboard.cli import main as cli_main

    log = workdir / "bench.tlog"
    t0 = time.perf_counter()
    made = make_tlog(log, s.minutes * 60.0)
    made["generate_s"] = round(time.perf_counter() - t0, 2)
    made["bytes"] = log.stat().st_size
    out = workdir / "replay-out"

    def one_replay() -> tuple[float, float]:
        w, c = time.perf_counter(), time.process_time()
        status = _quiet(lambda: cli_main(["replay", str(log), "--out", str(out), "--no-plot",
                                              "--force"]))
        w, c = time.perf_counter() - w, time.process_time() - c
        if status != 0:
            raise RuntimeError(f"onboard replay exited {status}")
        return w, c

    def one_parse() -> tuple[float, float]:
        c = time.process_time()
        w = pymavlink_parse_seconds(log)
        return w, time.process_time() - c

    one_replay()  # warm-up: imports and caches are not what is measured
    replays, parses = [], []
    for i in range(s.repeats):
        # alternate the order so a slow phase of the machine hits both sides
        if i % 2 == 0:
            parses.append(one_parse())
            replays.append(one_replay())
        else:
            replays.append(one_replay())
            parses.append(one_parse())
    cpu_ratios = [r[1] / p[1] for r, p in zip(replays, parses)]
    wall_ratios = [r[0] / p[0] for r, p in zip(replays, parses)]
    summary = json.loads((out / "summary.json").read_text())
    # CPU time of this process: what another process on the machine cannot inflate (on an
    # idle machine it equals the wall time, both loops being single-threaded and CPU-bound)
    rep.values["replay_vs_pymavlink_parse"] = round(statistics.median(cpu_ratios), 3)
    rep.detail["replay"] = {
        "log": made, "duration_s": summary["time_span"]["duration_s"],
        "samples": summary["read"]["samples"], "pipelines": summary["pipelines"],
        "replay_cpu_s": [round(x[1], 3) for x in replays],
        "pymavlink_cpu_s": [round(x[1], 3) for x in parses],
        "replay_wall_s": [round(x[0], 3) for x in replays],
        "pymavlink_wall_s": [round(x[0], 3) for x in parses],
        "cpu_ratios": [round(x, 3) for x in cpu_ratios],
        "wall_ratios": [round(x, 3) for x in wall_ratios],
        "wall_ratio_median": round(statistics.median(wall_ratios), 3),
        "breakdown_cpu_s": replay_breakdown(log),
    }


def replay_breakdown(log: Path) -> dict[str, float]:
    """Where the replay's CPU time goes: reading the tlog, the engine (validation, ticks),
    each pipeline's ``step``; one in-process pass (the CSV and summary are not included)."""
    from onboard.drivers.tlog import TlogReader
    from onboard.engine import Engine, run
    from onboard.offline.replay import choose_config

    cfg, _ = choose_config(str(log), None)
    c = time.process_time()
    samples = list(TlogReader(log))
    read = time.process_time() - c
    engine = Engine(cfg)
    timed = [_Timed(p) for p in engine.pipelines]
    engine.pipelines = timed  # type: ignore[assignment]
    c = time.process_time()
    ticks = run(engine, iter(samples), lambda t, recs: None)
    total = time.process_time() - c
    out = {"read": round(read, 3), "engine": round(total - sum(p.seconds for p in timed), 3)}
    for p in timed:
        out[f"pipeline.{p.name}"] = round(p.seconds, 3)
    out["ticks"] = ticks
    return out


BOAT_REPLAYS = 3
"""Replays of the bench's log timed for :func:`bench_boat_realtime` (1 in the fast mode)."""


def replays_cpu(log: Path, out: Path, n: int) -> tuple[dict, list[float]]:
    """The CPU seconds of ``n`` whole ``onboard replay LOG --no-plot`` in this process after
    a warm-up one (imports and caches are not what is measured), and the last one's
    summary.json."""
    from onboard.cli import main as cli_main

    def one_replay() -> float:
        c = time.process_time()
        status = _quiet(lambda: cli_main(["replay", str(log), "--out", str(out), "--no-plot",
                                          "--force"]))
        if status != 0:
            raise RuntimeError(f"onboard replay exited {status}")
        return time.process_time() - c

    one_replay()
    cpu = [one_replay() for _ in range(n)]
    return json.loads((out / "summary.json").read_text()), cpu


def bench_boat_realtime(s: Settings, workdir: Path, rep: Report) -> None:
    """``boat_replay_x_realtime``: simulated seconds of the rudder-boat tlog per CPU
    second of the whole ``onboard replay LOG --no-plot`` in this process (the log of
    :func:`bench_replay` when it is there), median of :data:`BOAT_REPLAYS` after a
    warm-up; the detail has each replay's CPU seconds."""
    log = workdir / "bench.tlog"
    if not log.exists():
        make_tlog(log, s.minutes * 60.0)
    summary, cpu = replays_cpu(log, workdir / "boat-out", 1 if s.fast else BOAT_REPLAYS)
    duration = float(summary["time_span"]["duration_s"])
    rep.values["boat_replay_x_realtime"] = round(duration / statistics.median(cpu), 1)
    rep.detail["boat_replay"] = {"duration_s": duration,
                                 "replay_cpu_s": [round(x, 3) for x in cpu]}


def aie_step_ratio(n: int = 5000, repeats: int = 5) -> dict[str, float]:
    """Time one AIE axis step against filterpy ``KalmanFilter(dim_x=3, dim_z=1)``
    predict+update on the same algorithms.md §1.2 model, in the same run.

    The surge axis with the default configuration (``n_c = 3``: 7 RCIE coefficients,
    the 3-state correlated-noise filter) is timed. Both loops run ``repeats`` times,
    interleaved, and the fastest repeat of each counts (robust to other load).

    Returns ``{"aie_axis_step_us", "filterpy_kf3_step_us", "ratio"}`` with ratio = AIE /
    filterpy (the goal is <= 0.5). filterpy is imported here only (the ``bench`` extra).
    """
    import numpy as np
    from filterpy.kalman import KalmanFilter

    from onboard.estimators.axis_model import AxisModel, augmented_matrices, discretize
    from onboard.core.pipeline_config import AieConfig
    from onboard.pipelines.aie import axis_filter

    top = AieConfig()
    ax = axis_filter(AxisModel(1.0, 3.0), top.surge, top)
    k = discretize(1.0, 1.0)
    rng = np.random.default_rng(0)
    ys = (1.0 + 2.0 * rng.standard_normal(n)).tolist()
    R = 4.0
    ax.step(k, ys[0], R, R, None)
    A, B, C = augmented_matrices(1.0, 1.0)
    f = KalmanFilter(dim_x=3, dim_z=1)
    f.F = A
    f.H = C.reshape(1, 3)
    f.R *= 2.0 * R
    f.Q = np.outer(B, B) * top.surge.tuned("v_d", True)
    f.P *= 10.0
    zs = [np.array([y]) for y in ys]
    step = ax.step
    best_aie = best_fp = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for y in ys:
            step(k, y, R, R, None)
        best_aie = min(best_aie, (time.perf_counter() - t0) / n)
        t0 = time.perf_counter()
        for z in zs:
            f.predict()
            f.update(z)
        best_fp = min(best_fp, (time.perf_counter() - t0) / n)
    return {"aie_axis_step_us": best_aie * 1e6, "filterpy_kf3_step_us": best_fp * 1e6,
            "ratio": best_aie / best_fp}


def bench_aie(s: Settings, rep: Report) -> None:
    """``aie_step_vs_filterpy_kf`` from :func:`aie_step_ratio`."""
    try:
        import filterpy  # noqa: F401
    except ImportError:
        raise NotAvailable("filterpy not installed (pip install 'onboard[bench]')") from None
    runs = [aie_step_ratio(s.aie_steps) for _ in range(s.aie_repeats)]
    ratios = [r["ratio"] for r in runs]
    rep.values["aie_step_vs_filterpy_kf"] = round(statistics.median(ratios), 3)
    rep.detail["aie"] = {
        "aie_axis_step_us": round(statistics.median(r["aie_axis_step_us"] for r in runs), 2),
        "filterpy_kf3_step_us": round(statistics.median(r["filterpy_kf3_step_us"] for r in runs), 2),
        "ratios": [round(x, 3) for x in ratios], "steps": s.aie_steps,
    }


SERVICE_KEYS = ("service_cpu_fraction", "sensor_to_zenoh_p50_ms", "sensor_to_zenoh_p99_ms",
                "service_rss_mb", "startup_to_ready_s")
_SERVICE_ALIASES: dict[str, tuple[str, ...]] = {
    "service_cpu_fraction": ("service_cpu_fraction", "cpu_fraction", "cpu"),
    "sensor_to_zenoh_p50_ms": ("sensor_to_zenoh_p50_ms", "latency_p50_ms", "p50_ms"),
    "sensor_to_zenoh_p99_ms": ("sensor_to_zenoh_p99_ms", "latency_p99_ms", "p99_ms"),
    "service_rss_mb": ("service_rss_mb", "rss_mb", "max_rss_mb"),
    "startup_to_ready_s": ("startup_to_ready_s", "ready_s", "startup_s"),
}


def _service_run(s: Settings, **kw: Any) -> tuple[dict[str, Any], dict[str, Any]]:
    """One :func:`onboard.apps.service_bench.measure` run of ``s.service_s`` seconds with
    ``kw`` (a short warm-up when fast): its figures, and those of them JSON can hold (the
    report's detail)."""
    import inspect

    fn = _import("onboard.apps.service_bench", "measure")
    params = inspect.signature(fn).parameters
    if any(k not in params for k in kw):
        raise NotAvailable(f"service_bench.measure takes no {', '.join(kw)}")
    if s.fast and "warmup_s" in params:
        kw["warmup_s"] = 0.5
    res = _quiet(lambda: fn(s.service_s, **kw))
    return res, {k: v for k, v in res.items() if _jsonable(v)}


def bench_service(s: Settings, rep: Report) -> None:
    """The service figures from :func:`onboard.apps.service_bench.measure`."""
    res, rep.detail["service"] = _service_run(s)
    for key in SERVICE_KEYS:
        v = next((res[a] for a in _SERVICE_ALIASES[key] if a in res), None)
        if v is None or not _finite(v):
            rep.missing([key], f"service_bench.measure gave no {key}")
        else:
            rep.values[key] = round(float(v), 4)


def bench_service_real_link(s: Settings, rep: Report) -> None:
    """``service_cpu_fraction_real_link``: :func:`bench_service`'s run with the traffic over
    ``sitl.link.ARDUSUB_TETHER``."""
    from onboard.sitl.link import ARDUSUB_TETHER

    res, rep.detail["service_real_link"] = _service_run(s, link=ARDUSUB_TETHER)
    v = res.get("service_cpu_fraction")
    if v is None or not _finite(v):
        raise NotAvailable("service_bench.measure gave no service_cpu_fraction")
    rep.values["service_cpu_fraction_real_link"] = round(float(v), 4)


def bench_service_wakeups(rep: Report) -> None:
    """``service_wakeups_per_s`` from the run of :func:`bench_service` (its detail)."""
    v = (rep.detail.get("service") or {}).get("service_wakeups_per_s")
    if v is None or not _finite(v):
        raise NotAvailable("the service run gave no wake-up count")
    rep.values["service_wakeups_per_s"] = round(float(v), 1)


def bench_mpc(s: Settings, rep: Report) -> None:
    """``mpc_solve_p99_ms`` from :func:`sitl.controllers.nmpc.solve_time_stats`."""
    fn = _import("onboard.sitl.controllers.nmpc", "solve_time_stats")
    res = _quiet(lambda: fn(s.mpc_solves))
    rep.values["mpc_solve_p99_ms"] = round(float(res["p99_ms"]), 2)
    rep.detail["mpc"] = res


class _Timed:
    """A pipeline whose ``step`` CPU time is accumulated; everything else passes through."""

    def __init__(self, inner: Any) -> None:
        self._inner = inner
        self.seconds = 0.0
        self.calls = 0

    def step(self, t: float, samples):
        t0 = time.process_time()
        out = self._inner.step(t, samples)
        self.seconds += time.process_time() - t0
        self.calls += 1
        return out

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)


def eseso_step_cost(duration_s: float = 20.0, tick_hz: float = 20.0) -> dict[str, float]:
    """Wall-clock cost of the ESESO pipeline's ``step`` on a synthetic hovering-ROV stream:
    50 Hz IMU, 20 Hz thruster commands, 5 Hz DVL, depth and attitude, ticked at
    ``tick_hz`` for ``duration_s`` seconds.

    Returns ``{"per_tick_us_p50", "per_tick_us_p99", "per_imu_sample_us", "ticks"}`` (µs).
    """
    import numpy as np

    from onboard.core.messages import ActuatorCommand, Attitude, Depth, DvlVelocity, Imu
    from onboard.pipelines.eseso import Eseso, EsesoConfig

    rng = np.random.default_rng(0)
    f = Eseso(EsesoConfig())
    samples: list[Any] = []
    n_imu = int(duration_s * 50)
    for k in range(n_imu):
        t = k / 50.0
        samples.append(Imu(t=t, accel_x=rng.normal(0, 0.05), accel_y=rng.normal(0, 0.05),
                           accel_z=-9.81 + rng.normal(0, 0.05), gyro_x=0.0, gyro_y=0.0,
                           gyro_z=0.0))
        if k % 10 == 0:
            samples.append(Attitude(t=t, roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0))
            samples.append(Depth(t=t, depth_m=20.0))
            samples.append(DvlVelocity(t=t, vx=0.0, vy=0.0, vz=0.0))
        if k % 5 == 0:
            samples.append(ActuatorCommand(t=t, thrusters=(0.0,) * 6))
    costs = []
    i = 0
    n_ticks = int(duration_s * tick_hz)
    for k in range(n_ticks):
        t = (k + 1) / tick_hz
        batch = []
        while i < len(samples) and samples[i].t <= t:
            batch.append(samples[i])
            i += 1
        t0 = time.perf_counter()
        f.step(t, batch)
        costs.append(time.perf_counter() - t0)
    c = np.array(costs) * 1e6
    return {"per_tick_us_p50": float(np.percentile(c, 50)),
            "per_tick_us_p99": float(np.percentile(c, 99)),
            "per_imu_sample_us": float(c.sum() / n_imu), "ticks": float(n_ticks)}


def bench_pipelines(s: Settings, rep: Report) -> None:
    """``pipeline_step_us``: mean step cost per engine tick of every pipeline, on the SITL
    stream of a vehicle it applies to (each pipeline timed once, on its first vehicle)."""
    from onboard.core import config as configmod
    from onboard.engine import Engine, run
    from onboard.pipelines import build

    try:
        from onboard.sitl.runner import simulate
    except ImportError:
        simulate = None
    costs: dict[str, float] = {}
    where: dict[str, str] = {}
    errors: dict[str, str] = {}
    for cfg_name, scenario in CLASS_SCENARIOS:
        try:
            cfg = configmod.load(configmod.resolve(cfg_name))
        except Exception:  # noqa: BLE001 - a config that does not load is just skipped
            continue
        todo = [p for p in build(cfg) if p.name not in costs]
        if not todo or simulate is None:
            continue
        timed = [_Timed(p) for p in todo]
        engine = Engine(cfg, pipelines=timed)  # type: ignore[arg-type]
        stream = (x for _, samples, _ in simulate(scenario, s.pipeline_sim_s, seed=0)
                  for x in samples)
        try:
            run(engine, stream, lambda t, recs: None)
        except Exception as err:  # noqa: BLE001 - a crashing pipeline is reported, not fatal
            errors[cfg_name] = f"{type(err).__name__}: {err}"
        for p in timed:
            if p.calls:
                costs[p.name] = round(p.seconds / p.calls * 1e6, 1)
                where[p.name] = f"{cfg_name} / {scenario}"
    if "eseso" not in costs:
        try:
            res = eseso_step_cost(max(2.0, s.pipeline_sim_s / 6))
            costs["eseso"] = round(float(res["per_tick_us_p50"]), 1)
            where["eseso"] = "eseso_step_cost (synthetic ROV stream), p50"
        except (NotAvailable, Exception):  # noqa: BLE001
            pass
    if not costs:
        raise NotAvailable("no pipeline applies to the bundled configs, or no simulator")
    rep.values["pipeline_step_us"] = dict(sorted(costs.items()))
    rep.detail["pipelines"] = {"measured_on": where, "sim_s": s.pipeline_sim_s,
                               "errors": errors}


ROV_SCENARIO = "bluerov2-circle"
"""The simulator scenario of ``rov_replay_x_realtime`` (a BlueROV2 config, the ESESO)."""
ROV_REPLAYS = 3
"""Replays of the ROV log whose median CPU time is reported (1 with ``ONBOARD_BENCH_FAST``)."""
ROV_MINUTES = 10.0
"""Default length (min) of the ROV log; ``ONBOARD_BENCH_ROV_MINUTES`` overrides it, and
``ONBOARD_BENCH_FAST`` makes it 20 s."""


def bench_rov_replay(s: Settings, workdir: Path, rep: Report) -> None:
    """``rov_replay_x_realtime``: the log's duration over the median CPU time of a whole
    ``onboard replay --no-plot`` of a simulated ROV tlog (after a warm-up replay)."""
    try:
        from onboard.sitl.runner import run_to_tlog
    except ImportError as err:
        raise NotAvailable(f"no simulator for the ROV log: {err}") from err
    minutes = float(os.environ.get("ONBOARD_BENCH_ROV_MINUTES") or
                    (20 / 60 if s.fast else ROV_MINUTES))
    log, out = workdir / "rov.tlog", workdir / "rov-out"
    run_to_tlog(ROV_SCENARIO, log, duration=minutes * 60.0, seed=0)

    summary, cpu = replays_cpu(log, out, 1 if s.fast else ROV_REPLAYS)
    duration = float(summary["time_span"]["duration_s"])
    rep.values["rov_replay_x_realtime"] = round(duration / statistics.median(cpu), 1)
    rep.detail["rov_replay"] = {
        "scenario": ROV_SCENARIO, "duration_s": duration, "pipelines": summary["pipelines"],
        "replay_cpu_s": [round(x, 3) for x in cpu], "breakdown_cpu_s": replay_breakdown(log)}


BATCH_LOGS = 4
"""Logs in the batch of ``batch_log_hours_per_wall_minute``: copies of one tlog (a batch
of identical logs keeps the two workers equally loaded)."""
BATCH_LOG_FRACTION = 1 / 3
"""Each batch log is this fraction of ``ONBOARD_BENCH_MINUTES`` long (5 min of 15)."""
BATCH_WORKERS = (1, 2)
"""The local workers the batch is timed with; the key is the last one's figure."""


def bench_batch(s: Settings, workdir: Path, rep: Report) -> None:
    """``batch_log_hours_per_wall_minute``: ``onboard batch --force`` of
    :data:`BATCH_LOGS` copies of a tlog, with 1 and with 2 local workers, interleaved
    (``repeats`` rounds, median); log-hours from runs.parquet's ``duration_s``."""
    from onboard.cli import main as cli_main

    try:
        import pyarrow.parquet as pq
    except ImportError:
        raise NotAvailable("pyarrow missing (pip install 'onboard[batch]')") from None
    logs = workdir / "batch-logs"
    logs.mkdir()
    made = make_tlog(logs / "log-0.tlog", s.minutes * 60.0 * BATCH_LOG_FRACTION, seed=1)
    for k in range(1, BATCH_LOGS):
        (logs / f"log-{k}.tlog").write_bytes((logs / "log-0.tlog").read_bytes())
    out = workdir / "batch-out"

    def one_batch(jobs: int) -> dict[str, float]:
        w, c = time.perf_counter(), time.process_time()
        status = _quiet(lambda: cli_main(["batch", str(logs), "--out", str(out), "--jobs",
                                          str(jobs), "--force"]))
        w = time.perf_counter() - w
        if status != 0:
            raise RuntimeError(f"onboard batch exited {status}")
        rows = pq.read_table(out / "runs.parquet").to_pylist()
        hours = sum(r["duration_s"] for r in rows) / 3600.0
        return {"wall_s": w, "parent_cpu_s": time.process_time() - c,
                "workers_cpu_s": sum(r["cpu_s"] for r in rows), "log_hours": hours,
                "per_wall_minute": hours / (w / 60.0)}

    one_batch(1)  # warm-up: the imports of the in-process worker are not what is measured
    runs: dict[int, list[dict[str, float]]] = {j: [] for j in BATCH_WORKERS}
    for i in range(max(1, s.repeats // 2)):
        for j in (BATCH_WORKERS if i % 2 == 0 else BATCH_WORKERS[::-1]):
            runs[j].append(one_batch(j))
    fig = {j: statistics.median(r["per_wall_minute"] for r in runs[j]) for j in runs}
    rep.values["batch_log_hours_per_wall_minute"] = round(fig[BATCH_WORKERS[-1]], 3)
    rep.detail["batch"] = {
        "log": made, "logs": BATCH_LOGS, "log_hours": runs[1][0]["log_hours"],
        "per_wall_minute": {str(j): round(v, 3) for j, v in fig.items()},
        "speedup": round(fig[BATCH_WORKERS[-1]] / fig[BATCH_WORKERS[0]], 3),
        "workers_cpu_s_per_log_hour": round(statistics.median(
            r["workers_cpu_s"] / r["log_hours"] for rs in runs.values() for r in rs), 2),
        "runs": {str(j): [{k: round(v, 3) for k, v in r.items()} for r in rs]
                 for j, rs in runs.items()}}


REFERENCE_STEPS = 10_000_000
"""Integer additions of :func:`reference_loop_s`'s loop (0.43 s of CPU on the 2-core
development VM of 2026-12-03)."""
REFERENCE_REPEATS = 3
"""Loops timed at the bench's start and as many at its end (1 each when fast)."""


def reference_loop_s(steps: int = REFERENCE_STEPS) -> float:
    """CPU seconds of ``steps`` integer additions in a plain Python loop, interpreted in
    either build (this module is not among setup.py's compiled ones)."""
    c = time.process_time()
    x = 0
    for i in range(steps):
        x += i
    return time.process_time() - c


def machine_reference_s(times: list[float]) -> float:
    """``machine_reference_s`` from the loops' CPU times: the least, the run least
    disturbed by the rest of the machine."""
    return round(min(times), 3)


def compiled_modules() -> list[str]:
    """The modules of this package that are extension modules: the replay's hot path when
    the package was built with ``ONBOARD_COMPILE=1`` (setup.py), none in the pure build."""
    import importlib.util
    import pkgutil

    package = Path(__file__).resolve().parents[1]  # onboard/, this module in onboard/apps/
    names = []
    for m in pkgutil.walk_packages([str(package)], "onboard."):
        if m.ispkg or m.name.startswith("onboard.sitl"):
            continue
        spec = importlib.util.find_spec(m.name)
        origin = spec.origin if spec else None
        if origin and not origin.endswith(".py"):
            names.append(m.name)
    return sorted(names)


def collect(s: Settings | None = None, progress: Callable[[str], None] | None = None) -> Report:
    """Measure everything; a failing or missing piece becomes ``None`` with its reason."""
    s = s or Settings.from_env()
    say = progress or (lambda msg: None)
    rep = Report()
    rep.detail["settings"] = {"fast": s.fast, "minutes": s.minutes, "repeats": s.repeats}
    rep.detail["compiled_modules"] = compiled_modules()
    loops = 1 if s.fast else REFERENCE_REPEATS
    reference = [reference_loop_s() for _ in range(loops)]
    with tempfile.TemporaryDirectory(prefix="onboard-bench-") as tmp:
        steps: list[tuple[str, tuple[str, ...], Callable[[], None]]] = [
            ("replay vs pymavlink", ("replay_vs_pymavlink_parse",),
             lambda: bench_replay(s, Path(tmp), rep)),
            ("AIE step vs filterpy", ("aie_step_vs_filterpy_kf",), lambda: bench_aie(s, rep)),
            ("service", SERVICE_KEYS, lambda: bench_service(s, rep)),
            ("MPC solve", ("mpc_solve_p99_ms",), lambda: bench_mpc(s, rep)),
            ("pipeline steps", ("pipeline_step_us",), lambda: bench_pipelines(s, rep)),
            ("ROV replay", ("rov_replay_x_realtime",),
             lambda: bench_rov_replay(s, Path(tmp), rep)),
            ("batch throughput", ("batch_log_hours_per_wall_minute",),
             lambda: bench_batch(s, Path(tmp), rep)),
            ("boat replay real-time factor", ("boat_replay_x_realtime",),
             lambda: bench_boat_realtime(s, Path(tmp), rep)),
            ("memory", MEMORY_KEYS, lambda: bench_memory(s, Path(tmp), rep)),
            ("fleet", FLEET_KEYS, lambda: bench_fleet(s, rep)),
            ("service wake-ups", ("service_wakeups_per_s",), lambda: bench_service_wakeups(rep)),
            ("service over a real link", ("service_cpu_fraction_real_link",),
             lambda: bench_service_real_link(s, rep)),
        ]
        for label, keys, fn in steps:
            say(f"measuring {label} ...")
            t0 = time.perf_counter()
            try:
                fn()
            except NotAvailable as err:
                rep.missing(keys, str(err))
            except Exception as err:  # noqa: BLE001 - one broken piece must not hide the rest
                rep.missing(keys, f"failed: {type(err).__name__}: {err}")
            rep.detail.setdefault("bench_wall_s", {})[label] = round(time.perf_counter() - t0, 2)
    reference += [reference_loop_s() for _ in range(loops)]
    rep.values["machine_reference_s"] = machine_reference_s(reference)
    rep.detail["machine_reference_loops_s"] = [round(x, 3) for x in reference]
    return rep


# --------------------------------------------------------------------------- memory

MEMORY_KEYS = ("replay_peak_rss_mb", "diagnose_peak_rss_mb")
"""The figures of :func:`bench_memory`."""


_OWN_PEAK = """\
import runpy, sys
out, module = sys.argv[1], sys.argv[2]
sys.argv = [module] + sys.argv[3:]
try:
    runpy.run_module(module, run_name="__main__", alter_sys=True)
finally:
    with open("/proc/self/status") as status, open(out, "w") as f:
        f.write(next((ln.split()[1] for ln in status if ln.startswith("VmHWM:")), ""))
"""
"""Runs ``python -m MODULE ARGS`` (``argv[1]``: where to write, ``argv[2]``: the module)
and writes the process's own peak resident memory (``VmHWM``, kB) when it ends."""


def peak_rss_of(args: list[str], module: str = "onboard") -> dict[str, float]:
    """Run ``python -m module args`` in a fresh process (output discarded) and return its
    own peak resident memory (MB) and CPU time (s). Raises RuntimeError when it fails.

    The peak is the process's ``VmHWM`` as it ends, which belongs to the program's own
    address space. ``ru_maxrss`` (``os.wait4``) is not: Linux carries the largest
    resident size over ``exec``, so a child started from a process larger than itself
    (the bench, after its earlier figures) reports its parent's size. Where there is no
    ``/proc`` the ``ru_maxrss`` is given, an upper bound."""
    import subprocess

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "vmhwm"
        argv = [sys.executable, "-c", _OWN_PEAK, str(out), module, *args] \
            if Path("/proc/self/status").exists() else [sys.executable, "-m", module, *args]
        with tempfile.TemporaryFile() as err:
            proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=err)
            _, status, ru = os.wait4(proc.pid, 0)
            proc.returncode = os.waitstatus_to_exitcode(status)
            if proc.returncode != 0:
                err.seek(0)
                tail = err.read().decode(errors="replace").strip().splitlines()[-1:]
                raise RuntimeError(f"{module} {' '.join(args[:1])} exited {proc.returncode}: "
                                   f"{tail}")
        hwm_kb = out.read_text().strip() if out.exists() else ""
    peak_kb = float(hwm_kb) if hwm_kb else ru.ru_maxrss
    return {"peak_rss_mb": round(peak_kb / 1024.0, 1),
            "cpu_s": round(ru.ru_utime + ru.ru_stime, 2)}


def bench_memory(s: Settings, workdir: Path, rep: Report) -> None:
    """``replay_peak_rss_mb``, ``diagnose_peak_rss_mb``: ``onboard replay --no-plot`` and
    ``onboard diagnose`` of a ``s.memory_hours`` log (:func:`make_tlog`; when fast,
    :func:`synthesize_tlog`, which takes no simulator start-up), each in a fresh process."""
    log = workdir / "memory.tlog"
    t0 = time.perf_counter()
    made = (synthesize_tlog if s.fast else make_tlog)(log, s.memory_hours * 3600.0)
    made["generate_s"] = round(time.perf_counter() - t0, 2)
    made["bytes"] = log.stat().st_size
    replay = peak_rss_of(["replay", str(log), "--no-plot", "--force",
                          "--out", str(workdir / "memory-replay")])
    diagnose = peak_rss_of(["diagnose", str(log), "--force",
                            "--out", str(workdir / "memory-diagnose")])
    rep.values["replay_peak_rss_mb"] = replay["peak_rss_mb"]
    rep.values["diagnose_peak_rss_mb"] = diagnose["peak_rss_mb"]
    rep.detail["memory"] = {"log": made, "log_hours": s.memory_hours,
                            "replay": replay, "diagnose": diagnose}


# --------------------------------------------------------------------------- fleet

FLEET_KEYS = ("fleet_cpu_share_10", "fleet_cpu_share_100", "fleet_query_p99_ms_10",
              "fleet_query_p99_ms_100")
"""The figures of :func:`bench_fleet`."""
FLEET_VEHICLES = (10, 100)
"""The simulated fleets' sizes."""


def bench_fleet(s: Settings, rep: Report) -> None:
    """The fleet figures from :func:`onboard.fleet.load.measure`: 120 s of fleet time after
    a 6-h history (fast: 5 s after 2 min), 200 queries."""
    measure = _import("onboard.fleet.load", "measure")
    kw = {"duration_s": 5.0, "history_s": 120.0, "queries": 20} if s.fast else \
        {"duration_s": 120.0}
    runs = {n: measure(n, **kw) for n in FLEET_VEHICLES}
    for n, r in runs.items():
        rep.values[f"fleet_cpu_share_{n}"] = round(r["cpu_share"], 4)
        rep.values[f"fleet_query_p99_ms_{n}"] = round(r["query_p99_ms"], 3)
    rep.detail["fleet"] = {str(n): {k: (round(v, 4) if isinstance(v, float) else v)
                                    for k, v in r.items()} for n, r in runs.items()}


# --------------------------------------------------------------------------- output


def _finite(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _jsonable(v: Any) -> bool:
    try:
        json.dumps(v)
        return True
    except (TypeError, ValueError):
        return False


def verdict(key: str, value: Any) -> str:
    """``ok``/``MISSED`` against the goal, ``""`` for context figures."""
    op, bound = GOALS[key]
    if bound is None or not _finite(value):
        return ""
    ok = {"<=": value <= bound, "<": value < bound, ">=": value >= bound}[op]
    return "ok" if ok else "MISSED"


def table(rep: Report) -> str:
    """The figures as a text table, goals beside them."""
    rows = [("figure", "value", "goal", "")]
    for k in KEYS:
        v = rep.values[k]
        op, bound = GOALS[k]
        goal = f"{op} {bound:g}" if bound is not None else "context"
        if k == "sensor_to_zenoh_p50_ms":
            goal = "context"
        if v is None:
            rows.append((k, f"not available: {rep.reasons.get(k, 'unknown')}", goal, ""))
        elif isinstance(v, dict):
            rows.append((k, ", ".join(f"{n} {c:g}" for n, c in v.items()), goal, ""))
        else:
            rows.append((k, f"{v:g}", goal, verdict(k, v)))
    w0 = max(len(r[0]) for r in rows)
    w2 = max(len(r[2]) for r in rows)
    lines = []
    for i, (a, b, c, d) in enumerate(rows):
        # a long "not available" reason goes last so the goal column stays aligned
        lines.append(f"{a:<{w0}}  {c:<{w2}}  {d:<6}  {b}".rstrip())
        if i == 0:
            lines.append("-" * min(100, w0 + w2 + 40))
    r = rep.detail.get("replay")
    if r:
        lines.append("")
        lines.append(f"replay log: {r['log']['source']}, {r['duration_s']:.0f} s, "
                     f"{r['samples']:,} samples, pipelines {', '.join(r['pipelines'])}")
        lines.append(f"  replay {statistics.median(r['replay_cpu_s']):.2f} s CPU, pymavlink parse "
                     f"{statistics.median(r['pymavlink_cpu_s']):.2f} s CPU (median of "
                     f"{len(r['cpu_ratios'])} interleaved pairs; ratio of CPU times; wall-time "
                     f"ratio {r['wall_ratio_median']:g})")
        b = dict(r.get("breakdown_cpu_s") or {})
        ticks = b.pop("ticks", 0)
        if b:
            lines.append("  replay CPU by stage: " + ", ".join(
                f"{k} {v:.2f} s" for k, v in b.items()) + f" ({ticks:,} ticks)")
    sv = rep.detail.get("service") or {}
    if "tick_to_zenoh_p99_ms" in sv:
        lines.append(f"service: tick-to-Zenoh p50 {sv.get('tick_to_zenoh_p50_ms', float('nan')):.2f} ms, "
                     f"p99 {sv['tick_to_zenoh_p99_ms']:.2f} ms (what the service adds beyond "
                     "the wait for the next tick)")
    a = rep.detail.get("aie")
    if a:
        lines.append(f"AIE axis step {a['aie_axis_step_us']:.1f} us, filterpy KF(3) "
                     f"predict+update {a['filterpy_kf3_step_us']:.1f} us")
    bt = rep.detail.get("batch")
    if bt:
        lines.append(f"batch: {bt['logs']} logs, {bt['log_hours']:.2f} log-h; log-hours per "
                     "wall minute " + ", ".join(f"{v:g} with {k} worker(s)" for k, v in
                                                bt["per_wall_minute"].items())
                     + f" (speed-up {bt['speedup']:g}); "
                     f"{bt['workers_cpu_s_per_log_hour']:g} s CPU per log-hour")
    loops = rep.detail.get("machine_reference_loops_s")
    if loops:
        lines.append(f"machine: {REFERENCE_STEPS:,} additions in a Python loop, "
                     f"{min(loops):.2f} s CPU at the least of {len(loops)} (start and end: "
                     + ", ".join(f"{x:.2f}" for x in loops) + "); the real-time factors and "
                     "CPU fractions scale with it, the ratios do not")
    compiled = rep.detail.get("compiled_modules")
    lines.append(f"build: compiled, {len(compiled)} modules (setup.py, ONBOARD_COMPILE=1)"
                 if compiled else "build: pure Python (`make bench-compiled` measures the "
                 "compiled build)")
    if rep.detail.get("settings", {}).get("fast"):
        lines.append("(fast mode: ONBOARD_BENCH_FAST is set; figures are not meaningful)")
    return "\n".join(lines)


def main(args) -> int:
    """Entry point of ``onboard bench``."""
    as_json = bool(getattr(args, "json", False))
    detail = os.environ.get("ONBOARD_BENCH_DETAIL")
    if detail:  # replaced by design: a measurement's dump, named anew each time
        check_outputs([Output("ONBOARD_BENCH_DETAIL", Path(detail), replace=True)])
    progress = None if as_json or not sys.stderr.isatty() else (
        lambda msg: print(msg, file=sys.stderr, flush=True))
    rep = collect(Settings.from_env(), progress)
    if as_json:
        print(json.dumps({k: rep.values[k] for k in KEYS}, indent=2))
        for k, why in rep.reasons.items():
            print(f"onboard bench: {k} not available: {why}", file=sys.stderr)
    else:
        print(table(rep))
    if detail:
        try:
            Path(detail).write_text(
                json.dumps({"values": rep.values, "reasons": rep.reasons,
                            "detail": rep.detail}, indent=2, default=str) + "\n")
        except OSError as err:  # checked before the run: a full disk, a removed folder
            raise OutputFailed(f"ONBOARD_BENCH_DETAIL {detail}: cannot write: "
                               f"{err.strerror or err}") from None
    return 0
