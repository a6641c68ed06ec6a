"""diagnosis.json (architecture.md §4.3) and report.html with figures.

The report is written for the engineer who maintains the boat: a plain-language summary
first, parameters in the units they use (degrees, m/s, s) with their one-sigma, which
effects explain the same residual (ambiguity), the structure no effect explains, and the
residual of each channel before and after, lines broken across data gaps
(:func:`onboard.offline.plots.break_gaps`).
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
from pathlib import Path

import numpy as np

from onboard.offline.closure import model as M
from onboard.offline.closure import stats
from onboard.offline.closure.base_models import BY_NAME
from onboard.offline.closure.dataset import MIN_YAW_RATE_HZ
from onboard.offline.closure.effects import ALL
from onboard.offline.closure.select import Selection
from onboard.offline.plots import break_gaps

PARAM_UNITS: dict[str, tuple[tuple[str, str, str, float], ...]] = {
    "water_current": (("north", "m/s", "m/s", 1.0), ("east", "m/s", "m/s", 1.0)),
    "compass_deviation": (("amplitude", "rad", "deg", math.degrees(1.0)),
                          ("phase", "rad", "deg", math.degrees(1.0))),
    "heading_bias": (("bias", "rad", "deg", math.degrees(1.0)),),
    "gyro_bias": (("bias", "rad/s", "deg/s", math.degrees(1.0)),),
    "gps_latency": (("seconds", "s", "s", 1.0),),
    "thrust_nonlinearity": (("quadratic_gain", "m/s^2", "m/s^2", 1.0),
                            ("reverse_gain", "m/s^2", "m/s^2", 1.0),
                            ("exponent", "", "", 1.0), ("reverse_ratio", "", "", 1.0)),
    "quadratic_drag": (("d", "1/m", "1/m", 1.0),),
    "surge_yaw_coupling": (("k", "s", "s", 1.0),),
    "sideslip": (("k", "s/m", "s/m", 1.0),),
    "wave_oscillation": (("period", "s", "s", 1.0),
                         ("direction", "rad", "deg", math.degrees(1.0)),
                         ("velocity_amplitude_mps", "m/s", "m/s", 1.0)),
    "actuator_mapping": (("swapped", "", "", 1.0), ("reversed_left", "", "", 1.0),
                         ("reversed_right", "", "", 1.0)),
    "wind_force": (("north", "m/s^2", "m/s^2", 1.0), ("east", "m/s^2", "m/s^2", 1.0),
                   ("speed_change_mps", "m/s", "m/s", 1.0)),
}
"""Per effect of the catalog: its reported parameters as ``(name, unit in
diagnosis.json, unit shown in the report, factor from the one to the other)``."""

CHANNEL_UNITS: dict[str, tuple[str, float]] = {
    "lateral": ("m/s", 1.0), "along": ("m/s", 1.0), "heading": ("deg", math.degrees(1.0))}
"""Residual channel -> (unit shown, factor from the SI value in diagnosis.json)."""

METRIC_WORDS: dict[str, str] = {
    "ground_velocity_rmse_mps": "ground velocity RMS error",
    "surge_speed_open_loop_rmse_mps": "open-loop surge speed RMS error",
    "lateral_velocity_rmse_mps": "lateral velocity RMS error",
}

def effect_table_markdown() -> str:
    """The docs/diagnose.md table of the effects, their parameters and units, made from
    :data:`PARAM_UNITS` in catalog order (tests/test_diagnose_report.py keeps the doc
    equal to it)."""
    rows = ["| effect | parameter | unit (diagnosis.json) | shown in the report |",
            "|---|---|---|---|"]
    for name in ALL:
        for param, unit, shown, _ in PARAM_UNITS.get(name, ()):
            rows.append(f"| `{name}` | `{param}` | {unit or '-'} | {shown or '-'} |")
    return "\n".join(rows) + "\n"


def unit_of(effect: str, param: str) -> tuple[str, float]:
    """The unit ``effect``'s parameter ``param`` is shown in and the factor from its SI
    value in diagnosis.json (:data:`PARAM_UNITS`); ``("", 1.0)`` for one not listed."""
    for p, _, shown, scale in PARAM_UNITS.get(effect, ()):
        if p == param:
            return shown, scale
    return "", 1.0


def format_param(effect: str, param: str, value, std=None) -> str:
    """``value +- std unit`` in the report's units (degrees for angles)."""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    if not isinstance(value, (int, float)):
        return str(value)
    unit, scale = unit_of(effect, param)
    text = f"{value * scale:.3g}"
    if isinstance(std, (int, float)) and math.isfinite(std):
        text += f" ± {std * scale:.2g}"
    return f"{text} {unit}".strip()


