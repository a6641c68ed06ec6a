"""What every fuzzed parser must satisfy, whatever its input."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec

from onboard.drivers.base import TIME_JUMP_S, ReadStats, UnreadableLog
from onboard.core.messages import Sample


def _finite_floats(v: Any) -> bool:
    if isinstance(v, float):
        return math.isfinite(v)
    if isinstance(v, (tuple, list)):
        return all(_finite_floats(x) for x in v)
    return True


def check_sample(s: Any) -> None:
    """A produced sample is typed, finitely timed, and carries no NaN/inf."""
    assert isinstance(s, Sample), type(s)
    assert isinstance(s.t, float) and math.isfinite(s.t), s
    for name in s.__struct_fields__:
        v = getattr(s, name)
        assert _finite_floats(v), f"{type(s).__name__}.{name} = {v!r}"


def check_stats(stats: ReadStats) -> None:
    """Counters are sane: no negative totals, every rejection reason a non-empty string
    with a positive count, every sample type counted positive."""
    assert stats.records >= 0 and stats.samples >= 0
    for reason, n in stats.rejected.items():
        assert isinstance(reason, str) and reason and n > 0, (reason, n)
    for kind, n in stats.by_type.items():
        assert n > 0, (kind, n)


def rejected(stats: ReadStats) -> int:
    """The number of records rejected, all reasons together."""
    return sum(stats.rejected.values())


def sample_key(s: Sample) -> bytes:
    """A sample as bytes (msgpack), to compare two parses sample by sample."""
    return msgspec.msgpack.encode(s)


def read_file_reader(make: Callable[[Path], Any], path: Path, *, ordered: bool = True) -> Any:
    """Open and iterate a log reader; UnreadableLog is allowed only when opening. With
    ``ordered`` the samples come in time order, but for steps back of more than
    ``TIME_JUMP_S``, which the readers pass on for the engine's time line to judge (a clock
    reset starts a segment, a lone bad stamp is an outlier: onboard/engine/timeline.py)."""
    try:
        reader = make(path)
    except UnreadableLog:
        return None
    out = list(reader)
    for s in out:
        check_sample(s)
    check_stats(reader.stats)
    if ordered:
        ts = [s.t for s in out]
        back = [(a, b) for a, b in zip(ts, ts[1:]) if b < a]
        assert all(a - b > TIME_JUMP_S for a, b in back), \
            f"readers yield samples in time order (steps back within {TIME_JUMP_S} s: {back[:3]})"
    return reader, out
