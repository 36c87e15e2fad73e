"""Solving a camera's calibration from board detections with OpenCV: intrinsics from several views,
extrinsics in the robot base frame from one view of the board at a known pose (``world_T_board``). A camera
on the gripper: :mod:`lerobot_omnid.calibration.solve_hand_eye`."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from lerobot_omnid.calibration.board import MIN_CHARUCO_CORNERS, BoardDetection, BoardSpec, detect_board
from lerobot_omnid.calibration.hand_eye import HandEyeCalibration
from lerobot_omnid.calibration.rig_file import read_mapping_file
from lerobot_omnid.calibration.schema import CalibrationError, CameraCalibration
from lerobot_omnid.keys import image_key

MIN_INTRINSICS_VIEWS = 4  # images with a detected board needed to estimate K
RECOMMENDED_VIEWS = 10
MAX_GOOD_RMS_PX = 1.0  # px: reprojection RMS above this gets a warning
BOARD_POINTS_TOL_M = 0.005  # m: allowed mismatch of measured board corner distances (or 2%)


@dataclass(frozen=True)
class Intrinsics:
    """``K`` (3, 3), OpenCV ``distortion`` (5,) or (0,) for a pinhole fit, reprojection RMS over all views
    and per view (px)."""

    K: np.ndarray
    distortion: np.ndarray
    rms_px: float
    view_rms_px: tuple[float, ...]


def calibrate_intrinsics(detections: Sequence[BoardDetection], pinhole: bool = False) -> Intrinsics:
    """OpenCV ``calibrateCamera`` over board views of one camera.

    Args:
        detections: views of the board, all of one image size.
        pinhole: fit a distortion-free model (distortion fixed to zero): the best pinhole approximation
            of the raw images, for datasets recorded without undistortion.
    """
    if len(detections) < MIN_INTRINSICS_VIEWS:
        raise CalibrationError(
            f"intrinsics: the board was found in {len(detections)} image(s), need at least "
            f"{MIN_INTRINSICS_VIEWS} (better {RECOMMENDED_VIEWS}+, tilted and spread over the image)"
        )
    sizes = {d.image_size for d in detections}
    if len(sizes) > 1:
        raise CalibrationError(f"intrinsics: images of different sizes {sorted(sizes)}; use one resolution")
    height, width = detections[0].image_size
    flags = 0
    if pinhole:
        flags = cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3
    object_points = [d.xyz_board.astype(np.float32) for d in detections]
    image_points = [d.uv_pix.astype(np.float32).reshape(-1, 1, 2) for d in detections]
    rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(
        object_points, image_points, (width, height), None, None, flags=flags
    )
    view_rms = []
    for obj, img, rvec, tvec in zip(object_points, image_points, rvecs, tvecs, strict=True):
        proj, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
        view_rms.append(float(np.sqrt(np.mean(np.sum((proj - img) ** 2, axis=-1)))))
    return Intrinsics(K, np.zeros(0) if pinhole else dist.ravel()[:5], float(rms), tuple(view_rms))


def estimate_cam_T_board(
    detection: BoardDetection, K: np.ndarray, distortion: np.ndarray
) -> tuple[np.ndarray, float]:
    """``cam_T_board`` (4, 4) of one view and its reprojection RMS (px): ``solvePnP`` (IPPE for a planar
    target, refined by Levenberg-Marquardt)."""
    obj = detection.xyz_board.astype(np.float64)
    img = detection.uv_pix.astype(np.float64).reshape(-1, 1, 2)
    ok, rvec, tvec = cv2.solvePnP(obj, img, K, distortion, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise CalibrationError("extrinsics: solvePnP found no board pose")
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, distortion, rvec, tvec)
    proj, _ = cv2.projectPoints(obj, rvec, tvec, K, distortion)
    rms = float(np.sqrt(np.mean(np.sum((proj - img) ** 2, axis=-1))))
    cam_T_board = np.eye(4)
    cam_T_board[:3, :3] = cv2.Rodrigues(rvec)[0]
    cam_T_board[:3, 3] = tvec.ravel()
    return cam_T_board, rms


def estimate_cam_T_world(
    detection: BoardDetection, world_T_board: np.ndarray, K: np.ndarray, distortion: np.ndarray
) -> tuple[np.ndarray, float]:
    """``cam_T_world`` (4, 4) from one view of the board at a known pose, and its reprojection RMS (px):
    ``cam_T_world = cam_T_board @ inv(world_T_board)``, ``cam_T_board`` from :func:`estimate_cam_T_board`."""
    cam_T_board, rms = estimate_cam_T_board(detection, K, distortion)
    return cam_T_board @ np.linalg.inv(world_T_board), rms


def world_T_board_on_table(x: float, y: float, yaw_deg: float, z: float = 0.0) -> np.ndarray:
    """Pose of a board lying face up: origin at (x, y, z), board x at ``yaw_deg`` from world x, z down."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    world_T_board = np.eye(4)
    # Columns: board x, board y = z cross x, board z = -world z (into the board, which faces up).
    world_T_board[:3, :3] = np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])
    world_T_board[:3, 3] = (x, y, z)
    return world_T_board


