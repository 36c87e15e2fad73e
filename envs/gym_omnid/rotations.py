"""Small pure rotation helpers: the 6D encoding used by actions and states, top-down grasp frames."""

from __future__ import annotations

import math

import numpy as np

_NORM_EPS = 1e-6


def rot6d_from_matrix(world_R_tcp: np.ndarray) -> np.ndarray:
    """(3, 3) rotation -> (6,) its first two columns, column-major (r00, r10, r20, r01, r11, r21)."""
    world_R_tcp = np.asarray(world_R_tcp, dtype=np.float64).reshape(3, 3)
    return np.concatenate([world_R_tcp[:, 0], world_R_tcp[:, 1]])


def matrix_from_rot6d(rot6d: np.ndarray) -> np.ndarray:
    """(6,) two (not necessarily unit or orthogonal) columns -> (3, 3) rotation by Gram-Schmidt.

    Degenerate inputs (a zero first column, or a second column parallel to the first) fall back to a
    valid rotation: the first column to +x, the second to any unit vector orthogonal to the first.
    """
    rot6d = np.asarray(rot6d, dtype=np.float64).reshape(6)
    a, b = rot6d[:3], rot6d[3:]
    a_norm = np.linalg.norm(a)
    x = a / a_norm if a_norm > _NORM_EPS else np.array([1.0, 0.0, 0.0])
    b_orth = b - x * (x @ b)
    b_norm = np.linalg.norm(b_orth)
    if b_norm <= _NORM_EPS:
        helper = np.array([0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
        b_orth = helper - x * (x @ helper)
        b_norm = np.linalg.norm(b_orth)
    y = b_orth / b_norm
    return np.stack([x, y, np.cross(x, y)], axis=1)


def topdown_rotation(yaw: float) -> np.ndarray:
    """``world_R_tcp`` (3, 3) of a gripper pointing straight down (tcp z = world -z).

    ``yaw`` (rad) is the angle of the tcp x axis (the finger closing direction) from world +x about
    world +z; yaw = 0 gives tcp x = world x, tcp y = world -y.
    """
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])


def tilted_rotation(yaw: float, tilt: float) -> np.ndarray:
    """``world_R_tcp`` (3, 3) of the top-down frame of ``yaw`` rotated by ``tilt`` rad about world x.

    A positive ``tilt`` tips the tool's upper end (the top of an object held upright) toward world -y:
    the pouring motion of the condiment expert; the arm reaches it up to past 120 deg.
    """
    c, s = math.cos(tilt), math.sin(tilt)
    world_R_tilt = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    return world_R_tilt @ topdown_rotation(yaw)


def rotation_error(world_R_target: np.ndarray, world_R_current: np.ndarray) -> np.ndarray:
    """(3,) axis-angle vector (world frame, rad) of the rotation taking current to target."""
    world_R_err = world_R_target @ world_R_current.T
    cos_angle = np.clip((np.trace(world_R_err) - 1.0) / 2.0, -1.0, 1.0)
    angle = math.acos(cos_angle)
    axis_sin = np.array(
        [
            world_R_err[2, 1] - world_R_err[1, 2],
            world_R_err[0, 2] - world_R_err[2, 0],
            world_R_err[1, 0] - world_R_err[0, 1],
        ]
    )
    if angle < 1e-6:
        return axis_sin / 2.0
    if math.pi - angle < 1e-4:
        # Near 180 deg the antisymmetric part vanishes: take the axis from the symmetric part.
        sym = (world_R_err + np.eye(3)) / 2.0
        axis = sym[:, int(np.argmax(np.diag(sym)))]
        return axis / np.linalg.norm(axis) * angle
    return axis_sin / (2.0 * math.sin(angle)) * angle
