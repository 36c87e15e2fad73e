"""A camera on the gripper (eye-in-hand): its hand-eye calibration file, and the extrinsics it has in every
frame, from the gripper's pose in that frame.

Frames: ``T_a_b`` maps points from frame b into frame a (``X_a = T_a_b @ X_b``), so it is also frame b's
pose in frame a (its last column is b's origin in a's coordinates). The base (world) frame is the robot
base frame of :mod:`lerobot_omnid.calibration.schema` (x forward, y left, z up, metres, z = 0 on the table
top); the gripper frame is any frame fixed to the link the camera is mounted on (flange, tool frame, or
the URDF's end-effector frame: the same one for calibrating and for the frames); the camera frame is
OpenCV's (x right, y down, z forward). With ``T_gripper_cam`` from ``omnid-calibrate hand-eye`` and the
gripper's pose ``T_base_gripper(t)`` in frame t (the robot's forward kinematics), the camera's extrinsics
are::

    T_cam_world(t) = inv(T_base_gripper(t) @ T_gripper_cam)

Hand-eye file (JSON or YAML, read and written like a calibration file of
:mod:`lerobot_omnid.calibration.rig_file`), keyed by camera (``wrist`` or ``observation.images.wrist``):

- ``image_size``, ``K``, ``distortion`` (optional), ``meta`` (optional): as in a calibration file;
- ``T_gripper_cam``: 4x4, maps OpenCV camera-frame points into the gripper frame
  (``X_gripper = T_gripper_cam @ X_cam``): the camera's pose on the gripper, its last column the optical
  centre in gripper coordinates (metres), its rotation columns the camera's x, y and optical axis.

Any other key is an error. Example (YAML)::

    observation.images.wrist:
      image_size: [480, 640]
      K: [[416.3, 0.0, 319.3], [0.0, 416.4, 239.3], [0.0, 0.0, 1.0]]
      T_gripper_cam:          # 8 cm beside and 14 cm behind the gripper frame's origin, along its z axis
        - [1.0, 0.0, 0.0, 0.0]
        - [0.0, 1.0, 0.0, -0.08]
        - [0.0, 0.0, 1.0, -0.14]
        - [0.0, 0.0, 0.0, 1.0]
      meta: {method: park, views: 10, board_spread_mm_max: 0.17, reprojection_rms_px: 0.06}

Gripper poses file (input of ``omnid-calibrate hand-eye``; JSON or YAML): the gripper's pose in the base
frame when each image was taken, keyed by image file name (without folders)::

    T_base_gripper:
      view00.png: [[r00, r01, r02, x], [r10, r11, r12, y], [r20, r21, r22, z], [0, 0, 0, 1]]
      view01.png: ...
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lerobot_omnid.calibration.frame_columns import extrinsics_key, intrinsics_key
from lerobot_omnid.calibration.rig_file import (
    homogeneous_matrix,
    load_camera_entries,
    parse_camera_entry,
    read_mapping_file,
    write_mapping_file,
)
from lerobot_omnid.calibration.schema import ASPECT_TOLERANCE, CalibrationError, CameraCalibration
from lerobot_omnid.keys import image_key

HAND_EYE_FIELDS = ("image_size", "K", "T_gripper_cam", "distortion", "meta")
POSES_FIELD = "T_base_gripper"
POSE_ROTATION_TOL = 1e-3  # max deviation of R^T R from identity accepted in a gripper pose (rounded input)
MAX_REACH_M = 5.0  # m: a gripper farther than this from the base means the poses are not in metres


def invert_rigid(a_T_b: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms (..., 4, 4): ``b_T_a``, float64."""
    a_T_b = np.asarray(a_T_b, dtype=np.float64)
    b_R_a = np.swapaxes(a_T_b[..., :3, :3], -1, -2)
    b_T_a = np.zeros_like(a_T_b)
    b_T_a[..., :3, :3] = b_R_a
    b_T_a[..., :3, 3] = -(b_R_a @ a_T_b[..., :3, 3:])[..., 0]
    b_T_a[..., 3, 3] = 1.0
    return b_T_a


