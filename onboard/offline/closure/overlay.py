"""``onboard diagnose --write-config FILE``: what the diagnosis found, as a config overlay.

The overlay is a TOML file meant to come after the config the diagnosis ran with
(``--config base.toml --config overlay.toml``, :func:`onboard.core.config.load_all`); it
only holds the keys it changes:

* ``[corrections]`` (applied to every validated sample by the engine, live and replay):
  ``gnss_latency_s`` from ``gps_latency``; ``gyro_bias_rps`` (z) from ``gyro_bias``;
  ``heading_offset_rad`` from ``heading_bias``; the first heading harmonics
  ``heading_harmonics_sin/cos`` from ``compass_deviation`` (``amplitude sin(psi + phase) =
  amplitude cos(phase) sin(psi) + amplitude sin(phase) cos(psi)``), with the deviation
  card in degrees as a comment. The data the diagnosis saw had the base config's
  corrections already taken out, so what it finds is added to them;
* ``[inputs.left]``/``[inputs.right]`` from ``actuator_mapping`` (channels swapped,
  ``reverse`` toggled), with ``from_autopilot = false`` so that the autopilot's
  ``SERVOn_FUNCTION`` parameters do not map them back;
* ``[pipelines.aie.surge]`` and ``[pipelines.kf.surge]`` ``a``, ``gain``, ``offset`` (the
  surge model of ``aie`` and of its ``kf`` baseline, algorithms.md §1.1; the same in both
  tables) from the diagnosis's surge fit when the log has commands; with a ``thrust_nonlinearity`` the pipelines' linear map is the least
  squares line through the fitted thrust curve over the commands the log flew (the
  curve itself is written as a comment);
* ``[pipelines.current] initial_current_std_mps`` from ``water_current``: the size of the
  current this log showed (plus three sigma) as the prior's scale, not its value
  (currents change from one mission to the next).

When the diagnosis ran on a config detected from the log (no ``--config``), the overlay
also holds the detected ``[vehicle]`` and ``[inputs]``, so that ``--config overlay.toml``
alone reproduces it.
Each of these is a :class:`Section`, checked before it is written
(:mod:`onboard.offline.closure.overlay_check`: plausible parameters, and a replay of the test part
through ``aie`` and ``kf`` that it must not make worse); a refused section is written as
comments only, with why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from onboard.core.config import ChannelMap, Config, to_dict

_CARD_STEP_DEG = 30
"""Heading step (deg) of the deviation card written as a comment."""


def _toml_value(v: Any) -> str:
    """A TOML literal for a bool, number, string or list of them."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"not a finite number: {v}")
        return repr(float(f"{v:.6g}"))
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"no TOML literal for {type(v).__name__}")


def _inline(table: dict[str, Any]) -> str:
    """A TOML inline table of plain values."""
    return "{ " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in table.items()) + " }"


def to_dict_channel(m: ChannelMap) -> dict[str, Any]:
    """A channel map as its TOML keys (every key, so the overlay replaces it whole)."""
    import msgspec

    return msgspec.to_builtins(m)


class _Doc:
    """TOML text built table by table, with comments."""

    def __init__(self) -> None:
        self.lines: list[str] = []

    def comment(self, text: str) -> None:
        for line in text.splitlines():
            self.lines.append(f"# {line}".rstrip())

    def table(self, name: str, items: dict[str, Any], note: str = "") -> None:
        if not items:
            return
        self.lines.append("")
        if note:
            self.comment(note)
        self.lines.append(f"[{name}]")
        for k, v in items.items():
            self.lines.append(f"{k} = {_inline(v) if isinstance(v, dict) else _toml_value(v)}")

    def text(self) -> str:
        return "\n".join(self.lines).strip() + "\n"


def _found(doc: dict) -> dict[str, dict]:
    return {e["name"]: e for e in doc["effects"] if e["detected"] and e["name"] != "unexplained"}


def _std(entry: dict, key: str) -> float | None:
    v = entry.get("evidence", {}).get("std", {}).get(key)
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) else None