def world_T_board_from_points(
    origin: Sequence[float], x_end: Sequence[float], y_end: Sequence[float], board: BoardSpec
) -> np.ndarray:
    """Board pose from three measured corners (world frame, metres): the origin, the last inner corner
    along x and the last inner corner along y. Their distances must match the board's geometry."""
    p0, px, py = (np.asarray(p, np.float64) for p in (origin, x_end, y_end))
    nx, ny = board.inner_corners
    for name, point, n in (("x", px, nx), ("y", py, ny)):
        measured, expected = np.linalg.norm(point - p0), (n - 1) * board.square_size
        if abs(measured - expected) > max(BOARD_POINTS_TOL_M, 0.02 * expected):
            raise CalibrationError(
                f"--board-points: the last inner corner along {name} is {measured:.4f} m from the origin, "
                f"expected {expected:.4f} m ({n - 1} squares of {board.square_size} m): check the points"
            )
    x_axis = (px - p0) / np.linalg.norm(px - p0)
    z_axis = np.cross(x_axis, py - p0)
    z_axis /= np.linalg.norm(z_axis)
    angle = math.degrees(math.acos(np.clip(np.dot(x_axis, (py - p0) / np.linalg.norm(py - p0)), -1, 1)))
    if abs(angle - 90.0) > 3.0:
        raise CalibrationError(f"--board-points: the x and y edges make {angle:.1f} degrees, expected 90")
    world_T_board = np.eye(4)
    world_T_board[:3, :3] = np.stack([x_axis, np.cross(z_axis, x_axis), z_axis], axis=1)
    world_T_board[:3, 3] = p0
    return world_T_board


def load_board_pose(path: str | Path) -> np.ndarray:
    """``T_world_board`` (4, 4) from a JSON/YAML file ``{"T_world_board": [[...], ...]}``."""
    data = read_mapping_file(Path(path))
    if "T_world_board" not in data:
        raise CalibrationError(f"board pose file {path}: expected a 'T_world_board' 4x4 matrix")
    # Reuse the rigid-transform validation of the calibration schema.
    dummy_K = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    try:
        calib = CameraCalibration.from_dict(
            {"K": dummy_K, "T_cam_world": data["T_world_board"], "image_size": [1, 1]}, camera=f"{path}"
        )
    except CalibrationError as e:
        raise CalibrationError(str(e).replace(".T_cam_world", ".T_world_board")) from e
    return np.asarray(calib.T_cam_world, np.float64)


@dataclass(frozen=True)
class CameraResult:
    """One camera's calibration and how well it fits (``meta`` goes into the calibration file)."""

    key: str
    calibration: CameraCalibration
    meta: dict

    def summary(self) -> str:
        K = np.asarray(self.calibration.K)
        world_T_cam = np.linalg.inv(np.asarray(self.calibration.T_cam_world))
        centre = ", ".join(f"{v:+.3f}" for v in world_T_cam[:3, 3])
        axis = ", ".join(f"{v:+.2f}" for v in world_T_cam[:3, 2])
        lines = [
            f"{self.key}: {self.calibration.image_size[1]}x{self.calibration.image_size[0]} px, "
            f"fx {K[0, 0]:.1f} fy {K[1, 1]:.1f} cx {K[0, 2]:.1f} cy {K[1, 2]:.1f} px",
            f"  camera centre ({centre}) m in the robot base frame, optical axis ({axis})",
        ]
        if "intrinsics_rms_px" in self.meta:
            views = self.meta["intrinsics_views"]
            lines.append(
                f"  intrinsics: reprojection RMS {self.meta['intrinsics_rms_px']:.3f} px over {views} images"
            )
        lines.append(f"  extrinsics: reprojection RMS {self.meta['extrinsics_rms_px']:.3f} px")
        return "\n".join(lines)