def summary_text(doc: dict) -> str:
    """The plain-language first lines of the report: what explains the log, and the
    test-part error before and after."""
    named = [e for e in doc["effects"] if e["detected"] and e["name"] != "unexplained"]
    parts = []
    for e in named:
        std = e["evidence"].get("std", {})
        vals = ", ".join(f"{k.replace('_', ' ')} {format_param(e['name'], k, v, std.get(k))}"
                         for k, v in e["params"].items())
        parts.append(f"{e['name'].replace('_', ' ')} ({vals})")
    metric = METRIC_WORDS.get(doc["holdout_metric"], doc["holdout_metric"])
    unit = "m/s" if doc["holdout_metric"].endswith("_mps") else ""
    before, after = doc["holdout_error_before"], doc["holdout_error_after"]
    err = (f"the {metric} on the test part (never fitted, never used to choose) "
           f"{'drops' if after < before else 'goes'} from {before:.3g} to {after:.3g} {unit}"
           if before is not None and after is not None else "no test-part error")
    if parts:
        text = "The log is explained by " + "; ".join(parts) + f"; {err}."
    else:
        text = f"No effect of the catalog is needed to explain this log; {err}."
    for r in doc.get("rejected_on_test") or ():
        if r.get("unphysical"):
            fitted = ", ".join(f"{k} {format_param(r['name'], k, v)}"
                               for k, v in (r.get("params") or {}).items())
            text += (f" Tried and rejected: {r['name'].replace('_', ' ')} (chosen on the "
                     "selection part; refitted on the fit and selection parts, its "
                     f"parameters are not physical: {fitted}).")
            continue
        text += (f" Tried and rejected: {r['name'].replace('_', ' ')} (chosen on the "
                 f"selection part, it made the test part worse: {r['test_error_without']:.3g}"
                 f" -> {r['test_error_with']:.3g} {unit})."
                 if r.get("test_error_without") is not None and r.get("test_error_with")
                 is not None else f" Tried and rejected: {r['name']}.")
    un = next((e for e in doc["effects"] if e["name"] == "unexplained"), None)
    if un is not None:
        chans = [f"{ch} (follows {v.get('regressor')})" for ch, v in un["evidence"].items()
                 if isinstance(v, dict)]
        text += (" Structure that no effect of the catalog explains remains in the "
                 + ", ".join(chans) + " residual: see Unexplained.")
    amb = [f"{e['name']} / {', '.join(e['evidence']['ambiguous_with'])}" for e in named
           if e["evidence"].get("ambiguous_with")]
    if amb:
        text += " Ambiguous (explain the same residual about as well): " + "; ".join(amb) + "."
    return text


def _clean(x):
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


def _residual_stats(hold, f: M.Fit) -> dict:
    res = M.residuals(hold, f)
    return {ch: stats.summary(r, hold.dt) for ch, r in res.items()}


