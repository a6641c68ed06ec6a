"""Every configuration field is documented and exercised: a meta-test in the manner of
python-control's ``kwargs`` test.

The configuration is the tree of msgspec Structs under :class:`onboard.core.config.Config`
(``[pipelines.<name>]`` included, :mod:`onboard.core.pipeline_config`). For every Struct
reachable from it and every field:

* (a) documented: an attribute docstring right after the field in the source of the
  class or of a base class, or the field named in double backquotes in the docstring of
  the class or a base class;
* (b) exercised: its TOML name appears as a key in some test (``"name"``, ``name =``,
  ``name=`` or ``.name`` in ``tests/**/*.py``) or bundled test configuration
  (``tests/**/*.toml``). Like python-control's, the check is textual: it finds fields no
  test mentions at all, the ones most likely to be silently ignored;
* (c) named by the rule (onboard/core/pipeline_config.py): every numeric key of a pipeline
  table ends in its unit, or :data:`NO_UNIT_SUFFIX` says why not.

Each checker has a negative control.
"""

from __future__ import annotations

import ast
import inspect
import re
import textwrap
import typing
from functools import cache
from pathlib import Path

import msgspec
import pytest

from onboard.core.config import Config

TESTS = Path(__file__).resolve().parent

NOT_EXERCISED: dict[str, str] = {}
"""``Struct.field`` -> why no test sets or reads it (keep this short)."""


def reachable_structs(root: type = Config) -> list[type]:
    """Every msgspec Struct type reachable from ``root`` through its fields' types
    (through ``X | None``, ``list[X]``, ``dict[str, X]`` and ``Annotated``), root first."""
    seen: list[type] = []

    def visit(tp: object) -> None:
        if isinstance(tp, type) and issubclass(tp, msgspec.Struct):
            if tp in seen:
                return
            seen.append(tp)
            for hint in typing.get_type_hints(tp).values():
                visit(hint)
            return
        for arg in typing.get_args(tp):
            visit(arg)

    visit(root)
    return seen


def _struct_bases(cls: type) -> list[type]:
    return [k for k in cls.__mro__ if isinstance(k, type) and issubclass(k, msgspec.Struct)
            and k is not msgspec.Struct]


def _attribute_docstrings(cls: type) -> set[str]:
    """Fields of ``cls`` and its bases with an attribute docstring in the source."""
    out: set[str] = set()
    for klass in _struct_bases(cls):
        try:
            src = textwrap.dedent(inspect.getsource(klass))
        except (OSError, TypeError):
            continue
        body = ast.parse(src).body[0].body  # type: ignore[attr-defined]
        for node, nxt in zip(body, body[1:]):
            if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)
                    and isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant)
                    and isinstance(nxt.value.value, str)):
                out.add(node.target.id)
    return out


def undocumented_fields(cls: type) -> list[str]:
    """The fields of Struct ``cls`` that have no attribute docstring and are not named in
    the class docstring (of it or a base)."""
    documented = _attribute_docstrings(cls)
    class_docs = " ".join(k.__doc__ or "" for k in _struct_bases(cls))
    return [f.name for f in msgspec.structs.fields(cls)
            if f.name not in documented and f"``{f.name}``" not in class_docs
            and f"``{f.encode_name}``" not in class_docs]


@cache
def corpus_of_tests() -> str:
    """The text of every test module and test TOML file."""
    files = [*TESTS.rglob("*.py"), *TESTS.rglob("*.toml")]
    return "\n".join(p.read_text(encoding="utf-8", errors="replace") for p in sorted(files))


def unexercised_fields(cls: type, corpus: str) -> list[str]:
    """The TOML names of the fields of ``cls`` that no test in ``corpus`` uses as a key."""
    out = []
    for f in msgspec.structs.fields(cls):
        n = re.escape(f.encode_name)
        if not re.search(rf"[\"']{n}[\"']|\b{n}\s*=|\.{n}\b", corpus):
            out.append(f.encode_name)
    return out


STRUCTS = reachable_structs()


def test_the_walk_reaches_the_pipeline_and_nested_tables():
    names = {s.__name__ for s in STRUCTS}
    assert {"Config", "Pipelines", "AieConfig", "SurgeAxisConfig", "KfConfig",
            "KfHeadingConfig", "CurrentConfig", "EsesoConfig", "NavConfig",
            "DiagnoseConfig", "ChannelMap", "SourceConfig", "ZenohOut"} <= names


@pytest.mark.parametrize("cls", STRUCTS, ids=lambda c: c.__name__)
def test_every_config_field_is_documented(cls):
    assert undocumented_fields(cls) == []


@pytest.mark.parametrize("cls", STRUCTS, ids=lambda c: c.__name__)
def test_every_config_field_is_exercised_by_a_test(cls):
    missing = [n for n in unexercised_fields(cls, corpus_of_tests())
               if f"{cls.__name__}.{n}" not in NOT_EXERCISED]
    assert missing == []


UNIT_SUFFIX = re.compile(r"_(s|m|mps|mps2|rad|rps|deg|n|kg|hz|us|mb|kgm3|pa|cc)(_rts)?$")
"""The unit suffixes of the naming rule (onboard/core/pipeline_config.py, README
"Configuration"); ``_rts``: a random walk's, per root second."""

