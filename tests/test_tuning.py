"""The tuning protocol (validation/tuning.py) and the ablation table it produced.

The tuning itself takes minutes per variant (``python -m validation tune``); here: its pieces, that
every variant builds a valid pipeline, and that docs/aie.md's ablation table is the
rendering of the committed docs/tuning.json (cheap, no simulation).
"""

from __future__ import annotations

import json
import math

import pytest

from onboard.core.errors import UsageError
from validation import tuning as T

REPO = T.TUNING_FILE.parents[1]


@pytest.fixture(scope="module")
def committed() -> dict:
    return json.loads(T.TUNING_FILE.read_text(encoding="utf-8"))


def test_the_ablation_table_in_docs_aie_md_is_rendered_from_docs_tuning_json(committed) -> None:
    page = (REPO / "docs" / "aie.md").read_text(encoding="utf-8")
    assert T.table_block(page) == T.render_table(committed), (
        "docs/aie.md's ablation table differs from docs/tuning.json: run "
        "`python -m validation tune --page docs/aie.md`")
    with pytest.raises(UsageError):
        T.table_block("no markers")


def test_the_committed_results_follow_the_protocol(committed) -> None:
    """Same budget, scenarios and held-out runs for every variant that was tuned."""
    assert committed["protocol"] == T.protocol()
    for name, rec in committed["variants"].items():
        keys = {k.split("@")[0] for k in rec["held_out"]}
        assert keys == set(T.TUNING_SCENARIOS) | set(T.UNSEEN_SCENARIOS), name
        if rec.get("tuned"):
            assert rec["evaluations"] <= T.BUDGET, name
            assert rec["objective"] <= rec["objective_start"], name
    for name in ("aie", "kf"):   # the tuned set beat the hand-tuned one on held-out runs
        after = T.held_out_objective(committed["variants"][name]["held_out"])
        before = T.held_out_objective(committed["variants"][f"{name} (before)"]["held_out"])
        assert after < before, name   # measured: AIE 1.22 < 1.62, KF 1.27 < 1.69


def test_the_shipped_defaults_are_the_tuned_ones(committed) -> None:
    """The tuned parameters of ``aie`` and ``kf`` (rounded to 2 digits) are the defaults
    of [pipelines.aie] / [pipelines.kf] (they won on the held-out objective); those of
    ``aie-no-doppler`` and ``kf-no-doppler`` the ``"auto"`` values without a Doppler
    speed (pipeline_config.TunedPair)."""
    for name in ("aie", "kf", "aie-no-doppler", "kf-no-doppler"):
        tuned = committed["variants"][name]["params"]
        start = dict(zip((p.key for p in T.VARIANTS[name].params),
                         (10.0 ** x for x in T.start_point(T.VARIANTS[name]))))
        for key, value in tuned.items():
            assert start[key] == pytest.approx(value, rel=0.05), (name, key)


@pytest.mark.parametrize("name", list(T.VARIANTS))
def test_every_variant_builds_a_valid_pipeline_within_its_bounds(name: str) -> None:
    from onboard.core import config as config_mod

    v = T.VARIANTS[name]
    x0 = T.start_point(v)
    for p, x in zip(v.params, x0):
        assert p.lo <= x <= p.hi, (name, p.key)
    table = T.merged(v.fixed, T.table_of(v.params, x0))
    data = {"vehicle": {"id": "t", "class": "rudder-boat"}, "pipelines": {v.pipeline: table}}
    cfg = config_mod.from_dict(data)
    assert getattr(cfg.pipelines, v.pipeline) is not None


def test_merged_and_table_of() -> None:
    base = {"surge": {"a": 1.0, "v_d": 0.1}, "step_s": 0.2}
    over = {"surge": {"v_d": 0.5}, "gnss_velocity": False}
    assert T.merged(base, over) == {"surge": {"a": 1.0, "v_d": 0.5}, "step_s": 0.2,
                                    "gnss_velocity": False}
    assert base["surge"]["v_d"] == 0.1          # not modified in place
    t = T.table_of(T.V_D, [-1.0, 0.0])
    assert t == {"surge": {"v_d": pytest.approx(0.1)}, "heading": {"v_d": 1.0}}


def test_the_objective_penalizes_an_overconfident_sigma() -> None:
    """Negative control: the same RMSE with a 2-sigma coverage below the floor scores
    worse, by the stated weight; above the floor there is no penalty."""
    good = {"speed": 0.05, "heading": 0.03, "speed_cover2": 0.95, "heading_cover2": 0.95}
    assert T.score(good) == pytest.approx(0.5 + 1.0)
    bad = dict(good, speed_cover2=0.80)
    assert T.score(bad) - T.score(good) == pytest.approx(T.COVERAGE_WEIGHT * 0.10)
    assert math.isfinite(T.score(dict(good, heading_cover2=0.0)))