def _pm(entry: dict, key: str, scale: float = 1.0, fmt: str = ".3g") -> str:
    s = _std(entry, key)
    return "" if s is None else f" +- {format(s * scale, fmt)}"


def corrections(doc: dict, cfg: Config) -> tuple[dict[str, Any], list[str]]:
    """The ``[corrections]`` keys (the base config's plus what ``doc`` found) and the
    comment lines explaining them."""
    f = _found(doc)
    base = cfg.corrections
    out: dict[str, Any] = {}
    notes: list[str] = []
    if "gps_latency" in f:
        e = f["gps_latency"]
        tau = float(e["params"]["seconds"])
        out["gnss_latency_s"] = base.gnss_latency_s + tau
        notes.append(f"gps_latency: GNSS fixes {tau:.3f}{_pm(e, 'seconds', fmt='.2f')} s late")
    if "gyro_bias" in f:
        e = f["gyro_bias"]
        b = float(e["params"]["bias"])
        g = list(base.gyro_bias_rps)
        g[2] += b
        out["gyro_bias_rps"] = g
        notes.append(f"gyro_bias: yaw rate reads {math.degrees(b):.3f}"
                     f"{_pm(e, 'bias', math.degrees(1.0), '.2g')} deg/s too much")
    if "heading_bias" in f:
        e = f["heading_bias"]
        b = float(e["params"]["bias"])
        out["heading_offset_rad"] = base.heading_offset_rad + b
        notes.append(f"heading_bias: heading reads {math.degrees(b):.2f}"
                     f"{_pm(e, 'bias', math.degrees(1.0), '.2g')} deg too much")
    if "compass_deviation" in f:
        e = f["compass_deviation"]
        amp, ph = float(e["params"]["amplitude"]), float(e["params"]["phase"])
        a1, b1 = amp * math.cos(ph), amp * math.sin(ph)
        notes.append(f"compass_deviation: {math.degrees(amp):.2f}"
                     f"{_pm(e, 'amplitude', math.degrees(1.0), '.2g')} deg x sin(heading + "
                     f"{math.degrees(ph):.1f}{_pm(e, 'phase', math.degrees(1.0), '.2g')} deg)")
        if base.heading_deviation_table:
            out["heading_deviation_table"] = [
                [h, err + math.degrees(a1 * math.sin(math.radians(h))
                                       + b1 * math.cos(math.radians(h)))]
                for h, err in base.heading_deviation_table]
        else:
            s = list(base.heading_harmonics_sin) or [0.0]
            c = list(base.heading_harmonics_cos) or [0.0]
            s[0] += a1
            c[0] += b1
            out["heading_harmonics_sin"] = s
            out["heading_harmonics_cos"] = c
            card = []
            for h in range(0, 360, _CARD_STEP_DEG):
                x = math.radians(h)
                dev = sum(v * math.sin((k + 1) * x) for k, v in enumerate(s)) + sum(
                    v * math.cos((k + 1) * x) for k, v in enumerate(c))
                card.append(f"{h:3d}: {math.degrees(dev):+5.1f}")
            notes.append("deviation card (true heading deg: heading error deg):")
            notes += ["  " + "   ".join(card[i:i + 6]) for i in range(0, len(card), 6)]
    return out, notes


def actuator_inputs(doc: dict, cfg: Config) -> tuple[dict[str, Any], list[str]]:
    """``[inputs]`` with the thruster channels re-mapped as ``actuator_mapping`` found
    (empty when it found nothing or the config has no ``left``/``right``)."""
    e = _found(doc).get("actuator_mapping")
    left, right = cfg.inputs.left, cfg.inputs.right
    if e is None or left is None or right is None:
        return {}, []
    p = e["params"]
    swapped, rev_l, rev_r = bool(p["swapped"]), bool(p["reversed_left"]), bool(p["reversed_right"])

    def flip(m: ChannelMap, rev: bool) -> dict[str, Any]:
        d = to_dict_channel(m)
        if rev:
            d["reverse"] = not d["reverse"]
        return d

    # port (the new ``left``) is the logged right channel when swapped, reversed if found so
    port = flip(right, rev_r) if swapped else flip(left, rev_l)
    stbd = flip(left, rev_l) if swapped else flip(right, rev_r)
    what = ", ".join(n for n, v in (("swapped", swapped), ("left reversed", rev_l),
                                    ("right reversed", rev_r)) if v)
    return ({"from_autopilot": False, "left": port, "right": stbd},
            [f"actuator_mapping: {what} (the logged commands re-mapped)"])


