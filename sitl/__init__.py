"""The software-in-the-loop simulator: plants, environment, sensors, injected effects,
emitters that speak the real protocols, scenarios and reference controllers, with a
hidden truth no estimator reads (docs/sitl.md). It uses the core messages and the
drivers' encoders, never the estimators; only its closed-loop runner runs the onboard
engine (docs/architecture.md §2)."""
