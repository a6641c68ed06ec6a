"""Warnings: a lasting condition is one warning with its span, a new one after a pause is
another, and the list is bounded."""

from __future__ import annotations

from onboard.monitor import alerts as alerts_mod
from onboard.monitor.alerts import Alerts


def test_a_repeated_warning_extends_its_span_and_counts() -> None:
    a = Alerts()
    for t in (10.0, 11.0, 15.0):
        a.warn("heading_course", f"off by {t:.0f} deg", t, pipeline="aie")
    (w,) = list(a)
    assert (w.t_start, w.t_end, w.n, w.message) == (10.0, 15.0, 3, "off by 15 deg")


def test_the_same_warning_after_a_pause_is_a_new_one_and_pipelines_are_apart() -> None:
    a = Alerts()
    a.warn("heading_course", "x", 10.0, pipeline="aie")
    a.warn("heading_course", "x", 10.0 + alerts_mod.MERGE_GAP_S + 1.0, pipeline="aie")
    a.warn("heading_course", "x", 10.0, pipeline="kf")
    assert [(w.pipeline, w.t_start) for w in a] == [("aie", 10.0), ("aie", 21.0), ("kf", 10.0)]


def test_a_whole_run_warning_has_no_times_and_the_list_is_bounded() -> None:
    a = Alerts()
    a.warn("no_position_source", "none")
    assert [(w.t_start, w.t_end) for w in a] == [(None, None)]
    for i in range(alerts_mod.MAX_ALERTS + 5):
        a.warn(f"code{i}", "x", float(i))
    assert len(a) == alerts_mod.MAX_ALERTS and a.dropped == 6


def test_each_new_warning_is_also_an_event_once() -> None:
    events: list[str] = []
    a = Alerts(events)
    a.warn("heading_course_mismatch", "off by 74 deg", 1.0, pipeline="aie")
    a.warn("heading_course_mismatch", "off by 75 deg", 2.0, pipeline="aie")   # extends
    assert events == ["heading_course_mismatch: off by 74 deg"]


def test_a_warning_is_one_line_and_its_details_and_its_events_carry_the_line() -> None:
    events: list[str] = []
    a = Alerts(events)
    a.warn("nis_out_of_band", "aie surge.rate: NIS 0.2; its noise is set in [pipelines.aie]",
           5.0, pipeline="aie", details="100 updates, dof 1")
    (w,) = list(a)
    assert (w.message, w.details) == ("aie surge.rate: NIS 0.2; its noise is set in "
                                      "[pipelines.aie]", "100 updates, dof 1")
    assert events == ["nis_out_of_band: aie surge.rate: NIS 0.2; its noise is set in "
                      "[pipelines.aie]"]


def test_revise_replaces_the_text_of_a_warning_and_keeps_its_span_and_count() -> None:
    """What is learnt later (a GNSS fix after headings were used magnetic) changes what is
    true of a warning already raised; its span stays the span it covered."""
    a = Alerts()
    for t in (30.0, 31.0):
        a.warn("no_declination", "no fix yet", t)
    assert a.revise("no_declination", "corrected after the fix", details="2 headings")
    (w,) = list(a)
    assert (w.message, w.details, w.t_start, w.t_end, w.n) == (
        "corrected after the fix", "2 headings", 30.0, 31.0, 2)
    assert not a.revise("no_declination", "x", pipeline="aie")   # none of that key
