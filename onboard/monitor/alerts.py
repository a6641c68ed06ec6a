"""What a user reads first: warnings about the log, the inputs and the estimates.

A warning (:class:`~onboard.core.messages.Alert`) has a code a program can test
(``pipeline_restarted``, ``no_position_source``, ``time_jump`` ...), the pipeline it is
about (empty for the log or the engine), one line for a person (what happened, where, and
the config key or command that changes it), the details after it, and the span of time it
covers. :class:`Alerts` collects them during a run: the same code of the same pipeline
again within :data:`MERGE_GAP_S` of the last extends that warning's span instead of
adding another, so a condition that lasts is one line with its start and end.
"""

from __future__ import annotations

import msgspec

from onboard.core.messages import Alert

MERGE_GAP_S = 10.0
"""A warning repeated within this long (s) after the last one of its kind extends it."""
MAX_ALERTS = 200
"""Warnings kept; beyond, they are counted in :attr:`Alerts.dropped`."""


class Alerts:
    """The warnings of one run, in the order they were first raised.

    Attributes:
        dropped: warnings not kept beyond :data:`MAX_ALERTS`.
    """

    def __init__(self, events: list[str] | None = None) -> None:
        """``events``: a list each new warning (not the extension of one) is also told
        to, as one line (the engine's health events: STATUSTEXT, the Zenoh health, the
        shore view)."""
        self._items: list[Alert] = []
        self._open: dict[tuple[str, str], int] = {}
        self._events = events
        self.dropped = 0

    def warn(self, code: str, message: str, t: float | None = None, *, pipeline: str = "",
             t_end: float | None = None, details: str = "") -> None:
        """Raise warning ``code`` (about ``pipeline``) at time ``t`` (s; None when it is
        about the whole run), lasting to ``t_end`` (default ``t``); ``message`` the one
        actionable line, ``details`` what follows it. The newest text of a warning that
        extends an earlier one replaces its text."""
        t_end = t if t_end is None else t_end
        key = (code, pipeline)
        i = self._open.get(key)
        if i is not None:
            last = self._items[i]
            if t is None or last.t_end is None or t - last.t_end <= MERGE_GAP_S:
                self._items[i] = Alert(code=code, pipeline=pipeline, message=message,
                                       details=details, t_start=last.t_start,
                                       t_end=_later(last.t_end, t_end), n=last.n + 1)
                return
        if len(self._items) >= MAX_ALERTS:
            self.dropped += 1
            return
        self._open[key] = len(self._items)
        self._items.append(Alert(code=code, pipeline=pipeline, message=message,
                                 details=details, t_start=t, t_end=t_end))
        if self._events is not None:
            self._events.append(f"{code}: {message}")

    def revise(self, code: str, message: str, *, pipeline: str = "",
               details: str = "") -> bool:
        """Replace the text of the newest warning ``code`` about ``pipeline`` (its span
        and count unchanged), when what was learnt later changes what is true of it;
        False when there is none."""
        i = self._open.get((code, pipeline))
        if i is None:
            return False
        self._items[i] = msgspec.structs.replace(self._items[i], message=message,
                                                 details=details)
        return True

    def __iter__(self):
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def codes(self) -> set[str]:
        """The codes raised so far."""
        return {a.code for a in self._items}


def _later(a: float | None, b: float | None) -> float | None:
    """The later of two times, either of which may be unknown."""
    if a is None or b is None:
        return b if a is None else a
    return max(a, b)
