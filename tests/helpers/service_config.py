"""The service configuration the service-level tests share."""

from __future__ import annotations

from typing import Any

from onboard.core.config import Config, from_dict


def service_config(**service: Any) -> Config:
    """A rudder boat (vehicle id ``testboat``, MAVLink system 3, 10 Hz engine) steered by
    servo channel 1 (+-500 us = +-0.5236 rad) with throttle on servo channel 3, and
    ``service`` as its ``[service]`` table (sources, recorder, zenoh, mavlink, ...)."""
    data = {"vehicle": {"id": "testboat", "class": "rudder-boat", "system_id": 3},
            "engine": {"rate_hz": 10.0},
            "inputs": {"rudder": {"source": "servo", "channel": 1, "half_range_us": 500,
                                  "full_scale": 0.5236},
                       "throttle": {"source": "servo", "channel": 3, "half_range_us": 500}},
            "service": service}
    return from_dict(data)
