"""Exceptions fuzzing found that are reported and still open: counted, not failed."""

from __future__ import annotations

import traceback
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

KNOWN_BUGS: dict[tuple[str, str, str], str] = {}
"""Signature (:func:`bug_signature`) -> "finding: description" of an exception found by
fuzzing, reported in docs/fuzzing.md with a reproducer (an xfail test in
test_regressions.py while open). Guarded targets count it in :data:`KNOWN_HITS` instead
of failing; any other exception fails. Delete an entry once its fix lands. Empty: every
reported exception is fixed."""

KNOWN_HITS: Counter[str] = Counter()
"""How often each known bug was hit in this process."""


def bug_signature(err: BaseException) -> tuple[str, str, str]:
    """(exception type, file, function) of the innermost frame in drivers/ or onboard/."""
    where = ("", "")
    for fr in traceback.extract_tb(err.__traceback__):
        if "/drivers/" in fr.filename or "/onboard/" in fr.filename:
            where = (Path(fr.filename).name, fr.name)
    return (type(err).__name__, *where)


@contextmanager
def known_bugs() -> Iterator[None]:
    """Let an exception of a :data:`KNOWN_BUGS` signature pass (counted); raise others."""
    try:
        yield
    except Exception as err:  # noqa: BLE001
        sig = bug_signature(err)
        if sig not in KNOWN_BUGS:
            raise
        KNOWN_HITS[KNOWN_BUGS[sig].split(":")[0]] += 1


def guarded(fn: Callable[..., None]) -> Callable[..., None]:
    """``fn`` run under :func:`known_bugs`."""

    def run(*args: Any, **kw: Any) -> None:
        with known_bugs():
            fn(*args, **kw)
    run.__name__ = fn.__name__.lstrip("_")
    return run
