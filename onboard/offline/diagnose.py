"""``onboard diagnose LOG [--config FILE ...] [--out DIR] [--write-config FILE] [--force]``:
model closure on measured data.

Reads the log with the same readers and engine as ``onboard replay``, fits the base model,
selects the effects that explain its structured residuals on held-out data, and writes
``DIR/diagnosis.json`` and ``DIR/report.html`` (architecture.md §4.3); with
``--write-config`` also a config overlay of what it found (:mod:`onboard.offline.closure.overlay`).
Options in the config's ``[diagnose]`` table (:class:`onboard.core.config.DiagnoseConfig`):
``declared`` (effects already in the model), ``known``, ``holdout_metric``, ``rate_hz``,
``base_terms``.
"""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path
from typing import Any

import msgspec

from onboard.drivers.base import UnreadableLog
from onboard.offline.closure import base_models, dataset, noise, overlay, overlay_check, report
from onboard.offline.closure.effects import ALL
from onboard.offline.closure.select import select
from onboard.core.errors import OutputFailed, UsageError
from onboard.core.outputs import Output, check as check_outputs, existing
from onboard.monitor.integrity import HEADING_OFFSET_HINT
from onboard.offline.replay import choose_config, print_warnings


def diagnose(log: str, cfg, out_dir: Path, declared: tuple[str, ...] = (), *,
             write_config: Path | None = None, config_note: str = "",
             detected: bool = False, base_terms: tuple[str, ...] | None = None) -> dict:
    """Model closure of ``log`` under configuration ``cfg``: fit, select the effects,
    write ``diagnosis.json`` and ``report.html`` into ``out_dir``; return the diagnosis.

    ``declared`` effects (default: the config's ``[diagnose] declared``) are
    taken as part of the model and not searched; an unknown name is a
    :class:`UsageError`. ``write_config``: also write the config overlay there
    (``config_note`` names the base config in its header; ``detected``: ``cfg`` was
    detected from the log, so the overlay carries its vehicle and inputs).
    ``base_terms``: the base model's optional terms to fit (default: the config's
    ``base_terms``, else :data:`onboard.offline.closure.dataset.DEFAULT_BASE_TERMS`;
    :func:`onboard.offline.closure.dataset.with_base_terms`). The base model is the vehicle
    class's (:func:`onboard.offline.closure.base_models.for_config`). A vehicle class with
    no base model, or a log without what model closure needs (a heading, a velocity over
    ground, 50 s of both: docs/diagnose.md, "What diagnose refuses"), is a
    :class:`UsageError` naming it.
    """
    opts = cfg.diagnose
    declared = tuple(declared) or tuple(opts.declared)
    unknown = [d for d in (*declared, *opts.known) if d not in ALL]
    if unknown:
        raise UsageError(f"unknown declared effect(s) {unknown}; known: {', '.join(ALL)}")
    base = base_models.for_config(cfg)
    try:
        ds = dataset.from_log(log, cfg, rate_hz=opts.rate_hz, base_model=base.name)
    except dataset.NotEnoughData as err:  # what is missing; any other error is a bug
        raise UsageError(str(err)) from None
    try:
        ds = dataset.with_base_terms(ds, base_terms if base_terms is not None
                                     else opts.base_terms)
    except ValueError as err:
        raise UsageError(str(err)) from None
    try:
        sel = select(ds, declared=declared, metric=opts.holdout_metric or None,
                     known=opts.known, candidates=base.effects or None)
    except dataset.NotEnoughData as err:
        raise UsageError(str(err)) from None
    doc = report.write(sel, log, out_dir)
    doc["sensor_noise"] = noise.identify(ds.raw)
    if ds.warnings:   # what reading the log raised (time outliers, jumps), beside the fit
        doc["warnings"] = [_answered(w, doc) for w in msgspec.to_builtins(ds.warnings)]
        doc["log_start_s"] = float(ds.t[0])
    doc = report._clean(doc)
    (out_dir / "diagnosis.json").write_text(json.dumps(doc, indent=2) + "\n")
    if write_config is not None:
        verdicts = overlay_check.check(overlay.sections(doc, cfg, sel), log, cfg, sel)
        doc = overlay_check.record(doc, verdicts, out_dir)
        text = overlay.overlay_text(doc, cfg, sel, detected=detected, base_note=config_note,
                                    refused={v.section: v.reason for v in verdicts
                                             if not v.written})
        try:
            Path(write_config).write_text(text, encoding="utf-8")
        except OSError as err:  # checked before the work: a full disk, a removed folder
            raise OutputFailed(f"--write-config {write_config}: cannot write: "
                               f"{err.strerror}; diagnosis.json is written") from None
    return doc


