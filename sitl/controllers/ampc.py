"""Adaptive NMPC (AMPC): the NMPC whose prediction model carries the ESESO's disturbance.

Paper §IV-A, eq. (27) and Remark 3: the estimated lumped disturbance ``xi`` enters the
prediction model's force balance. Here it is read from the published ``eseso`` estimate
record (``values["dist_x"|"dist_y"|"dist_z"]``, N, body FRD), exactly as an external
consumer would read it from Zenoh, and added in newtons (no empirical unit factor, unlike
the public code's division by ``compensate_coef``). By default it is held fixed in the
earth frame over the horizon, so its body components turn with the predicted yaw
(``disturbance_frame="earth"``); ``"body"`` holds it fixed in body axes as the paper does.
"""

from __future__ import annotations

import numpy as np

from onboard.core.messages import EstimateRecord
from onboard.sitl.controllers.base import Bluerov2Params
from onboard.sitl.controllers.nmpc import Nmpc, NmpcTuning


class Ampc(Nmpc):
    """The AMPC (``ampc``)."""

    name = "ampc"

    def __init__(self, params: Bluerov2Params | None = None, tuning: NmpcTuning | None = None,
                 disturbance_frame: str = "earth") -> None:
        super().__init__(params, tuning, disturbance_frame)

    def disturbance(self, estimate: EstimateRecord) -> np.ndarray:
        """``[dist_x, dist_y, dist_z]`` (N, body) from the record; zero while absent."""
        v = estimate.values
        try:
            xi = np.array([v["dist_x"], v["dist_y"], v["dist_z"]], dtype=float)
        except KeyError:
            return np.zeros(3)
        return xi if np.all(np.isfinite(xi)) else np.zeros(3)
