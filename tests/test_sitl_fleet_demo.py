"""``onboard demo --fleet`` (onboard/apps/demo_fleet.py): its members start in order and
stop in reverse (also on an error), the live truth is read from a file being written,
the score against the truth; the live fleet itself is ``slow``."""

from __future__ import annotations

import asyncio
import json
import math

import pytest

from onboard.apps.demo_fleet import (CommandMember, last_truth, run_members, score_vehicle,
                                     vehicle_line)
from onboard.core.messages import EstimateRecord
from onboard.sitl.truth import TruthRecord


class Member:
    def __init__(self, name, log, fail=False):
        self.name, self.log, self.fail = name, log, fail

    async def start(self, start):
        if self.fail:
            raise RuntimeError(f"{self.name} failed")
        self.log.append(("start", self.name))

    async def stop(self):
        self.log.append(("stop", self.name))


def test_members_start_in_order_and_stop_in_reverse():
    log: list = []
    ticks = []
    members = [Member("a", log), Member("b", log), Member("c", log)]
    asyncio.run(run_members(members, 0.0, lambda: len(ticks) >= 1, 0.01,
                            lambda: ticks.append(1)))
    assert log == [("start", "a"), ("start", "b"), ("start", "c"),
                   ("stop", "c"), ("stop", "b"), ("stop", "a")]
    log.clear()
    with pytest.raises(RuntimeError):
        asyncio.run(run_members([Member("a", log), Member("b", log, fail=True),
                                 Member("c", log)], 0.0, lambda: True, 1.0, lambda: None))
    assert log == [("start", "a"), ("stop", "a")]  # the started ones only


def test_command_member_is_one_more_process(tmp_path):
    import sys

    flag = tmp_path / "ran"
    m = CommandMember([sys.executable, "-c", f"open({str(flag)!r}, 'w').write('x')"])

    async def go():
        await m.start(0.0)
        m.proc.wait(30)
        await m.stop()

    asyncio.run(go())
    assert flag.read_text() == "x" and m.proc is None


def test_last_truth_reads_the_newest_complete_record(tmp_path):
    p = tmp_path / "t.jsonl"
    assert last_truth(str(p)) is None
    p.write_text(json.dumps({"t": 1.0}) + "\n" + json.dumps({"t": 2.0}) + "\n" + '{"t": 3')
    assert last_truth(str(p)) == {"t": 2.0}


def _truth(t, n, e):
    return TruthRecord(t=t, north=0, east=0, down=0, roll=0, pitch=0, yaw=0, u=0, v=0, w=0,
                       p=0, q=0, r=0, u_r=0, v_r=0, w_r=0, current_north=n, current_east=e)


def _rec(t, values, std):
    return EstimateRecord(vehicle="boat-1", pipeline="current", t=t, values=values, std=std)


def test_score_counts_known_estimates_against_the_truth_at_their_time():
    truth = [_truth(0.0, 0.2, 0.0), _truth(10.0, 0.4, 0.1)]
    hist = [_rec(5.0, {"north": 0.33, "east": 0.05}, {"north": 0.02, "east": 0.01}),
            _rec(6.0, {"east": 0.06}, {"north": 1.0, "east": 0.01})]
    sc = score_vehicle(hist, truth)
    # truth at 5 s: (0.3, 0.05); at 6 s: east 0.06
    assert sc["north"]["n"] == 1 and sc["north"]["rms"] == pytest.approx(0.03)
    assert sc["north"]["cover95"] == 1.0  # 0.03 < 1.96 * 0.02
    assert sc["east"]["n"] == 2 and sc["east"]["rms"] == pytest.approx(0.0, abs=1e-12)
    assert math.isnan(score_vehicle([], truth)["north"]["rms"])
    line = vehicle_line("boat-1", hist[1], {"t": 6.0, "current_north": 0.32,
                                             "current_east": 0.06})
    assert "est N unknown (sigma 1.00)" in line and "est E +0.060 ± 0.010" in line


@pytest.mark.slow
def test_fleet_demo_runs_every_vehicle_on_its_own_service(tmp_path):
    """The live fleet demo for 60 simulated seconds at 2x: every vehicle's service
    publishes over the shared router under its own id, and its truth was written."""
    from onboard.apps.demo_fleet import run_fleet_demo

    res = asyncio.run(run_fleet_demo("fleet-demo", 60.0, speed=2.0, out_dir=tmp_path,
                                     out=None))
    assert set(res) == {"boat-1", "boat-2", "auv-1"}
    for vid, r in res.items():
        assert r["estimates"] and all(e.vehicle == vid for e in r["estimates"])
        assert r["truth"]


def test_an_unknown_fleet_is_refused_before_anything_is_printed_or_started(tmp_path):
    import subprocess
    import sys

    run = subprocess.run([sys.executable, "-m", "onboard", "demo", "--fleet", "nosuch"],
                         capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert run.returncode == 2 and run.stdout == "", (run.stdout, run.stderr)
    assert run.stderr.startswith("onboard demo: unknown fleet 'nosuch'; fleets: ")
    assert len(run.stderr.strip().splitlines()) == 1 and not (tmp_path / "demo-out").exists()
