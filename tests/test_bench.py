"""``onboard bench``: the command runs and reports every figure (never a timing assertion).

Timing is never asserted here (architecture.md §5): the bench runs in its fast mode
(``ONBOARD_BENCH_FAST=1``: a 20 s log, one repeat) and the tests check the shape of the
output only. Measured: ~8 s for the subprocess run on a 2-core CI box.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from onboard.apps import bench


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["ONBOARD_BENCH_FAST"] = "1"
    return env


@pytest.mark.integration
def test_bench_json_prints_exactly_the_contract_keys():
    proc = subprocess.run([sys.executable, "-m", "onboard", "bench", "--json"], env=_env(),
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert list(out) == list(bench.KEYS)
    for key, value in out.items():
        if key == "pipeline_step_us":
            assert value is None or (isinstance(value, dict)
                                     and all(isinstance(v, (int, float)) for v in value.values()))
        else:
            assert value is None or isinstance(value, (int, float)), (key, value)
    # the replay ratio needs only the readers, the engine and pymavlink: always there
    assert out["replay_vs_pymavlink_parse"] is not None
    assert out["boat_replay_x_realtime"] is not None
    # the machine's speed beside the absolute figures: always measured
    assert out["machine_reference_s"] > 0.0
    # the service, Zenoh and the service bench are core parts: their figures are always
    # there (a subscriber on the wrong key gives null latencies)
    for key in ("service_cpu_fraction", "sensor_to_zenoh_p50_ms", "sensor_to_zenoh_p99_ms",
                "service_rss_mb", "startup_to_ready_s", "service_wakeups_per_s"):
        assert out[key] is not None, (key, proc.stderr)
    # a missing piece is explained on stderr, never silently null
    for key, value in out.items():
        if value is None:
            assert f"{key} not available" in proc.stderr


def test_table_names_every_figure_and_its_goal(monkeypatch):
    rep = bench.Report()
    rep.values["replay_vs_pymavlink_parse"] = 0.31
    rep.values["pipeline_step_us"] = {"nav": 12.0}
    rep.missing(bench.SERVICE_KEYS, "module onboard.apps.service_bench missing")
    text = bench.table(rep)
    for key in bench.KEYS:
        assert key in text
    assert "not available: module onboard.apps.service_bench missing" in text
    assert "<= 3" in text and "<= 0.015" in text and "< 50" in text and "<= 1.5" in text
    assert ">= 500" in text


def test_machine_reference_is_the_least_loop_and_scales_with_its_steps():
    assert bench.machine_reference_s([0.91, 0.62, 0.75, 0.64]) == 0.62
    short, long = (min(bench.reference_loop_s(n) for _ in range(3)) for n in (10**5, 10**6))
    assert 0.0 < short < long   # the loop does its work: ten times the steps, more CPU


def test_missing_module_gives_null_with_reason(monkeypatch):
    def unavailable(module, attr):
        raise bench.NotAvailable(f"module {module} missing")

    monkeypatch.setattr(bench, "_import", unavailable)
    rep = bench.Report()
    s = bench.Settings(fast=True)
    for fn in (bench.bench_service, bench.bench_mpc):
        with pytest.raises(bench.NotAvailable):
            fn(s, rep)


def test_synthetic_tlog_reads_back_at_the_stated_rates(tmp_path: Path):
    from onboard.drivers.tlog import TlogReader

    info = bench.synthesize_tlog(tmp_path / "s.tlog", 10.0)
    r = TlogReader(tmp_path / "s.tlog")
    samples = list(r)
    by = r.stats.by_type
    assert not r.stats.rejected
    assert by["SCALED_IMU"] == 500 and by["GPS_RAW_INT"] == 50 and by["ATTITUDE"] == 100
    assert r.stats.records == info["frames"]
    assert samples


def test_verdict_against_goals():
    assert bench.verdict("replay_vs_pymavlink_parse", 2.9) == "ok"
    assert bench.verdict("replay_vs_pymavlink_parse", 3.1) == "MISSED"
    assert bench.verdict("boat_replay_x_realtime", 510.0) == "ok"
    assert bench.verdict("boat_replay_x_realtime", 490.0) == "MISSED"
    assert bench.verdict("mpc_solve_p99_ms", 50.0) == "MISSED"
    assert bench.verdict("pipeline_step_us", {"nav": 1.0}) == ""


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs Linux's /proc")
def test_peak_memory_is_the_childs_own_not_its_parents():
    """``peak_rss_of`` reports the measured command's own peak: Linux carries a process's
    largest resident size over ``exec``, so ``ru_maxrss`` of a child started from a
    300 MB parent is at least 300 MB whatever the child does (measured: 312 MB for
    ``onboard --version``, which takes 13 MB)."""
    held = bytearray(300 * 1024 * 1024)
    held[::4096] = b"\x01" * len(held[::4096])   # resident, not only reserved
    got = bench.peak_rss_of(["--version"])
    assert got["peak_rss_mb"] < 100.0, got
    assert held[0] == 1
