"""The one Kalman update (onboard.estimators.kalman.update) and the shape of the estimators
around it: every filter updates through it, the ESESO's error state is indexed only by its
block names, an input model returns its decision, the estimators import each other without
a cycle, and no function of the estimators or the pipelines reaches 60 lines.

The update is checked against the textbook's standard form written here with
``np.linalg.solve`` (Bar-Shalom, Li & Kirubarajan 2001, section 5.2) and, for a gain that is not
the optimal one, against the sample covariance of simulated errors.
"""

from __future__ import annotations

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from onboard.estimators.axis_model import AxisModel, discretize
from onboard.estimators.increment_filter import IncrementFilter
from onboard.estimators.input_models import AxisInnovation, CommandedInput, InputStep
from onboard.estimators.kalman import IncrementKF, inv_small, update
from tests.helpers.imports import REPO

ESTIMATORS = REPO / "onboard" / "estimators"
PIPELINES = REPO / "onboard" / "pipelines"
MAX_FUNCTION_LINES = 60
"""The house limit of a function in the estimators and the pipelines (lines, ``def`` to
its last line)."""


def _spd(rng: np.random.Generator, n: int) -> np.ndarray:
    A = rng.normal(size=(n, n))
    return A @ A.T + 0.1 * np.eye(n)


# --------------------------------------------------------------------------- the update


def test_inv_small_is_the_inverse_and_says_singular():
    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 4):
        S = _spd(rng, n)
        assert np.allclose(inv_small(S), np.linalg.inv(S), rtol=1e-12, atol=1e-12)
        assert inv_small(np.zeros((n, n))) is None


@pytest.mark.parametrize("n, m", [(1, 1), (3, 1), (4, 2), (9, 3), (23, 3), (6, 5)])
def test_the_update_is_the_textbook_kalman_update(n: int, m: int):
    rng = np.random.default_rng(n * 10 + m)
    x, P, H, R = rng.normal(size=n), _spd(rng, n), rng.normal(size=(m, n)), _spd(rng, m)
    z = rng.normal(size=m)
    up = update(x, P, z, R, H)
    S = H @ P @ H.T + R
    K = np.linalg.solve(S, H @ P).T
    y = z - H @ x
    scale = float(np.max(np.abs(P)))
    assert np.allclose(up.y, y, rtol=0, atol=1e-12)
    assert np.allclose(up.S, S, rtol=1e-12, atol=1e-12 * scale)
    assert up.K is not None and np.allclose(up.K, K, rtol=1e-9, atol=1e-12)
    assert np.allclose(up.x, x + K @ y, rtol=1e-9, atol=1e-12)
    # the Joseph form equals (I - K H) P for the optimal gain
    assert np.allclose(up.P, (np.eye(n) - K @ H) @ P, rtol=1e-9, atol=1e-9 * scale)
    assert np.allclose(up.P, up.P.T, rtol=0, atol=1e-13 * scale)
    assert up.nis == pytest.approx(float(y @ np.linalg.solve(S, y)), rel=1e-9)


def test_the_update_leaves_its_arguments_as_they_were():
    rng = np.random.default_rng(5)
    x, P, H, R, z = rng.normal(size=4), _spd(rng, 4), rng.normal(size=(2, 4)), _spd(rng, 2), \
        rng.normal(size=2)
    before = [a.copy() for a in (x, P, H, R, z)]
    update(x, P, z, R, H, keep=slice(0, 2))
    assert all(np.array_equal(a, b) for a, b in zip((x, P, H, R, z), before))


def test_a_schmidt_update_corrects_only_the_kept_states_and_its_covariance_is_the_errors():
    """The gain's rows outside ``keep`` are zero, so those states are not corrected, and the
    Joseph form is the covariance of the error this suboptimal gain leaves: the sample
    covariance of 200000 simulated errors agrees within 2 % of the standard deviations'
    product (measured 0.5 %), where the standard form ``(I - K H) P`` is off by 150 %
    (negative control)."""
    rng = np.random.default_rng(11)
    n, m, keep = 4, 2, slice(0, 2)
    x, P, H, R = rng.normal(size=n), _spd(rng, n), rng.normal(size=(m, n)), _spd(rng, m)
    up = update(x, P, rng.normal(size=m), R, H, keep=keep)
    assert up.K is not None and np.all(up.K[2:] == 0.0)
    assert np.array_equal(up.x[2:], x[2:])
    e = rng.multivariate_normal(np.zeros(n), P, size=200_000)   # prior errors
    v = rng.multivariate_normal(np.zeros(m), R, size=200_000)   # measurement noise
    e_post = e - (e @ H.T + v) @ up.K.T                         # x+ - x_true
    sample = np.cov(e_post.T)
    ref = np.sqrt(np.outer(np.diag(up.P), np.diag(up.P)))
    assert float(np.max(np.abs(sample - up.P) / ref)) < 0.02
    standard = (np.eye(n) - up.K @ H) @ P
    assert float(np.max(np.abs(sample - standard) / ref)) > 0.5


