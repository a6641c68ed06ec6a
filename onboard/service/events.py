"""The severity of a service event, one classification for the log and STATUSTEXT.

A service event (an input that cannot be opened or was lost, a corrupt state file, the
estimator loop stalled, a source switched, a connection made) is a line of text that goes
to the log (:meth:`onboard.service.daemon.Service.event`), to the health record's
``events`` and, from there, to STATUSTEXT
(:meth:`onboard.service.publishers.mavlink_pub.MavlinkPublisher.event`). Both take its
severity from :func:`severity`: WARNING for what went wrong (its text names a loss, a
silence, a failure, an error, something that cannot be done or is ignored), INFO for the
rest. The log level is that severity's (:func:`log_level`), so ``ONBOARD_LOG_LEVEL=WARNING``
and ``journalctl -p warning`` keep exactly the events a ground station shows as warnings.
"""

from __future__ import annotations

import logging

__all__ = ["MAV_SEVERITY_INFO", "MAV_SEVERITY_WARNING", "WARNING_MARKS", "log_level",
           "severity"]

MAV_SEVERITY_EMERGENCY = 0
MAV_SEVERITY_ALERT = 1
MAV_SEVERITY_CRITICAL = 2
MAV_SEVERITY_ERROR = 3
MAV_SEVERITY_WARNING = 4
MAV_SEVERITY_NOTICE = 5
MAV_SEVERITY_INFO = 6
MAV_SEVERITY_DEBUG = 7
"""MAVLink's ``MAV_SEVERITY`` (common.xml; RFC 5424's levels), without importing a
dialect."""

WARNING_MARKS = ("lost", "silent", "stale", "stalled", "corrupt", "error", "fail", "drop",
                 "disk full", "low disk", "too slow", "cannot", "unreadable", "ignored",
                 "not restored", "disabled", "not sent")
"""Words (lower case) that make an event a warning where its text has one."""

_LOG_LEVELS = {
    MAV_SEVERITY_EMERGENCY: logging.CRITICAL,
    MAV_SEVERITY_ALERT: logging.CRITICAL,
    MAV_SEVERITY_CRITICAL: logging.CRITICAL,
    MAV_SEVERITY_ERROR: logging.ERROR,
    MAV_SEVERITY_WARNING: logging.WARNING,
    MAV_SEVERITY_NOTICE: logging.INFO,
    MAV_SEVERITY_INFO: logging.INFO,
    MAV_SEVERITY_DEBUG: logging.DEBUG,
}


def severity(text: str) -> int:
    """The ``MAV_SEVERITY`` of the event ``text``: WARNING when it has one of
    :data:`WARNING_MARKS`, else INFO."""
    low = text.lower()
    return MAV_SEVERITY_WARNING if any(w in low for w in WARNING_MARKS) else MAV_SEVERITY_INFO


def log_level(mav_severity: int) -> int:
    """The :mod:`logging` level of a ``MAV_SEVERITY`` (NOTICE is INFO; the three above
    ERROR are CRITICAL)."""
    return _LOG_LEVELS.get(mav_severity, logging.WARNING)
