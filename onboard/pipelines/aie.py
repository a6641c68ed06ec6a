"""Adaptive input estimation (AIE) of surge and heading: pipeline ``aie``.

Faros & Tanner, "System Identification and Adaptive Input Estimation on the Jaiabot",
arXiv 2504.02005 (2025); AIE = retrospective cost input estimation (RCIE, Ansari &
Bernstein, IEEE TCST 2019; :mod:`onboard.estimators.rcie`) driving a Kalman filter
(Verma, Sanjeevini, Sumer & Bernstein, IJC 2024; :mod:`onboard.estimators.kalman`,
algorithms.md §2). Each axis is an
:class:`~onboard.estimators.increment_filter.IncrementFilter` whose input model is
:class:`~onboard.estimators.input_models.RcieInput`: the filter's innovation and the
Markov parameters of its model go to RCIE, whose input estimate drives the next forecast
(§2.7). The measurement points, the track and the outputs are
:class:`onboard.pipelines.surge_heading.SurgeHeadingPipeline`, shared with ``kf``.
"""

from __future__ import annotations

from onboard.core.config import Config
from onboard.core.pipeline_config import AieConfig, AxisConfig
from onboard.core.vehicles import traits
from onboard.estimators.axis_model import AxisModel
from onboard.estimators.increment_filter import IncrementFilter
from onboard.estimators.input_models import RcieInput
from onboard.estimators.rcie import Rcie
from onboard.pipelines.surge_heading import SurgeHeadingPipeline, sensor_noise

COLUMNS = ("north", "east", "heading", "speed", "yaw_rate", "surge_input", "yaw_input",
           "std_north", "std_east", "std_speed", "std_heading")
"""The estimates of pipeline ``aie`` (units in docs/architecture.md §4.2)."""


def axis_filter(model: AxisModel, c: AxisConfig, top: AieConfig,
                name: str = "surge", doppler: bool = True) -> IncrementFilter:
    """One AIE axis: the increment filter with the RCIE input of ``c`` (§2.10), with
    the ``"auto"`` parameters of the measurement set (``doppler``: with a Doppler speed)."""
    rcie = Rcie(c.n_c, c.n_f, c.r_z, c.tuned("r_d", doppler), c.r_theta, c.lam, c.u_scale,
                1.0, c.u_max, rate_penalty=c.rate_penalty)
    estimate = RcieInput(rcie, u_max=c.u_max, u_scale=c.u_scale, known_input=c.known_input,
                         divergence_input=top.divergence_input,
                         divergence_nis=top.divergence_nis, adaptive=top.adaptive,
                         adaptive_window=top.adaptive_window)
    return IncrementFilter(model, estimate, input_error_var=c.tuned("v_d", doppler),
                           u_max=c.u_max, q_v=c.q_v, correlated=top.correlated_noise,
                           gate_nis=top.gate_nis,
                           adaptive_rate_noise=top.adaptive_rate_noise, name=name)


def retune(f: IncrementFilter, c: AxisConfig, doppler: bool) -> None:
    """Axis ``f`` (built by :func:`axis_filter` from ``c``) takes the ``v_d`` and
    ``r_d`` of the measurement set (``doppler``: with a Doppler speed)."""
    assert isinstance(f.input, RcieInput)
    f.set_input_error_var(c.tuned("v_d", doppler))
    f.input.rcie.set_input_penalty(c.tuned("r_d", doppler))


def build(cfg: AieConfig, gnss_position_std_m: float = 1.5, heading_std_rad: float = 0.03,
          gnss_velocity_std_mps: float = 0.1, gnss_drift_share: float = 0.0,
          gnss_drift_tau_s: float = 120.0) -> SurgeHeadingPipeline:
    """An AIE pipeline from an :class:`AieConfig` (for code and tests)."""
    return SurgeHeadingPipeline("aie", COLUMNS, cfg, gnss_position_std_m, heading_std_rad,
                                axis_filter, gnss_velocity_std_mps, retune=retune,
                                gnss_drift_share=gnss_drift_share,
                                gnss_drift_tau_s=gnss_drift_tau_s)


def create(cfg: Config) -> SurgeHeadingPipeline | None:
    """Pipeline ``aie`` for the vehicle classes its surge/heading model fits (None for the
    others: :attr:`onboard.core.vehicles.VehicleTraits.surge_heading_model`)."""
    if not traits(cfg.vehicle.vehicle_class).surge_heading_model:
        return None
    return build(cfg.pipelines.aie, *sensor_noise(cfg))