def test_a_singular_innovation_covariance_updates_nothing():
    x, P = np.array([1.0, 2.0]), np.zeros((2, 2))
    up = update(x, P, np.array([3.0, 4.0]), np.zeros((2, 2)), np.eye(2))
    assert up.K is None and math.isnan(up.nis)
    assert up.x is x and up.P is P
    assert np.array_equal(up.y, [2.0, 2.0])
    with pytest.raises(np.linalg.LinAlgError):
        update(x, P, np.array([3.0, 4.0]), np.zeros((2, 2)), np.eye(2), inverse=np.linalg.inv)


def test_a_symmetric_update_makes_s_symmetric_in_every_digit():
    rng = np.random.default_rng(2)
    x, P, H, R = rng.normal(size=7), _spd(rng, 7), rng.normal(size=(3, 7)), _spd(rng, 3)
    plain = update(x, P, np.zeros(3), R, H)
    sym = update(x, P, np.zeros(3), R, H, symmetric=True)
    assert np.array_equal(sym.S, sym.S.T)
    assert np.allclose(plain.S, sym.S, rtol=1e-14, atol=0)


# --------------------------------------------------------------------------- one update


def _calls(path: Path) -> set[str]:
    """The dotted names called in ``path`` (``kalman.update``, ``update``, ...)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Call):
            f = node.func
            if isinstance(f, ast.Name):
                out.add(f.id)
            elif isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name):
                out.add(f"{f.value.id}.{f.attr}")
    return out


def _joseph_by_hand(source: str) -> list[int]:
    """Lines of ``source`` that form ``K @ H`` or ``... @ K.T`` (a Kalman covariance
    update written out)."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.MatMult):
            left, right = ast.unparse(node.left), ast.unparse(node.right)
            if (left == "K" and right == "H") or right == "K.T":
                lines.append(node.lineno)
    return lines


def test_the_filters_update_through_the_one_kalman_update():
    assert "kalman.update" in _calls(ESTIMATORS / "current_kf.py")
    assert "kalman.update" in _calls(ESTIMATORS / "eseso_filter.py")
    kalman = ast.parse((ESTIMATORS / "kalman.py").read_text())
    ref = next(n for n in kalman.body
               if isinstance(n, ast.ClassDef) and n.name == "ReferenceIncrementKF")
    assert any(isinstance(c, ast.Call) and getattr(c.func, "id", "") == "update"
               for c in ast.walk(ref))
    found = {p.name: _joseph_by_hand(p.read_text()) for p in ESTIMATORS.glob("*.py")
             if p.name != "kalman.py"}
    assert not any(found.values()), found


def test_the_joseph_check_sees_an_update_written_out():
    assert _joseph_by_hand("IKH = I - K @ H\nP = IKH @ P @ IKH.T + K @ R @ K.T\n") == [1, 2]


# --------------------------------------------------------------------------- ESESO blocks

STATE_ARRAYS = {"P": "all", "F": "all", "G": "all", "q": "all", "dx": "all", "H": "columns",
                "K": "rows"}
"""The ESESO's arrays over its error state and which of their indices run over it."""


def _raw_state_indices(source: str) -> list[str]:
    """Subscripts of the error-state arrays with a number or a numeric slice where the
    error state is indexed (``H[:, 3:5]``, ``P[8, 8]``)."""

    def numeric(e: ast.expr) -> bool:
        if isinstance(e, ast.Constant):
            return isinstance(e.value, int)
        if isinstance(e, ast.Slice):
            return any(isinstance(b, ast.Constant) for b in (e.lower, e.upper))
        return False

    bad = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Subscript):
            continue
        v = node.value
        name = v.id if isinstance(v, ast.Name) else v.attr if isinstance(v, ast.Attribute) \
            else ""
        axes = STATE_ARRAYS.get(name)
        if axes is None:
            continue
        idx = list(node.slice.elts) if isinstance(node.slice, ast.Tuple) else [node.slice]
        state_idx = idx[1:] if axes == "columns" else idx[:1] if axes == "rows" else idx
        if any(numeric(e) for e in state_idx):
            bad.append(ast.unparse(node))
    return bad


