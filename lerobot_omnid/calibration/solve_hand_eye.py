"""Solving the pose of a camera on the gripper (eye-in-hand) with OpenCV: ``gripper_T_cam`` from views of a
board fixed in the scene, each taken at a known gripper pose ``base_T_gripper``, with
``cv2.calibrateHandEye``; and how consistently it explains the views (see
:mod:`lerobot_omnid.calibration.hand_eye` for the frames and the file it goes into)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import cv2
import numpy as np

from lerobot_omnid.calibration.board import BoardDetection, BoardSpec
from lerobot_omnid.calibration.hand_eye import HandEyeCalibration, invert_rigid, parse_hand_eye_entry
from lerobot_omnid.calibration.schema import CalibrationError, CameraCalibration
from lerobot_omnid.calibration.solve import (
    check_pose_board,
    detect_views,
    estimate_cam_T_board,
    fit_intrinsics,
)
from lerobot_omnid.keys import image_key

HAND_EYE_METHODS = MappingProxyType(
    {
        "tsai": cv2.CALIB_HAND_EYE_TSAI,
        "park": cv2.CALIB_HAND_EYE_PARK,
        "horaud": cv2.CALIB_HAND_EYE_HORAUD,
        "andreff": cv2.CALIB_HAND_EYE_ANDREFF,
        "daniilidis": cv2.CALIB_HAND_EYE_DANIILIDIS,
    }
)
"""``cv2.calibrateHandEye`` methods by their ``--method`` name."""
MIN_HAND_EYE_VIEWS = 3  # robot poses with a detected board: two motions about non-parallel axes at least
MIN_GOOD_TURN_DEG = 15.0  # deg: a largest rotation between two robot poses below this gets a warning
MAX_GOOD_SPREAD_MM = 5.0  # mm: board position spread over the views above this gets a warning
MAX_GOOD_SPREAD_DEG = 1.0  # deg: board rotation spread over the views above this gets a warning


def _rotation_deg(a_R_b: np.ndarray) -> np.ndarray:
    """Rotation angles (...,) in degrees of rotation matrices (..., 3, 3)."""
    cos = (np.trace(a_R_b, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _mean_rigid(a_T_b: np.ndarray) -> np.ndarray:
    """Mean (4, 4) of rigid transforms (N, 4, 4): mean translation, rotation nearest the mean matrix."""
    u, _, vt = np.linalg.svd(a_T_b[:, :3, :3].sum(axis=0))
    mean = np.eye(4)
    mean[:3, :3] = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    mean[:3, 3] = a_T_b[:, :3, 3].mean(axis=0)
    return mean


def board_consistency(
    base_T_gripper: np.ndarray,
    gripper_T_cam: np.ndarray,
    cam_T_board: np.ndarray,
    detections: Sequence[BoardDetection],
    board: BoardSpec,
    K: np.ndarray,
    distortion: np.ndarray,
) -> tuple[np.ndarray, dict[str, float]]:
    """How well one ``gripper_T_cam`` explains N views of a board that stayed in place.

    Each view implies the board's pose in the base frame, ``base_T_gripper @ gripper_T_cam @ cam_T_board``;
    they agree when the calibration, the robot poses and the board poses are right.

    Args:
        base_T_gripper: (N, 4, 4) the gripper's pose in each view; gripper_T_cam: (4, 4).
        cam_T_board: (N, 4, 4) the board's pose in the camera frame in each view (solvePnP).
        detections: the N views' corners; board, K, distortion: for reprojecting them.

    Returns:
        ``base_T_board`` (4, 4), the mean of the implied poses, and the residuals: the spread of the board's
        centre (``board_spread_mm_rms`` / ``_max``, mm) and of its orientation (``board_spread_deg_rms`` /
        ``_max``, degrees) around that mean, and the corners of the board at the mean pose reprojected into
        each view through ``inv(base_T_gripper @ gripper_T_cam)``, the per-frame extrinsics
        (``reprojection_rms_px`` over all corners, ``reprojection_max_view_px`` of the worst view).
    """
    base_T_board_views = base_T_gripper @ gripper_T_cam @ cam_T_board
    base_T_board = _mean_rigid(base_T_board_views)
    nx, ny, size = *board.inner_corners, board.square_size
    centre_board = np.array([(nx - 1) / 2 * size, (ny - 1) / 2 * size, 0.0, 1.0])  # homogeneous
    offsets_mm = (base_T_board_views @ centre_board - base_T_board @ centre_board)[:, :3] * 1000
    spread_mm = np.linalg.norm(offsets_mm, axis=1)
    spread_deg = _rotation_deg(base_T_board[:3, :3].T @ base_T_board_views[:, :3, :3])
    cam_T_base = invert_rigid(base_T_gripper @ gripper_T_cam)
    squared, view_rms = [], []
    for detection, cam_T_base_view in zip(detections, cam_T_base, strict=True):
        cam_T_board_view = cam_T_base_view @ base_T_board
        rvec = cv2.Rodrigues(cam_T_board_view[:3, :3])[0]
        proj, _ = cv2.projectPoints(
            detection.xyz_board.astype(np.float64), rvec, cam_T_board_view[:3, 3], K, distortion
        )
        err2 = np.sum((proj.reshape(-1, 2) - detection.uv_pix) ** 2, axis=-1)
        squared.append(err2)
        view_rms.append(float(np.sqrt(err2.mean())))
    residuals = {
        "board_spread_mm_rms": float(np.sqrt(np.mean(spread_mm**2))),
        "board_spread_mm_max": float(spread_mm.max()),
        "board_spread_deg_rms": float(np.sqrt(np.mean(spread_deg**2))),
        "board_spread_deg_max": float(spread_deg.max()),
        "reprojection_rms_px": float(np.sqrt(np.concatenate(squared).mean())),
        "reprojection_max_view_px": max(view_rms),
    }
    return base_T_board, residuals


def solve_gripper_T_cam(base_T_gripper: np.ndarray, cam_T_board: np.ndarray, method: str) -> np.ndarray:
    """Eye-in-hand ``gripper_T_cam`` (4, 4) with ``cv2.calibrateHandEye`` from (N, 4, 4) gripper poses in the
    base frame and board poses in the camera frame, N >= 3."""
    R, t = cv2.calibrateHandEye(
        base_T_gripper[:, :3, :3],
        base_T_gripper[:, :3, 3],
        cam_T_board[:, :3, :3],
        cam_T_board[:, :3, 3],
        method=HAND_EYE_METHODS[method],
    )
    if not (np.isfinite(R).all() and np.isfinite(t).all()) or abs(np.linalg.det(R) - 1.0) > 1e-6:
        raise CalibrationError(
            f"hand-eye: cv2.calibrateHandEye ({method}) found no rigid solution: the views are inconsistent"
        )
    gripper_T_cam = np.eye(4)
    gripper_T_cam[:3, :3], gripper_T_cam[:3, 3] = R, t.ravel()
    return gripper_T_cam


@dataclass(frozen=True)
class HandEyeResult:
    """A camera on the gripper: its calibration, the board's pose in the base frame (mean over the views,
    (4, 4)) and how well it all fits (``meta`` goes into the hand-eye file)."""

    key: str
    calibration: HandEyeCalibration
    base_T_board: np.ndarray
    meta: dict

    def summary(self) -> str:
        K, m = np.asarray(self.calibration.K), self.meta
        gripper_T_cam = np.asarray(self.calibration.T_gripper_cam)
        centre = ", ".join(f"{v:+.4f}" for v in gripper_T_cam[:3, 3])
        axis = ", ".join(f"{v:+.3f}" for v in gripper_T_cam[:3, 2])
        lines = [
            f"{self.key}: {self.calibration.image_size[1]}x{self.calibration.image_size[0]} px, "
            f"fx {K[0, 0]:.1f} fy {K[1, 1]:.1f} cx {K[0, 2]:.1f} cy {K[1, 2]:.1f} px",
            f"  camera centre ({centre}) m in the gripper frame, optical axis ({axis})",
        ]
        if "intrinsics_rms_px" in m:
            rms, views = m["intrinsics_rms_px"], m["intrinsics_views"]
            lines.append(f"  intrinsics: reprojection RMS {rms:.3f} px over {views} images")
        lines += [
            f"  board poses (solvePnP): reprojection RMS up to {m['pnp_rms_px_max']:.3f} px",
            f"  hand-eye ({m['method']}, {m['views']} views, largest turn between two of them "
            f"{m['largest_turn_deg']:.0f} deg): the board's pose in the base frame varies over the views by "
            f"RMS {m['board_spread_mm_rms']:.2f} mm / {m['board_spread_deg_rms']:.2f} deg (max "
            f"{m['board_spread_mm_max']:.2f} mm / {m['board_spread_deg_max']:.2f} deg)",
            f"  the board reprojected through the per-frame extrinsics: RMS "
            f"{m['reprojection_rms_px']:.2f} px (worst view {m['reprojection_max_view_px']:.2f} px)",
        ]
        return "\n".join(lines)


def _check_image_names(camera: str, images: Sequence[Path], base_T_gripper: Mapping[str, np.ndarray]) -> None:
    """Every image has a pose (by file name, each name once); poses without an image are listed."""
    names = [path.name for path in images]
    twice = sorted({name for name in names if names.count(name) > 1})
    if twice:
        raise CalibrationError(f"--images: file names given twice {twice[:5]}; poses are keyed by file name")
    missing = [name for name in names if name not in base_T_gripper]
    if missing:
        raise CalibrationError(
            f"--gripper-poses: no T_base_gripper for {len(missing)} image(s): {missing[:5]} (keys are image "
            f"file names without folders, e.g. {names[0]!r})"
        )
    unused = sorted(set(base_T_gripper) - set(names))
    if unused:
        print(f"{camera}: {len(unused)} gripper pose(s) without an image: {unused[:5]}")


def _inconsistency_hint(
    spread_mm: float,
    base_T_gripper: np.ndarray,
    cam_T_board: np.ndarray,
    detections: Sequence[BoardDetection],
    board: BoardSpec,
    K: np.ndarray,
    distortion: np.ndarray,
    method: str,
) -> str:
    """What to check when the views disagree by ``spread_mm``: inverted poses when those fit much better."""
    inverted = invert_rigid(base_T_gripper)
    try:
        gripper_T_cam = solve_gripper_T_cam(inverted, cam_T_board, method)
    except CalibrationError:
        gripper_T_cam = None
    if gripper_T_cam is not None:
        _, fit = board_consistency(inverted, gripper_T_cam, cam_T_board, detections, board, K, distortion)
        if fit["board_spread_mm_max"] < spread_mm / 3:
            return (
                f"with the poses inverted the board would vary by {fit['board_spread_mm_max']:.1f} mm: does "
                f"the file hold T_gripper_base instead of T_base_gripper?"
            )
    return "check that each pose belongs to its image, that they are in metres, and that the board stayed"


def calibrate_hand_eye(
    camera: str,
    board: BoardSpec,
    images: Sequence[Path],
    base_T_gripper: Mapping[str, np.ndarray],
    method: str = "park",
    intrinsics_images: Sequence[Path] = (),
    pinhole: bool = False,
    intrinsics: CameraCalibration | HandEyeCalibration | None = None,
) -> HandEyeResult:
    """``T_gripper_cam`` of a camera on the gripper from ``images`` of a board fixed in the scene, each taken
    at the gripper pose ``base_T_gripper[image file name]`` (4, 4, base frame, metres).

    Intrinsics are fitted to ``intrinsics_images`` (default: ``images``) unless ``intrinsics`` gives them;
    board poses come from ``solvePnP``, ``T_gripper_cam`` from ``cv2.calibrateHandEye`` (``method``, one of
    ``HAND_EYE_METHODS``), residuals from :func:`board_consistency`. Shows progress; warns about poor
    conditioning or fit; raises :class:`CalibrationError` naming the image or the file entry.
    """
    check_pose_board(board)
    if method not in HAND_EYE_METHODS:
        raise CalibrationError(f"--method: expected one of {sorted(HAND_EYE_METHODS)}, got {method!r}")
    _check_image_names(camera, images, base_T_gripper)
    detections = detect_views(camera, board, images)
    meta: dict[str, Any] = {"tool": "omnid-calibrate hand-eye", "board": board.describe(), "method": method}
    if intrinsics is None:
        views = detect_views(camera, board, intrinsics_images) if intrinsics_images else detections
        K, distortion, image_size, notes = fit_intrinsics(camera, views, pinhole)
        meta.update(notes)
    else:
        K, image_size = np.asarray(intrinsics.K), tuple(intrinsics.image_size)
        distortion = np.asarray(intrinsics.distortion, np.float64)
        meta["intrinsics"] = "reused"
    if len(detections) < MIN_HAND_EYE_VIEWS:
        raise CalibrationError(
            f"hand-eye: the board was found in {len(detections)} image(s), need at least "
            f"{MIN_HAND_EYE_VIEWS} (better 10+, the gripper turned about different axes between them)"
        )
    for path, detection in detections.items():
        if detection.image_size != image_size:
            raise CalibrationError(
                f"{path}: image size {detection.image_size} (h, w) differs from the intrinsics' {image_size}"
            )
    views = list(detections.values())
    base_T_gripper_views = np.stack([base_T_gripper[path.name] for path in detections])
    pnp = [estimate_cam_T_board(view, K, distortion) for view in views]
    cam_T_board = np.stack([cam_T_board_view for cam_T_board_view, _ in pnp])
    rotations = base_T_gripper_views[:, :3, :3]
    largest_turn = float(_rotation_deg(np.einsum("iba,jbc->ijac", rotations, rotations)).max())
    if largest_turn < MIN_GOOD_TURN_DEG:
        print(
            f"warning: {camera}: the gripper turns by at most {largest_turn:.1f} degrees between two views; "
            f"hand-eye needs rotations about different axes (tilt and roll the gripper by 20-40 degrees)"
        )
    evidence = (base_T_gripper_views, cam_T_board, views, board, K, distortion, method)
    try:
        gripper_T_cam = solve_gripper_T_cam(base_T_gripper_views, cam_T_board, method)
    except CalibrationError as e:
        raise CalibrationError(f"{e}; {_inconsistency_hint(math.inf, *evidence)}") from e
    base_T_board, residuals = board_consistency(
        base_T_gripper_views, gripper_T_cam, cam_T_board, views, board, K, distortion
    )
    spread_mm, spread_deg = residuals["board_spread_mm_max"], residuals["board_spread_deg_max"]
    if spread_mm > MAX_GOOD_SPREAD_MM or spread_deg > MAX_GOOD_SPREAD_DEG:
        print(
            f"warning: {camera}: the board's pose in the base frame varies over the views by up to "
            f"{spread_mm:.1f} mm / {spread_deg:.2f} deg; {_inconsistency_hint(spread_mm, *evidence)}"
        )
    meta.update(
        views=len(views),
        images=[path.name for path in detections],
        pnp_rms_px_max=max(rms for _, rms in pnp),
        largest_turn_deg=largest_turn,
        **residuals,
        T_base_board=base_T_board,
    )
    key = image_key(camera)
    entry = {
        "K": K.tolist(),
        "T_gripper_cam": gripper_T_cam.tolist(),
        "image_size": [int(image_size[0]), int(image_size[1])],
        "distortion": [float(v) for v in distortion],
    }
    return HandEyeResult(key, parse_hand_eye_entry(entry, camera=key), base_T_board, meta)