def surge_model(doc: dict, sel: Any) -> tuple[dict[str, Any], list[str]]:
    """``[pipelines.aie.surge]`` (and ``[pipelines.kf.surge]``) ``a``, ``gain``, ``offset``
    from the final surge fit, or empty without commands (see the module docstring for a
    thrust nonlinearity)."""
    bp = doc.get("base_params", {})
    if not {"a", "b", "c0"} <= set(bp) or sel is None:
        return {}, []
    a, b, c0 = float(bp["a"]), float(bp["b"]), float(bp["c0"])
    notes = [(f"surge model U' = -a U + gain c + offset (fit + selection parts): "
              f"a = {a:.3g} 1/s, gain = {b:.3g} m/s^2, offset = {c0:.3g} m/s^2")]
    f = _found(doc)
    fit = sel.final_fit
    if "thrust_nonlinearity" in f and "thrust_nonlinearity" in fit.theta:
        b2, brev = (float(x) for x in fit.theta["thrust_nonlinearity"])
        ds = sel.final_split.fit
        c = np.asarray(ds.cmd_surge, float)
        c = c[np.isfinite(c)]
        if len(c) > 10:
            u = b * c + b2 * c * np.abs(c) + brev * np.minimum(c, 0.0) + c0
            g, o = np.polyfit(c, u, 1)
            notes.append(f"thrust curve: u = {b:.3g} c + {b2:.3g} c|c| + {brev:.3g} min(c, 0) "
                         f"+ {c0:.3g} m/s^2; the pipelines' linear map is its least-squares "
                         f"line over the commands flown: gain {g:.3g}, offset {o:.3g}")
            b, c0 = float(g), float(o)
    if not (a > 0 and math.isfinite(b) and b > 0):
        return {}, notes + ["(not written: a non-physical surge fit)"]
    return {"a": a, "gain": b, "offset": c0}, notes


def current_prior(doc: dict) -> tuple[dict[str, Any], list[str]]:
    """``[pipelines.current] initial_current_std_mps`` from a ``water_current`` found."""
    e = _found(doc).get("water_current")
    if e is None:
        return {}, []
    n, east = float(e["params"]["north"]), float(e["params"]["east"])
    sn, se = _std(e, "north") or 0.0, _std(e, "east") or 0.0
    speed = math.hypot(n, east)
    scale = max(0.05, speed + 3.0 * math.hypot(sn, se))
    toward = math.degrees(math.atan2(east, n)) % 360
    return ({"initial_current_std_mps": round(scale, 3)},
            [f"water_current: {speed:.3f} m/s toward {toward:.0f} deg in this log; "
             + "its size is the prior's scale"])


