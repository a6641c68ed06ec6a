"""The classical Kalman-filter baseline of the AIE paper: pipeline ``kf``.

Faros & Tanner (arXiv 2504.02005, §3): "a standard Kalman filter is also implemented with
the assumption that the nominal operator control input is the one that is implemented".
Here: the same surge/heading filters as :mod:`onboard.pipelines.aie` (same model, same
measurements, same reconstruction; its own table ``[pipelines.kf]``) with the input taken
as the commanded one at nominal scaling, ``u = gain * command + offset``
(algorithms.md §2.12), and input-error variance ``v_d`` of ``[pipelines.kf.<axis>]``.
Without commands in the log the input is zero (a random-walk-driven filter).
"""

from __future__ import annotations

from onboard.core.config import Config
from onboard.core.pipeline_config import (
    AieConfig,
    AxisConfig,
    HeadingAxisConfig,
    KfAxisConfig,
    KfConfig,
    SurgeAxisConfig,
    SurgeHeadingConfig,
)
from onboard.estimators.axis_model import AxisModel, Discrete
from onboard.estimators.kalman import BiasIncrementKF
from onboard.pipelines.surge_heading import (
    AxisFactory,
    AxisFilter,
    SurgeHeadingPipeline,
    sensor_noise,
)

COLUMNS = ("north", "east", "heading", "speed", "yaw_rate",
           "std_north", "std_east", "std_speed", "std_heading")


class AxisKf(AxisFilter):
    """One axis forecast with the nominal commanded input (§2.2 with known input)."""

    def __init__(self, model: AxisModel, cfg: AxisConfig, top: AieConfig,
                 noise: KfAxisConfig) -> None:
        super().__init__(model, cfg, top, noise.v_d)
        self.noise = noise
        """The axis's ``[pipelines.kf.<axis>]`` table: input-error variance and bias walk."""
        if noise.bias_q > 0.0:
            self.kf = BiasIncrementKF(R=1.0, q_v=cfg.q_v, correlated=top.correlated_noise,
                                      q_b=0.0, pbb0=0.0)

    def step(self, k: Discrete, y: float, R: float, R_prev: float,
             command: float | None, y_v: float | None = None, R_v: float = 0.0) -> None:
        """:meth:`AxisFilter.step`; the input bias's random walk runs only over steps
        with a measured rate (increments alone observe it too weakly: 0.09 -> 0.33 m/s
        on a 1 Hz GNSS-only log, tests/test_kf.py), so without a Doppler speed the
        filter is the plain baseline."""
        kf = self.kf
        if isinstance(kf, BiasIncrementKF):
            kf.q_b = self.noise.bias_q if y_v is not None else 0.0
        super().step(k, y, R, R_prev, command, y_v, R_v)

    def damping(self, command: float | None) -> float:
        """Without a command the damped model with zero input would pull the rate to 0
        (and bias it by ``dt / c1``): use the constant-rate model (a -> 0) instead."""
        return self.model.a if command is not None else 1e-9

    def forecast_input(self, command: float | None) -> float:
        """Nominal input ``gain * command + offset``; without a command zero (with the
        constant-rate model of :meth:`damping`, the random-walk form of §2.12)."""
        self.u = 0.0 if command is None else self.model.input(command)
        return self.u

    def input_ahead(self, command: float | None) -> float:
        """The nominal input of the newest command (the last step's without one), plus
        the estimated input bias where the filter has one."""
        u = self.u if command is None or self.last_command is None else \
            self.model.input(command)
        kf = self.kf
        return u + kf.b if isinstance(kf, BiasIncrementKF) else u


def _shared_form(cfg: KfConfig) -> AieConfig:
    """``[pipelines.kf]`` as the :class:`AieConfig` the shared pipeline reads: the KF's
    measurement handling and axis models; the AIE's own keys, unused by the KF, at their
    defaults."""
    shared = {name: getattr(cfg, name) for name in SurgeHeadingConfig.__struct_fields__}

    def model(axis: KfAxisConfig) -> dict[str, float]:
        return {"a": axis.a, "gain": axis.gain, "offset": axis.offset, "u_max": axis.u_max,
                "q_v": axis.q_v}

    return AieConfig(**shared, surge=SurgeAxisConfig(**model(cfg.surge)),
                     heading=HeadingAxisConfig(**model(cfg.heading)))


def _axis_factory(cfg: KfConfig) -> AxisFactory:
    """Each axis's :class:`AxisKf` with its noise from ``[pipelines.kf.<axis>]``."""
    def make(model: AxisModel, axis: AxisConfig, top: AieConfig) -> AxisFilter:
        noise = cfg.surge if isinstance(axis, SurgeAxisConfig) else cfg.heading
        return AxisKf(model, axis, top, noise)
    return make


def build(cfg: KfConfig, gnss_std_m: float = 1.5, heading_std_rad: float = 0.03,
          gnss_velocity_std_mps: float = 0.1) -> SurgeHeadingPipeline:
    """A KF baseline pipeline from a :class:`KfConfig` (for code and tests)."""
    return SurgeHeadingPipeline("kf", COLUMNS, _shared_form(cfg), gnss_std_m,
                                heading_std_rad, _axis_factory(cfg), gnss_velocity_std_mps)


def create(cfg: Config) -> SurgeHeadingPipeline | None:
    """Pipeline ``kf`` wherever ``aie`` applies, from ``[pipelines.kf]``;
    ``[pipelines.kf] enabled = false`` is honoured by the pipeline registry."""
    if cfg.vehicle.vehicle_class in ("bluerov2", "spheroid"):
        return None
    return build(cfg.pipelines.kf, *sensor_noise(cfg))
