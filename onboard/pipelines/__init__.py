"""Estimation pipelines: pure functions of their inputs (see :mod:`.base`).

Each module exposes ``create(cfg) -> Pipeline | None``; :func:`build` instantiates
those that apply to a configuration, honouring ``[pipelines.<name>] enabled = false``.
"""

from __future__ import annotations

import importlib

from onboard.core.config import Config
from onboard.pipelines.base import Pipeline

MODULES: tuple[str, ...] = ("nav", "aie", "kf", "current", "dac", "eseso")
"""Pipeline modules in the order their columns appear in estimates.csv."""


def build(cfg: Config, only: set[str] | None = None) -> list[Pipeline]:
    """Instantiate every applicable, enabled pipeline for ``cfg``."""
    out: list[Pipeline] = []
    for mod_name in MODULES:
        if getattr(cfg.pipelines, mod_name).enabled is False:
            continue
        if only is not None and mod_name not in only:
            continue
        module = importlib.import_module(f"onboard.pipelines.{mod_name}")
        pipeline = module.create(cfg)
        if pipeline is not None:
            out.append(pipeline)
    return out