def sensor_noise(doc: dict, cfg: Config) -> tuple[dict[str, dict[str, Any]], list[str]]:
    """The ``[sensors.*]`` noise keys from the white noise identified in the log
    (``doc["sensor_noise"]``, :mod:`onboard.offline.closure.noise`): a channel whose
    noise is not white (a filtered output) is noted, not written. Fixes that report
    their accuracy keep it, and the overlay writes the share of it that wanders
    (``drift_share``) instead of ``position_std_m``, with the correlation time that gives
    the drift's measured rate of change (``drift_tau_s``) where the fixes carry a
    velocity."""
    from onboard.offline.closure.noise import CONFIG_KEYS

    found = doc.get("sensor_noise") or {}
    tables: dict[str, dict[str, Any]] = {}
    notes: list[str] = []
    for channel, fig in found.items():
        table, key = CONFIG_KEYS[channel]
        std = float(fig["std"])
        line = (f"{channel}: white noise {std:.3g} {fig['unit']} (second differences, "
                f"{fig['samples']} samples, lag-1 {fig['lag1']:.2f} against -0.67 for white)")
        if not fig["white"] or not std > 0:
            notes.append(line + "; not white (a filtered output): not written")
            continue
        if channel == "gnss_position" and fig.get("reported_understates"):
            tables.update(_receiver_set_aside(fig, std, cfg))
            notes.append(line + f"; the fixes report {fig['reported_std']:.3g} m, less than "
                         "their white noise alone: their reported accuracy set aside "
                         "(gnss_accuracy = false), the noise measured in its place (white "
                         "and drift)")
            continue
        if channel == "gnss_position" and "reported_std" in fig:
            share = round(min(0.9, float(fig["drift_share"])), 3)
            tables.setdefault(table, {})["drift_share"] = share
            notes.append(line + f"; the fixes report {fig['reported_std']:.3g} m: "
                         f"drift_share {share}")
            if share > 0.0 and "drift_tau_s" in fig:
                tau = float(f"{float(fig['drift_tau_s']):.3g}")
                tables[table]["drift_tau_s"] = tau
                notes.append(f"gnss_position: the drift changes by "
                             f"{fig['drift']['rate_m2_per_s']:.3g} m^2/s per axis (the "
                             f"fixes against their own velocity, "
                             f"{fig['drift']['span_s']:.0f} s): drift_tau_s {tau:g}")
            continue
        tables.setdefault(table, {})[key] = float(f"{std:.3g}")
        notes.append(line)
    return tables, notes


def _receiver_set_aside(fig: dict, white: float, cfg: Config) -> dict[str, dict[str, Any]]:
    """The tables for a receiver that understates its accuracy (``fig`` of
    ``gnss_position``, ``white`` its white noise, m): every position pipeline of ``cfg``
    with ``gnss_accuracy = false``, and ``[sensors.gnss]`` the noise measured, the white
    and the drift (:func:`onboard.offline.closure.noise.receiver_drift`) together as
    ``position_std_m``, the drift's share and correlation time where it was fitted."""
    out: dict[str, dict[str, Any]] = {
        f"pipelines.{name}": {"gnss_accuracy": False}
        for name in ("aie", "kf") if getattr(cfg.pipelines, name).enabled}
    drift = fig.get("drift") or {}
    s_b = float(drift.get("std", 0.0))
    total = math.hypot(white, s_b)
    gnss: dict[str, Any] = {"position_std_m": float(f"{total:.3g}"),
                            "drift_share": round(s_b * s_b / (total * total), 3)}
    if s_b > 0.0:
        gnss["drift_tau_s"] = float(f"{float(drift['tau_s']):.3g}")
    out["sensors.gnss"] = gnss
    return out


@dataclass
class Section:
    """One checked part of the overlay (:mod:`onboard.offline.closure.overlay_check`): its
    ``name``, the TOML ``tables`` it writes (table name -> keys), the comment ``notes``
    and the sections it ``needs`` (it was fitted with them)."""

    name: str
    tables: dict[str, dict[str, Any]]
    notes: list[str] = field(default_factory=list)
    needs: tuple[str, ...] = ()

    def layer(self) -> dict[str, Any]:
        """The tables as nested TOML tables, ready for :func:`onboard.core.config.merge`."""
        out: dict[str, Any] = {}
        for name, keys in self.tables.items():
            node = out
            for part in name.split("."):
                node = node.setdefault(part, {})
            node.update(keys)
        return out


def sections(doc: dict, cfg: Config, sel: Any = None) -> list[Section]:
    """The overlay's sections in the order they are checked and written:
    ``corrections``, ``inputs`` (the re-mapping only), ``surge model`` (aie and kf),
    ``current prior``, ``sensor noise``."""
    corr, c_notes = corrections(doc, cfg)
    inputs, i_notes = actuator_inputs(doc, cfg)
    surge, s_notes = surge_model(doc, sel)
    prior, p_notes = current_prior(doc)
    out = [Section("corrections", {"corrections": corr} if corr else {}, c_notes),
           Section("inputs", {"inputs": inputs} if inputs else {}, i_notes)]
    tables = {"pipelines.aie.surge": surge, "pipelines.kf.surge": surge} if surge else {}
    out.append(Section("surge model", tables, s_notes, ("inputs",) if inputs else ()))
    out.append(Section("current prior", {"pipelines.current": prior} if prior else {},
                       p_notes))
    noise, n_notes = sensor_noise(doc, cfg)
    out.append(Section("sensor noise", noise, n_notes))
    return out


