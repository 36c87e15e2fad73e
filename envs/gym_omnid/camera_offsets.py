"""Camera offsets: the env option ``camera_offsets`` moves rendered cameras by a small rigid delta.

It stands for a camera bumped after calibration: the images come from the moved camera while a policy
keeps the calibration it was given. Per camera six numbers ``(rx, ry, rz, tx, ty, tz)``: a rotation vector
``r`` in degrees (unit axis times angle) and a translation ``t`` in metres, both in the camera's OpenCV
frame (x right, y down, z forward), applied as

    T_cam_world' = [R(r) | t] @ T_cam_world

so the camera turns by ``|r|`` degrees about its optical centre and its optical centre then moves by
``|t|`` metres (to ``c - world_R_cam' @ t``). This is the convention of
``lerobot_omnid.geometry.perturb_extrinsics``: a calibration perturbed by a delta and a scene whose camera
moved by the same delta are mirror images. Offsets are added to the rig's placement (option ``rig``) and
apply to any camera, the wrist camera included (there relative to the hand).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import mujoco
import numpy as np

from gym_omnid.calibration import MJCAM_R_CVCAM
from gym_omnid.constants import ALL_CAMERAS

OFFSET_SIZE = 6  # rx, ry, rz (degrees), tx, ty, tz (metres)


def check_camera_offsets(value: Any) -> dict[str, tuple[float, ...]]:
    """Validate ``camera_offsets``: a mapping from cameras of ``ALL_CAMERAS`` to six finite numbers
    (rotation vector in degrees, translation in metres; see the module). Returns it with float tuples."""
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ValueError(
            f"camera_offsets: expected a mapping camera -> [rx, ry, rz (deg), tx, ty, tz (m)], got {value!r}"
        )
    offsets = {}
    for cam, offset in value.items():
        if cam not in ALL_CAMERAS:
            raise ValueError(f"camera_offsets: expected cameras from {list(ALL_CAMERAS)}, got {cam!r}")
        numbers = tuple(offset) if isinstance(offset, list | tuple | np.ndarray) else ()
        ok = len(numbers) == OFFSET_SIZE and all(
            isinstance(v, int | float | np.number) and not isinstance(v, bool) and math.isfinite(v)
            for v in numbers
        )
        if not ok:
            raise ValueError(
                f"camera_offsets[{cam}]: expected {OFFSET_SIZE} finite numbers [rx, ry, rz (deg), tx, ty, tz "
                f"(m)], got {offset!r}"
            )
        offsets[cam] = tuple(float(v) for v in numbers)
    return offsets


def rotation_from_vector_deg(rotvec_deg: np.ndarray) -> np.ndarray:
    """(3,) rotation vector in degrees (axis times angle) -> (3, 3) rotation matrix (Rodrigues)."""
    rotvec = np.radians(np.asarray(rotvec_deg, dtype=np.float64))
    angle = float(np.linalg.norm(rotvec))
    if angle == 0.0:
        return np.eye(3)
    x, y, z = rotvec / angle
    skew = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.eye(3) + math.sin(angle) * skew + (1.0 - math.cos(angle)) * (skew @ skew)


def offset_camera_pose(
    pos: np.ndarray, quat: np.ndarray, offset: tuple[float, ...]
) -> tuple[np.ndarray, np.ndarray]:
    """A MuJoCo camera's ``(cam_pos, cam_quat)`` in its parent's frame after ``offset`` (see the module).

    ``cam_quat`` gives ``parent_R_mjcam`` (MuJoCo camera axes: x right, y up, looking down -z).
    """
    cvcam_R_newcam = rotation_from_vector_deg(offset[:3]).T  # new camera axes in the old camera frame
    parent_R_mjcam = np.zeros(9)
    mujoco.mju_quat2Mat(parent_R_mjcam, np.asarray(quat, dtype=np.float64))
    parent_R_cvcam = parent_R_mjcam.reshape(3, 3) @ MJCAM_R_CVCAM
    parent_R_newcam = parent_R_cvcam @ cvcam_R_newcam
    new_pos = np.asarray(pos, dtype=np.float64) - parent_R_newcam @ np.asarray(offset[3:], dtype=np.float64)
    new_quat = np.zeros(4)
    mujoco.mju_mat2Quat(new_quat, (parent_R_newcam @ MJCAM_R_CVCAM).reshape(-1))
    return new_pos, new_quat


def apply_camera_offsets(model: mujoco.MjModel, offsets: Mapping[str, tuple[float, ...]]) -> None:
    """Move the model's cameras by ``offsets`` (validated by :func:`check_camera_offsets`), in place."""
    for cam, offset in offsets.items():
        cam_id = model.camera(cam).id
        model.cam_pos[cam_id], model.cam_quat[cam_id] = offset_camera_pose(
            model.cam_pos[cam_id], model.cam_quat[cam_id], offset
        )