def cam_T_world_from_gripper(base_T_gripper: np.ndarray, gripper_T_cam: np.ndarray) -> np.ndarray:
    """Extrinsics of a camera fixed on the gripper: ``inv(base_T_gripper @ gripper_T_cam)``.

    Args:
        base_T_gripper: (..., 4, 4) the gripper's poses in the robot base (world) frame, e.g. (T, 4, 4)
            for the T frames of an episode.
        gripper_T_cam: (4, 4) the camera's pose in the gripper frame (``T_gripper_cam``).

    Returns:
        (..., 4, 4) ``T_cam_world``: world points -> OpenCV camera frame, float64.
    """
    base_T_gripper = np.asarray(base_T_gripper, dtype=np.float64)
    gripper_T_cam = np.asarray(gripper_T_cam, dtype=np.float64)
    if base_T_gripper.shape[-2:] != (4, 4) or gripper_T_cam.shape != (4, 4):
        raise ValueError(
            f"expected base_T_gripper (..., 4, 4) and gripper_T_cam (4, 4), got shapes "
            f"{base_T_gripper.shape} and {gripper_T_cam.shape}"
        )
    return invert_rigid(base_T_gripper @ gripper_T_cam)


@dataclass(frozen=True)
class HandEyeCalibration:
    """A camera on the gripper: its intrinsics and its fixed pose on the gripper.

    Args:
        K: 3x3 intrinsics in pixels for images of ``image_size``.
        T_gripper_cam: 4x4 rigid transform from the OpenCV camera frame to the gripper frame.
        image_size: (height, width) in pixels that ``K`` refers to.
        distortion: OpenCV distortion coefficients of the raw images (empty for a pinhole fit).
    """

    K: tuple[tuple[float, ...], ...]
    T_gripper_cam: tuple[tuple[float, ...], ...]
    image_size: tuple[int, int]
    distortion: tuple[float, ...] = ()

    def at(self, base_T_gripper: np.ndarray) -> CameraCalibration:
        """The camera's calibration in a frame where the gripper is at ``base_T_gripper`` (4, 4)."""
        cam_T_world = cam_T_world_from_gripper(base_T_gripper, self.T_gripper_cam)
        rows = tuple(tuple(row) for row in cam_T_world.tolist())
        return CameraCalibration(self.K, rows, self.image_size, self.distortion)

    def to_entry(self) -> dict[str, Any]:
        """The camera's entry of a hand-eye file (without ``meta``)."""
        entry: dict[str, Any] = {
            "image_size": list(self.image_size),
            "K": [list(row) for row in self.K],
            "T_gripper_cam": [list(row) for row in self.T_gripper_cam],
        }
        if self.distortion:
            entry["distortion"] = list(self.distortion)
        return entry


def calibration_columns(
    camera: str,
    base_T_gripper: np.ndarray,
    hand_eye: HandEyeCalibration,
    image_size: tuple[int, int] | None = None,
    ignore_distortion: bool = False,
) -> dict[str, np.ndarray]:
    """The per-frame calibration columns (:mod:`lerobot_omnid.calibration.frame_columns`) of a camera on the
    gripper, from the gripper's pose in every frame.

    Args:
        camera: camera name or image key (``wrist``, ``observation.images.wrist``).
        base_T_gripper: (T, 4, 4) the gripper's pose in the robot base frame in each of T frames.
        hand_eye: the camera's hand-eye calibration.
        image_size: (height, width) of the dataset's images (default: the calibration's); ``K`` is
            rescaled to it (same aspect ratio; another one is refused).
        ignore_distortion: accept a calibration with non-zero distortion, although the columns hold ``K``
            only and OmniD projects with the pinhole model (the images must then be undistorted).

    Returns:
        ``{observation.extrinsics.<cam>: (T, 16), observation.intrinsics.<cam>: (T, 9)}``, float32 row-major.
    """
    base_T_gripper = np.asarray(base_T_gripper, dtype=np.float64)
    if base_T_gripper.ndim != 3 or base_T_gripper.shape[1:] != (4, 4) or len(base_T_gripper) == 0:
        raise ValueError(f"base_T_gripper: expected (T, 4, 4) with T >= 1, got shape {base_T_gripper.shape}")
    if any(hand_eye.distortion) and not ignore_distortion:
        raise CalibrationError(
            f"{image_key(camera)}.distortion: non-zero, but the columns hold K only and OmniD assumes "
            f"undistorted images; calibrate with --pinhole, or pass ignore_distortion=True for images "
            f"undistorted with this K"
        )
    (height, width), (calib_h, calib_w) = image_size or hand_eye.image_size, hand_eye.image_size
    if abs((height / calib_h) / (width / calib_w) - 1.0) > ASPECT_TOLERANCE:
        raise CalibrationError(
            f"{image_key(camera)}.image_size: the calibration is for {calib_h}x{calib_w} (h x w), the images "
            f"are {height}x{width}: another aspect ratio (a crop) cannot be rescaled"
        )
    K = np.asarray(hand_eye.at(base_T_gripper[0]).resized((height, width)).K)
    cam_T_world = cam_T_world_from_gripper(base_T_gripper, hand_eye.T_gripper_cam)
    frames = len(base_T_gripper)
    return {
        extrinsics_key(camera): cam_T_world.reshape(frames, 16).astype(np.float32),
        intrinsics_key(camera): np.tile(K.reshape(1, 9), (frames, 1)).astype(np.float32),
    }


