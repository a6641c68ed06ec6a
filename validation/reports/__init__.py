"""Validation reports: ``python -m validation.reports.<name>`` reruns the measurements
behind the tables and figures of docs/aie.md and docs/current.md."""
