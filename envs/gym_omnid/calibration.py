"""MuJoCo camera -> OpenCV pinhole calibration (pure numpy functions).

Conventions (docs/calibration.md): ``K`` is for an image of ``(height, width)`` with pixel centres at integer
coordinates, u right, v down. ``cam_T_world`` (stored as ``T_cam_world``) maps world points to the
OpenCV camera frame (x right, y down, z forward), so ``uv_pix = K @ (cam_T_world @ xyz_world)[:3]``
divided by its third component.

A MuJoCo camera frame has x right, y up and looks down its -z axis; ``cam_xmat`` holds the camera
axes as columns in world coordinates. OpenCV's frame is MuJoCo's with y and z flipped.
"""

from __future__ import annotations

import math

import numpy as np

# Rotation taking OpenCV camera coordinates to MuJoCo camera coordinates (flip y and z).
MJCAM_R_CVCAM = np.diag([1.0, -1.0, -1.0])
DEPTH_EPS = 1e-9  # m: smallest depth accepted in a perspective divide
# Observation keys of the per-frame calibration (env option ``per_frame_calibration``), one pair per
# observed camera: ``f"{EXTRINSICS_OBS_PREFIX}{cam}"`` is ``T_cam_world`` row-major (16,) and
# ``f"{INTRINSICS_OBS_PREFIX}{cam}"`` is ``K`` row-major (9,), float32. LeRobot's ``preprocess_observation``
# passes them on as ``observation.extrinsics.<cam>`` / ``observation.intrinsics.<cam>``, the names of
# the dataset columns ``omnid-record`` writes (by default).
EXTRINSICS_OBS_PREFIX = "extrinsics."
INTRINSICS_OBS_PREFIX = "intrinsics."


def look_at_xyaxes(
    position: tuple[float, float, float],
    target: tuple[float, float, float],
    roll_deg: float = 0.0,
    up: tuple[float, float, float] = (0.0, 0.0, 1.0),
) -> np.ndarray:
    """MuJoCo ``xyaxes`` (6,) of a camera at ``position`` looking at ``target``, in the parent's frame.

    MuJoCo cameras look along their -z axis, x right and y up. With ``roll_deg = 0`` the image's up is
    as close to ``up`` as the viewing direction allows; ``roll_deg`` then turns the camera about its
    viewing axis (positive: its x axis towards its y axis, so the scene turns clockwise in the image).
    """
    z_axis = np.asarray(position, dtype=np.float64) - np.asarray(target, dtype=np.float64)
    z_axis /= np.linalg.norm(z_axis)
    x_axis = np.cross(np.asarray(up, dtype=np.float64), z_axis)
    x_axis /= np.linalg.norm(x_axis)
    y_axis = np.cross(z_axis, x_axis)
    roll = math.radians(roll_deg)
    x_rolled = math.cos(roll) * x_axis + math.sin(roll) * y_axis
    y_rolled = -math.sin(roll) * x_axis + math.cos(roll) * y_axis
    return np.concatenate([x_rolled, y_rolled])


def intrinsics_from_fovy(fovy_deg: float, height: int, width: int) -> np.ndarray:
    """OpenCV ``K`` (3, 3) of a MuJoCo camera with vertical field of view ``fovy_deg`` (degrees).

    The image plane spans ``height`` pixels over fovy; pixels are square (fx = fy) and pixel centres
    are at integers, so the principal point is ((width - 1) / 2, (height - 1) / 2).
    """
    f_pix = (height / 2.0) / math.tan(math.radians(fovy_deg) / 2.0)
    return np.array(
        [[f_pix, 0.0, (width - 1) / 2.0], [0.0, f_pix, (height - 1) / 2.0], [0.0, 0.0, 1.0]],
        dtype=np.float64,
    )