def test_the_eseso_indexes_its_error_state_only_by_block_name():
    for path in (ESTIMATORS / "eseso_filter.py", PIPELINES / "eseso.py"):
        assert _raw_state_indices(path.read_text()) == [], path.name


def test_the_block_check_sees_raw_numbers():
    src = "H[:, 3:5] = I2\nH[0, P_D] = 1.0\nf.P[8, 8] = v\nP[TH, TH] = 0\nK[2:] = 0\n"
    assert _raw_state_indices(src) == ["H[:, 3:5]", "f.P[8, 8]", "K[2:]"]


# --------------------------------------------------------------------------- input models


class _DivergingInput(CommandedInput):
    """The commanded input whose every accepted innovation reports a divergence and a new
    input-error variance."""

    def __init__(self) -> None:
        super().__init__(bias_q=0.0)
        self.seen: list[AxisInnovation] = []

    def after_innovation(self, inn: AxisInnovation, k, u_known) -> InputStep:
        self.seen.append(inn)
        return InputStep(V_u=0.25, diverged=True)


def test_the_filter_acts_on_the_input_models_decision():
    model = AxisModel(a=0.5, gain=1.0, offset=0.0)
    f = IncrementFilter(model, _DivergingInput(), input_error_var=0.01, u_max=2.0, q_v=0.0,
                        correlated=True, gate_nis=1e9, adaptive_rate_noise=False)
    k = discretize(model.a, 0.1)
    f.step(k, 0.1, 1e-4, 1e-4, 0.5)
    f.step(k, 0.1, 1e-4, 1e-4, 0.5)
    pvv_forecast = f.kf.P[3]
    inn = f.input.seen[-1]
    assert isinstance(inn.kf, IncrementKF) and inn.V_u == 0.01 and inn.rate_z is None
    assert f.V_u == 0.25 and f.diverged == 1 and f.nis_avg == 1.0
    # widened by (u_max dt)^2 before the update: the update then shrinks it again
    assert pvv_forecast > 0.0 and f.steps == 1


def test_the_input_models_do_not_see_the_filter():
    text = (ESTIMATORS / "input_models.py").read_text()
    assert "IncrementFilter" not in text.replace(
        ":class:`~onboard.estimators.increment_filter.IncrementFilter`", "")


# --------------------------------------------------------------------------- imports, length


def _estimator_imports() -> dict[str, set[str]]:
    """Each estimator module's imports of the other estimator modules, type hints under
    ``TYPE_CHECKING`` included."""
    graph: dict[str, set[str]] = {}
    names = {p.stem for p in ESTIMATORS.glob("*.py")}
    for p in ESTIMATORS.glob("*.py"):
        deps = set()
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                mod = node.module.removeprefix("onboard.estimators")
                if node.module == "onboard.estimators":
                    deps |= {a.name for a in node.names if a.name in names}
                elif node.module.startswith("onboard.estimators."):
                    deps.add(mod.lstrip("."))
        graph[p.stem] = deps - {p.stem}
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph``, or None."""
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(v: str) -> list[str] | None:
        state[v] = 1
        path.append(v)
        for w in sorted(graph.get(v, ())):
            if state.get(w) == 1:
                return path[path.index(w):] + [w]
            if w not in state and (found := visit(w)):
                return found
        state[v] = 2
        path.pop()
        return None

    for v in sorted(graph):
        if v not in state and (found := visit(v)):
            return found
    return None


def test_the_estimators_import_each_other_without_a_cycle():
    assert _cycle(_estimator_imports()) is None


def test_the_cycle_check_sees_a_cycle_of_type_hints():
    graph = {**_estimator_imports(), "input_models": {"increment_filter"}}
    assert _cycle(graph) == ["increment_filter", "input_models", "increment_filter"]


def _long_functions(paths: list[Path]) -> list[tuple[str, str, int]]:
    """(file, function, lines) of every function of ``MAX_FUNCTION_LINES`` lines or more."""
    out = []
    for p in paths:
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n >= MAX_FUNCTION_LINES:
                    out.append((p.name, node.name, n))
    return out


def test_no_function_of_the_estimators_or_pipelines_reaches_sixty_lines():
    paths = sorted(ESTIMATORS.glob("*.py")) + sorted(PIPELINES.glob("*.py"))
    assert _long_functions(paths) == []


def test_the_length_check_sees_a_long_function(tmp_path: Path):
    long = tmp_path / "long.py"
    long.write_text("def f():\n" + "    x = 1\n" * 59)
    assert _long_functions([long]) == [("long.py", "f", 60)]