def _render_inputs(out: _Doc, inputs: dict[str, Any], notes: list[str]) -> None:
    out.lines.append("")
    out.comment("\n".join(notes) or "the input mapping detected from the log")
    out.lines.append("[inputs]")
    for k, v in inputs.items():
        if isinstance(v, dict):
            out.lines.append(f"{k} = {_inline(v)}")
        elif isinstance(v, list):
            out.lines.append(f"{k} = [" + ", ".join(_inline(x) for x in v) + "]")
        else:
            out.lines.append(f"{k} = {_toml_value(v)}")


def _render(out: _Doc, sec: Section, cfg: Config, detected: bool, refused: str) -> None:
    """One section's tables with its notes, or its notes and why it was refused."""
    notes = list(sec.notes) + ([f"NOT WRITTEN: {refused}"] if refused else [])
    if sec.name == "inputs" and detected:
        det = {k: v for k, v in to_dict(cfg)["inputs"].items() if v is not None and v != []}
        tables = sec.tables.get("inputs", {}) if not refused else {}
        if det or tables:
            _render_inputs(out, {**det, **tables}, notes)
        return
    if refused or not sec.tables:
        if notes:
            out.lines.append("")
            out.comment("\n".join(notes))
        return
    for i, (name, keys) in enumerate(sec.tables.items()):
        if name == "inputs":
            _render_inputs(out, keys, notes)
        elif sec.name == "surge model":
            out.table(name, keys, "\n".join(notes) if i == 0 else
                      "the same surge model for the KF baseline")
        else:
            out.table(name, keys, "\n".join(notes) if i == 0 else "")


def overlay_text(doc: dict, cfg: Config, sel: Any = None, *, detected: bool = False,
                 base_note: str = "", refused: dict[str, str] | None = None) -> str:
    """The overlay TOML for diagnosis ``doc`` of a log read with ``cfg`` (the Selection
    ``sel`` gives the commands flown, for a thrust curve). ``refused``: section name ->
    why it is not written (:func:`onboard.offline.closure.overlay_check.check`); those sections
    appear as comments only."""
    refused = refused or {}
    out = _Doc()
    how = ("Self-contained (the config was detected from the log): --config THIS_FILE"
           if detected else f"Apply after the config it ran with: --config "
           f"{base_note or 'BASE'} --config THIS_FILE")
    out.comment(f"Written by `onboard diagnose --write-config` from {doc['log']}.\n{how}\n"
                f"Test part {doc['holdout_metric']}: {doc['holdout_error_before']:.4g} -> "
                f"{doc['holdout_error_after']:.4g}")
    if detected:
        out.table("vehicle", to_dict(cfg)["vehicle"], "the config detected from the log")
    for sec in sections(doc, cfg, sel):
        _render(out, sec, cfg, detected, refused.get(sec.name, ""))
    unexplained = next((e for e in doc["effects"] if e["name"] == "unexplained"), None)
    ignored = [n for n in _found(doc) if n not in (
        "gps_latency", "gyro_bias", "heading_bias", "compass_deviation",
        "actuator_mapping", "thrust_nonlinearity", "water_current")]
    tail = []
    if ignored:
        tail.append("found but with no config key the pipelines read: " + ", ".join(ignored))
    if unexplained is not None:
        tail.append("unexplained residual structure (no correction written): " + ", ".join(
            f"{ch}: {v.get('regressor')}" for ch, v in unexplained["evidence"].items()
            if isinstance(v, dict)))
    if tail:
        out.lines.append("")
        out.comment("\n".join(tail))
    return out.text()