def parse_hand_eye_entry(entry: Any, camera: str) -> HandEyeCalibration:
    """Validate one camera's entry of a hand-eye file (see the module docstring); errors name ``camera`` and
    the field."""
    if not isinstance(entry, Mapping):
        raise CalibrationError(
            f"{camera}: expected a hand-eye calibration mapping, got {type(entry).__name__}"
        )
    unknown = sorted(str(k) for k in entry if k not in HAND_EYE_FIELDS)
    if unknown:
        raise CalibrationError(
            f"{camera}: unknown field(s) {unknown}; allowed fields are {list(HAND_EYE_FIELDS)}"
        )
    if "T_gripper_cam" not in entry:
        raise CalibrationError(
            f"{camera}: field 'T_gripper_cam' is missing (the camera's pose in the gripper frame, 4x4)"
        )
    as_rig_entry = {k: v for k, v in entry.items() if k != "T_gripper_cam"}
    as_rig_entry["T_cam_world"] = entry["T_gripper_cam"]
    try:
        calib = parse_camera_entry(as_rig_entry, camera)
    except CalibrationError as e:
        raise CalibrationError(str(e).replace(".T_cam_world", ".T_gripper_cam")) from e
    return HandEyeCalibration(calib.K, calib.T_cam_world, calib.image_size, calib.distortion)


def load_hand_eye_file(path: str | Path) -> dict[str, HandEyeCalibration]:
    """Read and validate a hand-eye file; errors name the file, the camera and the field.

    Returns the calibrations keyed by image feature key (``observation.images.<cam>``).
    """
    return load_camera_entries(path, parse_hand_eye_entry, kind="hand-eye file")


def save_hand_eye_file(
    path: str | Path, camera: str, calibration: HandEyeCalibration, meta: Mapping[str, Any] | None = None
) -> Path:
    """Add ``camera`` (or replace it) in the hand-eye file at ``path``, created if absent; the other cameras
    of an existing file are kept (it is validated first). Replaced whole or not at all."""
    path = Path(path)
    entries: dict[str, Any] = {}
    if path.exists():
        load_hand_eye_file(path)
        entries = {image_key(str(k)): v for k, v in read_mapping_file(path).items()}
    entry = calibration.to_entry()
    if meta:
        entry["meta"] = dict(meta)
    entries[image_key(camera)] = entry
    return write_mapping_file(path, entries)


def _gripper_pose(value: Any, where: str) -> np.ndarray:
    """A validated rigid 4x4 (metres) from a poses file; the rotation is projected onto the nearest one."""
    T = homogeneous_matrix(value, where)
    R = T[:3, :3]
    deviation = float(np.abs(R.T @ R - np.eye(3)).max())
    if deviation > POSE_ROTATION_TOL or np.linalg.det(R) < 0:
        raise CalibrationError(
            f"{where}: the rotation part is not a rotation (|R^T R - I| = {deviation:.2g}, det = "
            f"{np.linalg.det(R):.3f})"
        )
    reach = float(np.linalg.norm(T[:3, 3]))
    if reach > MAX_REACH_M:
        raise CalibrationError(
            f"{where}: the gripper is {reach:g} from the base; translations must be in metres"
        )
    u, _, vt = np.linalg.svd(R)
    T[:3, :3] = u @ vt
    return T


def load_gripper_poses(path: str | Path) -> dict[str, np.ndarray]:
    """``T_base_gripper`` (4, 4) by image file name from a gripper poses file (see the module docstring)."""
    path = Path(path)
    data = read_mapping_file(path)
    unknown = sorted(str(k) for k in data if k != POSES_FIELD)
    if unknown or not isinstance(data.get(POSES_FIELD), Mapping) or not data[POSES_FIELD]:
        raise CalibrationError(
            f"gripper poses file {path}: expected only '{POSES_FIELD}', a mapping of image file name to a "
            f"4x4 matrix, got {'field(s) ' + str(unknown) if unknown else repr(data.get(POSES_FIELD))[:80]}"
        )
    return {
        str(name): _gripper_pose(value, f"{path.name}: {POSES_FIELD}.{name}")
        for name, value in data[POSES_FIELD].items()
    }