def _answered(warning: dict[str, Any], doc: dict[str, Any]) -> dict[str, Any]:
    """``warning`` with its pointer to ``onboard diagnose`` replaced by what this
    diagnosis (``doc``) found: a heading/course mismatch says whether a constant offset or
    a compass deviation was measured, or that both were tried and neither kept (and what
    the offset did to the test part)."""
    msg = warning.get("message", "")
    if warning.get("code") != "heading_course_mismatch" or HEADING_OFFSET_HINT not in msg:
        return warning
    heading = {"heading_bias": "a constant offset (heading_bias)",
               "compass_deviation": "a compass deviation (compass_deviation)"}
    tried = [e for e in doc.get("effects", []) if e.get("name") in heading]
    found = [e["name"] for e in tried if e.get("detected")]
    if not tried:
        return warning
    if found:
        bias = next((e["params"].get("bias") for e in tried
                     if e["name"] == "heading_bias" and e.get("detected")), None)
        if bias is not None:
            heading["heading_bias"] = (f"a constant offset of {math.degrees(bias):.1f} deg "
                                       "(heading_bias)")
        answer = (f"this diagnosis measured {' and '.join(heading[n] for n in found)}: "
                  "diagnosis.json; --write-config FILE writes it")
    else:
        answer = (f"this diagnosis tried {' and '.join(heading[e['name']] for e in tried)} "
                  f"and kept {'neither' if len(tried) > 1 else 'nothing'}")
        worse = next((r for r in doc.get("rejected_on_test", [])
                      if r.get("name") == "heading_bias"), None)
        if worse is not None:
            answer += (f" (the offset fitted made the test part worse: {doc['holdout_metric']} "
                       f"{worse['test_error_without']:.3g} -> {worse['test_error_with']:.3g})")
        answer += ("; the heading is off the course by more than that explains: check the "
                   "compass's mounting and calibration, and whose heading it is")
    return {**warning, "message": msg.replace(HEADING_OFFSET_HINT, answer)}


DIAGNOSE_WRITES = ("diagnosis.json", "report.html")
"""What marks ``--out DIR`` as a previous diagnosis's (reused only with ``--force``);
the figures (PNG) beside them are replaced with them."""


def planned_outputs(args) -> list[Output]:
    """Every path ``onboard diagnose`` will write (:func:`onboard.core.outputs.check`)."""
    outs = [Output("--out", Path(args.out), "dir", DIAGNOSE_WRITES)]
    if getattr(args, "write_config", None):
        outs.append(Output("--write-config", Path(args.write_config)))
    return outs


def main(args) -> int:
    """``onboard diagnose``: check every output path, run :func:`diagnose` and print the
    effects found and the error on the test part (never used to fit or to choose)
    before and after, the warnings, and a last line saying what was written."""
    if not Path(args.log).exists():
        raise UsageError(f"{args.log}: no such file or directory")
    check_outputs(planned_outputs(args), force=bool(getattr(args, "force", False)),
                  inputs=[args.log, *existing(args.config)])
    try:
        cfg, _ = choose_config(args.log, args.config)
        doc = diagnose(args.log, cfg, Path(args.out),
                       write_config=getattr(args, "write_config", None),
                       config_note=" --config ".join(args.config or []),
                       detected=not args.config)
    except UnreadableLog as err:
        raise UsageError(str(err)) from None
    found = [e for e in doc["effects"] if e["detected"]]
    names = ", ".join(e["name"] for e in found) or "none"
    print(f"effects: {names}; test-part {doc['holdout_metric']}: "
          f"{doc['holdout_error_before']:.4g} -> {doc['holdout_error_after']:.4g} "
          f"({Path(args.out) / 'diagnosis.json'})")
    for v in doc.get("overlay_check", []):
        print(overlay_check.Verdict(v["section"], v["written"], v["reason"],
                                    v["speed_rmse_before_mps"], v["speed_rmse_after_mps"]).line())
    print_warnings(doc.get("warnings", []), doc.get("log_start_s", 0.0))
    print(_last_line(args, len(doc.get("warnings", []))))
    return 0


def _last_line(args, n_warnings: int) -> str:
    """What was written (report.html without figures when matplotlib, the ``plot`` extra,
    is missing), and how to use the overlay."""
    line = f"wrote diagnosis.json, report.html in {args.out}"
    if importlib.util.find_spec("matplotlib") is None:  # report.write draws no figure
        line += "; no figures in report.html: matplotlib is missing (pip install 'onboard[plot]')"
    if getattr(args, "write_config", None):
        base = " ".join(f"--config {c}" for c in args.config or [])
        line += (f", and the config overlay {args.write_config} (use: "
                 f"{base + ' ' if base else ''}--config {args.write_config})")
    if n_warnings:
        line += f" ({n_warnings} warning{'s' if n_warnings > 1 else ''} above)"
    return line
