"""The tuned noise parameters left at ``"auto"`` follow the measurement set present.

``v_d`` and ``r_d`` of ``[pipelines.aie.<axis>]`` and ``v_d`` of ``[pipelines.kf.<axis>]``
default to ``"auto"``: the values the common tuning protocol found with the GNSS Doppler
speed row (variants ``aie``, ``kf`` of docs/tuning.json) while fixes carry a speed over
ground, those it found without (``aie-no-doppler``, ``kf-no-doppler``) once no fix has
carried one for ``DOPPLER_HOLD_S`` (docs/aie.md section 2.2). A number in the
configuration wins.
"""

from __future__ import annotations

import math

import msgspec
import pytest

from onboard.core.geo import LocalFrame
from onboard.core.messages import GnssFix, Heading
from onboard.core.pipeline_config import (
    AIE_HEADING_R_D,
    AIE_HEADING_V_D,
    AIE_SURGE_R_D,
    AIE_SURGE_V_D,
    KF_HEADING_V_D,
    KF_SURGE_V_D,
    AieConfig,
    KfConfig,
)
from onboard.pipelines import aie as aie_mod
from onboard.pipelines import kf as kf_mod
from onboard.pipelines.surge_heading import DOPPLER_HOLD_S, SurgeHeadingPipeline

FRAME = LocalFrame(63.4, 10.4)
SPEED_MPS = 1.0


def _aie(table: dict | None = None) -> SurgeHeadingPipeline:
    return aie_mod.build(msgspec.convert(table or {}, AieConfig), 1.5, 0.03)


def _kf(table: dict | None = None) -> SurgeHeadingPipeline:
    return kf_mod.build(msgspec.convert(table or {}, KfConfig), 1.5, 0.03)


def _drive(p: SurgeHeadingPipeline, t0: float, t1: float,
           doppler: bool | None, sog: float = SPEED_MPS) -> None:
    """Steer north at 1 m/s from ``t0`` to ``t1`` (s): 10 Hz headings and, with
    ``doppler`` not None, 5 Hz fixes with (True) or without (False) a speed over ground
    (None: a GNSS outage)."""
    for i in range(round(t0 * 10), round(t1 * 10)):
        t = i / 10.0
        batch: list = [Heading(t=t, heading_rad=0.0)]
        if doppler is not None and i % 2 == 0:
            lat, lon = FRAME.to_latlon(SPEED_MPS * t, 0.0)
            batch.insert(0, GnssFix(t=t, lat_deg=lat, lon_deg=lon,
                                    sog_mps=sog if doppler else None,
                                    cog_rad=0.0 if doppler else None))
        p.step(t, batch)


def _rcie_penalty(p: SurgeHeadingPipeline, axis: str) -> float:
    rc = (p.surge if axis == "surge" else p.yaw).input.rcie
    return rc.lam / rc.wb


def test_auto_resolves_to_the_tuned_pair_and_a_number_wins() -> None:
    aie, kf = AieConfig(), KfConfig()
    assert aie.surge.v_d == aie.heading.r_d == kf.surge.v_d == "auto"
    assert aie.surge.tuned("v_d", True) == AIE_SURGE_V_D.doppler == 0.04
    assert aie.surge.tuned("v_d", False) == AIE_SURGE_V_D.no_doppler == 0.82
    assert aie.surge.tuned("r_d", False) == AIE_SURGE_R_D.no_doppler
    assert aie.heading.tuned("v_d", False) == AIE_HEADING_V_D.no_doppler
    assert aie.heading.tuned("r_d", True) == AIE_HEADING_R_D.doppler
    assert kf.surge.tuned("v_d", False) == KF_SURGE_V_D.no_doppler == 2.7
    assert kf.heading.tuned("v_d", True) == KF_HEADING_V_D.doppler
    mine = msgspec.convert({"surge": {"v_d": 0.5, "r_d": 3}}, AieConfig)
    assert mine.surge.tuned("v_d", True) == mine.surge.tuned("v_d", False) == 0.5
    assert mine.surge.tuned("r_d", False) == 3.0
    with pytest.raises(msgspec.ValidationError):
        msgspec.convert({"surge": {"v_d": "automatic"}}, AieConfig)


