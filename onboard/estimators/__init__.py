"""The estimation mathematics: axis models and their Kalman filter, RLS, the high-gain
and flow observers, the current filter, the vehicle regression models and the ESESO
filter. Pure numbers in and out: no I/O, no clock, no configuration parsing; only
:mod:`onboard.core` below them (docs/algorithms.md has the equations)."""
