"""The BlueBoat folder's overlay round trip (issue 22, item 5): ``diagnose --write-config``
on ``blueboat_sysid_ntnu`` must not raise the onboard filters' speed error.

Before the check the overlay held ``[pipelines.aie.surge] a = 0.0582, gain = 2.9652`` (a
top speed of 51.9 m/s at full command) and, replayed over the whole folder, took the
aie speed error against the GNSS speed over ground from 0.227 to 1.391 m/s and kf's from
0.316 to 1.103 m/s.
"""

from __future__ import annotations

import json

import pytest

from onboard.offline.closure import overlay_check
from onboard.core import config
from onboard.offline.diagnose import diagnose

pytestmark = [pytest.mark.data, pytest.mark.slow]


def test_blueboat_overlay_does_not_raise_the_aie_kf_speed_error(shared_data, tmp_path):
    log = str(shared_data / "blueboat_sysid_ntnu")
    base = config.load("blueboat-ntnu-csv")
    ov = tmp_path / "overlay.toml"
    doc = diagnose(log, base, tmp_path / "out", write_config=ov,
                   config_note="blueboat-ntnu-csv")
    verdicts = {v["section"]: v for v in doc["overlay_check"]}
    assert json.loads((tmp_path / "out" / "diagnosis.json").read_text())["overlay_check"]
    # the surge model is refused by its implausible top speed (51.9 m/s > 10 m/s)
    surge = verdicts["surge model"]
    assert not surge["written"] and "51.9 m/s" in surge["reason"]
    assert "[pipelines.aie.surge]" not in ov.read_text()
    # the compass deviation is written (judged by the diagnosis's own held-out test)
    assert verdicts["corrections"]["written"]
    # the whole folder replayed without and with the overlay, each filter's speed
    # predicted for the next fix against the fix's: aie 0.176, kf 0.297 m/s before it
    # (against the speed after each fix, before 2026-12-01: 0.167 -> 0.167 and 0.289 ->
    # 0.288; 0.227 -> 0.225 and 0.316 -> 0.316 before the filters learned their noise)
    whole = [(-1.0e12, 1.0e12)]
    before = overlay_check.speed_errors(log, base, whole)
    after = overlay_check.speed_errors(log, config.load_all(["blueboat-ntnu-csv", ov]), whole)
    for k in ("aie", "kf"):
        assert after[k] <= before[k] + overlay_check.TIE_MPS, (k, before, after)
    assert before["aie"] == pytest.approx(0.176, abs=0.01)
    assert before["kf"] == pytest.approx(0.297, abs=0.01)
