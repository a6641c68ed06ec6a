"""The classical Kalman-filter baseline of the AIE paper: pipeline ``kf``.

Faros & Tanner (arXiv 2504.02005, §3): "a standard Kalman filter is also implemented with
the assumption that the nominal operator control input is the one that is implemented".
Here: the same measurement points, filters, track and outputs as
:mod:`onboard.pipelines.aie` (its own table ``[pipelines.kf]``), with the input model
:class:`~onboard.estimators.input_models.CommandedInput`: the commanded input at nominal
scaling, ``u = gain * command + offset`` (algorithms.md §2.12), of error variance ``v_d``
of ``[pipelines.kf.<axis>]``, plus an input-bias state where ``bias_q > 0``. Without
commands in the log the input is zero (a random-walk-driven filter).
"""

from __future__ import annotations

from onboard.core.config import Config
from onboard.core.pipeline_config import KfAxisConfig, KfConfig
from onboard.core.vehicles import traits
from onboard.estimators.axis_model import AxisModel
from onboard.estimators.increment_filter import IncrementFilter
from onboard.estimators.input_models import CommandedInput
from onboard.pipelines.surge_heading import SurgeHeadingPipeline, sensor_noise

COLUMNS = ("north", "east", "heading", "speed", "yaw_rate",
           "std_north", "std_east", "std_speed", "std_heading")
"""The estimates of pipeline ``kf`` (units in docs/architecture.md §4.2)."""


def axis_filter(model: AxisModel, c: KfAxisConfig, top: KfConfig,
                name: str = "surge", doppler: bool = True) -> IncrementFilter:
    """One baseline axis: the increment filter with the commanded input of ``c``, with
    the ``"auto"`` ``v_d`` of the measurement set (``doppler``: with a Doppler speed)."""
    return IncrementFilter(model, CommandedInput(c.bias_q),
                           input_error_var=c.tuned("v_d", doppler), u_max=c.u_max,
                           q_v=c.q_v, correlated=top.correlated_noise, gate_nis=top.gate_nis,
                           adaptive_rate_noise=top.adaptive_rate_noise, name=name)


def retune(f: IncrementFilter, c: KfAxisConfig, doppler: bool) -> None:
    """Axis ``f`` (built by :func:`axis_filter` from ``c``) takes the ``v_d`` of the
    measurement set (``doppler``: with a Doppler speed)."""
    f.set_input_error_var(c.tuned("v_d", doppler))


def build(cfg: KfConfig, gnss_position_std_m: float = 1.5, heading_std_rad: float = 0.03,
          gnss_velocity_std_mps: float = 0.1, gnss_drift_share: float = 0.0,
          gnss_drift_tau_s: float = 120.0) -> SurgeHeadingPipeline:
    """A KF baseline pipeline from a :class:`KfConfig` (for code and tests)."""
    return SurgeHeadingPipeline("kf", COLUMNS, cfg, gnss_position_std_m, heading_std_rad,
                                axis_filter, gnss_velocity_std_mps, retune=retune,
                                gnss_drift_share=gnss_drift_share,
                                gnss_drift_tau_s=gnss_drift_tau_s)


def create(cfg: Config) -> SurgeHeadingPipeline | None:
    """Pipeline ``kf`` wherever ``aie`` applies, from ``[pipelines.kf]`` (``enabled =
    false`` is honoured by the pipeline registry)."""
    if not traits(cfg.vehicle.vehicle_class).surge_heading_model:
        return None
    return build(cfg.pipelines.kf, *sensor_noise(cfg))