def diagnosis(sel: Selection, log: str) -> dict:
    """The diagnosis document for a finished selection."""
    f = sel.final_fit
    last_round = {c.name: c for rnd in sel.rounds for c in rnd}
    effects = []
    for name in ALL:
        if name in sel.declared:
            continue
        cand = last_round.get(name)
        detected = name in sel.chosen
        entry = {"name": name, "detected": detected, "params": {}, "evidence": {}}
        if detected and name in sel.transformed:
            value, sd = sel.transformed[name]
            if hasattr(ALL[name], "describe_value"):
                entry["params"] = ALL[name].describe_value(value)
            else:
                entry["params"] = {ALL[name].params[0]: value}
                entry["evidence"]["std"] = {ALL[name].params[0]: sd}
        elif detected:
            if name == "thrust_nonlinearity":
                params, std = ALL[name].describe(f.theta[name], f.std[name], float(f.base[1]))
            elif name == "wind_force":
                params, std = ALL[name].describe(f.theta[name], f.std[name], float(f.base[0]))
            else:
                params, std = ALL[name].describe(f.theta[name], f.std[name])
            if name == "wave_oscillation":
                params["period"] = f.ctx.wave_period_s
                params["direction"] = f.ctx.extra.get("wave_direction")
            entry["params"] = params
            entry["evidence"]["std"] = std
        # every parameter of an effect with one changing: the components of one vector
        # (a current's north and east) move together, and one may cross the bound alone
        drift = {k.split(".", 1)[1]: v for k, v in sel.drift.get("params", {}).items()
                 if k.startswith(name + ".")}
        if detected and any(v["changing"] for v in drift.values()):
            entry["evidence"]["drift"] = drift
        if cand is not None:
            entry["evidence"].update({
                "held_out_gain": round(cand.gain, 4), "t_max": round(cand.t_max, 2),
                "held_out_headline": cand.headline})
            if not cand.physical:
                entry["evidence"]["unphysical_fit"] = True
            accepted = next((c for rnd in sel.rounds for c in rnd
                             if c.name == name and c.accepted), None)
            if accepted is not None and accepted.alternatives:
                entry["evidence"]["ambiguous_with"] = list(accepted.alternatives)
            rej = next((r for r in sel.rejected_on_test if r["name"] == name), None)
            if rej is not None:
                entry["evidence"]["rejected_on_test"] = {
                    k: v for k, v in rej.items() if k != "name"}
        elif (not ALL[name].applies(sel.split.fit, f.ctx)
              or BY_NAME[sel.split.fit.base_model].why_not(name)):
            entry["evidence"]["not_testable"] = _why_not(name, sel)
        effects.append(entry)
    if sel.unexplained:
        effects.append({"name": "unexplained", "detected": True, "params": {},
                        "evidence": sel.unexplained})
    a, b, c0 = (float(x) for x in f.base)
    return _clean({
        "log": log,
        "model": BY_NAME[sel.split.fit.base_model].description
                 + (f"; declared: {', '.join(sel.declared)}" if sel.declared else ""),
        "base_model": sel.split.fit.base_model,
        "split": sel.split.how,
        "base_params": {**({"a": a, "b": b, "c0": c0,
                            "actuator_lag_s": float(sel.actuator_lag_s)}
                           if sel.split.fit.has_commands else {}),
                        **{k: float(v) for k, v in f.lateral_params.items()}},
        "base_terms": list(sel.split.fit.base_terms),
        "known": {k: v.tolist() for k, v in f.known.items()},
        "split_parts": sel.split.parts,
        "residuals_before": _residual_stats(sel.base_test, sel.base_fit),
        "effects": effects,
        "residuals_after": _residual_stats(sel.final_split.test, f),
        "holdout_error_before": sel.before.headline,
        "holdout_error_after": sel.after.headline,
        "holdout_metric": sel.metric,
        "holdout_channels_before": sel.before.channels,
        "holdout_channels_after": sel.after.channels,
        "wave_search": sel.wave,
        "selection_error_before": sel.select_before.headline,
        "selection_error_after": sel.select_after.headline,
        "drift": sel.drift,
        "rejected_on_test": sel.rejected_on_test,
    })


def needs_yaw_rate(yaw_rate_hz: float) -> str:
    """Why an effect that needs the gyro is not tried on a log whose yaw rate came at
    ``yaw_rate_hz`` (0: none): none at all, or too rare to integrate
    (:data:`onboard.offline.closure.dataset.MIN_YAW_RATE_HZ`)."""
    if yaw_rate_hz <= 0.0:
        return "needs a yaw rate (no gyro or attitude rate in the log)"
    return (f"needs a yaw rate at {MIN_YAW_RATE_HZ:g} Hz or more (the log's comes at "
            f"{yaw_rate_hz:.3g} Hz: spot values that do not integrate to the heading change)")


def _why_not(name: str, sel: Selection) -> str:
    e = ALL[name]
    outside = BY_NAME[sel.split.fit.base_model].why_not(name)
    if outside:
        return outside
    if e.needs_gyro and not sel.split.fit.has_gyro:
        return needs_yaw_rate(sel.split.fit.yaw_rate_hz)
    if e.needs_commands and not sel.split.fit.has_commands:
        return "needs actuator commands"
    if name == "wave_oscillation":
        return "no significant spectral peak in the residual"
    if name == "actuator_mapping":
        return "needs two thruster commands (a skid-steered boat)"
    return "not applicable"


def _fig_png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    return base64.b64encode(buf.getvalue()).decode()


