"""Adaptive input estimation (AIE) of surge and heading: pipeline ``aie``.

Faros & Tanner, "System Identification and Adaptive Input Estimation on the Jaiabot",
arXiv 2504.02005 (2025); AIE = retrospective cost input estimation (RCIE, Ansari &
Bernstein, IEEE TCST 2019; :mod:`onboard.estimators.rcie`) driving a Kalman filter
(Verma, Sanjeevini, Sumer & Bernstein, IJC 2024; :mod:`onboard.estimators.kalman`,
forecast with ``d_hat``, algorithms.md §2.2). Per axis (:class:`AxisAie`): the filter's
innovation ``z`` and the Markov parameters ``H_i = C A_bar^{i-1} B`` of its model (§2.4)
go to RCIE, whose input estimate drives the next forecast (§2.7); ``z`` is normalized by
the measurement standard deviation (§2.10). The pipeline around the two axes (surge and
heading, measurements, trajectory reconstruction) is
:class:`onboard.pipelines.surge_heading.SurgeHeadingPipeline`, shared with ``kf``.

Divergence of the input estimate (the paper's remarks 2-3): a failed factorization,
non-finite numbers, a raw estimate beyond ``divergence_input * u_max`` or a mean NIS above
``divergence_nis`` resets ``theta``, ``P`` and the buffers (§2.7 start-up), counts
``<axis>.diverged`` in :meth:`health` and inflates the rate covariance.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

from onboard.core.config import Config
from onboard.estimators.axis_model import AxisModel, Discrete
from onboard.core.pipeline_config import AieConfig, AxisConfig
from onboard.estimators.rcie import Rcie
from onboard.pipelines.surge_heading import AxisFilter, SurgeHeadingPipeline, sensor_noise

COLUMNS = ("north", "east", "heading", "speed", "yaw_rate", "surge_input", "yaw_input",
           "std_north", "std_east", "std_speed", "std_heading")
"""The estimates of pipeline ``aie`` (units in docs/architecture.md §4.2)."""


# ---------------------------------------------------------------------------------------
# One AIE axis


class AxisAie(AxisFilter):
    """Kalman filter driven by the RCIE input estimate (§2.7), with divergence recovery
    and the optional adaptive input-error variance (ASE, §2.8)."""

    def __init__(self, model: AxisModel, cfg: AxisConfig, top: AieConfig) -> None:
        super().__init__(model, cfg, top, cfg.v_d)
        self.rcie = Rcie(cfg.n_c, cfg.n_f, cfg.r_z, cfg.r_d, cfg.r_theta, cfg.lam,
                         cfg.u_scale, 1.0, cfg.u_max, rate_penalty=cfg.rate_penalty)
        self.d_hat = 0.0
        self._z_scale_set = False
        self._zwin: list[float] = []

    def forecast_input(self, command: float | None) -> float:
        u = self.d_hat
        if self.cfg.known_input and command is not None:
            u += self.model.input(command)
        return u

    def input_ahead(self, command: float | None) -> float:
        if self.cfg.known_input and command is not None:
            return self.d_hat + self.model.input(command)
        return self.u

    def step(self, k: Discrete, y: float, R: float, R_prev: float,
             command: float | None, y_v: float | None = None, R_v: float = 0.0) -> None:
        if not self._z_scale_set:            # normalize z by the measurement std (§2.10)
            self.rcie.z_scale = math.sqrt(R + R_prev)
            self._z_scale_set = True
        super().step(k, y, R, R_prev, command, y_v, R_v)

    def after_innovation(self, k: Discrete, command: float | None) -> None:
        kf, rc, top = self.kf, self.rcie, self.top
        if self.rate_z is not None:
            # a measured rate (GNSS Doppler speed): its innovation is the informative
            # one, Markov parameter C_v B = c1, normalized by its predicted std (§2.10)
            rc.z_scale = math.sqrt(self.rate_S)
            d = rc.step(self.rate_z, [k.c1])
        else:
            H = [k.c2] if self.cfg.n_f == 1 else kf.markov(k, self.cfg.n_f)
            d = rc.step(kf.z, H)
        if (d is None or abs(rc.d_hat_raw) > top.divergence_input * self.cfg.u_max
                or (rc.steps > 30 and self.nis_avg > top.divergence_nis)):
            self._recover(k)
            d = 0.0
        self.d_hat = d
        self.u = d + (self.model.input(command)
                      if self.cfg.known_input and command is not None else 0.0)
        if top.adaptive:
            self._adapt(k)

    def _recover(self, k: Discrete) -> None:
        """Divergence (remarks 2-3 of the paper): restart RCIE, widen the KF."""
        self.diverged += 1
        self.rcie.reset()
        self.nis_avg = 1.0
        self.kf.pvv += (self.cfg.u_max * k.dt) ** 2

    def _adapt(self, k: Discrete) -> None:
        """ASE (§2.8): V_d such that the predicted innovation variance matches the
        sample variance over the last N_w steps. ``C P_f C^T`` is affine in V_d
        (``c1^2 P_vv + V_d c2^2``), so the grid search of §2.8 has this closed form."""
        w = self._zwin
        w.append(self.kf.z)
        nw = self.top.adaptive_window
        if len(w) > nw:
            del w[0]
        if len(w) < max(10, nw // 2):
            return
        m = sum(w) / len(w)
        s_hat = sum((x - m) ** 2 for x in w) / (len(w) - 1)
        # the filter's prediction, averaged the same way: S = pdd_f + R
        c2 = k.c2
        base = self.kf.S - self.V_u * c2 * c2
        v = (s_hat - base) / (c2 * c2)
        lo, hi = 1e-6 * self.cfg.u_scale ** 2, 10.0 * self.cfg.u_max ** 2
        v = lo if v < lo else hi if v > hi else v
        self.V_u += 0.1 * (v - self.V_u)


class AiePipeline(SurgeHeadingPipeline):
    """Pipeline ``aie``: surge and heading AIE with trajectory reconstruction."""

    def _extra_outputs(self, out: dict[str, float]) -> None:
        """The input estimates now: RCIE's d_hat plus, with ``known_input``, the nominal
        input of the newest command (m/s^2, rad/s^2)."""
        if self.surge.kf.initialized:
            out["surge_input"] = self.surge.input_ahead(self._latest_command(1))
        if self.yaw.kf.initialized and "heading" in out:
            out["yaw_input"] = self.yaw.input_ahead(self._latest_command(2))

    def health(self) -> Mapping[str, float]:
        h = dict(super().health())
        for nm, ax in (("surge", self.surge), ("heading", self.yaw)):
            assert isinstance(ax, AxisAie)
            h[f"{nm}.input"] = ax.d_hat
            h[f"{nm}.V_d"] = ax.V_u
            h[f"{nm}.theta_norm"] = math.sqrt(sum(x * x for x in ax.rcie.theta))
        return h

    def get_state(self) -> dict[str, Any]:
        st = super().get_state()
        for nm, ax in (("surge", self.surge), ("heading", self.yaw)):
            assert isinstance(ax, AxisAie)
            st[nm]["rcie"] = ax.rcie.get_state()
            st[nm]["V_d"] = ax.V_u
        return st

    def set_state(self, state: Mapping[str, Any]) -> None:
        super().set_state(state)
        for nm, ax in (("surge", self.surge), ("heading", self.yaw)):
            assert isinstance(ax, AxisAie)
            sub = state.get(nm)
            if isinstance(sub, dict) and isinstance(sub.get("rcie"), dict):
                ax.rcie.set_state(sub["rcie"])
            v = sub.get("V_d") if isinstance(sub, dict) else None
            if isinstance(v, (int, float)) and math.isfinite(v) and v > 0.0:
                ax.V_u = float(v)


def build(cfg: AieConfig, gnss_std_m: float = 1.5, heading_std_rad: float = 0.03,
          gnss_velocity_std_mps: float = 0.1) -> AiePipeline:
    """An AIE pipeline from an :class:`AieConfig` (for code and tests)."""
    return AiePipeline("aie", COLUMNS, cfg, gnss_std_m, heading_std_rad, AxisAie,
                       gnss_velocity_std_mps)


def create(cfg: Config) -> AiePipeline | None:
    """Pipeline ``aie`` for surface vehicles (None for the BlueROV2 and the spheroid)."""
    if cfg.vehicle.vehicle_class in ("bluerov2", "spheroid"):
        return None
    return build(cfg.pipelines.aie, *sensor_noise(cfg))