def _read_image(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise CalibrationError(f"{path}: not a readable image")
    return image


def check_pose_board(board: BoardSpec) -> None:
    """Refuse a board whose pose cannot be read from an image (a checkerboard symmetric under 180 degrees)."""
    if board.orientation_ambiguous:
        raise CalibrationError(
            f"--pattern {board.cols}x{board.rows}: a checkerboard with both inner corner counts "
            f"{'odd' if board.cols % 2 else 'even'} looks the same turned by 180 degrees, so its pose is "
            f"ambiguous; use one odd and one even count (e.g. 9x6) or a ChArUco board"
        )


def detect_views(camera: str, board: BoardSpec, paths: Sequence[Path]) -> dict[Path, BoardDetection]:
    """The board found in each image (images without it are left out and listed); shows progress."""
    detections, missed = {}, []
    for path in tqdm(paths, desc=f"{camera}: finding the board", unit="image"):
        found = detect_board(_read_image(path), board)
        if found is None:
            missed.append(path)
        else:
            detections[path] = found
    if missed:
        print(f"{camera}: no board found in {len(missed)} image(s): {', '.join(map(str, missed[:5]))}")
    return detections


def fit_intrinsics(
    camera: str, detections: Mapping[Path, BoardDetection], pinhole: bool
) -> tuple[np.ndarray, np.ndarray, tuple[int, int], dict[str, Any]]:
    """``K``, distortion, image size (h, w) and notes for the calibration file's ``meta``, from board views
    (:func:`calibrate_intrinsics`); warns when the reprojection error is high."""
    used = list(detections)
    result = calibrate_intrinsics(list(detections.values()), pinhole=pinhole)
    worst = int(np.argmax(result.view_rms_px))
    if result.rms_px > MAX_GOOD_RMS_PX:
        print(
            f"warning: {camera}: intrinsics reprojection RMS {result.rms_px:.2f} px is high (worst: "
            f"{used[worst]}, {result.view_rms_px[worst]:.2f} px); check focus, motion blur and the "
            f"board's flatness"
        )
    meta = {"intrinsics_views": len(used), "intrinsics_rms_px": result.rms_px, "pinhole_fit": pinhole}
    return result.K, result.distortion, detections[used[0]].image_size, meta


def calibrate_camera(
    camera: str,
    board: BoardSpec,
    intrinsics_images: Sequence[Path],
    extrinsics_image: Path,
    world_T_board: np.ndarray,
    pinhole: bool = False,
    intrinsics: CameraCalibration | HandEyeCalibration | None = None,
) -> CameraResult:
    """Intrinsics from ``intrinsics_images`` (or reuse those of ``intrinsics``), then ``T_cam_world`` from one
    view of the board at ``world_T_board``. Shows progress; raises :class:`CalibrationError` naming the
    image."""
    check_pose_board(board)
    key = image_key(camera)
    meta: dict = {"tool": "omnid-calibrate", "board": board.describe()}
    if intrinsics is None:
        K, distortion, image_size, notes = fit_intrinsics(
            camera, detect_views(camera, board, intrinsics_images), pinhole
        )
        meta.update(notes)
    else:
        K, image_size = np.asarray(intrinsics.K), intrinsics.image_size
        distortion = np.asarray(intrinsics.distortion, np.float64)
        meta["intrinsics"] = "reused"
    detection = detect_board(_read_image(extrinsics_image), board)
    if detection is None:
        needed = "every inner corner" if board.kind == "checkerboard" else f"{MIN_CHARUCO_CORNERS}+ corners"
        raise CalibrationError(f"{extrinsics_image}: the board was not found ({needed} must be visible)")
    if detection.image_size != tuple(image_size):
        raise CalibrationError(
            f"{extrinsics_image}: image size {detection.image_size} (h, w) differs from the intrinsics' "
            f"{tuple(image_size)}"
        )
    cam_T_world, rms = estimate_cam_T_world(detection, world_T_board, K, distortion)
    meta["extrinsics_rms_px"] = rms
    if rms > MAX_GOOD_RMS_PX:
        print(f"warning: {camera}: extrinsics reprojection RMS {rms:.2f} px is high ({extrinsics_image})")
    centre_world = np.linalg.inv(cam_T_world)[:3, 3]
    if centre_world[2] < 0:
        print(
            f"warning: {camera}: the camera comes out {-centre_world[2]:.2f} m below the table top; check "
            f"the board pose (the board's z axis points into the board: down for a board lying face up)"
        )
    calibration = CameraCalibration.from_dict(
        {
            "K": K.tolist(),
            "T_cam_world": cam_T_world.tolist(),
            "image_size": [int(image_size[0]), int(image_size[1])],
            "distortion": [float(v) for v in distortion],
        },
        camera=key,
    )
    return CameraResult(key, calibration, meta)
