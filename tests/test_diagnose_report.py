"""report.html a marine engineer can read: units (degrees, m/s, s), each parameter with
its one-sigma, ambiguity, the unexplained evidence, a plain-language summary, residual
plots per channel with lines broken at data gaps; and the docs/diagnose.md parameter
table kept equal to the code's catalog."""

from __future__ import annotations

import base64
import re
from pathlib import Path

import numpy as np
import pytest

from onboard.offline.closure import report
from onboard.offline.closure.dataset import from_arrays
from onboard.offline.closure.effects import ALL
from onboard.offline.closure.select import select

DOC = Path(__file__).resolve().parent.parent / "docs" / "diagnose.md"
BEGIN, END = "<!-- effect-table:begin -->", "<!-- effect-table:end -->"


def synth(seed: int, T: float, dev=(0.0, 0.0), gyro_bias=0.0, dt=0.1):
    """A first-order boat in turns with a compass deviation ``a sin psi + b cos psi``
    (rad) and a gyro bias (rad/s): the kinematics of tests/test_closure_synthetic.py."""
    rng = np.random.default_rng(seed)
    n = int(T / dt)
    t = np.arange(n) * dt
    thr = np.repeat(rng.uniform(0.3, 1.0, n // 400 + 1), 400)[:n]
    rud = np.sign(np.sin(2 * np.pi * t / 60)) * 0.3 * np.repeat(
        rng.uniform(0.5, 1, n // 300 + 1), 300)[:n]
    u = r = psi = 0.0
    U, PSI, R = np.empty(n), np.empty(n), np.empty(n)
    for i in range(n):
        u += dt * (-0.5 * u + thr[i])
        r += dt * (-1.0 * r + 0.6 * rud[i] * u)
        psi += dt * r
        U[i], PSI[i], R[i] = u, psi, r
    vlat = -0.3 * R
    vn = U * np.cos(PSI) - vlat * np.sin(PSI) + rng.normal(0, 0.05, n)
    ve = U * np.sin(PSI) + vlat * np.cos(PSI) + rng.normal(0, 0.05, n)
    psi_m = PSI + dev[0] * np.sin(PSI) + dev[1] * np.cos(PSI) + rng.normal(0, 0.01, n)
    gyro = R + gyro_bias + rng.normal(0, 0.005, n)
    return from_arrays(t, psi_m, vn, ve, r=gyro, cmd_surge=thr, cmd_yaw=rud)


def _doc() -> dict:
    return {
        "log": "boat.tlog", "model": "base", "split": "forward in time",
        "holdout_metric": "ground_velocity_rmse_mps",
        "holdout_error_before": 0.191, "holdout_error_after": 0.0955,
        "residuals_before": {"lateral": {"rmse": 0.17, "bias": 0.01, "whiteness_p": 0.0},
                             "heading": {"rmse": 0.4, "bias": -0.3, "whiteness_p": 0.0}},
        "residuals_after": {"lateral": {"rmse": 0.08, "bias": 0.0, "whiteness_p": 0.2},
                            "heading": {"rmse": 0.06, "bias": 0.0, "whiteness_p": 0.1}},
        "effects": [
            {"name": "compass_deviation", "detected": True,
             "params": {"amplitude": 0.119, "phase": 0.710},
             "evidence": {"std": {"amplitude": 0.0068, "phase": 0.056},
                          "held_out_gain": 0.41, "t_max": 17.3,
                          "ambiguous_with": ["water_current"]}},
            {"name": "gps_latency", "detected": True, "params": {"seconds": 0.572},
             "evidence": {"std": {"seconds": 0.061}, "held_out_gain": 0.2, "t_max": 9.0}},
            {"name": "sideslip", "detected": False, "params": {},
             "evidence": {"held_out_gain": 0.01, "t_max": 1.2}},
            {"name": "wave_oscillation", "detected": False, "params": {},
             "evidence": {"not_testable": "no significant spectral peak in the residual"}},
            {"name": "unexplained", "detected": True, "params": {},
             "evidence": {"heading": {"regressor": "heading harmonic 2",
                                      "regressor_gain": 0.8, "held_out_gain": 0.87}}},
        ],
    }


def test_summary_says_what_explains_the_log_in_report_units():
    text = report.summary_text(_doc())
    assert text.startswith("The log is explained by compass deviation (amplitude 6.82 ± 0.39 "
                           "deg, phase 40.7 ± 3.2 deg); gps latency (seconds 0.572 ± 0.061 s)")
    assert "drops from 0.191 to 0.0955 m/s" in text
    assert "heading (follows heading harmonic 2)" in text
    assert "compass_deviation / water_current" in text


def test_summary_when_nothing_is_found():
    doc = _doc()
    doc["effects"] = [e for e in doc["effects"] if not e["detected"]]
    doc["holdout_error_after"] = doc["holdout_error_before"]
    assert report.summary_text(doc).startswith("No effect of the catalog is needed")


def test_html_units_sigma_ambiguity_and_unexplained():
    page = report._html(_doc(), {})
    assert page.index('class="summary"') < page.index("<h2>Effects")
    assert "6.82 ± 0.39 deg" in page and "40.7 ± 3.2 deg" in page
    assert "0.572 ± 0.061 s" in page
    assert "0.71" not in page.split("<h2>Effects")[1].split("<h2>Unexplained")[0]  # no rad
    assert "<td>water_current</td>" in page  # the ambiguity column
    un = page.split("<h2>Unexplained</h2>")[1].split("<h2>")[0]
    assert "heading harmonic 2" in un and "87 %" in un and "80 %" in un
    # heading residual shown in degrees: 0.4 rad = 22.9 deg
    assert "22.9 deg" in page
    assert "no significant spectral peak" in page


@pytest.mark.parametrize("name", list(ALL))
def test_every_catalog_effect_has_its_units(name):
    assert name in report.PARAM_UNITS, f"add {name} to report.PARAM_UNITS (and the docs)"


def test_reported_parameter_names_are_the_catalog_ones():
    """The names diagnosis.json reports for each effect are those PARAM_UNITS lists."""
    for name, eff in ALL.items():
        listed = {p for p, *_ in report.PARAM_UNITS[name]}
        if hasattr(eff, "describe_value"):
            keys = set(eff.describe_value(0.0))
        elif getattr(eff, "transforms_data", False):
            keys = {eff.params[0]}
        else:
            th = np.full(len(eff.params), 0.1)
            if name == "thrust_nonlinearity":
                keys = set(eff.describe(th, th, 1.0)[0])
            elif name == "wind_force":
                keys = set(eff.describe(th, th, 0.5)[0])
            else:
                keys = set(eff.describe(th, th)[0])
        assert keys <= listed, (name, keys - listed)


def test_docs_effect_table_is_the_generated_one():
    text = DOC.read_text()
    assert BEGIN in text and END in text, f"docs/diagnose.md lacks {BEGIN} ... {END}"
    in_doc = text.split(BEGIN)[1].split(END)[0].strip() + "\n"
    assert in_doc == report.effect_table_markdown(), (
        "docs/diagnose.md's effect table is out of date; paste the output of "
        "`python -c 'from onboard.offline.closure.report import effect_table_markdown as f; "
        "print(f())'` between the markers")


def test_docs_physics_table_names_every_catalog_effect():
    text = DOC.read_text()
    names = set(re.findall(r"^\s*\| `(\w+)` \|", text.split("## Method")[1].split("\n4.")[0],
                           re.MULTILINE))
    assert names == set(ALL)


def test_break_gaps_breaks_lines_at_gaps_and_run_changes():
    t = np.array([0.0, 0.1, 0.2, 5.0, 5.1, 5.2, 5.3])
    y = np.arange(7.0)
    tt, yy = report.break_gaps(t, y)
    assert np.isnan(tt[3]) and np.isnan(yy[3]) and len(tt) == 8
    run = np.array(["a", "a", "a", "a", "b", "b", "b"])
    tt, yy = report.break_gaps(t, y, run=run)
    assert np.isnan(yy).sum() == 2
    tt, yy = report.break_gaps(t[:3], y[:3])
    assert not np.isnan(yy).any()


def test_report_figures_per_channel_from_a_selection(tmp_path):
    """A small synthetic log (300 s, compass deviation and gyro bias) through the whole
    report: per-channel residual figure and the gaps in it broken."""
    ds = synth(seed=3, T=300.0, dev=(0.08, 0.05), gyro_bias=0.01)
    sel = select(ds)
    doc = report.write(sel, "synthetic", tmp_path)
    found = {e["name"] for e in doc["effects"] if e["detected"]}
    assert {"compass_deviation", "gyro_bias"} <= found
    page = (tmp_path / "report.html").read_text()
    assert "residuals per channel" in page
    png = tmp_path / "residuals_per_channel.png"
    assert png.stat().st_size > 10_000
    assert base64.b64encode(png.read_bytes()).decode()[:200] in page
    assert "The log is explained by" in page and "deg/s" in page


def test_the_last_line_says_when_report_html_has_no_figures(monkeypatch):
    """Without matplotlib (the plot extra) report.html is written without figures; the
    last line says so and names the extra, as onboard replay does for track.png."""
    import sys
    from types import SimpleNamespace

    from onboard.offline.diagnose import _last_line

    args = SimpleNamespace(out="diag", write_config=None, config=None)
    assert "matplotlib" not in _last_line(args, 0)
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # not importable
    line = _last_line(args, 2)
    assert line.startswith("wrote diagnosis.json, report.html in diag; no figures in "
                           "report.html: matplotlib is missing (pip install 'onboard[plot]')")
    assert line.endswith("(2 warnings above)")
