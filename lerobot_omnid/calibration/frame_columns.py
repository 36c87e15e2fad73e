"""Per-frame camera calibration as ordinary LeRobot dataset columns.

Schema, for every camera ``<cam>`` (its image feature is ``observation.images.<cam>``):

- ``observation.extrinsics.<cam>``: float32, shape (16,), names ``T_cam_world_00`` ... ``T_cam_world_33``:
  the frame's ``T_cam_world`` (world = robot base frame -> OpenCV camera frame), row-major;
- ``observation.intrinsics.<cam>``: float32, shape (9,), names ``K_00`` ... ``K_22``: the frame's ``K`` for
  the image size stored in the dataset (the image feature's shape), row-major.

The convention is that of :mod:`lerobot_omnid.calibration.schema`. A static camera has constant
columns. LeRobot's open DP3 work uses the same key names with (4, 4) / (3, 3) shapes and a
camera-to-world extrinsic: these columns are flat (``reshape(4, 4)``) and hold the inverse,
world-to-camera.

The trap: LeRobot's ``dataset_to_policy_features`` turns every non-image ``observation.*`` key, these
included, into a STATE feature whose normaliser rescales it. A policy must read them raw and keep them
out of its state: :func:`is_calibration_key` tells them apart.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
import torch
from lerobot.utils.constants import OBS_IMAGES, OBS_STR
from torch import Tensor

from lerobot_omnid.keys import camera_name

EXTRINSICS_PREFIX = f"{OBS_STR}.extrinsics."
INTRINSICS_PREFIX = f"{OBS_STR}.intrinsics."
EXTRINSICS_SHAPE = (4, 4)
INTRINSICS_SHAPE = (3, 3)
EXTRINSICS_NAMES = tuple(f"T_cam_world_{r}{c}" for r in range(4) for c in range(4))
INTRINSICS_NAMES = tuple(f"K_{r}{c}" for r in range(3) for c in range(3))


def _camera(camera: str) -> str:
    """``cam_b`` or ``observation.images.cam_b`` -> ``cam_b``; other feature keys are refused."""
    name = camera_name(camera)
    if not name or name.startswith(f"{OBS_STR}."):
        raise ValueError(
            f"camera: expected a camera name or an image key '{OBS_IMAGES}.<camera>', got {camera!r}"
        )
    return name


def extrinsics_key(camera: str) -> str:
    """``cam_b`` (or ``observation.images.cam_b``) -> ``observation.extrinsics.cam_b``."""
    return EXTRINSICS_PREFIX + _camera(camera)


def intrinsics_key(camera: str) -> str:
    """``cam_b`` (or ``observation.images.cam_b``) -> ``observation.intrinsics.cam_b``."""
    return INTRINSICS_PREFIX + _camera(camera)


def is_calibration_key(key: str) -> bool:
    """Whether ``key`` is a per-frame calibration column (to be read raw, never as state)."""
    return key.startswith((EXTRINSICS_PREFIX, INTRINSICS_PREFIX))


def calibration_column_features(cameras: Iterable[str]) -> dict[str, dict[str, Any]]:
    """LeRobot feature specs (for ``LeRobotDataset.create``) of the columns of ``cameras``."""
    features: dict[str, dict[str, Any]] = {}
    for cam in cameras:
        features[extrinsics_key(cam)] = {
            "dtype": "float32",
            "shape": (len(EXTRINSICS_NAMES),),
            "names": list(EXTRINSICS_NAMES),
        }
        features[intrinsics_key(cam)] = {
            "dtype": "float32",
            "shape": (len(INTRINSICS_NAMES),),
            "names": list(INTRINSICS_NAMES),
        }
    return features


def _to_column(matrix: Any, shape: tuple[int, int], field: str) -> np.ndarray:
    values = np.asarray(matrix, dtype=np.float64)
    if values.shape != shape:
        raise ValueError(f"{field}: expected a {shape[0]}x{shape[1]} matrix, got shape {values.shape}")
    return values.astype(np.float32).reshape(-1)


def extrinsics_column(cam_T_world: Any) -> np.ndarray:
    """(4, 4) ``T_cam_world`` -> the (16,) float32 column value, row-major."""
    return _to_column(cam_T_world, EXTRINSICS_SHAPE, "T_cam_world")


def intrinsics_column(K: Any) -> np.ndarray:
    """(3, 3) ``K`` -> the (9,) float32 column value, row-major."""
    return _to_column(K, INTRINSICS_SHAPE, "K")


def _from_column[Array: (np.ndarray, Tensor)](values: Array, shape: tuple[int, int], field: str) -> Array:
    size = shape[0] * shape[1]
    if len(values.shape) == 0 or values.shape[-1] != size:
        raise ValueError(f"{field}: expected a last dimension of {size}, got shape {tuple(values.shape)}")
    return values.reshape(*values.shape[:-1], *shape)


def extrinsics_from_column[Array: (np.ndarray, Tensor)](values: Array) -> Array:
    """(..., 16) column values (numpy or torch) -> (..., 4, 4) ``T_cam_world``, same type and dtype."""
    return _from_column(values, EXTRINSICS_SHAPE, "extrinsics")


def intrinsics_from_column[Array: (np.ndarray, Tensor)](values: Array) -> Array:
    """(..., 9) column values (numpy or torch) -> (..., 3, 3) ``K``, same type and dtype."""
    return _from_column(values, INTRINSICS_SHAPE, "intrinsics")


FRAME_TOLERANCE = 1e-3
"""Absolute tolerance of the per-frame checks: float32 columns of a proper K and a rigid T are exact to
about 1e-6; an all-zero or garbled column is off by order 1."""


def frame_calibration_problem(
    K: Tensor, cam_T_world: Tensor, tolerance: float = FRAME_TOLERANCE
) -> tuple[tuple[int, ...], str] | None:
    """The first frame whose calibration is not a camera's, and why; None when every frame is one.

    The per-frame twin of :meth:`lerobot_omnid.calibration.schema.CameraCalibration.validate`, vectorised
    and with a tolerance for float32 columns.

    Args:
        K: (..., 3, 3) intrinsics, expected ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` with fx, fy > 0.
        cam_T_world: (..., 4, 4) extrinsics, expected rigid: orthonormal rotation of determinant +1, last
            row ``[0, 0, 0, 1]``.
    Returns:
        (index into the leading dims, reason) of the first bad frame, or None.
    """
    K, T = K.double(), cam_T_world.double()
    R = T[..., :3, :3]
    eye = torch.eye(3, dtype=R.dtype, device=R.device)
    checks = (
        (~torch.isfinite(K).all(dim=(-1, -2)), "K has non-finite values"),
        (~torch.isfinite(T).all(dim=(-1, -2)), "T_cam_world has non-finite values"),
        (
            (K[..., 0, 0] <= 0)
            | (K[..., 1, 1] <= 0)
            | (K[..., 1, 0].abs() > tolerance)
            | ((K[..., 2, :] - K.new_tensor([0.0, 0.0, 1.0])).abs() > tolerance).any(dim=-1),
            "K is not [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0",
        ),
        (
            ((T[..., 3, :] - T.new_tensor([0.0, 0.0, 0.0, 1.0])).abs() > tolerance).any(dim=-1),
            "T_cam_world's last row is not [0, 0, 0, 1]",
        ),
        (
            ((R @ R.transpose(-1, -2) - eye).abs() > tolerance).any(dim=(-1, -2)) | (torch.linalg.det(R) < 0),
            "T_cam_world's rotation part is not a rotation (orthonormal, determinant +1)",
        ),
    )
    for bad, reason in checks:
        if bad.any():
            index = tuple(int(i) for i in bad.nonzero()[0])
            return index, reason
    return None