NO_UNIT_SUFFIX: dict[str, str] = {
    **dict.fromkeys((
        "heading_anchor", "position_anchor", "gate_nis", "adaptive_window",
        "divergence_input", "divergence_nis", "n_c", "n_f", "r_z", "r_d", "r_theta", "lam",
        "model_rel_std", "net_weight_std", "forgetting", "heading_diversity",
        "turn_accel_gain", "yaw_forgetting", "calibrate_block", "restore_check_p",
        "gate_sigma", "max_consecutive_rejects", "thrust_huber", "allocation", "exponent",
        "deadband", "damping_rel_std", "thrust_rel_std", "lift_rel_std", "adapt_updates",
        "scale_max",
        "thrust_scale_max"), "dimensionless"),
    **dict.fromkeys((
        "a", "gain", "offset", "u_max", "u_scale", "v_d", "q_v", "bias_q", "gamma",
        "gamma_0", "rho", "gamma_max", "poles", "lift_kl", "lift_kl0", "drag_kd0", "drag_kd",
        "theta_std", "theta_std_floor", "model", "yaw_rls_p0"), "symbol, unit in its docstring"),
    **dict.fromkeys(("damping_linear", "damping_quadratic"), "compound unit (N s/m, N s^2/m^2)"),
    "rpm_scale": "its unit, rpm, is its first word",
}
"""The numeric keys of the pipeline tables without a unit suffix, and why (the rule's
exceptions, onboard/core/pipeline_config.py)."""


def keys_without_unit(structs: list[type]) -> list[str]:
    """``Struct.key`` of every numeric field (a number, or a list or table of numbers) of
    ``structs`` whose key ends in no unit suffix and is not in :data:`NO_UNIT_SUFFIX`."""
    out = []
    for cls in structs:
        hints = typing.get_type_hints(cls)
        for f in msgspec.structs.fields(cls):
            numeric = re.search(r"\b(float|int)\b", str(hints[f.name]))
            if (numeric and not UNIT_SUFFIX.search(f.encode_name)
                    and f.encode_name not in NO_UNIT_SUFFIX):
                out.append(f"{cls.__name__}.{f.encode_name}")
    return out


def test_every_numeric_pipeline_key_ends_in_its_unit_or_says_why_not():
    from onboard.core.pipeline_config import Pipelines

    structs = reachable_structs(Pipelines)
    assert keys_without_unit(structs) == []
    keys = {f.encode_name for cls in structs for f in msgspec.structs.fields(cls)}
    assert set(NO_UNIT_SUFFIX) <= keys  # no stale exception


def test_negative_control_a_key_without_its_unit_is_caught():
    class _Walk(msgspec.Struct, kw_only=True):
        current_walk: float = 0.01
        current_walk_mps_rts: float = 0.01
        gate_nis: float = 30.0

    assert keys_without_unit([_Walk]) == ["_Walk.current_walk"]


def test_allow_list_names_real_fields():
    fields = {f"{s.__name__}.{f.encode_name}" for s in STRUCTS
              for f in msgspec.structs.fields(s)}
    assert set(NOT_EXERCISED) <= fields


# ------------------------------------------------------------------- negative controls


class _Fake(msgspec.Struct, kw_only=True):
    """A table with one field documented here: ``in_class_doc``."""

    with_docstring: float = 0.0
    """Documented after the field."""
    in_class_doc: float = 0.0
    bare: float = 0.0


class _FakeChild(_Fake, kw_only=True):
    """Overrides defaults only."""

    with_docstring: float = 1.0


def test_negative_control_an_undocumented_field_is_caught():
    assert undocumented_fields(_Fake) == ["bare"]
    assert undocumented_fields(_FakeChild) == ["bare"]
    assert reachable_structs(_FakeChild) == [_FakeChild]


def test_negative_control_an_unexercised_field_is_caught():
    corpus = 'cfg = {"with_docstring": 1.0}\nx.in_class_doc\n'
    assert unexercised_fields(_Fake, corpus) == ["bare"]
    assert unexercised_fields(_Fake, corpus + "bare = 2\n") == []


RATE_OR_PERIOD = re.compile(r"(_hz|(^|_)(interval|period)_s)$")
"""Field names of a frequency or a period: none is meaningful below zero (a rate of 0
never fires, a negative rate or period fires on every loop, a filter's cut-off of 0
passes nothing)."""


def unbounded_rates(cls: type) -> list[str]:
    """The frequency and period fields of Struct ``cls`` (:data:`RATE_OR_PERIOD`) whose
    type carries no lower bound (``msgspec.Meta(gt=...)`` or ``ge=...``) at or above 0."""
    out = []
    hints = typing.get_type_hints(cls, include_extras=True)
    for f in msgspec.structs.fields(cls):
        if not RATE_OR_PERIOD.search(f.name):
            continue
        metas = []

        def collect(tp: object) -> None:
            if typing.get_origin(tp) is typing.Annotated:
                metas.extend(m for m in tp.__metadata__ if isinstance(m, msgspec.Meta))
            for arg in typing.get_args(tp):
                collect(arg)
        collect(hints[f.name])
        if not any((m.gt is not None and m.gt >= 0) or (m.ge is not None and m.ge >= 0)
                   for m in metas):
            out.append(f.name)
    return out


@pytest.mark.parametrize("cls", STRUCTS, ids=lambda c: c.__name__)
def test_every_rate_and_period_is_bounded_below(cls):
    assert unbounded_rates(cls) == []


def test_negative_control_an_unbounded_rate_is_caught():
    class Loose(msgspec.Struct):
        rate_hz: float = 1.0
        """A rate."""
        flush_interval_s: typing.Annotated[float, msgspec.Meta(ge=0.0)] = 0.5
        """A bounded period."""
        send_rate_hz: typing.Annotated[float, msgspec.Meta(gt=-1.0)] = 1.0
        """A rate bounded below zero."""
    assert unbounded_rates(Loose) == ["rate_hz", "send_rate_hz"]