@pytest.mark.parametrize("build", [_aie, _kf], ids=["aie", "kf"])
def test_fixes_with_a_speed_keep_the_doppler_set(build) -> None:
    """The set a Doppler log runs with is the one before this change: no switch."""
    p = build()
    _drive(p, 0.0, 30.0, doppler=True)
    h = p.health()
    assert h.doppler_set is True and h.set_switches == 0
    surge = AIE_SURGE_V_D if p.name == "aie" else KF_SURGE_V_D
    assert p.surge.V_u0 == surge.doppler
    if p.name == "aie":
        assert _rcie_penalty(p, "surge") == pytest.approx(AIE_SURGE_R_D.doppler)
        assert _rcie_penalty(p, "heading") == pytest.approx(AIE_HEADING_R_D.doppler)


@pytest.mark.parametrize("build", [_aie, _kf], ids=["aie", "kf"])
def test_fixes_without_a_speed_switch_to_the_no_doppler_set_at_the_first_fix(build) -> None:
    p = build()
    _drive(p, 0.0, 0.1, doppler=False)       # one fix
    assert p.health().doppler_set is False
    _drive(p, 0.1, 30.0, doppler=False)
    h = p.health()
    assert h.doppler_set is False and h.set_switches == 1
    surge, heading = ((AIE_SURGE_V_D, AIE_HEADING_V_D) if p.name == "aie"
                      else (KF_SURGE_V_D, KF_HEADING_V_D))
    assert p.surge.V_u == p.surge.V_u0 == surge.no_doppler
    assert p.yaw.V_u0 == heading.no_doppler
    if p.name == "aie":
        assert _rcie_penalty(p, "surge") == pytest.approx(AIE_SURGE_R_D.no_doppler)
        assert _rcie_penalty(p, "heading") == pytest.approx(AIE_HEADING_R_D.no_doppler)
    assert math.isfinite(p.step(30.0, [])["speed"])


def test_a_switch_mid_run_follows_the_newest_speed_with_a_hold() -> None:
    """Speeds stop: the Doppler set holds DOPPLER_HOLD_S (5 s), then the no-Doppler set;
    the first fix with a speed switches back at once. A GNSS outage is no switch."""
    p = _aie()
    _drive(p, 0.0, 20.0, doppler=True)
    _drive(p, 20.0, 20.0 + DOPPLER_HOLD_S - 0.2, doppler=False)
    assert p.doppler and p.set_switches == 0          # within the hold
    _drive(p, 24.8, 26.0, doppler=False)
    assert not p.doppler and p.set_switches == 1
    assert p.surge.V_u0 == AIE_SURGE_V_D.no_doppler
    _drive(p, 26.0, 26.2, doppler=True)
    assert p.doppler and p.set_switches == 2
    assert p.surge.V_u0 == AIE_SURGE_V_D.doppler
    _drive(p, 26.2, 60.0, doppler=None)               # 34 s without fixes
    assert p.doppler and p.set_switches == 2
    _drive(p, 60.0, 70.0, doppler=True)
    assert p.doppler and p.set_switches == 2


def test_a_speed_too_slow_to_sign_still_counts_as_doppler() -> None:
    """Below DOPPLER_SIGN_MIN_SPEED_MPS the speed is not used, but the receiver gives
    one: a Doppler log at rest keeps its set."""
    p = _kf()
    _drive(p, 0.0, 20.0, doppler=True, sog=0.05)
    assert p.doppler and p.set_switches == 0
    assert p.surge.rate_steps == 0


def test_a_number_in_the_configuration_is_used_with_either_set() -> None:
    p = _aie({"surge": {"v_d": 0.3, "r_d": 2.0}})
    _drive(p, 0.0, 10.0, doppler=False)
    assert not p.doppler
    assert p.surge.V_u0 == 0.3 and _rcie_penalty(p, "surge") == pytest.approx(2.0)
    assert p.yaw.V_u0 == AIE_HEADING_V_D.no_doppler   # the heading axis left at "auto"


def test_gnss_velocity_off_runs_on_the_no_doppler_set() -> None:
    """``gnss_velocity = false`` leaves the speeds out: the set of the increments alone."""
    p = _kf({"gnss_velocity": False})
    _drive(p, 0.0, 10.0, doppler=True)
    assert not p.doppler and p.surge.V_u0 == KF_SURGE_V_D.no_doppler
