"""SO(3) helpers: Exp/Log, skew, Euler angles, right Jacobian (onboard.core.so3)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from onboard.core.so3 import (
    euler_to_matrix,
    exp_so3,
    log_so3,
    matrix_to_euler,
    orthonormalize,
    right_jacobian,
    skew,
)

RNG = np.random.default_rng(7)


def test_skew_is_the_cross_product() -> None:
    a, b = RNG.normal(size=3), RNG.normal(size=3)
    assert np.allclose(skew(a) @ b, np.cross(a, b))
    assert np.allclose(skew(a), -skew(a).T)


@pytest.mark.parametrize("angle", [0.0, 1e-8, 1e-3, 0.5, 2.0, math.pi - 1e-6, math.pi])
def test_log_inverts_exp(angle: float) -> None:
    axis = RNG.normal(size=3)
    axis /= np.linalg.norm(axis)
    theta = angle * axis
    R = exp_so3(theta)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert abs(np.linalg.det(R) - 1.0) < 1e-12
    back = log_so3(R)
    if angle < math.pi - 1e-3:
        assert np.allclose(back, theta, atol=1e-9)
    else:  # at pi the axis sign is ambiguous; the rotation is not
        assert np.allclose(exp_so3(back), R, atol=1e-6)


def test_exp_matches_rodrigues_rotation_about_z() -> None:
    R = exp_so3(np.array([0.0, 0.0, 0.3]))
    assert np.allclose(R, euler_to_matrix(0.0, 0.0, 0.3))


def test_euler_round_trip_and_fossen_convention() -> None:
    for _ in range(20):
        roll, pitch, yaw = RNG.uniform(-1.2, 1.2), RNG.uniform(-1.2, 1.2), RNG.uniform(-3, 3)
        assert np.allclose(matrix_to_euler(euler_to_matrix(roll, pitch, yaw)),
                           (roll, pitch, yaw), atol=1e-12)
    # body x points north-east at yaw 45 deg (NED)
    assert np.allclose(euler_to_matrix(0, 0, math.pi / 4) @ [1, 0, 0],
                       [math.sqrt(0.5), math.sqrt(0.5), 0])


def test_right_jacobian_first_order() -> None:
    theta = np.array([0.3, -0.2, 0.9])
    d = 1e-6 * RNG.normal(size=3)
    lhs = exp_so3(theta + d)
    rhs = exp_so3(theta) @ exp_so3(right_jacobian(theta) @ d)
    assert np.allclose(lhs, rhs, atol=1e-11)


def test_orthonormalize_returns_a_rotation() -> None:
    R = euler_to_matrix(0.1, 0.2, 0.3) + 1e-4 * RNG.normal(size=(3, 3))
    Q = orthonormalize(R)
    assert np.allclose(Q @ Q.T, np.eye(3), atol=1e-12)
    assert abs(np.linalg.det(Q) - 1.0) < 1e-12