def cam_T_world_from_mujoco(cam_xpos: np.ndarray, cam_xmat: np.ndarray) -> np.ndarray:
    """World -> OpenCV camera transform (4, 4) from MuJoCo's camera pose.

    Args:
        cam_xpos: (3,) camera position in the world frame (``data.cam_xpos[i]``), metres.
        cam_xmat: (3, 3) or (9,) ``world_R_mjcam`` (``data.cam_xmat[i]``): MuJoCo camera axes as columns.
    """
    world_R_mjcam = np.asarray(cam_xmat, dtype=np.float64).reshape(3, 3)
    world_R_cvcam = world_R_mjcam @ MJCAM_R_CVCAM
    cvcam_R_world = world_R_cvcam.T
    cam_T_world = np.eye(4, dtype=np.float64)
    cam_T_world[:3, :3] = cvcam_R_world
    cam_T_world[:3, 3] = -cvcam_R_world @ np.asarray(cam_xpos, dtype=np.float64)
    return cam_T_world


def invert_rigid(a_T_b: np.ndarray) -> np.ndarray:
    """Inverse (4, 4) of a rigid transform: ``b_T_a``."""
    b_T_a = np.eye(4, dtype=np.float64)
    b_T_a[:3, :3] = a_T_b[:3, :3].T
    b_T_a[:3, 3] = -a_T_b[:3, :3].T @ a_T_b[:3, 3]
    return b_T_a


def project(K: np.ndarray, cam_T_world: np.ndarray, xyz_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project world points to pixels.

    Args:
        K: (3, 3) intrinsics.
        cam_T_world: (4, 4) world -> OpenCV camera.
        xyz_world: (N, 3) points in metres.

    Returns:
        ``uv_pix`` (N, 2) pixel coordinates (u right, v down) and ``depth`` (N,) along the optical axis
        in metres; points with ``depth <= DEPTH_EPS`` are behind the camera and their ``uv_pix`` is NaN.
    """
    xyz_world = np.atleast_2d(np.asarray(xyz_world, dtype=np.float64))
    xyz_cam = xyz_world @ cam_T_world[:3, :3].T + cam_T_world[:3, 3]
    depth = xyz_cam[:, 2]
    in_front = depth > DEPTH_EPS
    uvw = xyz_cam @ K.T
    uv_pix = np.full((len(xyz_world), 2), np.nan)
    uv_pix[in_front] = uvw[in_front, :2] / depth[in_front, None]
    return uv_pix, depth


def unproject(K: np.ndarray, cam_T_world: np.ndarray, uv_pix: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Inverse of :func:`project`: pixels (N, 2) with depths (N,) -> world points (N, 3)."""
    uv_pix = np.atleast_2d(np.asarray(uv_pix, dtype=np.float64))
    depth = np.asarray(depth, dtype=np.float64).reshape(-1)
    uv1 = np.concatenate([uv_pix, np.ones((len(uv_pix), 1))], axis=1)
    xyz_cam = (uv1 @ np.linalg.inv(K).T) * depth[:, None]
    world_T_cam = invert_rigid(cam_T_world)
    return xyz_cam @ world_T_cam[:3, :3].T + world_T_cam[:3, 3]


def mujoco_camera_calibration(
    fovy_deg: float, cam_xpos: np.ndarray, cam_xmat: np.ndarray, image_size: tuple[int, int]
) -> dict:
    """Calibration dict ``{"K", "T_cam_world", "image_size"}`` of one MuJoCo camera.

    Args:
        fovy_deg: the camera's vertical field of view (``model.cam_fovy[i]``), degrees.
        cam_xpos: (3,) camera position, world frame, metres.
        cam_xmat: (3, 3) or (9,) MuJoCo camera orientation (axes as columns).
        image_size: (height, width) in pixels of the rendered images.
    """
    height, width = image_size
    return {
        "K": intrinsics_from_fovy(fovy_deg, height, width),
        "T_cam_world": cam_T_world_from_mujoco(cam_xpos, cam_xmat),
        "image_size": (int(height), int(width)),
    }


def calibration_observation(cam: str, calib: dict) -> dict[str, np.ndarray]:
    """The per-frame calibration observation entries of camera ``cam`` (see ``EXTRINSICS_OBS_PREFIX``)."""
    return {
        f"{EXTRINSICS_OBS_PREFIX}{cam}": calib["T_cam_world"].astype(np.float32).reshape(16),
        f"{INTRINSICS_OBS_PREFIX}{cam}": calib["K"].astype(np.float32).reshape(9),
    }
