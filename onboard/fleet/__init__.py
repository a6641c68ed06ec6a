"""``onboard fleet``: one current field from every vehicle's estimates, served back.

* :mod:`onboard.fleet.field`: the estimator, pure (:class:`~onboard.fleet.field.CurrentField`:
  Gaussian-process regression in space and time, docs/algorithms.md);
* :mod:`onboard.fleet.messages`: what it answers and publishes (``FleetCurrent``,
  ``FleetGrid``; architecture.md §4.4) and set and drift of a current;
* :mod:`onboard.fleet.service`: the Zenoh service (subscriber, queryable, grid, MCAP).

Runs on shore, never on the vehicle (docs/fleet.md).
"""
