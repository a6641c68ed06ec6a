"""onboard: online estimation for small marine vehicles.

Packages: ``onboard.pipelines`` (the estimators), ``drivers`` (bytes <-> typed samples),
``sitl`` (the simulator). See README.md and architecture.md.
"""

__version__ = "0.1.0"
