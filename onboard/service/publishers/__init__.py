"""Publishers: where the service's estimates and health go.

* :mod:`.zenoh_pub` -- Zenoh, to shore (architecture.md §4.4);
* :mod:`.mavlink_pub` -- MAVLink, to the autopilot and ground stations (§4.5).

Both are fed on the estimator loop (``publish_estimates`` every tick, ``publish_health``
at 1 Hz) and must return quickly: neither blocks on the network.
"""