def figures(sel: Selection) -> dict[str, str]:
    """Base64 PNGs: residual vs heading and speed, spectrum, before/after traces."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    hold = sel.base_test
    after_data = sel.final_split.test
    rb = M.residuals(hold, sel.base_fit)
    ra_full = M.residuals(after_data, sel.final_fit)
    # After a latency re-alignment the final data are shorter; compare on common ticks.
    idx = np.searchsorted(after_data.t, hold.t).clip(0, len(after_data) - 1)
    same = after_data.t[idx] == hold.t
    ra = {k: np.where(same, v[idx], np.nan) for k, v in ra_full.items()}
    out = {}
    channels = [ch for ch in ("lateral", "heading", "along") if ch in rb]
    fig, axes = plt.subplots(len(channels), 1, figsize=(10, 2.4 * len(channels)),
                             sharex=True, squeeze=False)
    t_rel = hold.t - hold.t[0]
    for ax, ch in zip(axes[:, 0], channels):
        unit, scale = CHANNEL_UNITS.get(ch, ("", 1.0))
        for label, r in (("before", rb), ("after", ra)):
            tt, y = break_gaps(t_rel, r[ch] * scale, run=hold.run)
            ax.plot(tt, y, lw=0.7, label=f"{label}: RMS {M.rms(r[ch]) * scale:.3g} {unit}")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_ylabel(f"{ch} ({unit})")
        ax.legend(loc="upper right", fontsize=8)
    axes[-1][0].set_xlabel("time (s) of the test part")
    fig.suptitle("Residual per channel on the test part, base model and with the effects")
    fig.tight_layout()
    out["residuals_per_channel"] = _fig_png(fig)
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    heading = np.mod(hold.psi, 2 * np.pi)
    axes[0].plot(np.degrees(heading), rb["lateral"], ".", ms=2, alpha=0.4, label="before")
    axes[0].plot(np.degrees(heading), ra["lateral"], ".", ms=2, alpha=0.4, label="after")
    axes[0].set_xlabel("heading (deg)")
    axes[0].set_ylabel("lateral residual (m/s)")
    axes[0].legend()
    axes[1].plot(hold.along, rb["lateral"], ".", ms=2, alpha=0.4)
    axes[1].plot(hold.along, ra["lateral"], ".", ms=2, alpha=0.4)
    axes[1].set_xlabel("speed (m/s)")
    fig.tight_layout()
    out["residual_vs_heading_speed"] = _fig_png(fig)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(10, 3.2))
    for label, r in (("before", rb), ("after", ra)):
        x = np.nan_to_num(r["lateral"] - np.nanmean(r["lateral"]))
        f = np.fft.rfftfreq(len(x), hold.dt)[1:]
        p = (np.abs(np.fft.rfft(x)) ** 2)[1:]
        ax.loglog(f, p, lw=0.8, label=label)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("lateral residual power")
    ax.legend()
    fig.tight_layout()
    out["spectrum"] = _fig_png(fig)
    plt.close(fig)

    pb = M.predict(hold, sel.base_fit)
    pa_full = M.predict(after_data, sel.final_fit)
    pa = {k: np.where(same, v[idx], np.nan) for k, v in pa_full.items()}
    rows = 2 if "along" in pb else 1
    fig, axes = plt.subplots(rows, 1, figsize=(10, 3.0 * rows), sharex=True, squeeze=False)
    t = hold.t - hold.t[0]

    def brk(x):
        # Break the lines across gaps (between held-out segments, runs, dropouts).
        return break_gaps(t, x, run=hold.run)

    ax = axes[0][0]
    ax.plot(*brk(hold.lateral), lw=0.6, color="k", label="measured")
    ax.plot(*brk(pb["lateral"]), lw=0.8, label="base model")
    ax.plot(*brk(pa["lateral"]), lw=0.8, label="with effects")
    ax.set_ylabel("lateral (m/s)")
    ax.legend(loc="upper right")
    if rows == 2:
        ax = axes[1][0]
        ax.plot(*brk(hold.along), lw=0.6, color="k", label="measured")
        ax.plot(*brk(pb["along"]), lw=0.8, label="base model (open loop)")
        ax.plot(*brk(pa["along"]), lw=0.8, label="with effects (open loop)")
        ax.set_ylabel("along-track speed (m/s)")
        ax.legend(loc="upper right")
    axes[-1][0].set_xlabel("time (s) of the test part")
    fig.tight_layout()
    out["before_after"] = _fig_png(fig)
    plt.close(fig)
    return out


def write(sel: Selection, log: str, out_dir: Path) -> dict:
    """Write diagnosis.json, report.html and its figures (PNG) into ``out_dir``; return
    the diagnosis."""
    out_dir.mkdir(parents=True, exist_ok=True)
    doc = diagnosis(sel, log)
    (out_dir / "diagnosis.json").write_text(json.dumps(doc, indent=2) + "\n")
    try:
        figs = figures(sel)
    except ImportError:
        figs = {}
    for name, png in figs.items():
        (out_dir / f"{name}.png").write_bytes(base64.b64decode(png))
    (out_dir / "report.html").write_text(_html(doc, figs))
    return doc


def _html(doc: dict, figs: dict[str, str]) -> str:
    """report.html: summary, effects with their parameters (report units, one sigma),
    ambiguity and evidence, the unexplained structure, residual tables and figures."""
    e = html.escape
    rows = []
    for eff in doc["effects"]:
        if eff["name"] == "unexplained":
            continue
        ev = eff["evidence"]
        std = ev.get("std", {})
        params = "<br>".join(
            f"{e(k)} = {e(format_param(eff['name'], k, v, std.get(k)))}"
            for k, v in eff["params"].items())
        if ev.get("drift"):
            params += "<br>changing: " + e(", ".join(
                f"{k} {format_param(eff['name'], k, v['first'])} -> "
                f"{format_param(eff['name'], k, v['last'])}" for k, v in ev["drift"].items()))
        gain = ev.get("held_out_gain")
        tmax = ev.get("t_max")
        note = ev.get("not_testable", "")
        if ev.get("unphysical_fit"):
            note = (note + "; " if note else "") + "unphysical fit"
        status = "found" if eff["detected"] else ("not testable" if "not_testable" in ev
                                                  else "not needed")
        rows.append(
            f"<tr><td>{e(eff['name'])}</td><td>{status}</td><td>{params}</td>"
            f"<td>{'' if gain is None else f'{100 * gain:.0f} %'}</td>"
            f"<td>{'' if tmax is None else f'{tmax:.1f}'}</td>"
            f"<td>{e(', '.join(ev.get('ambiguous_with', [])))}</td><td>{e(note)}</td></tr>")
    unexplained = next((x for x in doc["effects"] if x["name"] == "unexplained"), None)
    un_html = "<p>None: no structure left that the generic basis finds.</p>"
    if unexplained is not None:
        un_rows = "".join(
            f"<tr><td>{e(ch)}</td><td>{e(str(v.get('regressor')))}</td>"
            f"<td>{100 * v.get('regressor_gain', float('nan')):.0f} %</td>"
            f"<td>{100 * v.get('held_out_gain', float('nan')):.0f} %</td></tr>"
            for ch, v in unexplained["evidence"].items() if isinstance(v, dict))
        un_html = ("<table><tr><th>channel</th><th>regressor carrying the structure</th>"
                   "<th>its gain alone</th><th>held-out gain</th></tr>" + un_rows + "</table>")

    def res_table(key):
        out = []
        for ch, v in doc[key].items():
            if v["rmse"] is None:
                continue
            unit, scale = CHANNEL_UNITS.get(ch, ("", 1.0))
            wp = v["whiteness_p"]
            out.append(f"<tr><td>{e(ch)}</td><td>{v['rmse'] * scale:.3g} {unit}</td>"
                       f"<td>{v['bias'] * scale:.3g} {unit}</td>"
                       f"<td>{'' if wp is None else format(wp, '.3g')}</td></tr>")
        return "".join(out)

    imgs = "".join(f'<h3>{e(k.replace("_", " "))}</h3><img src="data:image/png;base64,{v}">'
                   for k, v in figs.items())
    before, after = doc["holdout_error_before"], doc["holdout_error_after"]
    metric = METRIC_WORDS.get(doc["holdout_metric"], doc["holdout_metric"])
    unit = "m/s" if doc["holdout_metric"].endswith("_mps") else ""
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>diagnosis</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:2em auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:3px 8px;vertical-align:top}}img{{max-width:100%}}
.summary{{font-size:1.1em;background:#f4f6f8;padding:0.8em;border-left:4px solid #357}}</style></head><body>
<h1>Model closure: {e(doc['log'])}</h1>
<p class="summary">{e(summary_text(doc))}</p>
<p><b>Base model:</b> {e(doc['model'])}.<br><b>Split:</b> {e(str(doc['split']))}.</p>
<p><b>Test part, {e(metric)}:</b> {before:.3g} {unit} before, {after:.3g} {unit} after.
Angles in degrees, speeds in m/s, times in s; each parameter with its one-sigma (±).</p>
<h2>Effects</h2><table><tr><th>effect</th><th>status</th><th>parameters</th>
<th>held-out gain (selection part)</th><th>|t| max</th><th>ambiguous with</th><th>note</th></tr>
{''.join(rows)}</table>
<h2>Unexplained</h2>{un_html}
<h2>Residuals on the test part</h2><h3>before (base model)</h3><table><tr><th>channel</th><th>RMS</th><th>bias</th>
<th>whiteness p</th></tr>{res_table('residuals_before')}</table>
<h3>after (with the effects)</h3><table><tr><th>channel</th><th>RMS</th><th>bias</th><th>whiteness p</th></tr>
{res_table('residuals_after')}</table>{imgs}</body></html>
"""
