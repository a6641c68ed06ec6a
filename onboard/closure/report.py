"""diagnosis.json (architecture.md §4.3) and report.html with figures."""

from __future__ import annotations

import base64
import html
import io
import json
import math
from pathlib import Path

import numpy as np

from onboard.closure import model as M
from onboard.closure import stats
from onboard.closure.effects import ALL
from onboard.closure.select import Selection

BASE_MODEL = ("velocity over ground along the measured heading but for the hull's sway in "
              "turns (v = x_p r); heading rate equal to the gyro's; first-order surge model "
              "U' = -a U + b c + c0 from the normalized command")


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
        changing = {k.split(".", 1)[1]: v for k, v in sel.drift.get("params", {}).items()
                    if k.startswith(name + ".") and v["changing"]}
        if detected and changing:
            entry["evidence"]["drift"] = changing
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
        elif not ALL[name].applies(sel.split.fit, f.ctx):
            entry["evidence"]["not_testable"] = _why_not(name, sel)
        effects.append(entry)
    if sel.unexplained:
        effects.append({"name": "unexplained", "detected": True, "params": {},
                        "evidence": sel.unexplained})
    a, b, c0 = (float(x) for x in f.base)
    return _clean({
        "log": log,
        "model": BASE_MODEL + (f"; declared: {', '.join(sel.declared)}" if sel.declared else ""),
        "split": sel.split.how,
        "base_params": {**({"a": a, "b": b, "c0": c0} if sel.split.fit.has_commands else {}),
                        "x_p": float(f.x_p)},
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
    })


def _why_not(name: str, sel: Selection) -> str:
    e = ALL[name]
    if e.needs_gyro and not sel.split.fit.has_gyro:
        return "needs a gyro"
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
    # Break the lines between held-out segments instead of joining them across the gap.
    gap = np.r_[False, hold.run[1:] != hold.run[:-1]]

    def brk(x):
        x = np.asarray(x, float).copy()
        x[gap] = np.nan
        return x

    pb = {k: brk(v) for k, v in pb.items()}
    pa = {k: brk(v) for k, v in pa.items()}
    ax = axes[0][0]
    ax.plot(t, brk(hold.lateral), lw=0.6, color="k", label="measured")
    ax.plot(t, pb["lateral"], lw=0.8, label="base model")
    ax.plot(t, pa["lateral"], lw=0.8, label="with effects")
    ax.set_ylabel("lateral (m/s)")
    ax.legend(loc="upper right")
    if rows == 2:
        ax = axes[1][0]
        ax.plot(t, brk(hold.along), lw=0.6, color="k", label="measured")
        ax.plot(t, pb["along"], lw=0.8, label="base model (open loop)")
        ax.plot(t, pa["along"], lw=0.8, label="with effects (open loop)")
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
    e = html.escape
    rows = []
    for eff in doc["effects"]:
        mark = "&#10003;" if eff["detected"] else ""
        params = ", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}"
                           for k, v in eff["params"].items())
        ev = eff["evidence"]
        gain = ev.get("held_out_gain")
        if eff["name"] == "unexplained":
            params = "; ".join(f"{ch}: {v['regressor']} (gain alone {v['regressor_gain']:.2f})"
                               for ch, v in ev.items() if isinstance(v, dict))
        elif ev.get("drift"):
            params += " (changing: " + ", ".join(
                f"{k} {v['first']:.3g} -> {v['last']:.3g}" for k, v in ev["drift"].items()) + ")"
        rows.append(f"<tr><td>{e(eff['name'])}</td><td>{mark}</td><td>{e(params)}</td>"
                    f"<td>{'' if gain is None else f'{gain:.3f}'}</td>"
                    f"<td>{e(str(ev.get('t_max', ev.get('not_testable', ''))))}</td></tr>")

    def res_table(key):
        return "".join(
            f"<tr><td>{e(ch)}</td><td>{v['rmse']:.4g}</td><td>{v['bias']:.4g}</td>"
            f"<td>{v['whiteness_p'] if v['whiteness_p'] is None else format(v['whiteness_p'], '.3g')}</td></tr>"
            for ch, v in doc[key].items() if v["rmse"] is not None)

    imgs = "".join(f'<h3>{e(k.replace("_", " "))}</h3><img src="data:image/png;base64,{v}">'
                   for k, v in figs.items())
    before, after = doc["holdout_error_before"], doc["holdout_error_after"]
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>diagnosis</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:2em auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:3px 8px}}img{{max-width:100%}}</style></head><body>
<h1>Model closure: {e(doc['log'])}</h1>
<p><b>Base model:</b> {e(doc['model'])}.<br><b>Split:</b> {e(doc['split'])}.</p>
<p><b>Held-out {e(doc['holdout_metric'])}:</b> {before:.4g} before, {after:.4g} after.</p>
<h2>Effects</h2><table><tr><th>effect</th><th>detected</th><th>parameters</th>
<th>held-out gain</th><th>|t| max</th></tr>{''.join(rows)}</table>
<h2>Held-out residuals</h2><h3>before</h3><table><tr><th>channel</th><th>RMS</th><th>bias</th>
<th>whiteness p</th></tr>{res_table('residuals_before')}</table>
<h3>after</h3><table><tr><th>channel</th><th>RMS</th><th>bias</th><th>whiteness p</th></tr>
{res_table('residuals_after')}</table>{imgs}</body></html>
"""
