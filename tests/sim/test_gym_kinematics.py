"""Rotations (6D encoding), damped-least-squares IK, and the action -> TCP pose loop of the env."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gym_omnid.constants import ARM_JOINT_RANGES, ARM_JOINTS, HOME_JOINTS
from gym_omnid.experts import waypoint_action
from gym_omnid.ik import DampedLeastSquaresIK
from gym_omnid.robot import TCP_SITE
from gym_omnid.rotations import matrix_from_rot6d, rot6d_from_matrix, rotation_error, topdown_rotation


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def test_rot6d_round_trip() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        world_R_tcp = _random_rotation(rng)
        np.testing.assert_allclose(matrix_from_rot6d(rot6d_from_matrix(world_R_tcp)), world_R_tcp, atol=1e-12)


def test_rot6d_gram_schmidt_and_degenerate_inputs() -> None:
    rng = np.random.default_rng(1)
    for rot6d in [
        rng.normal(size=6) * 3,
        np.zeros(6),
        np.array([1.0, 0, 0, 2.0, 0, 0]),
        np.array([0, 0, 0, 0, 1.0, 0]),
    ]:
        world_R = matrix_from_rot6d(rot6d)
        np.testing.assert_allclose(world_R.T @ world_R, np.eye(3), atol=1e-12)
        assert np.linalg.det(world_R) == pytest.approx(1.0)
    scaled = matrix_from_rot6d(np.array([2.0, 0, 0, 0.5, 3.0, 0]))
    np.testing.assert_allclose(scaled, np.eye(3), atol=1e-12)


@pytest.mark.parametrize("yaw", [0.0, 0.7, -2.0])
def test_topdown_rotation(yaw: float) -> None:
    world_R_tcp = topdown_rotation(yaw)
    np.testing.assert_allclose(world_R_tcp[:, 2], [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(world_R_tcp[:, 0], [math.cos(yaw), math.sin(yaw), 0], atol=1e-12)
    assert np.linalg.det(world_R_tcp) == pytest.approx(1.0)


@pytest.mark.parametrize("angle", [1e-8, 0.3, 2.0, math.pi - 1e-6])
def test_rotation_error_is_axis_angle(angle: float) -> None:
    rng = np.random.default_rng(2)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    kx = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    rot = np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx
    current = _random_rotation(rng)
    err = rotation_error(rot @ current, current)
    assert np.linalg.norm(err) == pytest.approx(angle, abs=1e-5)
    if angle > 1e-3:
        np.testing.assert_allclose(abs(err @ axis), angle, atol=1e-5)


def test_ik_recovers_poses_reached_by_forward_kinematics(make_env) -> None:
    env = make_env("select_apple")
    ik = DampedLeastSquaresIK(env.model, TCP_SITE, ARM_JOINTS)
    rng = np.random.default_rng(3)
    home = np.array(HOME_JOINTS)
    lower, upper = np.array(ARM_JOINT_RANGES).T
    for _ in range(10):
        q_goal = np.clip(home + rng.uniform(-0.4, 0.4, size=6), lower, upper)
        xyz, world_R = ik.forward(q_goal)
        q = ik.solve(xyz, world_R, home)
        xyz_got, world_R_got = ik.forward(q)
        assert np.linalg.norm(xyz_got - xyz) < 1e-3
        assert np.linalg.norm(rotation_error(world_R, world_R_got)) < 1e-2
        assert (q >= lower).all() and (q <= upper).all()


@pytest.mark.parametrize(
    ("xyz", "yaw"), [((0.45, 0.2, 0.15), 0.0), ((0.75, -0.3, 0.05), 0.8), ((0.35, -0.1, 0.3), -1.2)]
)
def test_action_drives_tcp_to_target(make_env, xyz, yaw) -> None:
    """Holding an absolute TCP target (approached from 15 cm above) for 1 s brings the TCP onto it."""
    env = make_env("select_apple", cameras=["cam_a"], image_size=32)
    env.reset(seed=0)
    for _ in range(10):
        env.step(waypoint_action(np.add(xyz, (0.0, 0.0, 0.15)), yaw, 0.0))
    action = waypoint_action(np.array(xyz), yaw, 0.0)
    for _ in range(10):
        obs, *_ = env.step(action)
    tcp_xyz, world_R_tcp = env.tcp_pose()
    assert np.linalg.norm(tcp_xyz - xyz) < 5e-3
    assert np.linalg.norm(rotation_error(topdown_rotation(yaw), world_R_tcp)) < 0.03
    np.testing.assert_allclose(obs["agent_pos"][:3], tcp_xyz, atol=1e-6)
    np.testing.assert_allclose(obs["agent_pos"][3:9], action[3:9], atol=0.03)
